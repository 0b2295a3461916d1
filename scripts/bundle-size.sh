#!/usr/bin/env bash
# Builds the page as it would be deployed (the size-optimised `release` profile with LTO, then
# wasm-opt -Oz) into $HNET_CACHE/dist-release and prints the wasm bundle's size, raw and gzipped
# (docs/benchmarks.md). Not part of the test suite: the fat-LTO link takes many minutes.
#
# wasm-opt comes from npm's binaryen 132 (Debian's binaryen 108 writes modules that fail to
# instantiate), installed once into $HNET_CACHE/wasm-tools.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh >/dev/null
. scripts/env.sh
BINARYEN_VERSION=132.0.0
tools="$HNET_CACHE/wasm-tools"
if [ "$(node -p "try{require('$tools/node_modules/binaryen/package.json').version}catch{''}")" != "$BINARYEN_VERSION" ]; then
  npm install --prefix "$tools" --no-audit --no-fund --silent --save-exact "binaryen@$BINARYEN_VERSION"
fi
export PATH="$tools/node_modules/.bin:$PATH"
. scripts/wasm-env.sh
dist="$HNET_CACHE/dist-release"
trunk build --locked --release --dist "$dist"
wasm=$(ls "$dist"/*.wasm)
raw=$(stat -c %s "$wasm")
gz=$(gzip -9 -c "$wasm" | wc -c)
printf 'release page: %s\n  wasm %.1f MB, gzipped %.1f MB\n' "$dist" "$(echo "$raw/1000000" | bc -l)" "$(echo "$gz/1000000" | bc -l)"
