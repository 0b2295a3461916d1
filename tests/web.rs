//! Browser tests, run in headless Chromium by `wasm-bindgen-test-runner` (see DEVELOPERS.md):
//! H-Net on the CPU backend, the backend choice and a WebGPU worker that cannot load, the browser storage, inference
//! on a twin pair, and the page's components.
#![cfg(target_arch = "wasm32")]

use std::collections::BTreeMap;
use std::rc::Rc;

use burn::tensor::{Device, Tensor};
use hnet_model::catheter_entry::{CatheterEntry, EntrySetting};
use hnet_model::mask_averaging::MaskAveraging;
use hnet_model::{HNet, HNetConfig};
use hnet_studio::browser::{JsError, yield_to_browser};
use hnet_studio::compute::{Backend, BackendChoice, choose_backend};
use hnet_studio::engine::{Engine, WeightsOrigin};
use hnet_studio::error_text::with_causes;
use hnet_studio::gpu_worker::GpuWorker;
use hnet_studio::imaging::WORK_SIZE;
use hnet_studio::storage;
use hnet_studio::twin_live::{TwinControls, XrayBackground};
use hnet_twin::model_facts::{MeasuredForce, ModelFacts};
use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_test::*;

wasm_bindgen_test_configure!(run_in_browser);

fn small_hnet(device: &Device) -> (HNet, HNetConfig) {
    let config = HNetConfig::new().with_image_size(hnet_units::ImageSize::square(32));
    (config.init(device).unwrap(), config)
}

/// A small H-Net on the CPU, and its weights file.
fn small_hnet_weights() -> (HNet, Vec<u8>) {
    let (model, config) = small_hnet(&Device::flex());
    let bytes = model.to_weights_bytes(&config, &BTreeMap::new()).unwrap();
    (model, bytes)
}

#[wasm_bindgen_test]
fn hnet_forward_pass_on_the_cpu_backend() {
    let device = Device::flex();
    let (model, _) = small_hnet(&device);
    let a = Tensor::zeros([1, 3, 32, 32], &device);
    let b = Tensor::ones([1, 3, 32, 32], &device);
    let out = model.forward(a, b);
    assert_eq!(out.mask_a().dims(), [1, 1, 32, 32]);
    assert_eq!(out.force.dims(), [1, 3]);
}

/// The project's convolution kernels (crates/hnet-conv) give Burn's results in the browser too,
/// built for wasm32 with SIMD128: forward passes of random convolutions, of H-Net's two layer
/// shapes and of layers wide enough for the Winograd kernel's 2 x 2 and 4 x 4 tiles on flex,
/// within the native tests' tolerance (the gradients, which the page never computes, are checked
/// natively: crates/hnet-conv/tests/against_burn.rs).
#[wasm_bindgen_test]
fn the_project_convolutions_compute_what_burn_computes() {
    use hnet_conv::conformance::{ConvCase, TOLERANCE};
    let device = Device::flex();
    let cases = (0..64)
        .map(ConvCase::from_seed)
        .filter(ConvCase::is_valid)
        .chain([false, true].map(|transposed| ConvCase::h_net_layer(transposed, 3)))
        .chain([
            ConvCase::winograd_layer(3),
            ConvCase::winograd_large_tile_layer(3),
        ]);
    let mut checked = 0;
    for case in cases {
        let error = case.forward_error(&device);
        assert!(error <= TOLERANCE, "{case:?}: error {error:e}");
        checked += 1;
    }
    assert!(checked >= 40, "only {checked} cases were valid");
}

#[wasm_bindgen_test]
async fn asking_for_the_cpu_gives_the_cpu() {
    let backend = choose_backend(BackendChoice::Cpu).await;
    assert_eq!(backend.label(), "CPU (WebAssembly)");
    assert_eq!(backend.reason(), Some("CPU chosen"));
}

/// "Fastest available" does not take a software WebGPU adapter (SwiftShader here): the CPU path
/// is many times faster, and the reason is said in plain words.
#[wasm_bindgen_test]
async fn the_fastest_choice_passes_over_a_software_adapter() {
    let backend = choose_backend(BackendChoice::Auto).await;
    let Backend::Cpu { reason } = &backend else {
        panic!("headless Chromium has no hardware adapter, yet {backend:?} was chosen");
    };
    assert!(
        reason.contains("software adapter")
            || reason.contains("no adapter")
            || reason.contains("no WebGPU"),
        "{reason}"
    );
}

/// The WebGPU worker's script is not served here (only the page's build has it): starting the
/// worker fails with why, and does not hang. (H-Net on WebGPU in a worker is tested in
/// crates/hnet-gpu, the page's switch to it end to end.)
#[wasm_bindgen_test]
async fn a_webgpu_worker_that_cannot_load_is_an_error() {
    let Err(err) = GpuWorker::shared().await else {
        panic!("the worker started without its script");
    };
    let text = with_causes(&err);
    assert!(text.starts_with("the WebGPU worker stopped ("), "{text}");
}

