#!/usr/bin/env bash
# Runs every test: formatting, clippy (native and wasm32), the native tests, a type check of the
# GPU (wgpu) build of `hnet`, the browser tests (wasm-bindgen-test in headless Chromium: the
# page's, and the WebGPU worker's in a dedicated worker), the trunk build of the page and the
# Playwright end-to-end tests.
#
# Clippy runs inside the builds that the tests need: clippy-driver is cargo's workspace wrapper
# (what `cargo clippy` itself does, for `cargo check`), so every workspace crate is compiled once,
# linted with `-D warnings`, and tested. Dependencies are compiled once, not checked and then
# built. This keeps a cold run on 2 cores well inside CI's limit (docs/benchmarks.md).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
. scripts/env.sh
step() { printf '\n== %s (%ss)\n' "$*" "$SECONDS"; }

clippy_driver="$(dirname "$(rustup which cargo)")/clippy-driver"
with_clippy() {
  RUSTC_WORKSPACE_WRAPPER="$clippy_driver" \
    CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__" "$@"
}

step "cargo fmt --check"
cargo fmt --all -- --check

step "native: clippy, build and tests"
with_clippy cargo test --workspace --all-targets --locked

# The GPU backend cannot run here, but it must keep compiling (scripts/gpu-build.sh builds it
# for a lent GPU machine): a type check, 3 min 17 s from a cold check cache on this machine.
step "native: type-check hnet with the wgpu backend"
cargo check -p hnet-cli --features wgpu --locked

# The page and its WebGPU worker (crates/hnet-gpu) are tested one package at a time: each test
# build then has the features of its trunk build below and shares its compiled dependencies
# (tested together, cargo would unify their features and build Burn's stack a third time).
(
  . scripts/wasm-env.sh
  if [ -n "${RUSTC_BOOTSTRAP:-}" ]; then
    # Debian's rustc-web has no clippy; the native run above linted all but the page's
    # wasm-only components.
    step "wasm: browser tests (headless Chromium; no wasm32 clippy with Debian's rustc-web)"
    cargo test -p hnet-studio --target wasm32-unknown-unknown --locked
    cargo test -p hnet-gpu --target wasm32-unknown-unknown --locked
    step "wasm: trunk build"
    trunk build --locked
  else
    step "wasm: clippy, build and browser tests (headless Chromium)"
    with_clippy cargo test -p hnet-studio --target wasm32-unknown-unknown --all-targets --locked
    with_clippy cargo test -p hnet-gpu --target wasm32-unknown-unknown --all-targets --locked
    step "wasm: trunk build"
    with_clippy trunk build --locked
  fi
)

step "end-to-end (Playwright, headless Chromium)"
node --test end2end/tests/

step "all tests passed"
