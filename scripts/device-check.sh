#!/usr/bin/env bash
# One call of the `device` tool that checks a build on the GPU machine before it is timed, then
# times it against older builds: the lib tests (the kernels' parity tests against the host,
# which lavapipe cannot fully stand in for: its subgroups are 8 wide and its workgroups run on a
# thread pool), falling-boxes at 3k with each binary, then the settled 100k pile
# (scripts/pile-on-device.sh), whose results must agree bit for bit between builds that change
# no arithmetic.
#
# Here, first: scripts/build-devbin.sh; an older build stripped into .devbin/tumble-<name>; the
# lib test binary stripped into .devbin/libtest/tumble-lib:
#   strip -o .devbin/libtest/tumble-lib "$(cargo test -p tumble --lib --no-run 2>&1 |
#     grep -oE 'target/debug/deps/tumble-[0-9a-f]+' | head -1)"
# Then, with carry [".gl", ".devbin"]:   BINS="tumble-<name> tumble" bash scripts/device-check.sh
set -u
out=${OUT:?"OUT is not set: run this through the device tool, or set OUT to a folder"}
source "$(dirname "$0")/device-env.sh"
bins=${BINS:-tumble}
if [ -x .devbin/libtest/tumble-lib ]; then
  echo "== lib tests"
  timeout 240 .devbin/libtest/tumble-lib --test-threads 1 > "$out/libtests.txt" 2>&1
  grep -E "^test result|FAILED|panicked" "$out/libtests.txt" | head -20
fi
echo "== falling-boxes at 3k, two rounds"
for round in 1 2; do
  for bin in $bins; do
    echo -n "$bin: "
    ".devbin/$bin" run falling-boxes --device gpu --steps 300 --json 2> /dev/null | tail -1 |
      tee -a "$out/falling-3k.txt" |
      grep -oE '"ms_per_step":[0-9.]+|"kinetic_energy":[0-9.]+' | tr '\n' ' '
    echo
  done
done
.devbin/tumble run falling-boxes --device gpu --steps 300 --profile > "$out/falling-3k-profile.txt" 2>&1
echo "== the settled 100k pile"
BINS="$bins" bash "$(dirname "$0")/pile-on-device.sh" 33.3 1500 120 2>&1 |
  grep -E "===|ms_per_step" | cut -c1-200
grep -oE '"kinetic_energy":[0-9.]+|"sleeping":[0-9]+|"contacts":[0-9]+' "$out/pile.txt" | tr '\n' ' '
echo
