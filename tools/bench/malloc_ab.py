#!/usr/bin/env python3
"""The allocator settings of the command (xtask/src/memory.rs) against glibc's defaults: one
gb-nerf command, run in turn with the binary's settings (A) and with `GB_MALLOC_DEFAULTS=1`
(B, the reference), PAIRS times, A then B. Records each run's wall time and peak resident
memory (the child's own rusage), the medians and the per-pair ratio A/B, and the machine, in
one JSON. `{tmp}` in the command's arguments is a fresh empty folder for each run.

    python3 tools/bench/malloc_ab.py --bin target/debug/gb-nerf --pairs 3 \\
        --out bench/results/malloc-export-stairs-cpu-2core.json \\
        -- export --run out/RUN --to {tmp}/export --orbit-frames 0

Standard library only.
"""

import argparse
import json
import os
import platform
import statistics
import subprocess
import tempfile
import time


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def one(binary, command, defaults):
    env = dict(os.environ)
    env.pop("GB_MALLOC_DEFAULTS", None)
    if defaults:
        env["GB_MALLOC_DEFAULTS"] = "1"
    with tempfile.TemporaryDirectory() as tmp:
        argv = [binary] + [a.replace("{tmp}", tmp) for a in command]
        start = time.monotonic()
        proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.monotonic() - start
        err = proc.stderr.read().decode(errors="replace")
        proc.stderr.close()
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise SystemExit(f"error: {' '.join(argv)} exited {code}: {err.strip()[-400:]}")
    return {"wall_seconds": wall, "peak_rss_mib": usage.ru_maxrss / 1024.0}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", required=True, help="the gb-nerf binary")
    ap.add_argument("--label", required=True, help="what the command measures, for the report")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--out", required=True)
    ap.add_argument("command", nargs="+", help="the gb-nerf arguments, after --")
    args = ap.parse_args()
    if not os.access(args.bin, os.X_OK):
        raise SystemExit(f"error: --bin {args.bin}: not an executable file")
    pairs = []
    for i in range(args.pairs):
        a = one(args.bin, args.command, defaults=False)
        b = one(args.bin, args.command, defaults=True)
        pairs.append({"kept": a, "glibc_defaults": b,
                      "wall_ratio": a["wall_seconds"] / b["wall_seconds"]})
        print(f"pair {i}: kept {a['wall_seconds']:.1f} s, defaults {b['wall_seconds']:.1f} s, "
              f"peak {a['peak_rss_mib']:.0f} / {b['peak_rss_mib']:.0f} MiB", flush=True)

    def med(key, field):
        return statistics.median(p[key][field] for p in pairs)

    report = {
        "benchmark": f"{args.label}: the command's malloc settings against glibc's defaults",
        "machine": {"cpu": cpu_model(), "cores": os.cpu_count(), "system": platform.platform()},
        "command": " ".join([args.bin] + args.command),
        "reference": "the same binary with GB_MALLOC_DEFAULTS=1 (glibc's defaults), run in turn",
        "pairs": pairs,
        "median_wall_seconds": {"kept": med("kept", "wall_seconds"),
                                "glibc_defaults": med("glibc_defaults", "wall_seconds")},
        "median_peak_rss_mib": {"kept": med("kept", "peak_rss_mib"),
                                "glibc_defaults": med("glibc_defaults", "peak_rss_mib")},
        "median_wall_ratio": statistics.median(p["wall_ratio"] for p in pairs),
    }
    with open(args.out, "w") as f:
        json.dump(report, f, indent=1)
        f.write("\n")
    print(f"median ratio kept/defaults {report['median_wall_ratio']:.3f}; wrote {args.out}")


if __name__ == "__main__":
    main()
