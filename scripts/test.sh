#!/usr/bin/env bash
# Runs every test: formatting, clippy, native tests, the browser tests (wasm-bindgen-test in
# headless Chromium), the trunk build of the page and the Playwright end-to-end tests.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
. scripts/env.sh
step() { printf '\n== %s (%ss)\n' "$*" "$SECONDS"; }

step "cargo fmt --check"
cargo fmt --all -- --check

step "native: clippy"
cargo clippy --workspace --all-targets --locked -- -D warnings

step "native: tests"
cargo test --workspace --locked

(
  . scripts/wasm-env.sh
  step "wasm: clippy (app)"
  cargo clippy -p hnet-studio --target wasm32-unknown-unknown --all-targets --locked -- -D warnings
  step "wasm: browser tests (headless Chromium)"
  cargo test -p hnet-studio --target wasm32-unknown-unknown --locked
  step "wasm: trunk build"
  trunk build --locked
)

step "end-to-end (Playwright, headless Chromium)"
node --test end2end/tests/

step "all tests passed"
