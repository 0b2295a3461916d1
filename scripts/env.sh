# shellcheck shell=bash
# Shared by the scripts: one cargo target folder outside the clone, reused by every build
# (tests, the CLI, the page) so that nothing compiles twice.
export HNET_CACHE="${HNET_CACHE:-$HOME/.cache/hnet-studio}"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HNET_CACHE/target}"
export PATH="$HOME/.cargo/bin:$PATH"
