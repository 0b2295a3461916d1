// Inference time per stereo pair in headless Chromium, on the CPU backend (WebAssembly) and on
// WebGPU where the browser offers an adapter (here: SwiftShader, a software adapter); and the
// time of the catheter's 3D reconstruction and rod fit (centrelines, matching, triangulation,
// Levenberg-Marquardt) per twin pair, on the page's thread (WebAssembly).
// Also the time to the first inference: from opening the page to the model loaded on the CPU, and
// to the twin tab's first estimate; and the time from choosing the backend to its model ready
// (for WebGPU: the worker started, the weights loaded and checked against the CPU).
// And the twin sample cine's force trace (24 frames) on the CPU workers, alone and while the cine
// plays (the playback's frame intervals).
// Usage, after `trunk build`: node end2end/bench.mjs [runs]   (docs/benchmarks.md)
// HNET_DIST=<folder> times another build (e.g. scripts/bundle-size.sh's release page).
// HNET_WEIGHTS=<model.bpk> loads those weights through the model bar first (e.g. a 128 px model
// from `hnet train`), so that the page's time for another network size is measured.
// HNET_PAGE_QUERY=<query> opens the page with that query (src/page_query.rs).
// HNET_NO_WORKERS=1 deletes window.Worker first: the page's thread alone, one core.
// HNET_BACKENDS=cpu times the CPU path only (the software WebGPU adapter takes seconds a run).
// HNET_CATHETER_ENTRY=<value of the model bar's "Catheter enters from": bottom, auto, left, ...>
// times H-Net with that setting (auto, "find it", reads each pair at its four quarter turns);
// unset, the page's default (the bottom, as trained).
import { statSync, readdirSync } from "node:fs";
import { join } from "node:path";
import { DIST, serveDist, launchBrowser, openPage, waitForModel, loadWeightsFromEnv } from "./harness.mjs";

const runs = Number(process.argv[2] ?? 10);

