# shellcheck shell=bash
# Source this in the shell that builds or tests the browser app (never for native builds when
# the Debian fallback is active: it puts Debian's cargo first and turns build-std on).
if rustup target list --installed 2>/dev/null | grep -qx wasm32-unknown-unknown; then
  : # rustup's own wasm32 standard library
else
  # Debian's rustc-web: rebuild std for wasm32 from rust-web-src.
  export PATH="/usr/bin:$PATH:$HOME/.cargo/bin"
  export CARGO=/usr/bin/cargo RUSTC=/usr/bin/rustc
  export RUSTC_BOOTSTRAP=1 CARGO_UNSTABLE_BUILD_STD=std,panic_abort
fi
# `cargo test --target wasm32-unknown-unknown` runs the tests in headless Chromium.
export CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_RUNNER=wasm-bindgen-test-runner
export CHROMEDRIVER=/usr/bin/chromedriver
export WASM_BINDGEN_TEST_TIMEOUT="${WASM_BINDGEN_TEST_TIMEOUT:-180}"
# trunk: no update check (no internet needed).
export TRUNK_SKIP_VERSION_CHECK=true
