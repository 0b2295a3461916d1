// The memory each CPU worker holds (crates/hnet-cpu, one per core: docs/benchmarks.md, "Every
// core"): its WebAssembly linear memory, which holds the network's weights and the activations
// of the views it read, and its JavaScript heap; beside them the page's own linear memory. Read
// once the twin pair's two views have been read on the workers and again after a 24-frame cine
// trace (every worker busy), in headless Chromium.
// Usage, after `trunk build`: node end2end/worker-memory.mjs   (HNET_DIST=<folder> for another build)
import { serveDist, launchBrowser, openPage, waitForModel } from "./harness.mjs";

const MB = 1024 * 1024;

/** Linear memory and JS heap of every CPU worker, MB. */
async function workerMemory(page) {
  const workers = page.workers().filter((w) => w.url().includes("module=hnet-cpu"));
  return Promise.all(
    workers.map((w) =>
      w.evaluate(async () => {
        // The module is initialised once; asking again returns its exports.
        const wasm = await (await import("./hnet-cpu.js")).default();
        return {
          linear: wasm.memory.buffer.byteLength,
          heap: self.performance?.memory?.usedJSHeapSize ?? null,
        };
      }),
    ),
  );
}

/** The page's own linear memory (the page's wasm module), MB. */
async function pageMemory(page) {
  return page.evaluate(async () => {
    const module = await import(document.querySelector("script[data-hnet-js]").dataset.hnetJs);
    const wasm = await module.default();
    return { linear: wasm.memory.buffer.byteLength, heap: performance.memory?.usedJSHeapSize ?? null };
  });
}

const show = (label, m) =>
  console.log(`${label}: linear ${(m.linear / MB).toFixed(1)} MB, JS heap ${m.heap === null ? "n/a" : (m.heap / MB).toFixed(1) + " MB"}`);

const server = await serveDist();
const browser = await launchBrowser();
try {
  const { page } = await openPage(browser, server.url);
  await waitForModel(page);
  await page.waitForSelector("#force-verdict", { timeout: 120_000 });
  await page.waitForFunction(() => / workers, one per core/.test(document.querySelector("#cpu-workers")?.title), null, { timeout: 60_000 });
  // The pair read again on the workers (a setting change clears the estimates).
  await page.selectOption("#catheter-entry", "left");
  await page.waitForFunction(() => !document.querySelector("#busy"), null, { timeout: 60_000 });
  await page.selectOption("#catheter-entry", "bottom");
  await page.waitForFunction(() => / workers$/.test(document.querySelector("#inference-time").textContent) && !document.querySelector("#busy"), null, { timeout: 60_000 });
  (await workerMemory(page)).forEach((m, i) => show(`after one pair, CPU worker ${i + 1}`, m));
  show("after one pair, the page", await pageMemory(page));
  await page.click("#tab-cine");
  await page.click("#cine-sample");
  await page.waitForSelector("#cine-trace:not([disabled])", { timeout: 120_000 });
  await page.waitForFunction(() => !document.querySelector("#busy"), null, { timeout: 120_000 });
  await page.click("#cine-trace");
  await page.waitForFunction(() => document.querySelector("#force-trace")?.dataset.traced === "24" && !document.querySelector("#busy"), null, { timeout: 300_000 });
  (await workerMemory(page)).forEach((m, i) => show(`after a 24-frame trace, CPU worker ${i + 1}`, m));
  show("after a 24-frame trace, the page", await pageMemory(page));
} finally {
  await browser.close();
  await server.close();
}
