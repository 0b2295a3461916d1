// Screenshots of the page's main screens for docs/app.md (docs/images/app-*.png).
// Usage, after `trunk build`: node end2end/screenshots.mjs
import { mkdtemp, writeFile } from "node:fs/promises";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import { serveDist, launchBrowser, openPage, waitForModel } from "./harness.mjs";
import { catheterFrame } from "./images.mjs";

const IMAGES = resolve(new URL("..", import.meta.url).pathname, "docs", "images");

const server = await serveDist();
const context = await launchBrowser();
try {
  const { page } = await openPage(context, server.url);
  await page.setViewportSize({ width: 1500, height: 1150 });
  await waitForModel(page);

  // The live twin on an XRay-2 background, H-Net's masks and both force arrows.
  await page.click("#tab-background");
  await page.waitForSelector("#force-verdict", { timeout: 120_000 });
  await page.screenshot({ path: join(IMAGES, "app-composer.png") });

  // A kept twin pair with H-Net's masks as pre-labels, corrected with the brush.
  await page.click("#tab-twin");
  await page.locator("#twin-fx").fill("-0.2");
  await page.locator("#twin-fx").dispatchEvent("change");
  await page.waitForFunction(() => !document.querySelector("#busy"));
  await page.waitForSelector("#force-verdict");
  await page.click("#keep-draft");
  await page.click("#accept-masks");
  const box = await page.locator("#view-a").boundingBox();
  await page.mouse.move(box.x + box.width * 0.3, box.y + box.height * 0.25);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width * 0.36, box.y + box.height * 0.3, { steps: 8 });
  await page.mouse.up();
  await page.screenshot({ path: join(IMAGES, "app-labeling.png") });

  // Two uploaded images.
  const files = await mkdtemp(join(tmpdir(), "hnet-shots-"));
  await writeFile(join(files, "frame_a.png"), catheterFrame(300, 0.25));
  await writeFile(join(files, "frame_b.png"), catheterFrame(300, -0.15));
  await page.click("#tab-images");
  await page.setInputFiles("#file-pair", [join(files, "frame_a.png"), join(files, "frame_b.png")]);
  await page.waitForFunction(() => /loaded/.test(document.querySelector("#notice")?.textContent ?? ""));
  await page.waitForFunction(() => !document.querySelector("#busy"));
  await page.screenshot({ path: join(IMAGES, "app-upload.png") });
  console.log(`screenshots written to ${IMAGES}`);
} finally {
  await context.close();
  await server.close();
}
