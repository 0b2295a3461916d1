#!/usr/bin/env bash
# Prepares, on this (CPU) machine, what scripts/gpu-run.sh needs on a lent GPU machine, which has
# no Rust toolchain and no network:
#   gpu/hnet.gz  `hnet` built with the wgpu backend (Vulkan), stripped and compressed to fit the
#                device tool's 64 MiB carry limit (about 18 MB; 71 MB unpacked);
#   .gl/*.deb    the Vulkan loader (libvulkan1) and GL/EGL libraries, for a machine without them.
# Then, with the device tool: run `scripts/gpu-run.sh` carrying `gpu` and `.gl`.
# Burn's CUDA runtime is not an option here: its build script downloads LLVM.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/env.sh
cargo build -p hnet-cli --features wgpu --locked
mkdir -p gpu
strip -o gpu/hnet "$CARGO_TARGET_DIR/debug/hnet"
gzip -9 -f gpu/hnet
ls -l gpu/hnet.gz
if ! ls .gl/*.deb >/dev/null 2>&1; then
  mkdir -p .gl /tmp/amd64/partial
  o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
  # shellcheck disable=SC2086
  apt-get $o update -q >/dev/null
  # shellcheck disable=SC2086
  (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
fi
ls -l .gl
