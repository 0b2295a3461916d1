#[cfg(target_arch = "wasm32")]
fn main() {
    console_error_panic_hook::set_once();
    leptos::mount::mount_to_body(hnet_studio::App);
}

#[cfg(not(target_arch = "wasm32"))]
fn main() {
    eprintln!("H-Net Studio's page runs in the browser: `scripts/demo.sh` builds and serves it.");
    std::process::exit(2);
}
