// The page at scale (issue #13): N labeled pairs in the browser's storage, loaded at start-up and
// exported as one dataset zip; the browser's memory (resident set of all Chromium processes, and
// the page's JS heap with its WebAssembly memory) after loading and at the export's peak.
// Usage, after `trunk build`: node end2end/scale.mjs [pairs]   (docs/reliability.md, "Scale")
// The pairs are copies of one twin pair written straight into IndexedDB (what the page would
// have saved), so the measurement times the page, not the labeling.
import { execSync } from "node:child_process";
import { serveDist, launchBrowser, openPage, waitForModel } from "./harness.mjs";

const pairs = Number(process.argv[2] ?? 1000);
const server = await serveDist();
const context = await launchBrowser();

/** Resident memory of every Chromium process, MiB. */
function chromiumRssMib() {
  const out = execSync("ps -C chromium -o rss= || true").toString();
  return out.split("\n").filter(Boolean).reduce((a, b) => a + Number(b), 0) / 1024;
}

try {
  const { page } = await openPage(context, server.url);
  await waitForModel(page);
  const baseline = chromiumRssMib();
  await page.click("#tab-twin");
  await page.click("#twin-keep");
  await page.waitForSelector("#pairs li[data-id]");
  await page.waitForTimeout(1000);
  const written = await page.evaluate(async (n) => {
    const db = await new Promise((ok) => {
      const r = indexedDB.open("hnet-studio");
      r.onsuccess = () => ok(r.result);
    });
    const keys = await new Promise((ok) => {
      const r = db.transaction("pairs").objectStore("pairs").getAllKeys();
      r.onsuccess = () => ok(r.result);
    });
    const record = await new Promise((ok) => {
      const r = db.transaction("pairs").objectStore("pairs").get(keys[0]);
      r.onsuccess = () => ok(r.result);
    });
    const meta = JSON.parse(record.metadata);
    meta.force_n = meta.force_n ?? [0.1, 0.0, -0.1];
    meta.masks_labeled = true;
    const t = db.transaction("pairs", "readwrite");
    for (let i = keys.length; i < n; i++) {
      const id = `scale-${String(i).padStart(5, "0")}`;
      t.objectStore("pairs").put({ ...record, metadata: JSON.stringify({ ...meta, id, split: null }) }, id);
    }
    await new Promise((ok) => (t.oncomplete = ok));
    db.close();
    const bytes = ["view_a", "view_b", "mask_a", "mask_b"].reduce((s, k) => s + record[k].length, 0);
    return { bytes };
  }, pairs);
  const cdp = await context.newCDPSession(page);
  await cdp.send("Performance.enable");
  const heapMib = async () => {
    const { metrics } = await cdp.send("Performance.getMetrics");
    return metrics.find((m) => m.name === "JSHeapTotalSize").value / 2 ** 20;
  };
  const opened = performance.now();
  await page.reload();
  await waitForModel(page);
  await page.waitForFunction((n) => document.querySelectorAll("#pairs li[data-id]").length >= n, pairs, {
    timeout: 600_000,
  });
  const loadS = (performance.now() - opened) / 1000;
  const loaded = { rss: chromiumRssMib(), heap: await heapMib() };
  /** Exports every pair; the time, the page's longest unresponsive stretch, the memory peak. */
  const exportAll = async () => {
    // The page's longest unresponsive stretch during the export: a 50 ms heartbeat's largest gap.
    await page.evaluate(() => {
      window.hnetLongestGapMs = 0;
      let last = performance.now();
      window.hnetHeartbeat = setInterval(() => {
        const now = performance.now();
        window.hnetLongestGapMs = Math.max(window.hnetLongestGapMs, now - last);
        last = now;
      }, 50);
    });
    let peak = loaded.rss;
    const poll = setInterval(() => (peak = Math.max(peak, chromiumRssMib())), 200);
    const started = performance.now();
    const [download] = await Promise.all([
      page.waitForEvent("download", { timeout: 600_000 }),
      page.click("#export", { timeout: 600_000 }),
    ]);
    const exportS = (performance.now() - started) / 1000;
    const path = await download.path();
    clearInterval(poll);
    const longestGapMs = await page.evaluate(() => {
      clearInterval(window.hnetHeartbeat);
      return window.hnetLongestGapMs;
    });
    const zipMib = Number(execSync(`stat -c %s '${path}'`).toString()) / 2 ** 20;
    return { exportS, longestGapMs, peak, zipMib };
  };
  // The first export gives every pair its split (saved to storage); the second only exports.
  const first = await exportAll();
  const second = await exportAll();
  const { exportS, longestGapMs, peak, zipMib } = first;
  console.log(
    JSON.stringify({
      pairs,
      record_png_kib: Math.round(written.bytes / 1024),
      chromium_rss_mib_one_pair: Math.round(baseline),
      load_s: +loadS.toFixed(1),
      chromium_rss_mib_loaded: Math.round(loaded.rss),
      js_heap_mib_loaded: Math.round(loaded.heap),
      export_s: +exportS.toFixed(1),
      export_longest_unresponsive_ms: Math.round(longestGapMs),
      second_export_s: +second.exportS.toFixed(1),
      second_export_longest_unresponsive_ms: Math.round(second.longestGapMs),
      chromium_rss_mib_export_peak: Math.round(peak),
      zip_mib: +zipMib.toFixed(1),
      notice: await page.textContent("#notice"),
    }),
  );
  // Leave the profile as it was (it is a fresh temporary one anyway).
  await page.evaluate(async () => {
    const db = await new Promise((ok) => {
      const r = indexedDB.open("hnet-studio");
      r.onsuccess = () => ok(r.result);
    });
    const t = db.transaction("pairs", "readwrite");
    t.objectStore("pairs").clear();
    await new Promise((ok) => (t.oncomplete = ok));
  });
} finally {
  await context.close();
  await server.close();
}