/** The backends to time, from HNET_BACKENDS (default: both). */
function backends() {
  const chosen = (process.env.HNET_BACKENDS || "cpu,webgpu")
    .split(",")
    .map((b) => b.trim().toLowerCase())
    .filter(Boolean);
  const unknown = chosen.filter((b) => b !== "cpu" && b !== "webgpu");
  if (unknown.length || !chosen.length) {
    console.error(`HNET_BACKENDS: expected cpu, webgpu or both, comma-separated; got "${process.env.HNET_BACKENDS}"`);
    process.exit(2);
  }
  return chosen;
}
const server = await serveDist();
// HNET_PAGE_QUERY=<query> opens the page with that query, e.g. `?cpu-fused=0` for the CPU workers
// without relaxed SIMD in a browser that has it (src/page_query.rs).
const pageUrl = server.url + (process.env.HNET_PAGE_QUERY ?? "");
const context = await launchBrowser();
// HNET_NO_WORKERS=1: a browser without Web Workers, so H-Net runs on the page's thread (the
// single-core path, to compare with the workers in the same build).
if (process.env.HNET_NO_WORKERS === "1") await context.addInitScript(() => delete window.Worker);
const results = [];
try {
  for (const choice of backends()) {
    const opened = performance.now();
    const { page } = await openPage(context, pageUrl);
    await waitForModel(page);
    const modelReadyMs = performance.now() - opened;
    const chosen = performance.now();
    await page.selectOption("#backend-choice", choice);
    // The model reloads on the chosen device; wait until the model bar names it (a browser
    // without a WebGPU adapter stays on the CPU: then "webgpu" is timed on the CPU).
    const wanted = choice === "cpu" ? "CPU" : "WebGPU";
    await page
      .waitForFunction((w) => document.querySelector("#backend")?.textContent.includes(w), wanted, {
        timeout: 60_000,
      })
      .catch(() => {});
    await waitForModel(page);
    // From the choice to the model ready on that backend: on WebGPU, fetching the worker's
    // module, setting WebGPU up in it, loading the weights and the check against the CPU.
    const switchMs = performance.now() - chosen;
    const check = (await page.$("#backend-check")) && (await page.textContent("#backend-check"));
    await loadWeightsFromEnv(page);
    const entry = process.env.HNET_CATHETER_ENTRY;
    if (entry) await page.selectOption("#catheter-entry", entry);
    const backend = await page.textContent("#backend");
    await page.click("#tab-twin");
    await page.waitForSelector("#force-verdict", { timeout: 120_000 });
    const firstEstimateMs = performance.now() - opened;
    // On the CPU the pool of workers starts after the first estimate: time the runs once it
    // has settled (workers running, or the page's thread with its reason).
    if (backend.includes("CPU")) {
      await page.waitForFunction(() => /one per core|no workers:/.test(document.querySelector("#cpu-workers")?.title), null, { timeout: 60_000 });
    }
    const workers = (await page.$("#cpu-workers")) && (await page.getAttribute("#cpu-workers", "title"));
    const times = [];
    for (let i = 0; i < runs; i++) {
      await page.waitForFunction(() => !document.querySelector("#busy"));
      await page.click("#run-model");
      await page.waitForFunction(() => !document.querySelector("#busy"));
      const text = await page.textContent("#inference-time");
      times.push(Number(text.match(/(\d+) ms/)[1]));
    }
    times.sort((a, b) => a - b);
    results.push({
      backend,
      weights: await page.textContent("#weights"),
      input: await page.textContent("#input-size"),
      catheter_entry: entry || "the page's default",
      cpu_workers: workers,
      runs,
      median_ms: times[Math.floor(times.length / 2)],
      min_ms: times[0],
      // Only meaningful for the first backend timed (a fresh page; the second reloads the model).
      model_ready_ms: Math.round(modelReadyMs),
      switch_ms: Math.round(switchMs),
      webgpu_check: check,
      first_estimate_ms: Math.round(firstEstimateMs),
    });
    await page.close();
  }
  // The cine trace: the twin's 24-frame sample cine traced on the CPU (its workers settled),
  // then traced again while it plays, the playback's frame intervals recorded.
  {
    const { page } = await openPage(context, pageUrl);
    await waitForModel(page);
    await page.selectOption("#backend-choice", "cpu");
    await waitForModel(page);
    await loadWeightsFromEnv(page);
    await page.waitForFunction(() => /one per core|no workers:/.test(document.querySelector("#cpu-workers")?.title), null, { timeout: 60_000 });
    await page.click("#tab-cine");
    await page.click("#cine-sample");
    await page.waitForSelector("#cine-source", { timeout: 60_000 });
    const traced = async () => {
      await page.waitForFunction(() => !document.querySelector("#busy"));
      await page.click("#cine-trace");
      await page.waitForFunction(() => !document.querySelector("#trace-progress") && !document.querySelector("#busy") && /traced over/.test(document.querySelector("#notice")?.textContent), null, { timeout: 300_000 });
      return Number((await page.textContent("#notice")).match(/in ([\d.]+) s/)[1]);
    };
    const seconds = [];
    for (let i = 0; i < Math.min(runs, 5); i++) seconds.push(await traced());
    seconds.sort((a, b) => a - b);
    // Playing while tracing: every change of the frame shown, timed in the page.
    await page.evaluate(() => {
      window.__frames = [];
      new MutationObserver(() => window.__frames.push(performance.now())).observe(document.querySelector("#cine-frame"), { childList: true, characterData: true, subtree: true });
    });
    await page.click("#cine-play");
    const whilePlaying = await traced();
    await page.click("#cine-play");
    const intervals = await page.evaluate(() => window.__frames.slice(1).map((t, i) => t - window.__frames[i]).sort((a, b) => a - b));
    const at = (q) => Math.round(intervals[Math.min(intervals.length - 1, Math.floor(q * intervals.length))]);
    results.push({
      trace: "twin sample cine, 24 frame pairs, 224 px, on the CPU",
      weights: (await page.textContent("#weights"))?.trim(),
      cpu_workers: await page.getAttribute("#cpu-workers", "title"),
      runs: seconds.length,
      median_s: seconds[Math.floor(seconds.length / 2)],
      min_s: seconds[0],
      while_playing_s: whilePlaying,
      playback_frame_interval_ms: { nominal: Math.round(1000 / 15), median: at(0.5), p95: at(0.95), max: at(1), frames: intervals.length + 1 },
    });
    await page.close();
  }
  // The catheter in 3D: each Fx step of the twin's slider renders a new pair, reconstructed once.
  const { page } = await openPage(context, pageUrl);
  await waitForModel(page);
  await page.click("#tab-twin");
  await page.waitForSelector("#catheter-3d[data-state=ready]", { timeout: 60_000 });
  const times = [];
  for (let i = 0; i < runs; i++) {
    const pair = await page.getAttribute("#catheter-3d", "data-pair");
    await page.focus("#twin-fx");
    await page.keyboard.press(i % 2 ? "ArrowRight" : "ArrowLeft");
    await page.waitForFunction(
      (p) => {
        const c = document.querySelector("#catheter-3d");
        return c.dataset.pair !== p && c.dataset.state === "ready";
      },
      pair,
      { timeout: 60_000 },
    );
    times.push(Number(await page.getAttribute("#catheter-3d", "data-millis")));
  }
  times.sort((a, b) => a - b);
  results.push({
    reconstruction: "twin pair at 224 px: centrelines, reconstruction and rod fit",
    runs,
    median_ms: times[Math.floor(times.length / 2)],
    min_ms: times[0],
    max_ms: times[times.length - 1],
  });
  await page.close();
} finally {
  await context.close();
  await server.close();
}
const dist = DIST;
const wasm = readdirSync(dist).filter((f) => f.endsWith(".wasm"));
console.log(JSON.stringify({ results, wasm: wasm.map((f) => ({ file: f, bytes: statSync(join(dist, f)).size })) }, null, 2));
