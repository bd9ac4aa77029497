#!/usr/bin/env bash
# Builds the release `tumble` binary and the kernel_stats example here and puts them, stripped
# and gzipped, with the commit they were built from, into .devbin/ for the scripts that run on
# the GPU machine (binaries built here run there; device-env.sh unpacks them).
#
#   scripts/build-devbin.sh [NAME [COMMIT]]
#
# NAME (say `base`, or a variant's name) makes .devbin/tumble-NAME.gz and
# .devbin/kernel_stats-NAME.gz, so that several builds travel in one call for an A/B (BINS in
# pile-on-device.sh and device-check.sh); without it, .devbin/tumble.gz and the commit.
# COMMIT builds that commit instead of the working tree, in a git worktree under /tmp with a
# target directory of its own under this checkout's (target/worktree; only the crates that
# differ build again from one commit to the next), so that each of a series of commits can be
# timed alone. Not this checkout's target directory: cargo keeps a binary it finds fresh
# where it is, so a working-tree build after a worktree's could leave the worktree's binary
# in target/release (it did, in session 22: a kernel_stats build without its change).
# Gzipped, a build is 6.6 MB instead of 16 (and kernel_stats 3.2 MB): five fit in the 64 MiB
# a call carries. NO_STATS=1 leaves kernel_stats out, for calls that carry more builds.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
target=${CARGO_TARGET_DIR:-$root/target}
suffix=${1:+-$1}
source_dir=$root
if [ -n "${2:-}" ]; then
  target=$target/worktree
  source_dir=/tmp/devbin-$(git rev-parse --short "$2")
  if [ ! -d "$source_dir" ]; then
    git worktree add --detach "$source_dir" "$2" > /dev/null
  fi
fi
(
  cd "$source_dir"
  export CARGO_TARGET_DIR=$target
  cargo build --release -p tumble-cli
  if [ -z "${NO_STATS:-}" ]; then
    cargo build --release -p tumble --example kernel_stats
  fi
)
mkdir -p .devbin
# Stripped: the debug line tables make the binary larger than what a device call carries.
strip -o ".devbin/tumble$suffix" "$target/release/tumble"
gzip -f ".devbin/tumble$suffix"
if [ -z "${NO_STATS:-}" ]; then
  strip -o ".devbin/kernel_stats$suffix" "$target/release/examples/kernel_stats"
  gzip -f ".devbin/kernel_stats$suffix"
fi
commit=$(git -C "$source_dir" rev-parse --short HEAD)
# A build from uncommitted changes says so: its numbers belong to no commit.
git -C "$source_dir" diff --quiet HEAD -- . ':!.devbin' ':!.gl' || commit="$commit-dirty"
if [ -z "$suffix" ]; then
  echo "$commit" > .devbin/COMMIT
fi
echo "${1:-tumble}: $commit" >> .devbin/BUILDS
echo "built .devbin/tumble$suffix.gz at $commit"
