// ONNX Runtime Web's time for one H-Net stereo pair in headless Chromium (Debian's, launched by
// ../harness.mjs with the end-to-end tests' flags and a fresh profile): the reference the page's
// CPU inference (../bench.mjs) is held to (docs/benchmarks.md, issue #11).
//
//   python bench/pytorch_hnet.py --size 64 --onnx end2end/ort-bench/model/hnet-64.onnx
//   (cd end2end/ort-bench && npm ci)
//   node end2end/ort-bench/bench.mjs [runs] [--threads N] [--warmup N] [--model FILE] [--size N]
//
// --model is a file under end2end/ort-bench/ (default model/hnet-<size>.onnx, gitignored).
// --threads is ONNX Runtime Web's numThreads (default 1, as the page's Burn CPU path has one
// thread in wasm); for more than 1 this server turns on cross-origin isolation, which they need.
import { existsSync } from "node:fs";
import { relative, resolve } from "node:path";
import { parseArgs } from "node:util";
import { launchBrowser, serveFolder } from "../harness.mjs";

const HERE = resolve(new URL(".", import.meta.url).pathname);
const { values, positionals } = parseArgs({
  allowPositionals: true,
  options: {
    threads: { type: "string", default: "1" },
    warmup: { type: "string", default: "5" },
    size: { type: "string", default: "64" },
    model: { type: "string" },
  },
});
const runs = Number(positionals[0] ?? 20);
const size = Number(values.size);
const model = resolve(values.model ?? resolve(HERE, "model", `hnet-${size}.onnx`));
const inside = relative(HERE, model);
if (inside.startsWith("..") || !existsSync(model)) {
  console.error(
    `no model at ${model} (it must be a file under ${HERE}); make it with\n` +
      `  python bench/pytorch_hnet.py --size ${size} --onnx end2end/ort-bench/model/hnet-${size}.onnx`,
  );
  process.exit(2);
}
if (!existsSync(resolve(HERE, "node_modules/onnxruntime-web"))) {
  console.error(`onnxruntime-web is not installed: (cd ${HERE} && npm ci)`);
  process.exit(2);
}

// Cross-origin isolation gives the page SharedArrayBuffer, which ONNX Runtime Web's threads need;
// with one thread the page is served as the H-Net Studio page is, without it.
const threads = Number(values.threads);
const server = await serveFolder(
  HERE,
  threads > 1
    ? { "cross-origin-opener-policy": "same-origin", "cross-origin-embedder-policy": "require-corp" }
    : {},
);
const context = await launchBrowser();
try {
  const page = await context.newPage();
  const errors = [];
  page.on("pageerror", (e) => errors.push(String(e)));
  page.on("console", (m) => m.type() === "error" && errors.push(m.text()));
  await page.goto(server.url);
  await page.waitForFunction(() => window.benchOrtReady === true, null, { timeout: 60_000 }).catch(() => {
    throw new Error(`the bench page did not load: ${errors.join("; ")}`);
  });
  const result = await page.evaluate((options) => window.benchOrt(options), {
    model: `./${inside.split("\\").join("/")}`,
    size,
    threads,
    warmup: Number(values.warmup),
    runs,
  });
  const round = (ms) => Math.round(ms * 100) / 100;
  console.log(
    JSON.stringify(
      {
        ...result,
        model: inside,
        size,
        browser: context.browser()?.version() ?? null,
        load_ms: round(result.load_ms),
        median_ms: round(result.median_ms),
        min_ms: round(result.min_ms),
        max_ms: round(result.max_ms),
        times_ms: result.times_ms.map(round),
      },
      null,
      2,
    ),
  );
} finally {
  await context.close();
  await server.close();
}
