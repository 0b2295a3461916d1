// Serves the trunk-built page (dist/) and drives Debian's headless Chromium with playwright-core.
import { createServer } from "node:http";
import { readFile, mkdtemp } from "node:fs/promises";
import { tmpdir } from "node:os";
import { extname, join, normalize, resolve } from "node:path";
import { chromium } from "playwright-core";

// HNET_DIST serves another build (e.g. scripts/bundle-size.sh's release page).
export const DIST = process.env.HNET_DIST
  ? resolve(process.env.HNET_DIST)
  : resolve(new URL("..", import.meta.url).pathname, "dist");
const TYPES = {
  ".html": "text/html",
  ".js": "text/javascript",
  ".mjs": "text/javascript",
  ".wasm": "application/wasm",
  ".css": "text/css",
  ".json": "application/json",
  ".png": "image/png",
  ".bpk": "application/octet-stream",
  ".onnx": "application/octet-stream",
};

/** Starts a static server for dist/ on a free port; returns { url, close }. */
export async function serveDist() {
  return serveFolder(DIST);
}

/** Starts a static server for the folder `root` on a free port, adding `headers` to every
 * answer; returns { url, close }. */
export async function serveFolder(root, headers = {}) {
  const server = createServer(async (req, res) => {
    const path = decodeURIComponent(new URL(req.url, "http://x").pathname);
    const file = normalize(join(root, path === "/" ? "index.html" : path));
    if (!file.startsWith(root)) {
      res.writeHead(403).end();
      return;
    }
    try {
      const body = await readFile(file);
      res.writeHead(200, {
        ...headers,
        "content-type": TYPES[extname(file)] ?? "application/octet-stream",
      });
      res.end(body);
    } catch {
      res.writeHead(404).end("not found");
    }
  });
  await new Promise((ok) => server.listen(0, "127.0.0.1", ok));
  const { port } = server.address();
  return { url: `http://127.0.0.1:${port}/`, close: () => new Promise((ok) => server.close(ok)) };
}

/** Launches headless Chromium with a fresh profile. */
export async function launchBrowser() {
  const profile = await mkdtemp(join(tmpdir(), "hnet-chromium-"));
  return chromium.launchPersistentContext(profile, {
    executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
    headless: true,
    args: [
      "--no-sandbox",
      "--disable-background-networking",
      "--disable-component-update",
      "--disable-sync",
      "--no-first-run",
      "--disable-quic",
      "--enable-unsafe-webgpu",
    ],
  });
}

/** Opens the page, recording requests and console errors. */
export async function openPage(context, url) {
  const page = await context.newPage();
  const requests = [];
  const errors = [];
  page.on("request", (r) => requests.push(r.url()));
  page.on("console", (m) => m.type() === "error" && errors.push(m.text()));
  page.on("pageerror", (e) => errors.push(String(e)));
  await page.goto(url);
  return { page, requests, errors };
}

/** Waits until the page's model is ready (it fails the test if loading failed). */
export async function waitForModel(page) {
  await page.waitForSelector("#model-status [data-state=ready], #model-status [data-state=failed]", {
    timeout: 180_000,
  });
  const failed = await page.$("#model-status [data-state=failed]");
  if (failed) throw new Error(`the model did not load: ${await failed.textContent()}`);
}

/**
 * Loads the weights file `HNET_WEIGHTS` names (e.g. a model.bpk from `hnet train`) through the
 * model bar and waits until it is ready; does nothing when the variable is unset.
 */
export async function loadWeightsFromEnv(page) {
  const file = process.env.HNET_WEIGHTS;
  if (!file) return;
  const name = file.split("/").pop();
  await page.setInputFiles("#weights-file", file);
  await page.waitForFunction((n) => document.querySelector("#weights")?.textContent.includes(n), name, {
    timeout: 60_000,
  });
  await waitForModel(page);
}
