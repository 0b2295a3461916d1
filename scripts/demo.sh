#!/usr/bin/env bash
# Sets up what is missing, builds the page with trunk and serves it (with the bundled model) at
# http://127.0.0.1:8080. Everything runs in the browser; nothing leaves the machine.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
. scripts/env.sh
. scripts/wasm-env.sh
exec trunk serve --locked --address "${HNET_ADDRESS:-127.0.0.1}" --port "${HNET_PORT:-8080}" "$@"
