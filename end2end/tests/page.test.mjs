// End-to-end tests of the trunk-built page (dist/) in Debian's headless Chromium.
import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { mkdtemp, writeFile, readFile } from "node:fs/promises";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { serveDist, launchBrowser, openPage, waitForModel } from "../harness.mjs";
import { catheterFrame, readStoredZip } from "../images.mjs";

let server;
let context;
let files;
before(async () => {
  server = await serveDist();
  context = await launchBrowser();
  files = await mkdtemp(join(tmpdir(), "hnet-e2e-"));
  await writeFile(join(files, "frame_a.png"), catheterFrame(300, 0.25));
  await writeFile(join(files, "frame_b.png"), catheterFrame(300, -0.15));
  await writeFile(join(files, "notes.txt"), "not an image");
});
after(async () => {
  await context?.close();
  await server?.close();
});

const labelPixels = async (page, view) =>
  Number(await page.getAttribute(`#view-${view}`, "data-label-pixels"));

/** Drags the mouse across a view's canvas, from and to fractions of its size. */
async function paint(page, view, from, to) {
  const box = await page.locator(`#view-${view}`).boundingBox();
  const at = ([fx, fy]) => [box.x + fx * box.width, box.y + fy * box.height];
  await page.mouse.move(...at(from));
  await page.mouse.down();
  for (let i = 1; i <= 10; i++) {
    const t = i / 10;
    await page.mouse.move(...at([from[0] + t * (to[0] - from[0]), from[1] + t * (to[1] - from[1])]));
  }
  await page.mouse.up();
}

test("the page loads H-Net, says where it runs, and asks for nothing outside", async () => {
  const { page, requests, errors } = await openPage(context, server.url);
  await waitForModel(page);
  assert.match(await page.textContent("#backend"), /WebGPU|CPU/);
  assert.match(await page.textContent("#params"), /^\d+$/);
  // The bundled weights load (a build without them would say "untrained").
  assert.match(await page.textContent("#weights"), /hnet-cpu\.bpk/);
  const origin = new URL(server.url).origin;
  const foreign = requests.filter((u) => !u.startsWith(origin) && !u.startsWith("data:") && !u.startsWith("blob:"));
  assert.deepEqual(foreign, []);
  assert.deepEqual(errors, []);
  await page.close();
});

test("load a pair, run H-Net, paint, undo, reload with labels kept, export the dataset", async () => {
  const { page, errors } = await openPage(context, server.url);
  await waitForModel(page);
  await page.setInputFiles("#file-pair", [join(files, "frame_b.png"), join(files, "frame_a.png")]);
  await page.waitForSelector('#pairs li[data-id="pair-0001"]');
  // H-Net runs on the new pair: masks on both views and the force with its band.
  await page.waitForSelector("#force-verdict", { timeout: 120_000 });
  assert.match(await page.textContent("#force-verdict"), /\|F\| = \d\.\d{3} N: (below|within|above) the 0\.1–0\.3 N ablation band/);
  assert.notEqual(await page.getAttribute("#view-a", "data-predicted-pixels"), "");
  assert.match(await page.textContent("#inference-time"), /\d+ ms on (WebGPU|CPU)/);
  assert.match(await page.textContent(".view figcaption"), /frame_a\.png/);

  // Paint a stroke with the brush, then undo it.
  await page.click("#tool-brush");
  assert.equal(await labelPixels(page, "a"), 0);
  await paint(page, "a", [0.2, 0.2], [0.6, 0.3]);
  const painted = await labelPixels(page, "a");
  assert.ok(painted > 50, `${painted} pixels painted`);
  await page.keyboard.press("Control+z");
  await page.waitForFunction(() => document.querySelector("#view-a").dataset.labelPixels === "0");
  await page.keyboard.press("Control+Shift+z");
  await page.waitForFunction((n) => document.querySelector("#view-a").dataset.labelPixels === String(n), painted);
  // And view B, with the eraser afterwards taking part of it away.
  await paint(page, "b", [0.3, 0.7], [0.7, 0.7]);
  const b = await labelPixels(page, "b");
  await page.keyboard.press("e");
  await paint(page, "b", [0.5, 0.6], [0.5, 0.8]);
  assert.ok((await labelPixels(page, "b")) < b);
  const erased = await labelPixels(page, "b");

  // A force label, typed.
  await page.fill("#label-fx", "0.12");
  await page.fill("#label-fy", "-0.05");
  await page.fill("#label-fz", "0.2");
  await page.click("#label-save");
  await page.waitForSelector('#pairs li[data-id="pair-0001"] .flag.done[title="force"]');

  // Reload: the pair, its strokes and its force label are still there.
  await page.reload();
  await waitForModel(page);
  await page.waitForSelector('#pairs li[data-id="pair-0001"] .flag.done[title="masks"]');
  await page.waitForFunction((n) => document.querySelector("#view-a").dataset.labelPixels === String(n), painted);
  assert.equal(await labelPixels(page, "b"), erased);
  assert.equal(await page.inputValue("#label-fx"), "0.120");

  // Export: a zip in the dataset format.
  const [download] = await Promise.all([page.waitForEvent("download"), page.click("#export")]);
  assert.equal(download.suggestedFilename(), "hnet-studio-labels.zip");
  const path = join(files, "export.zip");
  await download.saveAs(path);
  const zip = readStoredZip(await readFile(path));
  const names = [...zip.keys()].sort();
  for (const name of [
    "hnet-studio-labels/dataset.json",
    "hnet-studio-labels/manifest.csv",
    "hnet-studio-labels/samples/pair-0001.json",
    "hnet-studio-labels/samples/pair-0001_view_a.png",
    "hnet-studio-labels/samples/pair-0001_view_b.png",
    "hnet-studio-labels/samples/pair-0001_mask_a.png",
    "hnet-studio-labels/samples/pair-0001_mask_b.png",
  ]) {
    assert.ok(names.includes(name), `${name} missing from ${names}`);
  }
  const header = JSON.parse(zip.get("hnet-studio-labels/dataset.json").toString());
  assert.equal(header.format, "hnet-dataset");
  assert.deepEqual(header.image_size, [224, 224]);
  const manifest = zip.get("hnet-studio-labels/manifest.csv").toString().trim().split("\n");
  assert.match(manifest[0], /^id,split,fx,fy,fz/);
  assert.match(manifest[1], /^pair-0001,train,0\.12,-0\.05,0\.2/);
  assert.match(await page.textContent("#notice"), /1 pair\(s\) exported/);
  assert.deepEqual(errors, []);
  await page.close();
});

