import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { serveDist, launchBrowser, openPage } from "../harness.mjs";

let server;
let context;
before(async () => {
  server = await serveDist();
  context = await launchBrowser();
});
after(async () => {
  await context?.close();
  await server?.close();
});

test("the page loads H-Net and says which backend it runs on", async () => {
  const { page, requests, errors } = await openPage(context, server.url);
  await page.waitForSelector("#model-status [data-state=ready], #model-status [data-state=failed]", {
    timeout: 120_000,
  });
  const failed = await page.$("#model-status [data-state=failed]");
  assert.equal(failed, null, failed && (await failed.textContent()));
  const backend = await page.textContent("#backend");
  assert.match(backend, /WebGPU|CPU/);
  assert.match(await page.textContent("#params"), /^\d+$/);
  // Nothing but the page's own files.
  const origin = new URL(server.url).origin;
  const foreign = requests.filter((u) => !u.startsWith(origin) && !u.startsWith("data:") && !u.startsWith("blob:"));
  assert.deepEqual(foreign, []);
  assert.deepEqual(errors, []);
});
