//! Where H-Net runs in the browser: WebGPU when the browser offers an adapter, the CPU
//! (Burn's flex backend, compiled to WebAssembly with SIMD) otherwise.

use burn::tensor::Device;

/// The backend the page settled on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Backend {
    /// WebGPU through wgpu.
    WebGpu,
    /// Burn's flex CPU backend (WebAssembly).
    Cpu {
        /// Why WebGPU was not used.
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

/// Picks the device: WebGPU if an adapter can be had, the CPU otherwise.
pub async fn select_device(prefer_cpu: bool) -> (Device, Backend) {
    if prefer_cpu {
        return (
            Device::flex(),
            Backend::Cpu {
                reason: "CPU chosen".into(),
            },
        );
    }
    if !has_webgpu() {
        return (
            Device::flex(),
            Backend::Cpu {
                reason: "this browser has no WebGPU".into(),
            },
        );
    }
    match Device::wgpu_options().init_async().await {
        Ok(device) => (device, Backend::WebGpu),
        Err(e) => (
            Device::flex(),
            Backend::Cpu {
                reason: format!("no WebGPU adapter: {e}"),
            },
        ),
    }
}
