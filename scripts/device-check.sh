#!/usr/bin/env bash
# One call of the `device` tool that compares builds on the GPU machine: what NVIDIA's
# compiler makes of each build's kernels (registers, spills: each .devbin/kernel_stats-NAME of
# a build in BINS), falling-boxes at 3k with each build, two rounds, then the settled 100k
# pile (scripts/pile-on-device.sh), whose results must agree bit for bit between builds that
# change no arithmetic, and last the lib tests (the kernels' parity tests against the host,
# which lavapipe cannot fully stand in for: its subgroups are 8 wide and its workgroups run on
# a thread pool), when their binary was carried. The newest build (the last of BINS) also runs
# 3k and the pile with each dispatch timed (falling-3k-dispatches.txt, pile-dispatches.txt).
#
# Here, first: `scripts/build-devbin.sh NAME` for each build (tumble-NAME.gz and
# kernel_stats-NAME.gz in .devbin, 10 MB a build), and optionally the lib tests:
#   mkdir -p .devbin/libtest && strip -o .devbin/libtest/tumble-lib "$(cargo test -p tumble \
#     --lib --no-run 2>&1 | grep -oE 'target/debug/deps/tumble-[0-9a-f]+' | head -1)" &&
#     gzip -f .devbin/libtest/tumble-lib
# Then, with carry [".gl", ".devbin"]:   BINS="tumble-base tumble-new" bash scripts/device-check.sh
set -u
out=${OUT:?"OUT is not set: run this through the device tool, or set OUT to a folder"}
source "$(dirname "$0")/device-env.sh"
bins=${BINS:-tumble}
for bin in $bins; do
  stats=.devbin/kernel_stats${bin#tumble}
  [ -x "$stats" ] || continue
  # stacked-boxes has contacts from its first step, so its three steps compile every kernel of
  # a box world's step (falling-boxes' boxes are still in the air).
  "$stats" stacked-boxes 3 > "$out/kernel-stats-$bin.txt" 2>&1
  echo "== kernel stats, $bin"
  grep -E "kernels of|report|^(solve|warm_start_bodies|narrowphase|rows build|radix scatter) /" \
    "$out/kernel-stats-$bin.txt" | cut -c1-300
done
echo "== falling-boxes at 3k, two rounds"
for round in 1 2; do
  for bin in $bins; do
    echo -n "$bin: "
    ".devbin/$bin" run falling-boxes --device gpu --steps 300 --json 2> /dev/null | tail -1 |
      tee -a "$out/falling-3k.txt" |
      grep -oE '"ms_per_step":[0-9.]+|"kinetic_energy":[0-9.]+|"solver":[0-9.]+' | tr '\n' ' '
    echo
  done
done
for bin in $bins; do
  ".devbin/$bin" run falling-boxes --device gpu --steps 300 --profile \
    > "$out/falling-3k-profile-$bin.txt" 2>&1
done
TUMBLE_PROFILE_DISPATCHES=1 ".devbin/${bins##* }" run falling-boxes --device gpu --steps 300 \
  --profile > "$out/falling-3k-dispatches.txt" 2>&1
echo "== the settled 100k pile"
BINS="$bins" bash "$(dirname "$0")/pile-on-device.sh" 33.3 1500 120 2>&1 |
  grep -E "===|ms_per_step" | cut -c1-200
grep -E "^=== |kernels|solver \(|collision \(" "$out/pile.txt" | cut -c1-120
echo "== the pile's ten slowest kernels, each dispatch timed (${bins##* })"
# The lines under the profile's `dispatches` line (N -- dispatches: its kernels are N.1, N.2...).
line=$(grep -oE "^[0-9]+ -- dispatches" "$out/pile-dispatches.txt" | cut -d' ' -f1)
grep -E "^   ${line:-none}\.[0-9]+ -- " "$out/pile-dispatches.txt" | sort -t: -k3 -rn | head -10 |
  cut -c1-120
if [ -x .devbin/libtest/tumble-lib ]; then
  echo "== lib tests"
  timeout 240 .devbin/libtest/tumble-lib --test-threads 1 > "$out/libtests.txt" 2>&1
  grep -E "^test result|FAILED|panicked" "$out/libtests.txt" | head -20
fi
# Last, the medians again: the device tool brings back the tail of stdout only, and with
# several builds the profiles above push the head out (session 23 lost the pile's medians).
echo "== summary: falling-boxes at 3k (ms_per_step, builds in order, two rounds), the pile's medians"
grep -oE '"ms_per_step":[0-9.]+' "$out/falling-3k.txt" | cut -d: -f2 | tr '\n' ' '
echo
grep -A1 -E "^=== .*: median" "$out/pile.txt" | grep -oE "^=== [^:]+|\"ms_per_step\":[0-9.]+" |
  tr '\n' ' '
echo