test("bad input gets a clear message and loses nothing", async () => {
  const { page } = await openPage(context, server.url);
  await waitForModel(page);
  await page.waitForSelector('#pairs li[data-id="pair-0001"]');
  const before = await page.locator("#pairs li").count();
  await page.setInputFiles("#file-pair", [join(files, "notes.txt"), join(files, "frame_a.png")]);
  await page.waitForSelector('#notice[data-kind="error"]');
  assert.match(await page.textContent("#notice"), /notes\.txt: not an image/);
  await page.setInputFiles("#file-pair", [join(files, "frame_a.png")]);
  await page.waitForFunction(() => /1 file was given/.test(document.querySelector("#notice")?.textContent));
  assert.equal(await page.locator("#pairs li").count(), before);

  // Weights that are not H-Net's: refused by name, the current model stays.
  const weights = await page.textContent("#weights");
  await page.setInputFiles("#weights-file", join(files, "notes.txt"));
  await page.waitForFunction(() => /notes\.txt/.test(document.querySelector("#notice")?.textContent));
  assert.match(await page.textContent("#notice"), /Still using/);
  await waitForModel(page);
  assert.equal(await page.textContent("#weights"), weights);
  await page.close();
});

test("the live twin bends the catheter with the sliders and composes X-ray backgrounds", async () => {
  const { page, errors } = await openPage(context, server.url);
  await waitForModel(page);
  await page.click("#tab-twin");
  await page.waitForSelector("#keep-draft");
  const straight = await labelPixels(page, "a");
  assert.ok(straight > 200);
  const caption = await page.textContent(".view figcaption");
  assert.match(caption, /C-arm \+0° \/ \+0°/);
  // Push the tip sideways: the catheter's silhouette changes.
  const before = await page.evaluate(() => document.querySelector("#view-a").toDataURL());
  await page.locator("#twin-fx").fill("-0.35");
  await page.waitForFunction((b) => document.querySelector("#view-a").toDataURL() !== b, before);
  // The true force is shown beside H-Net's estimate, with the error, and the bundled weights'
  // caveat beside it.
  await page.waitForSelector("#force-table tr.error");
  assert.match(await page.textContent("#force-caveat"), /R² 0\.40/);

  await page.click("#tab-background");
  await page.waitForSelector("#background-source-canvas");
  assert.match(await page.textContent("#background-source"), /phantom/);
  const seed = Number(await page.inputValue("#background-seed"));
  const shuffled = await page.evaluate(() => document.querySelector("#background-a").toDataURL());
  await page.click("#background-shuffle");
  assert.equal(Number(await page.inputValue("#background-seed")), seed + 1);
  await page.waitForFunction((s) => document.querySelector("#background-a").toDataURL() !== s, shuffled);
  await page.click("#style-xray1");

  const pairs = await page.locator("#pairs li").count();
  await page.click("#keep-draft");
  await page.waitForFunction((n) => document.querySelectorAll("#pairs li").length === n + 1, pairs);
  assert.deepEqual(errors, []);
  await page.close();
});