#[wasm_bindgen_test]
async fn the_engine_runs_on_a_twin_pair_at_the_working_size() {
    let (_, bytes) = small_hnet_weights();
    let engine = Engine::from_weights(
        Rc::from(bytes),
        "small.bpk",
        WeightsOrigin::File,
        "test".into(),
    )
    .unwrap();
    let pair = TwinControls::default()
        .render("pair-0001".into(), &XrayBackground::phantom())
        .unwrap();
    let prediction = engine
        .infer(&pair.view_a, &pair.view_b, EntrySetting::AS_TRAINED)
        .await
        .unwrap();
    assert_eq!(prediction.mask_a.len(), WORK_SIZE.pixels());
    assert!(prediction.mask_b.iter().all(|p| (0.0..=1.0).contains(p)));
    assert!(prediction.head_force_n.unwrap().is_finite());
    // This small untrained network's masks may show no catheter: then no force is read, and
    // the panel says why.
    match &prediction.no_catheter {
        None => {
            assert_eq!(prediction.force_n, prediction.head_force_n);
            assert_eq!(prediction.force_left_out(), None);
        }
        Some(why) => {
            assert_eq!(prediction.force_n, None);
            assert!(why.contains("no catheter found"), "{why}");
            assert!(
                prediction
                    .force_left_out()
                    .unwrap()
                    .starts_with("No force is read")
            );
        }
    }
    // A view read turned for its catheter's entry edge: masks in the view's own frame, and no
    // force of the head's, with the reason.
    let turned = engine
        .infer(
            &pair.view_a,
            &pair.view_b,
            EntrySetting::Known([CatheterEntry::Left, CatheterEntry::Bottom]),
        )
        .await
        .unwrap();
    assert_eq!(turned.mask_a.len(), WORK_SIZE.pixels());
    assert_eq!(turned.entry, [CatheterEntry::Left, CatheterEntry::Bottom]);
    assert_eq!(turned.force_n, None);
    let why = turned.force_left_out().unwrap();
    assert!(why.contains("view A from the left"), "{why}");
}

/// Weights whose calibration was measured reading each view twice (`hnet eval --mask-averaging
/// mirrored --record`) are read so on the page: the masks differ from one reading's, the force
/// head's answer does not. (That both are what `hnet eval` reads is tested natively, in
/// crates/hnet-model's `model.rs`.)
#[wasm_bindgen_test]
async fn weights_calibrated_on_two_readings_are_read_twice() {
    let (model, config) = small_hnet(&Device::flex());
    let mut provenance = BTreeMap::new();
    ModelFacts {
        force_domain: None,
        measured: Some(MeasuredForce {
            data: "xray2-bench-224-s33".into(),
            split: "train".into(),
            pairs: 480,
            estimator: "blind".into(),
            mask_averaging: MaskAveraging::Mirrored,
            head_mse_n2: [0.005; 3],
            head_coverage_90: None,
            combined: None,
            command: "hnet eval --mask-averaging mirrored --record".into(),
        }),
    }
    .write(&mut provenance);
    let engine = |provenance: &BTreeMap<String, String>| {
        let bytes = model.to_weights_bytes(&config, provenance).unwrap();
        Engine::from_weights(
            Rc::from(bytes),
            "small.bpk",
            WeightsOrigin::File,
            "test".into(),
        )
        .unwrap()
    };
    let (once, twice) = (engine(&BTreeMap::new()), engine(&provenance));
    assert_eq!(once.mask_averaging, MaskAveraging::Single);
    assert_eq!(twice.mask_averaging, MaskAveraging::Mirrored);
    let pair = TwinControls::default()
        .render("pair-0001".into(), &XrayBackground::phantom())
        .unwrap();
    let read = async |engine: &Engine| {
        engine
            .infer(&pair.view_a, &pair.view_b, EntrySetting::AS_TRAINED)
            .await
            .unwrap()
    };
    let (one, two) = (read(&once).await, read(&twice).await);
    assert_ne!(one.mask_a, two.mask_a);
    let [f1, f2] = [one, two].map(|p| p.head_force_n.unwrap().newtons());
    assert!(
        f1.iter().zip(f2).all(|(a, b)| (a - b).abs() < 1e-6),
        "{f1:?} {f2:?}"
    );
}

#[wasm_bindgen_test]
async fn weights_of_another_network_are_refused_by_name() {
    let err = Engine::from_weights(
        Rc::from(&b"not a weights file"[..]),
        "junk.bpk",
        WeightsOrigin::File,
        "test".into(),
    )
    .err()
    .unwrap();
    let text = with_causes(&err);
    assert!(text.starts_with("weights file 'junk.bpk': "), "{text}");
}

