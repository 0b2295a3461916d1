// The WebGPU worker: H-Net on WebGPU off the page's thread (crates/hnet-gpu; the page's side is
// src/gpu_worker.rs). Each message `{ id, call, args }` calls the module's export `call`; the
// reply is `{ id, value }` or `{ id, error }`. A module that fails to load answers every call
// with why.
import init, * as gpu from "./hnet-gpu.js";

const ready = init();

self.onmessage = async ({ data: { id, call, args } }) => {
  try {
    await ready;
    if (typeof gpu[call] !== "function" || call === "default") {
      throw new Error(`the WebGPU module has no function "${call}"`);
    }
    const value = await gpu[call](...args);
    self.postMessage({ id, value }, ArrayBuffer.isView(value) ? [value.buffer] : []);
  } catch (error) {
    self.postMessage({ id, error: String(error?.message ?? error) });
  }
};
