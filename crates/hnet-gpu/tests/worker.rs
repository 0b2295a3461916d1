//! The WebGPU worker's module in a dedicated worker of headless Chromium, as the page runs it.
//! With `--enable-unsafe-webgpu` (webdriver.json) Chromium offers a software adapter
//! (SwiftShader): H-Net computes there what it computes on the CPU, and bad calls are errors.
#![cfg(target_arch = "wasm32")]

use std::collections::BTreeMap;

use burn::tensor::Device;
use hnet_model::HNetConfig;
use hnet_model::inference::{StereoPair, StereoPrediction};
use hnet_model::mask_averaging::MaskAveraging;
use hnet_units::ImageSize;
use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_test::*;

wasm_bindgen_test_configure!(run_in_dedicated_worker);

/// The message of an export's error.
fn message(error: wasm_bindgen::JsError) -> String {
    JsValue::from(error)
        .unchecked_into::<js_sys::Error>()
        .message()
        .into()
}

#[wasm_bindgen_test]
async fn h_net_on_webgpu_computes_what_the_cpu_computes() {
    hnet_gpu::start().await.map_err(message).unwrap();
    // Starting again reuses the device.
    hnet_gpu::start().await.map_err(message).unwrap();
    let size = ImageSize::square(32);
    let config = HNetConfig::new().with_image_size(size);
    let cpu = config.init(&Device::flex()).unwrap();
    let weights = cpu.to_weights_bytes(&config, &BTreeMap::new()).unwrap();
    let handle = hnet_gpu::load(&weights, "small.bpk", "single")
        .map_err(message)
        .unwrap();
    let image = |phase: f32| -> Vec<u8> {
        (0..size.pixels() * 3)
            .map(|i| (((i as f32 * 0.37 + phase).sin() + 1.0) * 127.0) as u8)
            .collect()
    };
    let (a, b) = (image(0.0), image(1.0));
    let expected = cpu
        .predict(
            &[StereoPair {
                view_a: &a,
                view_b: &b,
            }],
            size,
            &Device::flex(),
            MaskAveraging::Single,
        )
        .unwrap()
        .remove(0);
    let packed = hnet_gpu::infer(handle, a, b)
        .await
        .map_err(message)
        .unwrap();
    let found = StereoPrediction::from_packed(&packed.to_vec(), size).unwrap();
    let largest = |x: &[f32], y: &[f32]| {
        x.iter()
            .zip(y)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    assert!(
        largest(&expected.force.newtons(), &found.force.newtons()) < 1e-4,
        "{found:?}"
    );
    assert!(largest(&expected.mask_a, &found.mask_a) < 1e-4);
    assert!(largest(&expected.mask_b, &found.mask_b) < 1e-4);

    // A freed network, a wrong image and a file that is no weights are errors that say so.
    hnet_gpu::unload(handle);
    let err = hnet_gpu::infer(handle, vec![0; 3], vec![0; 3]).await;
    assert_eq!(
        message(err.unwrap_err()),
        format!("the WebGPU worker holds no network {handle}")
    );
    let other = hnet_gpu::load(&weights, "small.bpk", "mirrored")
        .map_err(message)
        .unwrap();
    assert_ne!(other, handle);
    let err = hnet_gpu::infer(other, vec![0; 3], vec![0; 3]).await;
    assert!(message(err.unwrap_err()).starts_with("pair 0 view A: 3 bytes"));
    let err = hnet_gpu::load(&weights, "small.bpk", "twice").unwrap_err();
    assert_eq!(
        message(err),
        "no way of reading a view is called `twice` (single or mirrored)"
    );
    let err = hnet_gpu::load(b"not weights", "junk.bpk", "single").unwrap_err();
    assert!(message(err).starts_with("weights file 'junk.bpk': "));
}
