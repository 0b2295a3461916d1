//! Browser tests: run in headless Chromium by `wasm-bindgen-test-runner`.
#![cfg(target_arch = "wasm32")]

use burn::tensor::{Device, Tensor};
use hnet_model::HNetConfig;
use wasm_bindgen_test::*;

wasm_bindgen_test_configure!(run_in_browser);

#[wasm_bindgen_test]
fn hnet_forward_pass_on_the_cpu_backend() {
    let device = Device::flex();
    let model = HNetConfig::new()
        .with_image_size([32, 32])
        .init(&device)
        .unwrap();
    let a = Tensor::zeros([1, 3, 32, 32], &device);
    let b = Tensor::ones([1, 3, 32, 32], &device);
    let out = model.forward(a, b);
    assert_eq!(out.mask_a().dims(), [1, 1, 32, 32]);
    assert_eq!(out.force.dims(), [1, 3]);
}
