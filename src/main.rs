#[cfg(target_arch = "wasm32")]
unsafe extern "C" {
    /// The linker's function that runs the module's static constructors (some of Burn's
    /// dependencies register plugins through `inventory`).
    fn __wasm_call_ctors();
}

#[cfg(target_arch = "wasm32")]
fn main() {
    // Run the constructors once, here. Without this call the linker treats the page as a
    // command-style module and runs every constructor again at the start of every exported
    // function (each allocation and closure call from JavaScript): about 12 % of the page's busy
    // time in its profile (docs/benchmarks.md, "In the browser"). The `inventory` crate documents
    // this fix.
    // SAFETY: called once (wasm-bindgen runs `main` once per instance), before any code that reads
    // what the constructors register.
    unsafe { __wasm_call_ctors() };
    console_error_panic_hook::set_once();
    leptos::mount::mount_to_body(hnet_studio::App);
}

#[cfg(not(target_arch = "wasm32"))]
fn main() {
    eprintln!("H-Net Studio's page runs in the browser: `scripts/demo.sh` builds and serves it.");
    std::process::exit(2);
}
