#!/usr/bin/env bash
# Builds the page as it would be deployed (the size-optimised `release` profile with LTO, then
# wasm-opt -Oz) into $HNET_CACHE/dist-release and prints its download, raw and gzipped
# (docs/benchmarks.md): what every visitor fetches (the page's code, styles and the bundled
# weights) and what the WebGPU worker adds for the browsers that use it (crates/hnet-gpu). Not
# part of the test suite: the two fat-LTO links take many minutes.
#
# wasm-opt: scripts/binaryen-env.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh >/dev/null
. scripts/env.sh
. scripts/binaryen-env.sh
. scripts/wasm-env.sh
dist="$HNET_CACHE/dist-release"
trunk build --locked --release --dist "$dist"

# Sizes of files, raw and gzipped (-9), in MB.
sizes() {
  local raw=0 gz=0 file
  for file in "$@"; do
    raw=$((raw + $(stat -c %s "$file")))
    gz=$((gz + $(gzip -9 -c "$file" | wc -c)))
  done
  printf '%.2f MB, gzipped %.2f MB' "$(echo "$raw/1000000" | bc -l)" "$(echo "$gz/1000000" | bc -l)"
}
cd "$dist"
page_code=(hnet-studio-*_bg.wasm hnet-studio-*.js boot.js style-*.css index.html)
weights=(assets/hnet-cpu.bpk)
gpu=(hnet-gpu_bg.wasm hnet-gpu.js module-worker.js)
cpu=(hnet-cpu_bg.wasm hnet-cpu.js)
cpu_fused=(hnet-cpu-fused_bg.wasm hnet-cpu-fused.js)
echo "release page: $dist"
printf '  page code (wasm, JS, CSS, HTML): %s\n' "$(sizes "${page_code[@]}")"
printf '  bundled weights:                 %s\n' "$(sizes "${weights[@]}")"
printf '  every visitor (the two above):   %s\n' "$(sizes "${page_code[@]}" "${weights[@]}")"
printf '  CPU workers, after the first estimate (one fetch, compiled per worker): %s\n' "$(sizes "${cpu[@]}")"
printf '    or, where WebAssembly has relaxed SIMD, their fused build instead: %s\n' "$(sizes "${cpu_fused[@]}")"
printf '  WebGPU worker, when used:        %s\n' "$(sizes "${gpu[@]}")"
printf '  a visitor on WebGPU (all):       %s\n' "$(sizes "${page_code[@]}" "${weights[@]}" "${gpu[@]}")"
