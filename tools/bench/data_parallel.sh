#!/usr/bin/env bash
# Issue 35's benchmark: data-parallel LoRA fine-tuning of the tiny prior on the procedural
# pairs, 2 MPI ranks of one thread each against one process of one thread at the same global
# batch (the one process accumulates 2 micro-batches per step), alternating, REPS runs each.
# From each run's printed summary: steps/s, the gradient exchange's share of the training
# time, the bytes each rank exchanges per step against the trainable (LoRA) bytes. Writes
# bench/results/finetune-data-parallel-<host>-<date>.json.
# GB_NERF names gb-nerf built with the mpi feature (cargo build -p xtask --features mpi).
# Usage: GB_NERF=BIN tools/bench/data_parallel.sh [STEPS] [REPS]
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${GB_NERF:?GB_NERF must name gb-nerf built with --features mpi}"
steps="${1:-40}" reps="${2:-3}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
export RAYON_NUM_THREADS=1 OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
common=(finetune --synthetic --base tiny --steps "$steps" --validation-samples 0 --quiet)
for r in $(seq "$reps"); do
    "$bin" "${common[@]}" --grad-accum 2 --out "$tmp/one-$r" > "$tmp/one-$r.json"
    mpirun -n 2 --oversubscribe -x RAYON_NUM_THREADS "$bin" "${common[@]}" --grad-accum 1 \
        --out "$tmp/two-$r" > "$tmp/two-$r.json"
done
out="bench/results/finetune-data-parallel-$(hostname -s)-$(date +%F).json"
python3 - "$tmp" "$reps" "$steps" "$out" <<'PY'
import json, os, platform, statistics, sys
tmp, reps, steps, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
def runs(kind):
    return [json.load(open(os.path.join(tmp, f"{kind}-{r}.json"))) for r in range(1, reps + 1)]
def losses(kind, r):
    with open(os.path.join(tmp, f"{kind}-{r}", "train_log.jsonl")) as f:
        return [json.loads(l)["loss"] for l in f]
one, two = runs("one"), runs("two")
med = lambda xs: statistics.median(xs)
cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")), platform.processor())
gap = max(abs(a - b) / abs(a) for r in range(1, reps + 1) for a, b in zip(losses("one", r), losses("two", r)))
doc = {
    "benchmark": "data-parallel LoRA fine-tuning (tools/bench/data_parallel.sh)",
    "machine": {"host": platform.node(), "cpu": cpu, "cores": os.cpu_count()},
    "workload": f"tiny prior, procedural pairs, {steps} steps, no validation; the same global batch: 2 ranks x 1 micro-batch against one process x 2 micro-batches; one thread per process",
    "runs": reps,
    "one_process": {"steps_per_second": [x["steps_per_second"] for x in one]},
    "two_ranks": {
        "steps_per_second": [x["steps_per_second"] for x in two],
        "exchange_share": [x["exchange_seconds"] / x["train_seconds"] for x in two],
        "exchanged_bytes_per_step": two[0]["exchanged_bytes_per_step"],
        "trainable_bytes": two[0]["trainable_bytes"],
    },
    "median_speedup_two_ranks_over_one_process": med([x["steps_per_second"] for x in two]) / med([x["steps_per_second"] for x in one]),
    "max_relative_loss_gap": gap,
}
with open(out, "w") as f:
    json.dump(doc, f, indent=2)
    f.write("\n")
print(json.dumps(doc, indent=2))
PY
echo "wrote $out"
