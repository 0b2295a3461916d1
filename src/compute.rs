//! Where H-Net runs in the browser: WebGPU when the browser offers a hardware adapter, the CPU
//! (Burn's flex backend, compiled to WebAssembly with SIMD) otherwise or when the user asks for
//! it. WebGPU on a software adapter only when the user asks for WebGPU. WebGPU runs in a worker
//! whose module the page fetches only then ([`crate::gpu_worker`]).

use js_sys::{Function, Promise, Reflect};
use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_futures::JsFuture;

/// What the user asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendChoice {
    /// WebGPU on a hardware adapter; the CPU where the browser has none or only a software one.
    Auto,
    /// WebGPU on whatever adapter the browser offers, software ones included.
    WebGpu,
    /// The CPU.
    Cpu,
}

impl BackendChoice {
    /// The value of the choice in the page's `<select>`.
    pub fn value(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::WebGpu => "webgpu",
            Self::Cpu => "cpu",
        }
    }

    /// The choice of a `<select>` value (`auto` for anything unknown).
    pub fn from_value(value: &str) -> Self {
        match value {
            "webgpu" => Self::WebGpu,
            "cpu" => Self::Cpu,
            _ => Self::Auto,
        }
    }
}

/// The backend the page settled on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Backend {
    /// WebGPU through wgpu, in the WebGPU worker.
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

/// The browser's WebGPU object, `navigator.gpu`, if it has one.
fn navigator_gpu() -> Option<JsValue> {
    let window = web_sys::window()?;
    Reflect::get(&window.navigator(), &JsValue::from_str("gpu"))
        .ok()
        .filter(|gpu| gpu.is_object())
}

/// The browser's default WebGPU adapter as the page will get it: `None` when there is none,
/// else `Some(Some(name))` for a software adapter (such as Chromium's SwiftShader) and
/// `Some(None)` for a hardware one.
async fn default_adapter(gpu: &JsValue) -> Option<Option<String>> {
    let request: Function = Reflect::get(gpu, &JsValue::from_str("requestAdapter"))
        .ok()?
        .dyn_into()
        .ok()?;
    let promise: Promise = request.call0(gpu).ok()?.dyn_into().ok()?;
    let adapter = JsFuture::from(promise).await.ok()?;
    if !adapter.is_object() {
        return None;
    }
    let get = |object: &JsValue, key: &str| Reflect::get(object, &JsValue::from_str(key)).ok();
    let info = get(&adapter, "info").filter(JsValue::is_object);
    let text = |key: &str| {
        info.as_ref()
            .and_then(|i| get(i, key))
            .and_then(|v| v.as_string())
            .unwrap_or_default()
    };
    let fallback = |object: &JsValue| {
        get(object, "isFallbackAdapter")
            .and_then(|v| v.as_bool())
            .unwrap_or(false)
    };
    let names = ["vendor", "architecture", "device", "description"]
        .map(text)
        .join(" ")
        .to_lowercase();
    const SOFTWARE: [&str; 5] = [
        "swiftshader",
        "llvmpipe",
        "lavapipe",
        "software",
        "basic render",
    ];
    let software = fallback(&adapter)
        || info.as_ref().is_some_and(fallback)
        || SOFTWARE.iter().any(|s| names.contains(s));
    Some(software.then(|| {
        let name = names.split_whitespace().collect::<Vec<_>>().join(" ");
        if name.is_empty() {
            "a software adapter".to_string()
        } else {
            format!("a software adapter ({name})")
        }
    }))
}

/// The backend for `choice`, from the adapter the browser offers. `Auto` takes WebGPU only on a
/// hardware adapter: a software adapter (Chromium's SwiftShader, Mesa's llvmpipe) runs H-Net
/// many times slower than the CPU path (docs/benchmarks.md), so the CPU is used and the reason
/// says so. WebGPU itself is set up by the caller, in the worker, and may still fail there.
pub async fn choose_backend(choice: BackendChoice) -> Backend {
    let cpu = |reason: String| Backend::Cpu { reason };
    if choice == BackendChoice::Cpu {
        return cpu("CPU chosen".into());
    }
    let Some(gpu) = navigator_gpu() else {
        return cpu("this browser has no WebGPU".into());
    };
    match default_adapter(&gpu).await {
        None => cpu(
            "this browser's WebGPU offers no adapter (no supported GPU, or WebGPU is turned off)"
                .into(),
        ),
        Some(Some(software)) if choice == BackendChoice::Auto => cpu(format!(
            "WebGPU here is {software}, much slower than the CPU path; choose \u{201c}WebGPU\u{201d} \
             to use it anyway"
        )),
        Some(_) => Backend::WebGpu,
    }
}
