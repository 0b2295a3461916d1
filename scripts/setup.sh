#!/usr/bin/env bash
# Installs what building and testing H-Net Studio needs and is missing; safe to run again.
#
#   - Debian packages: chromium and chromium-driver (browser tests);
#   - the wasm32 target: `rustup target add` first (with a time limit); where rustup cannot
#     download it, Debian's rustc-web with its std sources (scripts/wasm-env.sh then builds std
#     for wasm32 itself);
#   - trunk and wasm-bindgen-cli at the versions the project pins (compiled once, ~3-6 min);
#   - playwright-core from npm for the end-to-end tests (end2end/package-lock.json).
#
# Environment: HNET_CACHE (default ~/.cache/hnet-studio) holds the shared cargo target folder and
# the tools' build folder.
set -euo pipefail
cd "$(dirname "$0")/.."

TRUNK_VERSION=0.21.14
# Must equal the wasm-bindgen version in Cargo.lock (and Cargo.toml's pin).
WASM_BINDGEN_VERSION=0.2.130
HNET_CACHE="${HNET_CACHE:-$HOME/.cache/hnet-studio}"
say() { printf '[setup] %s\n' "$*"; }

as_root() {
  if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi
}

apt_install() {
  local missing=()
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  say "apt: installing ${missing[*]}"
  as_root env DEBIAN_FRONTEND=noninteractive apt-get update -q >/dev/null
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null
}

# ---------------------------------------------------------------- browser
apt_install chromium chromium-driver

# ---------------------------------------------------------------- wasm32 toolchain
if rustup target list --installed 2>/dev/null | grep -qx wasm32-unknown-unknown; then
  say "wasm32 target: rustup (installed)"
elif timeout 300 rustup target add wasm32-unknown-unknown >/dev/null 2>&1; then
  say "wasm32 target: rustup (added)"
else
  say "rustup could not add wasm32-unknown-unknown; using Debian's rustc-web with build-std"
  apt_install rustc-web cargo-web rust-web-src rust-web-llvm lld-22
fi

# ---------------------------------------------------------------- trunk, wasm-bindgen-cli
cargo_tool() { # binary crate version
  local have=""
  if [ -x "$HOME/.cargo/bin/$1" ]; then have=$("$HOME/.cargo/bin/$1" --version 2>/dev/null | awk '{print $2}'); fi
  if [ "$have" = "$3" ]; then return 0; fi
  say "cargo install $2 $3 (have: ${have:-none})"
  # Build tools, not shipped code: skip link-time optimisation and most optimisation to
  # compile them in minutes; both tools share one build folder.
  CARGO_TARGET_DIR="$HNET_CACHE/tools-target" \
  CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16 \
  CARGO_PROFILE_RELEASE_OPT_LEVEL=1 CARGO_PROFILE_RELEASE_DEBUG=false \
    "$HOME/.cargo/bin/cargo" install --quiet "$2" --version "=$3" --force ${4:-}
}
cargo_tool wasm-bindgen wasm-bindgen-cli "$WASM_BINDGEN_VERSION"
cargo_tool trunk trunk "$TRUNK_VERSION" --locked

locked=$(awk '/^name = "wasm-bindgen"$/{getline; gsub(/"/,"",$3); print $3; exit}' Cargo.lock)
if [ "$locked" != "$WASM_BINDGEN_VERSION" ]; then
  say "ERROR: Cargo.lock has wasm-bindgen $locked but the CLI is $WASM_BINDGEN_VERSION"
  exit 1
fi

# ---------------------------------------------------------------- end-to-end test driver
if [ ! -f end2end/node_modules/playwright-core/package.json ] \
   || ! cmp -s end2end/package-lock.json end2end/node_modules/.package-lock.json; then
  say "npm ci (end2end)"
  (cd end2end && npm ci --no-audit --no-fund --silent)
fi
say "ready"
