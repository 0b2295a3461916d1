// Starts the WebAssembly app. Trunk writes the hashed file names into the
// script tag's data attributes (Trunk.toml, `pattern_script`).
const tag = document.querySelector("script[data-hnet-js]");
const { default: init } = await import(tag.dataset.hnetJs);
await init({ module_or_path: tag.dataset.hnetWasm });
