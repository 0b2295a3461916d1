// The bench page: H-Net's ONNX export in ONNX Runtime Web's wasm execution provider, on the
// page's main thread as the H-Net Studio page runs Burn. bench.mjs calls window.benchOrt.
import * as ort from "./node_modules/onnxruntime-web/dist/ort.wasm.min.mjs";

const median = (sorted) => sorted[Math.floor(sorted.length / 2)];

/** Times `runs` inferences of one stereo pair after `warmup` untimed ones; milliseconds. */
async function benchOrt({ model, size, threads, warmup, runs }) {
  ort.env.wasm.wasmPaths = new URL("./node_modules/onnxruntime-web/dist/", location.href).href;
  ort.env.wasm.numThreads = threads;
  ort.env.wasm.simd = true; // fixed-width SIMD; ONNX Runtime Web only ships SIMD builds
  ort.env.wasm.proxy = false; // on this thread, like the page's Burn
  const load = performance.now();
  const session = await ort.InferenceSession.create(model, {
    executionProviders: ["wasm"],
    graphOptimizationLevel: "all",
  });
  const loadMs = performance.now() - load;
  // One pair of random RGB images in [0, 1], planar, as the page feeds Burn.
  const pixels = 3 * size * size;
  const viewA = Float32Array.from({ length: pixels }, () => Math.random());
  const viewB = Float32Array.from({ length: pixels }, () => Math.random());
  const once = async () => {
    const start = performance.now();
    const out = await session.run({
      view_a: new ort.Tensor("float32", viewA, [1, 3, size, size]),
      view_b: new ort.Tensor("float32", viewB, [1, 3, size, size]),
    });
    // Read the three outputs back, as the page does.
    const read = [out.mask_a.data, out.mask_b.data, out.force.data];
    const ms = performance.now() - start;
    if (read[0].length !== size * size || read[2].length !== 3) throw new Error("unexpected outputs");
    return ms;
  };
  for (let i = 0; i < warmup; i++) await once();
  const times = [];
  for (let i = 0; i < runs; i++) times.push(await once());
  const sorted = [...times].sort((a, b) => a - b);
  await session.release();
  return {
    onnxruntime_web: ort.env.versions.web,
    execution_provider: "wasm",
    num_threads: ort.env.wasm.numThreads,
    simd: ort.env.wasm.simd,
    cross_origin_isolated: globalThis.crossOriginIsolated,
    hardware_concurrency: navigator.hardwareConcurrency,
    load_ms: loadMs,
    warmup,
    runs,
    median_ms: median(sorted),
    min_ms: sorted[0],
    max_ms: sorted[sorted.length - 1],
    times_ms: times,
  };
}

window.benchOrt = benchOrt;
window.benchOrtReady = true;
