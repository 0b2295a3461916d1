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
    // The paper's network, and one with position channels on its first convolution.
    for config in [config(), config().with_position_channels(Some(true))] {
        let model = config.init(&device).unwrap();
        let bytes = model.to_weights_bytes(&config, &provenance()).unwrap();
        let (loaded, loaded_config, header) =
            HNet::from_weights_bytes(&bytes, &device, "model.bpk").unwrap();
        assert_eq!(loaded_config, config);
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
    // Nor did they have position channels.
    let old_json = serde_json::to_string(&config)
        .unwrap()
        .replace(r#"{"width":32,"height":16}"#, "[16,32]")
        .replace(r#""position_channels":null,"#, "");
    assert!(old_json.contains("[16,32]"), "{old_json}");
    assert!(!old_json.contains("position_channels"), "{old_json}");
    let bytes = weights::encode(model, "hnet", &old_json, &provenance(), "old.bpk").unwrap();
    let (_, read, _) = HNet::from_weights_bytes(&bytes, &device, "old.bpk").unwrap();
    assert_eq!(read.image_size, ImageSize::new(32, 16));
    assert!(!read.uses_position_channels());
}

// ---------------------------------------------------------------------------------------------
// Property tests (issue #13, docs/reliability.md): arbitrary and mutated weights files are an
// error, never a panic or an unbounded allocation, and a saved network loads back exactly.
// ---------------------------------------------------------------------------------------------

/// A file whose header claims a huge network fails visibly (see `hnet_mutations`).
#[global_allocator]
static ALLOCATOR: hnet_mutations::CappedAllocator = hnet_mutations::CappedAllocator;

mod properties {
    use std::collections::BTreeMap;
    use std::sync::OnceLock;

    use burn::module::Module;
    use burn::tensor::Device;
    use hnet_model::architectures::StereoModel;
    use hnet_model::weights;
    use hnet_model::{HNet, HNetConfig};
    use hnet_mutations::{cases, edits, mutate_near_start};
    use hnet_units::ImageSize;
    use proptest::prelude::*;

    fn small() -> HNetConfig {
        HNetConfig::new()
            .with_filters(2)
            .with_depth(1)
            .with_image_size(ImageSize::square(8))
            .with_force_hidden([4, 2])
    }

    /// A valid, small weights file (made once).
    fn valid_file() -> &'static [u8] {
        static FILE: OnceLock<Vec<u8>> = OnceLock::new();
        FILE.get_or_init(|| {
            let device = Device::flex();
            small()
                .init(&device)
                .unwrap()
                .to_weights_bytes(&small(), &BTreeMap::new())
                .unwrap()
        })
    }

    /// Loads `bytes` every way the CLI and the page do; each must return, never panic.
    fn load_every_way(bytes: &[u8]) {
        let device = Device::flex();
        let _ = weights::read_header(bytes, "p.bpk");
        let _ = HNet::from_weights_bytes(bytes, &device, "p.bpk");
        let _ = StereoModel::from_weights_bytes(bytes, &device, "p.bpk");
    }

    /// A settings value as a weights file may claim it: small, zero, huge or past `usize`.
    fn claimed_size() -> impl Strategy<Value = serde_json::Value> {
        prop_oneof![
            3 => (0u64..40).prop_map(serde_json::Value::from),
            1 => Just(serde_json::Value::from(0)),
            1 => (1u64 << 20..1 << 40).prop_map(serde_json::Value::from),
            1 => any::<u64>().prop_map(serde_json::Value::from),
            1 => Just(serde_json::Value::from(-1)),
            1 => Just(serde_json::Value::from(1.5)),
        ]
    }

    /// The settings of any architecture with claimed sizes (what `hnet.config` may hold).
    fn claimed_settings() -> impl Strategy<Value = (String, String)> {
        let size = || claimed_size();
        prop_oneof![
            (
                size(),
                size(),
                size(),
                size(),
                size(),
                size(),
                size(),
                any::<bool>()
            )
                .prop_map(|(c, f, d, w, h, h0, h1, share)| (
                    "hnet".to_string(),
                    serde_json::json!({"in_channels": c, "filters": f, "depth": d,
                        "image_size": {"width": w, "height": h}, "share_weights": share,
                        "force_hidden": [h0, h1]})
                    .to_string()
                )),
            (size(), size()).prop_map(|(f, d)| (
                "unet".to_string(),
                serde_json::json!({"base_filters": f, "depth": d}).to_string()
            )),
            size().prop_map(|f| (
                "fcn".to_string(),
                serde_json::json!({"base_filters": f}).to_string()
            )),
            size().prop_map(|w| (
                "hrnet".to_string(),
                serde_json::json!({"width": w}).to_string()
            )),
            (size(), size(), size()).prop_map(|(f, h0, h1)| (
                "ynet".to_string(),
                serde_json::json!({"base_filters": f, "hidden": [h0, h1]}).to_string()
            )),
        ]
    }

    proptest! {
        #![proptest_config(cases(128))]

        #[test]
        fn any_bytes_are_an_error_never_a_panic(
            magic in any::<bool>(),
            bytes in proptest::collection::vec(any::<u8>(), 0..1024),
        ) {
            let mut bytes = bytes;
            if magic {
                // Past the magic-number check, into burnpack's own parser.
                let head = burn_pack::MAGIC_NUMBER.to_le_bytes();
                bytes.splice(0..0, head);
            }
            load_every_way(&bytes);
        }

        #[test]
        fn a_mutated_weights_file_is_an_error_or_a_network(edits in edits()) {
            load_every_way(&mutate_near_start(valid_file().to_vec(), &edits, 512));
        }

        #[test]
        fn settings_claiming_any_size_are_an_error_or_a_network((architecture, settings) in claimed_settings()) {
            // Real tensors (the small H-Net's) under a header that claims other settings.
            let device = Device::flex();
            let bytes = weights::encode(
                small().init(&device).unwrap(),
                &architecture,
                &settings,
                &BTreeMap::new(),
                "claims.bpk",
            )
            .unwrap();
            load_every_way(&bytes);
        }
    }

    proptest! {
        #![proptest_config(cases(32))]

        #[test]
        fn saved_networks_load_back_exactly(
            filters in 1usize..5,
            depth in 1usize..3,
            [w, h] in [1usize..4, 1usize..4],
            share_weights in any::<bool>(),
            hidden in [1usize..6, 1usize..6],
            provenance in proptest::collection::btree_map("[a-z_.]{1,12}", "\\PC{0,20}", 0..4),
        ) {
            let config = HNetConfig::new()
                .with_filters(filters)
                .with_depth(depth)
                .with_image_size(ImageSize::new(w << depth, h << depth))
                .with_share_weights(share_weights)
                .with_force_hidden(hidden);
            let device = Device::flex();
            let model = config.init(&device).unwrap();
            let bytes = model.to_weights_bytes(&config, &provenance).unwrap();
            let (loaded, loaded_config, header) = HNet::from_weights_bytes(&bytes, &device, "rt.bpk").unwrap();
            prop_assert_eq!(&loaded_config, &config);
            prop_assert_eq!(&header.provenance, &provenance);
            prop_assert_eq!(loaded.num_params(), model.num_params());
            // Every parameter, bit for bit: the reloaded network writes the same file.
            prop_assert!(loaded.to_weights_bytes(&config, &provenance).unwrap() == bytes);
            let (any, spec, _) = StereoModel::from_weights_bytes(&bytes, &device, "rt.bpk").unwrap();
            prop_assert_eq!(spec.name(), "hnet");
            prop_assert_eq!(any.num_params(), model.num_params());
        }
    }
}

/// Regression (found by `settings_claiming_any_size_are_an_error_or_a_network`, 2026-12-07): an
/// H-Net weights file claiming 2^62 filters overflowed its force head's input size while the
/// network was built. Such settings are refused, naming the size that overflows.
#[test]
fn hnet_settings_whose_sizes_overflow_are_refused() {
    let device = Device::flex();
    let settings = r#"{"depth":1,"filters":4611686018427387904,"force_hidden":[1048576,1048576],"image_size":{"height":51628000098,"width":12},"in_channels":1,"share_weights":false}"#;
    let model = config().init(&device).unwrap();
    let bytes = weights::encode(model, "hnet", settings, &provenance(), "x.bpk").unwrap();
    let err = HNet::from_weights_bytes(&bytes, &device, "x.bpk").expect_err(settings);
    assert!(
        hnet_units::with_causes(&err).contains("overflow"),
        "{}",
        hnet_units::with_causes(&err)
    );
}

/// Regression (found by `settings_claiming_any_size_are_an_error_or_a_network`): a U-Net weights
/// file claiming a depth of 2^40 tried to allocate its layer list and aborted; a depth of 0
/// underflowed. Both are now refused as out-of-range settings, as are zero or huge filter counts.
#[test]
fn baseline_settings_claiming_impossible_sizes_are_refused() {
    let device = Device::flex();
    for (architecture, settings) in [
        ("unet", r#"{"base_filters": 16, "depth": 1099511627776}"#),
        ("unet", r#"{"base_filters": 16, "depth": 0}"#),
        ("unet", r#"{"base_filters": 1099511627776, "depth": 4}"#),
        ("fcn", r#"{"base_filters": 0}"#),
        ("hrnet", r#"{"width": 1099511627776}"#),
        ("ynet", r#"{"base_filters": 4, "hidden": [0, 8]}"#),
    ] {
        let model = config().init(&device).unwrap();
        let bytes = weights::encode(model, architecture, settings, &provenance(), "x.bpk").unwrap();
        let err =
            hnet_model::architectures::StereoModel::from_weights_bytes(&bytes, &device, "x.bpk")
                .expect_err(settings);
        assert!(
            matches!(
                err.problem,
                WeightsProblem::BadConfig(weights::ConfigProblem::OutOfRange(..))
            ),
            "{architecture} {settings}: {err}"
        );
    }
}
