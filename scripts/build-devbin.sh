#!/usr/bin/env bash
# Builds the release `tumble` binary and the kernel_stats example here and puts them, stripped
# and gzipped, with the commit they were built from, into .devbin/ for the scripts that run on
# the GPU machine (binaries built here run there; device-env.sh unpacks them).
#
#   scripts/build-devbin.sh [NAME]
#
# NAME (say `base`, or a variant's name) makes .devbin/tumble-NAME.gz and
# .devbin/kernel_stats-NAME.gz, so that several builds travel in one call for an A/B (BINS in
# pile-on-device.sh and device-check.sh); without it, .devbin/tumble.gz and the commit.
# Gzipped, a build is 6.6 MB instead of 16: five fit in the 64 MiB a call carries.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p tumble-cli
cargo build --release -p tumble --example kernel_stats
target=${CARGO_TARGET_DIR:-target}
suffix=${1:+-$1}
mkdir -p .devbin
# Stripped: the debug line tables make the binary larger than what a device call carries.
strip -o ".devbin/tumble$suffix" "$target/release/tumble"
strip -o ".devbin/kernel_stats$suffix" "$target/release/examples/kernel_stats"
gzip -f ".devbin/tumble$suffix" ".devbin/kernel_stats$suffix"
commit=$(git rev-parse --short HEAD)
# A build from uncommitted changes says so: its numbers belong to no commit.
git diff --quiet HEAD -- . ':!.devbin' ':!.gl' || commit="$commit-dirty"
if [ -z "$suffix" ]; then
  echo "$commit" > .devbin/COMMIT
fi
echo "${1:-tumble}: $commit" >> .devbin/BUILDS
echo "built .devbin/tumble$suffix.gz at $commit"