/// A browser call's failure reaches the page as the JS error's own message.
#[wasm_bindgen_test]
fn js_errors_keep_the_browsers_message() {
    let message = |value: JsValue| JsError::from(value).message;
    assert_eq!(message(js_sys::Error::new("boom").into()), "boom");
    assert_eq!(
        message(
            web_sys::DomException::new_with_message("quota exceeded")
                .unwrap()
                .into()
        ),
        "quota exceeded"
    );
    assert_eq!(message(JsValue::from_str("refused")), "refused");
}

#[wasm_bindgen_test]
async fn pairs_survive_in_the_browser_storage() {
    let mut pair = TwinControls::default()
        .render("test-storage-1".into(), &XrayBackground::phantom())
        .unwrap();
    pair.mask_a[0] = 255;
    storage::save_pair(&pair).await.unwrap();
    let (pairs, damaged) = storage::load_pairs().await.unwrap();
    assert!(damaged.is_empty(), "{damaged:?}");
    let back = pairs.iter().find(|p| p.id == pair.id).expect("saved pair");
    assert_eq!(back, &pair);
    storage::delete_pair(&pair.id).await.unwrap();
    let (pairs, _) = storage::load_pairs().await.unwrap();
    assert!(pairs.iter().all(|p| p.id != pair.id));
}

/// A split or force label is saved by putting the stored record back with new metadata: the
/// images read back unchanged, and a pair that was never stored is named for a whole save.
#[wasm_bindgen_test]
async fn metadata_changes_are_saved_without_the_images() {
    let mut pair = TwinControls::default()
        .render("test-storage-metadata".into(), &XrayBackground::phantom())
        .unwrap();
    storage::save_pair(&pair).await.unwrap();
    pair.split = Some(hnet_twin::dataset::Split::Val);
    pair.force_n = Some(hnet_units::TipForce::new(0.1, -0.05, 0.2));
    let never_stored = TwinControls::default()
        .render(
            "test-storage-never-stored".into(),
            &XrayBackground::phantom(),
        )
        .unwrap();
    let metadata = [&pair, &never_stored]
        .into_iter()
        .map(|p| storage::PairMetadata::of(p).unwrap())
        .collect();
    let unsaved = storage::save_metadata(metadata).await.unwrap();
    assert_eq!(unsaved, vec![never_stored.id.clone()]);
    let (pairs, damaged) = storage::load_pairs().await.unwrap();
    assert!(damaged.is_empty(), "{damaged:?}");
    assert_eq!(pairs.iter().find(|p| p.id == pair.id), Some(&pair));
    assert!(pairs.iter().all(|p| p.id != never_stored.id));
    storage::delete_pair(&pair.id).await.unwrap();
}

/// Polls the document until `selector` matches (the page works asynchronously).
async fn wait_for(selector: &str) -> web_sys::Element {
    let document = web_sys::window().unwrap().document().unwrap();
    for _ in 0..2000 {
        if let Ok(Some(element)) = document.query_selector(selector) {
            return element;
        }
        yield_to_browser().await;
    }
    panic!("{selector} never appeared");
}

fn click(selector: &str) {
    web_sys::window()
        .unwrap()
        .document()
        .unwrap()
        .query_selector(selector)
        .unwrap()
        .unwrap_or_else(|| panic!("no {selector}"))
        .dyn_into::<web_sys::HtmlElement>()
        .unwrap()
        .click();
}

#[wasm_bindgen_test]
async fn the_page_loads_a_model_and_renders_the_live_twin() {
    leptos::mount::mount_to_body(hnet_studio::App);
    let ready = wait_for("#model-status [data-state=ready]").await;
    let backend = wait_for("#backend").await.text_content().unwrap();
    assert!(
        backend == "WebGPU" || backend == "CPU (WebAssembly)",
        "{backend}"
    );
    assert!(ready.text_content().unwrap().contains("Parameters"));

    // The twin tab renders a pair with its exact labels into both views.
    click("#tab-twin");
    let labeled = wait_for("#view-a:not([data-label-pixels='0'])")
        .await
        .get_attribute("data-label-pixels")
        .unwrap()
        .parse::<usize>()
        .unwrap();
    assert!(labeled > 200, "{labeled} labeled pixels");
    wait_for("#keep-draft").await;
    // H-Net runs on it and fills the force table.
    wait_for("#force-verdict").await;
    click("#keep-draft");
    let item = wait_for("#pairs li[data-id]").await;
    assert!(item.get_attribute("data-id").unwrap().starts_with("pair-"));
}
