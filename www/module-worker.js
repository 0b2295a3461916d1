// The page's module workers, off the page's thread: `module-worker.js?module=hnet-cpu` reads views
// with H-Net on the CPU, one worker per core (crates/hnet-cpu); `?module=hnet-gpu` runs H-Net
// on WebGPU (crates/hnet-gpu), `?module=hnet-tune` fine-tunes it on the CPU (crates/hnet-tune).
// The page's side is src/module_worker.rs. Each message `{ id, call, args }` calls the module's
// export `call`; the reply is `{ id, value }` or `{ id, error }`. A module that fails to load
// answers every call with why.
const MODULES = ["hnet-cpu", "hnet-cpu-fused", "hnet-gpu", "hnet-tune"];
const name = new URL(self.location.href).searchParams.get("module");

const ready = MODULES.includes(name)
  ? import(`./${name}.js`).then(async (module) => {
      await module.default();
      return module;
    })
  : Promise.reject(new Error(`the page has no worker module "${name}"`));
// Failures are reported by the calls that wait for the module.
ready.catch(() => {});

self.onmessage = async ({ data: { id, call, args } }) => {
  try {
    const module = await ready;
    if (typeof module[call] !== "function" || call === "default") {
      throw new Error(`the ${name} module has no function "${call}"`);
    }
    const value = await module[call](...args);
    self.postMessage({ id, value }, ArrayBuffer.isView(value) ? [value.buffer] : []);
  } catch (error) {
    self.postMessage({ id, error: String(error?.message ?? error) });
  }
};
