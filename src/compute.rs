//! Where H-Net runs in the browser: WebGPU when the browser offers an adapter, the CPU (Burn's
//! flex backend, compiled to WebAssembly with SIMD) otherwise or when the user asks for it.

use burn::tensor::Device;

/// What the user asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendChoice {
    /// WebGPU if the browser has an adapter, else the CPU.
    Auto,
    /// The CPU.
    Cpu,
}

/// The backend the page settled on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Backend {
    /// WebGPU through wgpu.
    WebGpu,
    /// Burn's flex CPU backend (WebAssembly).
    Cpu {
        /// Why WebGPU is not used.
        reason: String,
    },
}

impl Backend {
    /// Short name shown on the page.
    pub fn label(&self) -> &'static str {
        match self {
            Backend::WebGpu => "WebGPU",
            Backend::Cpu { .. } => "CPU (WebAssembly)",
        }
    }

    /// Why the CPU is used, if it is.
    pub fn reason(&self) -> Option<&str> {
        match self {
            Backend::WebGpu => None,
            Backend::Cpu { reason } => Some(reason),
        }
    }
}

/// Whether the browser exposes `navigator.gpu` at all.
fn has_webgpu() -> bool {
    web_sys::window()
        .map(|w| {
            js_sys::Reflect::has(&w.navigator(), &wasm_bindgen::JsValue::from_str("gpu"))
                .unwrap_or(false)
        })
        .unwrap_or(false)
}

thread_local! {
    /// The WebGPU device, once set up: wgpu registers one runtime per device and page, so
    /// switching back to WebGPU (after the CPU, or to load other weights) reuses it.
    static WEBGPU: std::cell::RefCell<Option<Device>> = const { std::cell::RefCell::new(None) };
}

/// Picks the device: WebGPU if asked for (`Auto`) and an adapter can be had, the CPU otherwise.
pub async fn select_device(choice: BackendChoice) -> (Device, Backend) {
    let cpu = |reason: String| (Device::flex(), Backend::Cpu { reason });
    if choice == BackendChoice::Cpu {
        return cpu("CPU chosen".into());
    }
    if !has_webgpu() {
        return cpu("this browser has no WebGPU".into());
    }
    if let Some(device) = WEBGPU.with_borrow(|d| d.clone()) {
        return (device, Backend::WebGpu);
    }
    match Device::wgpu_options().init_async().await {
        Ok(device) => {
            WEBGPU.set(Some(device.clone()));
            (device, Backend::WebGpu)
        }
        Err(e) => cpu(format!("no WebGPU adapter: {e}")),
    }
}
