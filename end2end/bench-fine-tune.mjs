// The page's fine-tune on this machine (docs/benchmarks.md, "Fine-tuning in the page"): how long
// its epochs take and whether the page keeps answering while the worker trains, and when the
// result is kept. Clicks are timed twice: by Playwright (its own checks and polling included)
// and inside the page, from the click to the next frame drawn, idle and while it trains. The
// browser's long tasks (over 50 ms) are listed from the start of the run, and after Keep.
// Usage, after `trunk build --release` (or `trunk build`): node end2end/bench-fine-tune.mjs [PAIRS] [EPOCHS]
// HNET_PAGE_QUERY=<query> opens the page with that query (src/page_query.rs), e.g.
// `?tune-patience=100` to run every epoch asked for.
import { serveDist, launchBrowser, openPage, waitForModel } from "./harness.mjs";

const TABS = ["#tab-images", "#tab-twin", "#tab-images", "#tab-twin", "#tab-images", "#tab-twin"];

/// Each of `tabs` clicked inside the page, the time from the click to the next frame drawn, ms.
async function clicksToFrame(page, tabs) {
  const times = [];
  for (const tab of tabs) {
    await page.waitForTimeout(300);
    times.push(await page.evaluate(async (selector) => {
      const t0 = performance.now();
      document.querySelector(selector).click();
      await new Promise((frame) => requestAnimationFrame(() => setTimeout(frame, 0)));
      return Math.round(performance.now() - t0);
    }, tab));
  }
  return times;
}

/// Each of `tabs` clicked by Playwright, until the tab reads as selected, ms.
async function playwrightClicks(page, tabs) {
  const times = [];
  for (const tab of tabs) {
    const t0 = Date.now();
    await page.click(tab);
    await page.waitForSelector(`${tab}[aria-selected=true]`);
    times.push(Date.now() - t0);
  }
  return times;
}

const pairs = Number(process.argv[2] ?? 10);
const epochs = Number(process.argv[3] ?? 2);
const server = await serveDist();
const context = await launchBrowser();
try {
  const { page } = await openPage(context, server.url + (process.env.HNET_PAGE_QUERY ?? ""));
  await waitForModel(page);
  await page.click("#tab-twin");
  for (let i = 0; i < pairs; i++) {
    await page.focus("#twin-fx");
    await page.keyboard.press(i % 2 ? "ArrowLeft" : "ArrowRight");
    await page.waitForSelector("#keep-draft:not([disabled])");
    await page.click("#keep-draft");
    await page.waitForFunction((n) => document.querySelectorAll("#pairs li[data-id]").length === n, i + 1);
  }
  const idle = { clicks_ms: await playwrightClicks(page, TABS), click_to_frame_ms: await clicksToFrame(page, TABS) };
  await page.click("#tune-epochs", { clickCount: 3 });
  await page.keyboard.type(String(epochs));
  await page.keyboard.press("Tab");
  // The page's event loop, sampled every 50 ms while the worker trains: the longest wait for a
  // timer is the longest the page could not answer input.
  await page.evaluate(() => {
    window.__start = performance.now();
    window.__longTasks = [];
    new PerformanceObserver((list) => {
      for (const task of list.getEntries()) window.__longTasks.push([Math.round(task.startTime - window.__start), Math.round(task.duration)]);
    }).observe({ type: "longtask" });
    window.__lags = [];
    let last = performance.now();
    window.__lagTimer = setInterval(() => {
      const now = performance.now();
      window.__lags.push(now - last - 50);
      last = now;
    }, 50);
  });
  const started = Date.now();
  await page.click("#tune-start");
  // A click on a tab answers while it trains.
  await page.waitForFunction(() => /Epoch 1 of/.test(document.querySelector("#tune-progress-text")?.textContent ?? ""), null, { timeout: 600_000 });
  // The start (twin pairs drawn, workers loaded, the starting network scored) ends here.
  const trainingFrom = (Date.now() - started) / 1000;
  // Where the steps run: "on WebGPU", or "on N CPU workers…".
  const progress = await page.textContent("#tune-progress-text");
  const workers = / · on WebGPU$/.test(progress) ? "WebGPU" : Number(progress.match(/ · on (\d+) CPU workers?/)?.[1]);
  const clicks = await playwrightClicks(page, TABS.slice(0, 4));
  const clickToFrame = await clicksToFrame(page, TABS);
  await page.waitForSelector("#tune-table", { timeout: 1_800_000 });
  const seconds = (Date.now() - started) / 1000;
  const lags = await page.evaluate(() => {
    clearInterval(window.__lagTimer);
    const sorted = [...window.__lags].sort((a, b) => a - b);
    return { samples: sorted.length, p99: sorted[Math.floor(sorted.length * 0.99)], max: sorted[sorted.length - 1] };
  });
  const rows = await page.$$eval("#tune-table tbody tr", (trs) => trs.map((tr) => [...tr.cells].map((c) => c.textContent)));
  const caption = await page.textContent("#tune-table caption");
  const reference = await page.textContent("#tune-reference");
  // Keep: the result stored, chosen and loaded.
  const longTasksWhileTuning = await page.evaluate(() => window.__longTasks.splice(0));
  const kept = await page.evaluate(() => performance.now() - window.__start);
  await page.click("#tune-keep");
  await page.waitForFunction(() => document.querySelector("#weights")?.textContent === "hnet-fine-tuned.bpk", null, { timeout: 60_000 });
  await page.waitForTimeout(5000);
  const longTasksAfterKeep = await page.evaluate((kept) => window.__longTasks.map(([at, ms]) => [Math.round(at - kept), ms]), kept);
  console.log(JSON.stringify({
    pairs, epochs, workers, seconds, training_from_s: trainingFrom, caption, idle, clicks_ms: clicks, click_to_frame_ms: clickToFrame, event_loop_lag_ms: lags,
    long_tasks_ms: { while_tuning: longTasksWhileTuning, after_keep: longTasksAfterKeep }, table: rows, reference,
  }));
} finally {
  await context.close();
  await server.close();
}
