#!/usr/bin/env bash
# Builds the release `tumble` binary here and puts it, with the commit it was built from, into
# .devbin/ for scripts/bench-on-device.sh on the GPU machine (binaries built here run there).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p tumble-cli
target=${CARGO_TARGET_DIR:-target}
mkdir -p .devbin
# Stripped: the debug line tables make the binary larger than what a device call carries (64 MiB).
strip -o .devbin/tumble "$target/release/tumble"
commit=$(git rev-parse --short HEAD)
# A build from uncommitted changes says so: its numbers belong to no commit.
git diff --quiet HEAD -- . ':!.devbin' ':!.gl' || commit="$commit-dirty"
echo "$commit" > .devbin/COMMIT
echo "built .devbin/tumble at $commit"
