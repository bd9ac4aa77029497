#!/usr/bin/env bash
# A settled pile on the GPU machine, in one call of the `device` tool (BENCHMARKS.md,
# "Reproducing"). falling-boxes' first 300 steps are the landing; the pile that stands after
# it costs several times more (about six pairs a box, islands sleeping and waking). The top
# layers fall from higher as the scale grows: at 100k (scale 33.3) the pile is at rest by
# about step 1500 (kinetic energy 22 J), at 500k (166.1) the last boxes land near step 750 at
# about 120 m/s and the pile comes to rest by about step 2400 (3.3 J; 17 MJ at step 900). This
# settles the pile with the last of BINS, dumps it, then runs each binary from the same dump:
# the profile, then the median step without the profiler (`--json`), and last the newest
# build's profile with each dispatch timed (pile-dispatches.txt).
#
#   bash scripts/pile-on-device.sh [SCALE [SETTLE_STEPS [STEPS]]]    # defaults 33.3 900 120
#
# Environment: BINS, the binaries in .devbin/ to run from the dump (default "tumble"; builds
# named by `scripts/build-devbin.sh NAME`, tumble-NAME, give an A/B on the identical pile).
# Builds before acb32e6 refuse a dump with the narrowphase's cache in its contacts (an unknown
# field): against one of those, list it last, so that it settles the pile.
set -euo pipefail

scale=${1:-33.3}
settle=${2:-900}
steps=${3:-120}
out=${OUT:?"OUT is not set: run this through the device tool, or set OUT to a folder"}
source "$(dirname "$0")/device-env.sh"
bins=${BINS:-tumble}
# The pile is settled by the last of BINS (the newest build, by convention).
settler=.devbin/${bins##* }
for bin in $bins; do
  if [ ! -x ".devbin/$bin" ]; then
    echo ".devbin/$bin is missing: run scripts/build-devbin.sh on the development machine and carry .devbin" >&2
    exit 1
  fi
done

{
  echo "date: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
  echo "commit: $(cat .devbin/COMMIT 2> /dev/null || echo unknown)"
  echo "gpu: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2> /dev/null || echo none)"
  echo "cores: $(nproc)"
  echo "pile: falling-boxes --scale $scale, settled $settle steps, then $steps steps a run"
} > "$out/machine.txt"
cat "$out/machine.txt"

# The dump is large (230 MB at 100k bodies): on the machine's disk, not in $OUT.
dump=$(mktemp -d)/pile.json
report="$out/pile.txt"
echo "=== settle: $settler, $settle steps" | tee -a "$report"
"$settler" run falling-boxes --scale "$scale" --device gpu --steps "$settle" --json \
  --dump "$dump" | tail -1 | tee -a "$report"
for bin in $bins; do
  echo "=== $bin: profile" >> "$report"
  ".devbin/$bin" run "$dump" --device gpu --steps "$steps" --profile >> "$report" 2>&1 || true
  echo "=== $bin: median" | tee -a "$report"
  ".devbin/$bin" run "$dump" --device gpu --steps "$steps" --json 2>&1 | tail -1 | tee -a "$report" |
    grep -oE '"ms_per_step":[0-9.]+' || true
done
# Each dispatch timed (gpu/profiler.rs), with the newest build: which kernel takes the time.
echo "=== ${bins##* }: each dispatch timed" >> "$report"
TUMBLE_PROFILE_DISPATCHES=1 "$settler" run "$dump" --device gpu --steps "$steps" --profile \
  > "$out/pile-dispatches.txt" 2>&1 || true
rm -f "$dump"
