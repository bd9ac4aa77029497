#!/usr/bin/env bash
# Builds the engine's test binary here, stripped, into .devbin/tests/ for
# scripts/test-on-device.sh, with the test modules to run there, so that the kernels' parity
# tests also run on the GPU machine: lavapipe's subgroups are 8 wide and its workgroups run on
# a CPU thread pool, so it cannot catch every NVIDIA-only bug (one scan passed here and was
# wrong on the H100).
#
#   bash scripts/build-device-tests.sh gpu_scan gpu_compact gpu_radix_sort ...
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -eq 0 ]; then
  echo "usage: $0 MODULE... (test modules of crates/tumble/tests/engine, e.g. gpu_scan)" >&2
  exit 2
fi
for name in "$@"; do
  if [ ! -f "crates/tumble/tests/engine/$name.rs" ]; then
    echo "no test module crates/tumble/tests/engine/$name.rs" >&2
    exit 2
  fi
done
rm -rf .devbin/tests
mkdir -p .devbin/tests
# The test binary's path, from cargo's own report of what it built.
path=$(cargo test -p tumble --test engine --no-run --message-format=json 2>/dev/null |
  python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["kind"] == ["test"]:
        print(m["executable"])')
strip -o .devbin/tests/engine "$path"
printf '%s\n' "$@" > .devbin/tests/modules
ls -l .devbin/tests
