#!/usr/bin/env bash
# Builds the page as it would be deployed (the size-optimised `release` profile with LTO, then
# wasm-opt -Oz) into $HNET_CACHE/dist-release and prints the wasm bundle's size, raw and gzipped
# (docs/benchmarks.md). Not part of the test suite: the fat-LTO link takes many minutes.
#
# wasm-opt: scripts/binaryen-env.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh >/dev/null
. scripts/env.sh
. scripts/binaryen-env.sh
. scripts/wasm-env.sh
dist="$HNET_CACHE/dist-release"
trunk build --locked --release --dist "$dist"
wasm=$(ls "$dist"/*.wasm)
raw=$(stat -c %s "$wasm")
gz=$(gzip -9 -c "$wasm" | wc -c)
printf 'release page: %s\n  wasm %.1f MB, gzipped %.1f MB\n' "$dist" "$(echo "$raw/1000000" | bc -l)" "$(echo "$gz/1000000" | bc -l)"
