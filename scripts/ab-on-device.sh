#!/usr/bin/env bash
# An A/B of builds on both settled piles in one short call of the `device` tool, for when
# machines are scarce (session 28's shape, BENCHMARKS.md): settle 100k boxes once, run each build
# from the dump in alternating rounds (`--json` medians), the same at 500k, then the per-batch
# dispatch profile of the first build at 100k. Every build's kinetic energy is printed beside its
# time: builds that change no arithmetic must agree to the bit. Output is written as it comes
# (log.txt in $OUT), so a call cut short still brings back what it measured; about 190 s with
# three builds on an H100.
#
#   BINS="base new" bash scripts/ab-on-device.sh [ROUNDS]      # builds .devbin/tumble-NAME
#
# Environment: BINS (build names, as scripts/build-devbin.sh NAME makes them; default "base"),
# PILES (default "100k 500k"), ROUNDS (or the first argument; default 2).
set -uo pipefail

out=${OUT:?"OUT is not set: run this through the device tool, or set OUT to a folder"}
source "$(dirname "$0")/device-env.sh"
bins=${BINS:-base}
rounds=${1:-${ROUNDS:-2}}
first=${bins%% *}
for bin in $bins; do
  if [ ! -x ".devbin/tumble-$bin" ]; then
    echo ".devbin/tumble-$bin is missing: run scripts/build-devbin.sh $bin here and carry .devbin" >&2
    exit 1
  fi
done
exec > >(tee "$out/log.txt") 2>&1
echo "gpu: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2> /dev/null || echo none)"
echo "builds: $bins ($(tr '\n' ' ' < .devbin/BUILDS 2> /dev/null))"
dump=$(mktemp -d)/pile.json

# One run of build $1 from the dump for $2 steps: its median and kinetic energy.
median() {
  ".devbin/tumble-$1" run "$dump" --device gpu --steps "$2" --json 2> /dev/null | tail -1 |
    grep -oE '"ms_per_step":[0-9.]+|"kinetic_energy":[0-9.]+' | tr '\n' ' '
}

for pile in ${PILES:-100k 500k}; do
  # falling-boxes' scale, settling steps (rest by about step 1500 at 100k, 2400 at 500k) and
  # steps a run, as scripts/pile-on-device.sh has them.
  case "$pile" in
    100k) scale=33.3 settle=1500 steps=120 ;;
    500k) scale=166.1 settle=2400 steps=40 ;;
    *) echo "unknown pile $pile (100k or 500k)" >&2; exit 2 ;;
  esac
  SECONDS=0
  ".devbin/tumble-$first" run falling-boxes --scale "$scale" --device gpu --steps "$settle" \
    --json --dump "$dump" > /dev/null 2>&1
  echo "== $pile pile, settled by $first in $SECONDS s; $steps steps a run"
  for _ in $(seq "$rounds"); do
    for bin in $bins; do
      echo "$bin: $(median "$bin" "$steps")"
    done
  done
  if [ "$pile" = 100k ]; then
    for bin in $bins; do
      ".devbin/tumble-$bin" run "$dump" --device gpu --steps "$steps" --profile \
        > "$out/profile-$bin.txt" 2>&1
      echo "$bin, solver's kernels: $(grep -E '^   [0-9]+\.[0-9]+ -- kernels \[gpu\]' \
        "$out/profile-$bin.txt" | tail -1 | grep -oE '[0-9.]+ ms')"
    done
    TUMBLE_PROFILE_DISPATCHES=1 ".devbin/tumble-$first" run "$dump" --device gpu \
      --steps "$steps" --profile > "$out/dispatches-$first.txt" 2>&1
  fi
done
rm -rf "$(dirname "$dump")"
