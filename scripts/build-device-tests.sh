#!/usr/bin/env bash
# Builds GPU test binaries here, stripped, into .devbin/tests/ for scripts/test-on-device.sh, so
# that the kernels' parity tests also run on the GPU machine: lavapipe's subgroups are 8 wide
# and its workgroups run on a CPU thread pool, so it cannot catch every NVIDIA-only bug (one
# scan passed here and was wrong on the H100). A device call carries at most 64 MiB: about six
# test binaries at a time.
#
#   bash scripts/build-device-tests.sh gpu_scan gpu_compact gpu_radix_sort ...
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -eq 0 ]; then
  echo "usage: $0 TEST... (test files of crates/tumble/tests, e.g. gpu_scan)" >&2
  exit 2
fi
rm -rf .devbin/tests
mkdir -p .devbin/tests
args=()
for name in "$@"; do args+=(--test "$name"); done
# The test binaries' paths, from cargo's own report of what it built.
cargo test -p tumble "${args[@]}" --no-run --message-format=json 2>/dev/null |
  python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["kind"] == ["test"]:
        print(m["target"]["name"], m["executable"])' |
  while read -r name path; do strip -o ".devbin/tests/$name" "$path"; done
ls .devbin/tests
