#!/usr/bin/env bash
# Sets up what is missing, builds the page with trunk and serves it (with the bundled model) at
# http://127.0.0.1:8080. Everything runs in the browser; nothing leaves the machine.
#
# `scripts/demo.sh --release` serves the deployed build instead (the page's code size-optimised,
# LTO, wasm-opt; the CPU workers at opt-level 3 without LTO, as fast as this build's): smaller,
# but its first build takes several minutes more (docs/benchmarks.md). Other arguments go to
# `trunk serve`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
. scripts/env.sh
. scripts/wasm-env.sh
if [ "${1:-}" = "--release" ]; then
  . scripts/binaryen-env.sh
fi
exec trunk serve --locked --address "${HNET_ADDRESS:-127.0.0.1}" --port "${HNET_PORT:-8080}" "$@"
