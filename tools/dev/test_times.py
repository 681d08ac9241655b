#!/usr/bin/env python3
"""Times every test of the README's test command and writes the slowest to a JSON report.

Runs `cargo test --workspace` (plus any extra cargo arguments given after `--`) with libtest's
JSON output and per-test times (`-Z unstable-options --format json --report-time`, which a
stable toolchain's test harness accepts under RUSTC_BOOTSTRAP=1; that variable is set by a
runner for the test binaries only, since in cargo's own environment it would change every
crate's fingerprint and rebuild the whole stack), and writes
`bench/results/test-times-LABEL.json`: the machine, the wall time of the whole command, the
number of tests passed, failed and ignored, the number of test binaries run, and the slowest
tests (binary, name, seconds).

    tools/dev/test_times.py LABEL [--top N] [-- EXTRA CARGO ARGS]

Run it alone on the machine: the figures are only comparable that way.
"""

import argparse
import datetime
import json
import os
import platform
import re
import subprocess
import sys
import time


def machine():
    cpu = ""
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "host": platform.node(),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "os": platform.platform(),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("label", help="names the report: bench/results/test-times-LABEL.json")
    ap.add_argument("--top", type=int, default=20, help="how many of the slowest to keep")
    ap.add_argument("extra", nargs="*", help="extra cargo test arguments (after --)")
    args = ap.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    triple = subprocess.run(["rustc", "-vV"], capture_output=True, text=True, check=True).stdout
    triple = re.search(r"^host: (\S+)", triple, re.M).group(1)
    runner = "CARGO_TARGET_" + triple.upper().replace("-", "_") + "_RUNNER"
    env = dict(os.environ, **{runner: "env RUSTC_BOOTSTRAP=1"})
    # the doc-tests run under rustdoc, which the runner does not reach: left out
    cmd = ["cargo", "test", "--workspace", "--lib", "--bins", "--tests", *args.extra, "--",
           "-Z", "unstable-options", "--format", "json", "--report-time"]
    start = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    binary = None
    binaries = []
    tests = []
    counts = {"ok": 0, "failed": 0, "ignored": 0}
    running = re.compile(r"^\s*(Running|Doc-tests)\s+(\S+)")
    for line in proc.stdout:
        sys.stdout.write(line)
        m = running.match(line)
        if m:
            binary = m.group(2)
            binaries.append(binary)
            continue
        if not line.startswith("{"):
            continue
        try:
            event = json.loads(line)
        except json.JSONDecodeError:
            continue
        if event.get("type") != "test" or event.get("event") not in counts:
            continue
        counts[event["event"]] += 1
        if "exec_time" in event:
            tests.append({"binary": binary, "name": event["name"],
                          "seconds": round(float(event["exec_time"]), 3),
                          "result": event["event"]})
    rc = proc.wait()
    wall = time.monotonic() - start
    tests.sort(key=lambda t: -t["seconds"])
    report = {
        "benchmark": "test-times",
        "command": " ".join(cmd),
        "date": datetime.date.today().isoformat(),
        "machine": machine(),
        "exit_status": rc,
        "wall_seconds": round(wall, 1),
        "passed": counts["ok"],
        "failed": counts["failed"],
        "ignored": counts["ignored"],
        "binaries_run": len(binaries),
        "sum_of_test_seconds": round(sum(t["seconds"] for t in tests), 1),
        "slowest": tests[: args.top],
    }
    out = os.path.join(root, "bench", "results", f"test-times-{args.label}.json")
    with open(out, "w") as f:
        json.dump(report, f, indent=2)
        f.write("\n")
    print(f"test_times: {out}: {counts} in {wall:.0f} s, {len(binaries)} binaries", file=sys.stderr)
    sys.exit(rc)


if __name__ == "__main__":
    main()
