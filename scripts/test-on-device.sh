#!/usr/bin/env bash
# Runs the test modules of scripts/build-device-tests.sh on the GPU machine (one call of the
# `device` tool, carrying .gl and .devbin) and says which failed.
set -uo pipefail
source "$(dirname "$0")/device-env.sh"
failed=0
while read -r module; do
  output=$(.devbin/tests/engine --test-threads 1 "$module::" 2>&1)
  echo "== $module: $(echo "$output" | grep '^test result' | tail -1)"
  if ! echo "$output" | grep -q '^test result: ok'; then
    echo "$output" | grep -E -A2 'panicked' | cut -c1-300 | head -20
    failed=1
  fi
done < .devbin/tests/modules
exit $failed
