//! Weights files: round trip, and clear errors for every kind of bad file.

use std::collections::BTreeMap;

use burn::tensor::{Device, Distribution, Tensor};
use hnet_model::weights::{self, WeightsProblem};
use hnet_model::{HNet, HNetConfig};
use hnet_units::ImageSize;

fn config() -> HNetConfig {
    HNetConfig::new()
        .with_filters(4)
        .with_depth(2)
        .with_image_size(ImageSize::square(16))
}

fn provenance() -> BTreeMap<String, String> {
    BTreeMap::from([("seed".to_string(), "42".to_string())])
}

#[test]
fn a_saved_network_loads_back_identically_with_its_config() {
    let device = Device::flex();
    let model = config().init(&device).unwrap();
    let bytes = model.to_weights_bytes(&config(), &provenance()).unwrap();
    let (loaded, loaded_config, header) =
        HNet::from_weights_bytes(&bytes, &device, "model.bpk").unwrap();
    assert_eq!(loaded_config, config());
    assert_eq!(header.architecture, "hnet");
    assert_eq!(header.provenance, provenance());

    let shape = [1, 3, 16, 16];
    let a = Tensor::random(shape, Distribution::Default, &device);
    let b = Tensor::random(shape, Distribution::Default, &device);
    let expected = model.forward(a.clone(), b.clone());
    let actual = loaded.forward(a, b);
    actual
        .force
        .into_data()
        .assert_eq(&expected.force.into_data(), true);
    actual
        .mask_logits_a
        .into_data()
        .assert_eq(&expected.mask_logits_a.into_data(), true);
}

#[test]
fn truncated_files_are_reported_not_panicked_on() {
    let device = Device::flex();
    let bytes = config()
        .init(&device)
        .unwrap()
        .to_weights_bytes(&config(), &provenance())
        .unwrap();
    // Every prefix that cuts into the header, the metadata or the tensor data.
    let step = (bytes.len() / 97).max(1);
    for cut in (0..bytes.len()).step_by(step) {
        let err = HNet::from_weights_bytes(&bytes[..cut], &device, "cut.bpk").expect_err(&format!(
            "a file cut at {cut} of {} bytes loaded",
            bytes.len()
        ));
        assert_eq!(err.source_name, "cut.bpk");
        assert!(
            err.to_string().starts_with("weights file 'cut.bpk': "),
            "{err}"
        );
    }
}

#[test]
fn a_file_that_is_not_burnpack_is_named_in_the_error() {
    let device = Device::flex();
    let err = HNet::from_weights_bytes(b"\x89PNG\r\n\x1a\n not a model", &device, "photo.png")
        .unwrap_err();
    assert!(matches!(
        err.problem,
        WeightsProblem::NotWeights("a PNG image")
    ));
    assert_eq!(
        err.to_string(),
        "weights file 'photo.png': not an H-Net weights file (.bpk, written by `hnet train`): \
         this is a PNG image"
    );
    let err = HNet::from_weights_bytes(b"not a model", &device, "notes.txt").unwrap_err();
    assert!(matches!(
        err.problem,
        WeightsProblem::NotWeights("a text file")
    ));
}

#[test]
fn a_burnpack_file_from_elsewhere_is_rejected() {
    let device = Device::flex();
    // A plain Burn record without H-Net Studio's metadata.
    use burn::module::Module;
    let bytes = config()
        .init(&device)
        .unwrap()
        .into_record()
        .into_bytes()
        .unwrap();
    let err = HNet::from_weights_bytes(&bytes, &device, "plain.bpk").unwrap_err();
    assert!(matches!(err.problem, WeightsProblem::NotHNetStudio));
}

#[test]
fn weights_that_do_not_fit_the_config_are_a_mismatch() {
    let device = Device::flex();
    let model = config().init(&device).unwrap();
    // Claim 8 filters for a network that has 4.
    let lying = config().with_filters(8);
    let bytes = weights::encode(
        model,
        "hnet",
        &serde_json::to_string(&lying).unwrap(),
        &provenance(),
        "lying.bpk",
    )
    .unwrap();
    let err = HNet::from_weights_bytes(&bytes, &device, "lying.bpk").unwrap_err();
    assert!(matches!(err.problem, WeightsProblem::Mismatch(_)), "{err}");
    assert!(err.to_string().contains("lying.bpk"));
    // Burn's own account of the mismatch is kept as the cause.
    let cause = std::error::Error::source(&err.problem).expect("the record error is kept");
    assert!(!cause.to_string().is_empty());
}

#[test]
fn weights_of_another_architecture_are_rejected() {
    let device = Device::flex();
    let model = config().init(&device).unwrap();
    let bytes = weights::encode(model, "unet", "{}", &provenance(), "unet.bpk").unwrap();
    let err = HNet::from_weights_bytes(&bytes, &device, "unet.bpk").unwrap_err();
    assert!(
        matches!(
            &err.problem,
            WeightsProblem::WrongArchitecture { expected, found } if expected == "hnet" && found == "unet"
        ),
        "{err}"
    );
}

#[test]
fn files_written_before_named_sizes_keep_their_height_and_width() {
    // Settings used to store the size as `[height, width]`.
    let device = Device::flex();
    let config = config().with_image_size(ImageSize::new(32, 16));
    let model = config.init(&device).unwrap();
    let old_json = serde_json::to_string(&config)
        .unwrap()
        .replace(r#"{"width":32,"height":16}"#, "[16,32]");
    assert!(old_json.contains("[16,32]"), "{old_json}");
    let bytes = weights::encode(model, "hnet", &old_json, &provenance(), "old.bpk").unwrap();
    let (_, read, _) = HNet::from_weights_bytes(&bytes, &device, "old.bpk").unwrap();
    assert_eq!(read.image_size, ImageSize::new(32, 16));
}
