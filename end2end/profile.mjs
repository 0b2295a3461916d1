// Where the page's CPU inference spends its time: Chromium's sampling profiler (DevTools
// protocol) over N runs of the model on a twin pair, self time summed by function (WebAssembly
// functions by their Rust names, from the build's name section), largest first. The busy time
// counts everything but idle (the garbage collector and redraws included).
// Usage, after `trunk build`: node end2end/profile.mjs [runs] [top]   (docs/benchmarks.md)
// HNET_WEIGHTS=<model.bpk> profiles those weights instead of the bundled ones.
import { serveDist, launchBrowser, openPage, waitForModel, loadWeightsFromEnv } from "./harness.mjs";

const runs = Number(process.argv[2] ?? 10);
const top = Number(process.argv[3] ?? 25);
const server = await serveDist();
const context = await launchBrowser();
// H-Net's views run in CPU workers, which this profiler does not see: the page's thread reads
// them here, with the plain SIMD128 kernels (the workers' relaxed-SIMD build is not profiled).
await context.addInitScript(() => delete window.Worker);
try {
  const { page } = await openPage(context, server.url);
  await waitForModel(page);
  await page.selectOption("#backend-choice", "cpu");
  await page.waitForFunction(() => document.querySelector("#backend")?.textContent.includes("CPU"), null, {
    timeout: 60_000,
  });
  await waitForModel(page);
  await loadWeightsFromEnv(page);
  await page.click("#tab-twin");
  await page.waitForSelector("#force-verdict", { timeout: 120_000 });
  const cdp = await context.newCDPSession(page);
  await cdp.send("Profiler.enable");
  await cdp.send("Profiler.setSamplingInterval", { interval: 200 }); // microseconds
  await page.waitForFunction(() => !document.querySelector("#busy"));
  await cdp.send("Profiler.start");
  const times = [];
  for (let i = 0; i < runs; i++) {
    await page.click("#run-model");
    await page.waitForFunction(() => !document.querySelector("#busy"));
    times.push(Number((await page.textContent("#inference-time")).match(/(\d+) ms/)[1]));
  }
  const { profile } = await cdp.send("Profiler.stop");
  // Self time per node: the interval after each sample that landed on it (as DevTools counts).
  const self = new Map();
  profile.samples.forEach((id, i) => self.set(id, (self.get(id) ?? 0) + (profile.timeDeltas[i + 1] ?? 0)));
  const byFunction = new Map();
  let total = 0;
  for (const node of profile.nodes) {
    const us = self.get(node.id) ?? 0;
    const name = node.callFrame.functionName || `(${node.callFrame.url.split("/").pop() || "anonymous"})`;
    if (name === "(idle)" || name === "(program)") continue;
    byFunction.set(name, (byFunction.get(name) ?? 0) + us);
    total += us;
  }
  const rows = [...byFunction].sort((a, b) => b[1] - a[1]).slice(0, top);
  times.sort((a, b) => a - b);
  console.log(
    JSON.stringify(
      {
        weights: await page.textContent("#weights"),
        runs,
        median_ms: times[Math.floor(times.length / 2)],
        busy_ms: Math.round(total / 1000),
        functions: rows.map(([name, us]) => ({ share: `${((100 * us) / total).toFixed(1)} %`, name })),
      },
      null,
      2,
    ),
  );
} finally {
  await context.close();
  await server.close();
}
