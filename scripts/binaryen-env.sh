# shellcheck shell=bash
# Source this (after scripts/env.sh) before a `trunk build --release` or `trunk serve --release`:
# trunk runs wasm-opt on release builds, and takes it from PATH. wasm-opt comes from npm's
# binaryen 132 (Debian's binaryen 108 writes modules that fail to instantiate), installed once into
# $HNET_CACHE/wasm-tools.
BINARYEN_VERSION=132.0.0
tools="$HNET_CACHE/wasm-tools"
if [ "$(node -p "try{require('$tools/node_modules/binaryen/package.json').version}catch{''}")" != "$BINARYEN_VERSION" ]; then
  npm install --prefix "$tools" --no-audit --no-fund --silent --save-exact "binaryen@$BINARYEN_VERSION"
fi
export PATH="$tools/node_modules/.bin:$PATH"
