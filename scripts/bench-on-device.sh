#!/usr/bin/env bash
# The benchmark suite on the GPU machine, in one call of the `device` tool (BENCHMARKS.md,
# "Reproducing"). Builds nothing, copies nothing: runs the release binary built here beforehand
# by scripts/build-devbin.sh and writes tables, CSVs, charts and machine.txt into $OUT.
#
#   bash scripts/bench-on-device.sh [all|falling|stacked|prims|profile]
#
# Environment: THREADS (default "1,<all cores>"), TIME_LIMIT_MS (default 250).
set -euo pipefail

part=${1:-all}
case "$part" in
  all | falling | stacked | prims | profile) ;;
  *) echo "usage: $0 [all|falling|stacked|prims|profile]" >&2; exit 2 ;;
esac
out=${OUT:?"OUT is not set: run this through the device tool, or set OUT to a folder"}
binary=.devbin/tumble
source "$(dirname "$0")/device-env.sh"
if [ ! -x "$binary" ]; then
  echo "$binary is missing: run scripts/build-devbin.sh on the development machine and carry .devbin" >&2
  exit 1
fi

threads=${THREADS:-1,$(nproc)}
limit=${TIME_LIMIT_MS:-250}
{
  echo "date: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
  echo "commit: $(cat .devbin/COMMIT 2> /dev/null || echo unknown)"
  echo "gpu: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2> /dev/null || echo none)"
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')"
  echo "cores: $(nproc)"
  echo "threads: $threads  time limit: $limit ms"
} | tee "$out/machine.txt"

# One scene with its flags; the table goes to stdout and to $out/<scene>.txt.
bench() {
  local scene=$1
  shift
  "$binary" bench "$scene" "$@" --threads "$threads" --time-limit-ms "$limit" \
    --csv "$out/$scene.csv" --png "$out/$scene.png" | tee "$out/$scene.txt"
}

if [ "$part" = all ] || [ "$part" = falling ]; then
  bench falling-boxes --bodies 1000,3000,10000,30000,100000,300000,1000000 \
    --engines tumble-cpu,tumble-gpu,rapier --warmup 60 --steps 120
fi
if [ "$part" = all ] || [ "$part" = stacked ]; then
  bench stacked-boxes --scales 1,10 \
    --engines tumble-cpu,tumble-gpu,rapier,rapier-default --warmup 60 --steps 120
fi
if [ "$part" = all ] || [ "$part" = prims ]; then
  "$binary" bench prims | tee "$out/prims.txt"
  # The peer for the sort: PyTorch on the same GPU, in the same call (median of 7, 20 sorts each).
  python3 - << 'PY' 2>&1 | tee -a "$out/prims.txt" || true
import time, torch
for n in (1 << 20, 1 << 24):
    keys = torch.randint(0, 2**31 - 1, (n,), dtype=torch.int64, device="cuda").to(torch.int32)
    for _ in range(3):
        torch.sort(keys, stable=True)
    torch.cuda.synchronize()
    samples = []
    for _ in range(7):
        start = time.perf_counter()
        for _ in range(20):
            torch.sort(keys, stable=True)
        torch.cuda.synchronize()
        samples.append((time.perf_counter() - start) * 1e3 / 20)
    ms = sorted(samples)[3]
    print(f"torch.sort (stable, with indices) {n:>9} keys {ms:10.4f} ms {n / ms / 1e3:10.0f} Mkeys/s")
PY
fi
if [ "$part" = all ] || [ "$part" = profile ]; then
  # The GPU step's stages, copies and waits at 3k and 100k falling boxes: the profile, then
  # the median step without the profiler's timestamps.
  for scale in 1 33; do
    "$binary" run falling-boxes --scale "$scale" --device gpu --steps 300 --profile |
      tee "$out/profile-falling-$scale.txt"
    "$binary" run falling-boxes --scale "$scale" --device gpu --steps 300 --json |
      tee -a "$out/profile-falling-$scale.txt"
  done
fi
