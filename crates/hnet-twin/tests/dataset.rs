//! Writing, resuming and reading datasets, simulated and imported.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use hnet_twin::dataset::import::{ImportOptions, MaskThreshold, import_recordings};
use hnet_twin::dataset::shard::{Shard, merge_shards};
use hnet_twin::dataset::simulate::{
    OFF_BENCH_VIEWS, Part, nominal_base, read_sample_record, simulate_dataset,
    simulate_dataset_part, simulate_off_bench_dataset,
};
use hnet_twin::dataset::{Dataset, LoadedPair, Split};
use hnet_twin::simulator::carm::triangulate;
use hnet_twin::simulator::off_bench::OffBench;
use hnet_twin::simulator::raster::GreyImage;
use hnet_twin::simulator::scene::{Backgrounds, Modality, SceneSampling, TwinConfig};
use hnet_twin::simulator::synthetic_xray::BackgroundSource;
use hnet_units::ImageSize;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hnet-twin-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    dir
}

/// Every file under `root` with its bytes.
fn tree(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.insert(
                    path.strip_prefix(root).unwrap().to_path_buf(),
                    fs::read(&path).unwrap(),
                );
            }
        }
    }
    out
}

/// Asserts two folders hold the same files with the same bytes, naming the first difference.
fn assert_same_tree(a: &Path, b: &Path) {
    let (ta, tb) = (tree(a), tree(b));
    assert_eq!(
        ta.keys().collect::<Vec<_>>(),
        tb.keys().collect::<Vec<_>>(),
        "different files"
    );
    for (path, bytes) in &ta {
        assert!(bytes == &tb[path], "{} differs", path.display());
    }
}

fn simulate(config: &TwinConfig, samples: usize, seed: u64, out: &Path) {
    let backgrounds = Backgrounds::phantom(&config.views);
    simulate_dataset(config, &backgrounds, &[], samples, seed, out, &|_| {}).unwrap();
}

#[test]
fn the_same_seed_gives_byte_identical_datasets() {
    let config = TwinConfig::new(Modality::Xray2, ImageSize::square(48));
    let (a, b) = (scratch("same-a"), scratch("same-b"));
    simulate(&config, 6, 9, &a);
    simulate(&config, 6, 9, &b);
    assert_eq!(tree(&a).len(), 2 + 6 * 5);
    assert_same_tree(&a, &b);
    let c = scratch("same-c");
    simulate(&config, 6, 10, &c);
    assert!(tree(&c) != tree(&a));
    for dir in [a, b, c] {
        fs::remove_dir_all(dir).ok();
    }
}

#[test]
fn a_killed_generation_resumes_to_the_same_result() {
    let config = TwinConfig::new(Modality::Rgb, ImageSize::square(48));
    let (whole, resumed) = (scratch("whole"), scratch("resumed"));
    simulate(&config, 8, 3, &whole);
    simulate(&config, 8, 3, &resumed);
    // What a kill leaves behind: no manifest, a sample missing, a half-written sample folder.
    fs::remove_file(resumed.join("manifest.csv")).unwrap();
    fs::remove_file(resumed.join("samples/000005.json")).unwrap();
    fs::write(resumed.join("samples/000005_mask_b.png.partial"), b"half").unwrap();
    fs::write(resumed.join("samples/000005_view_a.png"), b"half").unwrap();
    assert!(Dataset::open(&resumed).is_err());

    let backgrounds = Backgrounds::phantom(&config.views);
    let report = simulate_dataset(&config, &backgrounds, &[], 8, 3, &resumed, &|_| {}).unwrap();
    assert_eq!((report.generated, report.resumed), (1, 7));
    assert_same_tree(&resumed, &whole);
    for dir in [whole, resumed] {
        fs::remove_dir_all(dir).ok();
    }
}

#[test]
fn a_generation_started_before_named_sizes_resumes() {
    let config = TwinConfig::new(Modality::Rgb, ImageSize::square(16));
    let out = scratch("resume-bare-side");
    simulate(&config, 4, 3, &out);
    // Before ImageSize, the twin's settings in the header held the image size as a bare side.
    let header_path = out.join("dataset.json");
    let mut header: serde_json::Value =
        serde_json::from_slice(&fs::read(&header_path).unwrap()).unwrap();
    header["source"]["twin"]["image_size"] = 16.into();
    fs::write(&header_path, serde_json::to_vec_pretty(&header).unwrap()).unwrap();
    fs::remove_file(out.join("samples/000002.json")).unwrap();

    let backgrounds = Backgrounds::phantom(&config.views);
    let report = simulate_dataset(&config, &backgrounds, &[], 4, 3, &out, &|_| {}).unwrap();
    assert_eq!((report.generated, report.resumed), (1, 3));
    let twin = Dataset::open(&out).unwrap().header.source["twin"].clone();
    assert_eq!(serde_json::from_value::<TwinConfig>(twin).unwrap(), config);
    fs::remove_dir_all(out).ok();
}

#[test]
fn a_simulation_in_four_parts_merges_into_the_same_bytes() {
    // The size: 2,000 pairs, at a size that keeps the test to seconds.
    let (config, samples, seed) = (
        TwinConfig::new(Modality::Rgb, ImageSize::square(16)),
        2000,
        5,
    );
    let whole = scratch("shard-whole");
    simulate(&config, samples, seed, &whole);
    let backgrounds = Backgrounds::phantom(&config.views);
    let parts: Vec<PathBuf> = (0..4).map(|k| scratch(&format!("shard-{k}"))).collect();
    // Made in any order, each on its own (as four machines would).
    for k in [2, 0, 3, 1] {
        let part = Part {
            samples,
            seed,
            shard: Shard { index: k, count: 4 },
        };
        let report =
            simulate_dataset_part(&config, &backgrounds, &[], part, &parts[k], &|_| {}).unwrap();
        assert_eq!(report.generated, 500);
    }
    // A part alone, or a part given twice, is refused naming the folder.
    let merged = scratch("shard-merged");
    let err = merge_shards(&parts[..3], &merged).unwrap_err();
    assert!(err.to_string().contains("part 3/4 is missing"), "{err}");
    let twice = [
        parts[0].clone(),
        parts[0].clone(),
        parts[1].clone(),
        parts[2].clone(),
    ];
    let err = merge_shards(&twice, &merged).unwrap_err();
    assert!(err.to_string().contains("given twice"), "{err}");
    let err = merge_shards(std::slice::from_ref(&whole), &merged).unwrap_err();
    assert!(err.to_string().contains("not a part"), "{err}");
    assert!(!merged.exists(), "nothing is written for a refused merge");

    let report = merge_shards(&parts, &merged).unwrap();
    assert_eq!((report.samples, report.parts), (samples, 4));
    assert_same_tree(&merged, &whole);
    for dir in parts.into_iter().chain([whole, merged]) {
        fs::remove_dir_all(dir).ok();
    }
}

#[test]
fn other_settings_or_foreign_folders_are_refused() {
    let config = TwinConfig::new(Modality::Xray1, ImageSize::square(32));
    let out = scratch("refuse");
    simulate(&config, 2, 1, &out);
    let backgrounds = Backgrounds::phantom(&config.views);
    let err = simulate_dataset(&config, &backgrounds, &[], 3, 1, &out, &|_| {}).unwrap_err();
    assert!(err.to_string().contains("other settings"), "{err}");

    let foreign = scratch("foreign");
    fs::create_dir_all(&foreign).unwrap();
    fs::write(foreign.join("notes.txt"), b"keep me").unwrap();
    let err = simulate_dataset(&config, &backgrounds, &[], 2, 1, &foreign, &|_| {}).unwrap_err();
    assert!(err.to_string().contains("not empty"), "{err}");
    assert_eq!(fs::read(foreign.join("notes.txt")).unwrap(), b"keep me");
    for dir in [out, foreign] {
        fs::remove_dir_all(dir).ok();
    }
}

#[test]
fn a_simulated_dataset_reads_back_with_splits_masks_and_geometry() {
    let config = TwinConfig::new(Modality::Xray1, ImageSize::square(64));
    let out = scratch("read");
    simulate(&config, 20, 5, &out);
    let dataset = Dataset::open(&out).unwrap();
    assert_eq!(dataset.rows.len(), 20);
    assert_eq!(dataset.split(Split::Train).count(), 16);
    assert_eq!(dataset.split(Split::Val).count(), 2);
    assert_eq!(dataset.split(Split::Test).count(), 2);
    let row = &dataset.rows[0];
    assert!(row.force_n.magnitude() <= 0.4 + 1e-6);
    let pair = dataset.load_pair(row, None).unwrap();
    assert_eq!(pair.size, hnet_units::ImageSize::square(64));
    assert_eq!(pair.view_a.len(), 64 * 64 * 3);
    assert!(pair.mask_a.iter().any(|&m| m > 0.99));
    let resized = dataset
        .load_pair(row, Some(hnet_units::ImageSize::square(32)))
        .unwrap();
    assert_eq!(resized.mask_b.len(), 32 * 32);
    // A pair rendered on the fly (training's stream) is the pair read back from the files.
    let index: u64 = row.id.parse().unwrap();
    let backgrounds = Backgrounds::phantom(&config.views);
    let sample = hnet_twin::simulator::scene::generate(&config, &backgrounds, 5, index).unwrap();
    let small = hnet_units::ImageSize::square(32);
    assert_eq!(
        LoadedPair::from_sample(&sample, ImageSize::square(64), small),
        resized
    );

    // The saved camera matrices reconstruct the saved 3D centreline.
    let record = read_sample_record(&dataset, &row.id).unwrap();
    let camera = |i: usize| record.views[i].camera_matrix;
    let tip = *record.centreline_mm.last().unwrap();
    let project = |p: &[[f64; 4]; 3]| {
        let h: Vec<f64> = (0..3)
            .map(|r| (0..3).map(|c| p[r][c] * tip[c]).sum::<f64>() + p[r][3])
            .collect();
        [h[0] / h[2], h[1] / h[2]]
    };
    let (pa, pb) = (camera(0), camera(1));
    let back = triangulate(&pa, project(&pa), &pb, project(&pb));
    assert!((back - tip).max_abs() < 1e-6);
    fs::remove_dir_all(out).ok();
}

#[test]
fn an_off_bench_dataset_records_each_pairs_own_views() {
    let config = TwinConfig::new(Modality::Xray2, ImageSize::square(32));
    // On a flat radiograph: the phantom takes seconds per view to render in a debug build.
    let flat = BackgroundSource::chest_radiograph("flat", GreyImage::filled(64, 64, 0.5));
    let off_bench = OffBench::new(config.clone(), vec![flat], 1.0);
    let out = scratch("off-bench");
    let names = ["phantom:off-bench".to_string()];
    simulate_off_bench_dataset(&off_bench, &names, Part::whole(4, 9), &out, &|_| {}).unwrap();
    let dataset = Dataset::open(&out).unwrap();
    assert_eq!(dataset.header.source["views"], OFF_BENCH_VIEWS);
    // The header records the scenes drawn (`varied`), not the bench's the look came with: a
    // blind estimate reads its nominal base and tolerance from them.
    assert_eq!(
        nominal_base(&dataset),
        SceneSampling::varied().nominal_base()
    );
    let views: Vec<_> = dataset
        .rows
        .iter()
        .map(|row| read_sample_record(&dataset, &row.id).unwrap().views[1].carm)
        .collect();
    assert!(views.iter().all(|v| *v != config.views.b), "{views:?}");
    for (row, carm) in dataset.rows.iter().zip(&views) {
        let index: u64 = row.id.parse().unwrap();
        assert_eq!(off_bench.draw(9, index).0.views.b, *carm);
    }
    fs::remove_dir_all(out).ok();
}

/// Writes a small recording: `n` frames per view, dark bar on a light background.
fn recording(root: &Path, n: usize) -> (PathBuf, PathBuf, PathBuf) {
    let (a, b) = (root.join("cam_a"), root.join("cam_b"));
    fs::create_dir_all(&a).unwrap();
    fs::create_dir_all(&b).unwrap();
    let mut csv = String::from("image,fx,fy,fz\n");
    for i in 0..n {
        let frame = image::GrayImage::from_fn(40, 30, |x, _| {
            image::Luma([if (18..22).contains(&x) { 30 } else { 200 }])
        });
        frame.save(a.join(format!("frame_{i:02}.png"))).unwrap();
        frame.save(b.join(format!("frame_{i:02}.png"))).unwrap();
        csv.push_str(&format!("frame_{i:02}.png,0.{i},-0.1,0.2\n"));
    }
    let forces = root.join("forces.csv");
    fs::write(&forces, csv).unwrap();
    (a, b, forces)
}

fn import_options(a: PathBuf, b: PathBuf, forces: PathBuf, out: PathBuf) -> ImportOptions {
    ImportOptions {
        view_a: a,
        view_b: b,
        forces,
        out,
        threshold: MaskThreshold::Otsu,
        bright_catheter: false,
        size: None,
        skip_bad: false,
        seed: 1,
        label_origin: hnet_twin::dataset::label_origin::LabelOrigin::Measured,
    }
}

#[test]
fn recordings_import_into_the_same_format_with_thresholded_masks() {
    let root = scratch("import");
    let (a, b, forces) = recording(&root, 10);
    let out = root.join("dataset");
    let report = import_recordings(&import_options(a, b, forces, out.clone()), &|_, _| {}).unwrap();
    assert_eq!(report.imported, 10);
    let dataset = Dataset::open(&out).unwrap();
    assert_eq!(
        dataset.header.image_size,
        hnet_units::ImageSize::new(40, 30)
    );
    let row = dataset.rows.iter().find(|r| r.id == "frame_03").unwrap();
    assert_eq!(row.force_n, hnet_units::TipForce::new(0.3, -0.1, 0.2));
    // The forces table does not say where its labels came from: the import's option does.
    assert_eq!(
        row.label_origin(),
        Ok(hnet_twin::dataset::label_origin::LabelOrigin::Measured)
    );
    let pair = dataset.load_pair(row, None).unwrap();
    // The dark bar is the mask.
    assert_eq!(pair.mask_a[5 * 40 + 19], 1.0);
    assert_eq!(pair.mask_a[5 * 40 + 5], 0.0);
    fs::remove_dir_all(root).ok();
}

#[test]
fn bad_rows_and_files_are_named_and_skippable() {
    let root = scratch("import-bad");
    let (a, b, forces) = recording(&root, 4);
    // NaN force, a missing image, a corrupt image, a size mismatch.
    fs::write(
        &forces,
        "image,fx,fy,fz\nframe_00.png,0.1,0.1,nan\nmissing.png,0,0,0\nframe_01.png,0,0,0\nframe_02.png,0,0,0\nframe_03.png,0.2,0,0\n",
    )
    .unwrap();
    fs::write(a.join("frame_01.png"), b"not a png").unwrap();
    image::GrayImage::new(10, 10)
        .save(b.join("frame_02.png"))
        .unwrap();
    let out = root.join("dataset");
    let options = import_options(a, b, forces.clone(), out.clone());

    let err = import_recordings(&options, &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("forces.csv") && err.contains("line 2: fz of `frame_00.png` is `nan`"),
        "{err}"
    );
    assert!(!out.exists(), "nothing is written when the import stops");

    let report = import_recordings(
        &ImportOptions {
            skip_bad: true,
            ..options
        },
        &|_, _| {},
    )
    .unwrap();
    assert_eq!(report.imported, 1);
    let messages = report
        .skipped
        .iter()
        .map(|e| e.to_string())
        .collect::<Vec<_>>()
        .join("\n");
    assert!(messages.contains("line 2: fz"), "{messages}");
    assert!(
        messages.contains("missing.png: missing (named on line 3"),
        "{messages}"
    );
    assert!(
        messages.contains("frame_01.png: unreadable image"),
        "{messages}"
    );
    assert!(
        messages.contains("cam_b/frame_02.png: is 10×10 but"),
        "{messages}"
    );
    assert_eq!(Dataset::open(&out).unwrap().rows[0].id, "frame_03");
    fs::remove_dir_all(root).ok();
}

/// Regression (found by `dataset_headers_round_trip_exactly` and
/// `sample_records_round_trip_exactly`): serde_json's default float parser read these values
/// back one ulp off; the workspace now enables its `float_roundtrip` feature.
#[test]
fn headers_and_records_keep_every_float_bit_for_bit() {
    for value in [-0.9825891323239336f64, -1.6964455841479201e-254] {
        let header = hnet_twin::dataset::DatasetHeader::new(
            hnet_units::ImageSize::new(0, 0),
            0,
            serde_json::json!([value]),
        );
        let back: hnet_twin::dataset::DatasetHeader =
            serde_json::from_slice(&hnet_twin::dataset::header_json(&header)).unwrap();
        assert_eq!(back, header);
        let json = serde_json::to_vec_pretty(&[value]).unwrap();
        let back: [f64; 1] = serde_json::from_slice(&json).unwrap();
        assert_eq!(back[0].to_bits(), value.to_bits(), "{value:e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Property tests (issue #13, docs/reliability.md): every reader of the dataset format turns
// arbitrary and mutated bytes into an error, never a panic, and what the writers write reads
// back exactly. Case counts suit CI's two cores; `PROPTEST_CASES` raises them for a long run.
// ---------------------------------------------------------------------------------------------

mod properties {
    use std::path::Path;

    use hnet_mutations::{cases, edits, mutate};
    use hnet_twin::dataset::force_table::{parse_newtons, read_force_table};
    use hnet_twin::dataset::simulate::{SampleRecord, ViewRecord, read_sample_record};
    use hnet_twin::dataset::{
        Dataset, DatasetHeader, HEADER_FILE, MANIFEST_FILE, ManifestRow, SAMPLES_DIR, Split,
        header_json, manifest_csv, parse_manifest, record_path,
    };
    use hnet_twin::simulator::carm::CArm;
    use hnet_twin::simulator::raster::Rect;
    use hnet_twin::simulator::rod::RodConfig;
    use hnet_twin::simulator::scene::SceneParams;
    use hnet_twin::simulator::synthetic_xray::{Anatomy, PatchLayout};
    use hnet_twin::vec3::Vec3;
    use hnet_units::{ImageSize, TipForce};
    use proptest::prelude::*;

    /// A finite `f64` of any magnitude, subnormals and signed zeros included.
    fn finite() -> impl Strategy<Value = f64> {
        prop_oneof![
            any::<f64>().prop_filter("finite", |v| v.is_finite()),
            -1.0f64..1.0,
            Just(0.0),
            Just(-0.0),
        ]
    }

    fn split() -> impl Strategy<Value = Split> {
        prop_oneof![Just(Split::Train), Just(Split::Val), Just(Split::Test)]
    }

    /// Free text for extra manifest columns: commas, quotes, new lines and non-ASCII included.
    fn text() -> impl Strategy<Value = String> {
        "[a-zA-Z0-9 ,\"\r\n.éß_-]{0,12}"
    }

    /// Valid manifest rows: unique valid ids, finite forces, the same extra columns on every row.
    fn rows() -> impl Strategy<Value = Vec<ManifestRow>> {
        (
            proptest::collection::btree_set("[a-zA-Z0-9_-][a-zA-Z0-9._-]{0,20}", 0..12),
            proptest::collection::vec("[a-z][a-z0-9_ ,\"]{0,8}", 0..4),
        )
            .prop_flat_map(|(ids, mut columns)| {
                // Extra columns must not take the name of a known one, nor repeat.
                columns.retain(|c| !["id", "split", "fx", "fy", "fz"].contains(&c.as_str()));
                columns.sort();
                columns.dedup();
                let n_extra = columns.len();
                let ids: Vec<String> = ids.into_iter().collect();
                let n = ids.len();
                (
                    Just(ids),
                    Just(columns),
                    proptest::collection::vec(
                        (
                            split(),
                            tip_force(),
                            proptest::collection::vec(text(), n_extra),
                        ),
                        n,
                    ),
                )
            })
            .prop_map(|(ids, columns, values)| {
                ids.into_iter()
                    .zip(values)
                    .map(|(id, (split, force_n, extra))| ManifestRow {
                        id,
                        split,
                        force_n,
                        extra: columns.iter().cloned().zip(extra).collect(),
                    })
                    .collect()
            })
    }

    /// JSON values for a header's free-form `source` (finite numbers: JSON has no others).
    fn json_value() -> impl Strategy<Value = serde_json::Value> {
        let leaf = prop_oneof![
            Just(serde_json::Value::Null),
            any::<bool>().prop_map(serde_json::Value::from),
            any::<i64>().prop_map(serde_json::Value::from),
            any::<u64>().prop_map(serde_json::Value::from),
            finite().prop_map(serde_json::Value::from),
            "\\PC{0,10}".prop_map(serde_json::Value::from),
        ];
        leaf.prop_recursive(3, 24, 4, |inner| {
            prop_oneof![
                proptest::collection::vec(inner.clone(), 0..4).prop_map(serde_json::Value::from),
                proptest::collection::btree_map("\\PC{0,6}", inner, 0..4)
                    .prop_map(|m| serde_json::Value::Object(m.into_iter().collect())),
            ]
        })
    }

    fn header() -> impl Strategy<Value = DatasetHeader> {
        (any::<usize>(), any::<usize>(), any::<usize>(), json_value()).prop_map(
            |(width, height, samples, source)| {
                DatasetHeader::new(ImageSize::new(width, height), samples, source)
            },
        )
    }

    /// A finite force component, N: any finite `f32` (signed zeros included) or a typical one.
    fn newtons() -> impl Strategy<Value = f32> {
        prop_oneof![
            any::<f32>().prop_filter("finite", |v| v.is_finite()),
            -1.0f32..1.0,
            Just(0.0),
            Just(-0.0),
        ]
    }

    fn tip_force() -> impl Strategy<Value = TipForce> {
        [newtons(), newtons(), newtons()].prop_map(TipForce::from_newtons)
    }

    fn vec3() -> impl Strategy<Value = Vec3> {
        [finite(), finite(), finite()].prop_map(Vec3)
    }

    fn carm() -> impl Strategy<Value = CArm> {
        (
            [finite(), finite(), finite(), finite(), finite()],
            1usize..5000,
            1usize..5000,
        )
            .prop_map(|(v, w, h)| CArm {
                primary_deg: v[0],
                secondary_deg: v[1],
                source_to_isocentre_mm: v[2],
                source_to_detector_mm: v[3],
                pixel_pitch_mm: v[4],
                image_size: ImageSize::new(w, h),
            })
    }

    fn view_record() -> impl Strategy<Value = ViewRecord> {
        let row = || [finite(), finite(), finite(), finite()];
        let layout = (
            proptest::option::of(prop_oneof![
                Just(Anatomy::Heart),
                Just(Anatomy::Aorta),
                Just(Anatomy::Svc)
            ]),
            [finite(), finite(), finite(), finite()],
            proptest::collection::vec(any::<u8>(), 0..20),
            proptest::collection::vec(any::<bool>(), 0..20),
        )
            .prop_map(|(anatomy, region, permutation, dark)| PatchLayout {
                anatomy,
                region: Rect(region),
                permutation,
                dark,
                grid_offset: [0.25, 0.5],
            });
        (
            carm(),
            [row(), row(), row()],
            proptest::option::of(("\\PC{0,12}", layout)),
        )
            .prop_map(|(carm, camera_matrix, background)| ViewRecord {
                carm,
                camera_matrix,
                background,
            })
    }

    fn sample_record() -> impl Strategy<Value = SampleRecord> {
        let scene = (
            tip_force(),
            [finite(), finite(), finite()],
            vec3(),
            [finite(), finite(), finite()],
            proptest::option::of(vec3()),
        )
            .prop_map(
                |(tip_force_n, [ei, length, curvature], base, [tilt, azimuth, roll], wall)| {
                    SceneParams {
                        tip_force_n,
                        bending_stiffness_n_m2: ei,
                        length_mm: length,
                        precurvature_per_mm: curvature,
                        base_position_mm: base,
                        base_tilt_deg: tilt,
                        base_azimuth_deg: azimuth,
                        base_roll_deg: roll,
                        plate: None,
                        wall_normal: wall,
                    }
                },
            );
        (
            scene,
            (finite(), finite()),
            proptest::collection::vec(vec3(), 0..16),
            proptest::collection::vec(finite(), 0..16),
            [view_record(), view_record()],
        )
            .prop_map(
                |(scene, (length, diameter), centreline_mm, arc_mm, views)| {
                    let rod = RodConfig {
                        length_mm: length,
                        diameter_mm: diameter,
                        ..RodConfig::default()
                    };
                    SampleRecord {
                        scene,
                        rod,
                        centreline_mm,
                        arc_mm,
                        views,
                    }
                },
            )
    }

    /// A scratch dataset folder for one property, reused by its cases.
    fn folder(name: &str) -> std::path::PathBuf {
        let dir = super::scratch(&format!("prop-{name}"));
        std::fs::create_dir_all(dir.join(SAMPLES_DIR)).unwrap();
        dir
    }

    fn valid_header_bytes() -> Vec<u8> {
        header_json(&DatasetHeader::new(
            ImageSize::new(48, 32),
            3,
            serde_json::json!({"generator": "hnet-twin", "seed": 7, "twin": {"size": [48, 32]}}),
        ))
    }

    fn valid_manifest_bytes() -> Vec<u8> {
        b"id,split,fx,fy,fz,note\n000001,train,0.1,-0.25,0.001,\"a, \"\"b\"\"\"\n\
          000002,val,0,0,-0.3,x\n000003,test,1e-3,2,3,\n"
            .to_vec()
    }

    proptest! {
        #![proptest_config(cases(256))]

        #[test]
        fn any_bytes_as_a_manifest_are_rows_or_an_error(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = parse_manifest(&bytes, Path::new("m.csv"));
        }

        #[test]
        fn a_mutated_manifest_is_rows_or_an_error_naming_it(edits in edits()) {
            let bytes = mutate(valid_manifest_bytes(), &edits);
            if let Err(e) = parse_manifest(&bytes, Path::new("m.csv")) {
                prop_assert!(e.to_string().starts_with("m.csv: "), "{}", e);
            }
        }

        #[test]
        fn manifests_round_trip_exactly(rows in rows()) {
            let bytes = manifest_csv(&rows);
            let back = parse_manifest(&bytes, Path::new("m.csv"));
            prop_assert!(back.is_ok(), "{:?}\n{}", back, String::from_utf8_lossy(&bytes));
            let back = back.unwrap();
            // Bit-exact forces (a -0 stays -0).
            for (a, b) in back.iter().zip(&rows) {
                prop_assert_eq!(a.force_n.newtons().map(f32::to_bits), b.force_n.newtons().map(f32::to_bits));
            }
            prop_assert_eq!(back, rows);
        }

        #[test]
        fn any_bytes_as_a_dataset_header_are_an_error_or_a_header(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
            let _ = serde_json::from_slice::<DatasetHeader>(&bytes);
        }

        #[test]
        fn a_mutated_dataset_header_is_an_error_or_a_header(edits in edits()) {
            let _ = serde_json::from_slice::<DatasetHeader>(&mutate(valid_header_bytes(), &edits));
        }

        #[test]
        fn dataset_headers_round_trip_exactly(header in header()) {
            let back: DatasetHeader = serde_json::from_slice(&header_json(&header)).unwrap();
            prop_assert_eq!(back, header);
        }

        #[test]
        fn sample_records_round_trip_exactly(record in sample_record()) {
            let json = serde_json::json!({ "manifest": {}, "record": record });
            #[derive(serde::Deserialize)]
            struct File {
                record: SampleRecord,
            }
            let bytes = serde_json::to_vec_pretty(&json).unwrap();
            let back: File = serde_json::from_slice(&bytes).unwrap();
            prop_assert_eq!(back.record, record);
        }

        #[test]
        fn any_bytes_as_a_force_table_are_rows_or_an_error(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let _ = read_force_table(&bytes, &["id", "image"]);
        }

        #[test]
        fn a_mutated_force_table_is_rows_or_an_error(edits in edits()) {
            let valid = b"image,FX,fy,fz,note\na.png,0.1,-0.2,0.3,x\nb.png,\"0,05\",0,0,\nc.png,1e-3,2,3,y\n";
            if let Ok(rows) = read_force_table(&mutate(valid.to_vec(), &edits), &["image", "id"]) {
                for row in rows.into_iter().flatten() {
                    prop_assert!(row.force_n.is_finite());
                    prop_assert!(!row.key.is_empty());
                }
            }
        }

        #[test]
        fn force_tables_round_trip_exactly(
            rows in proptest::collection::vec(("[a-zA-Z0-9_.-]{1,16}", [newtons(), newtons(), newtons()]), 0..16)
        ) {
            let mut csv = String::from("id,fx,fy,fz\n");
            for (key, [x, y, z]) in &rows {
                csv.push_str(&format!("{key},{x},{y},{z}\n"));
            }
            let back = read_force_table(csv.as_bytes(), &["id"]).unwrap();
            prop_assert_eq!(back.len(), rows.len());
            for (line, (read, (key, force))) in back.into_iter().zip(&rows).enumerate() {
                let read = read.unwrap();
                prop_assert_eq!(&read.key, key);
                prop_assert_eq!(read.line, line as u64 + 2);
                prop_assert_eq!(read.force_n.newtons().map(f32::to_bits), force.map(f32::to_bits));
            }
        }

        #[test]
        fn newtons_parse_exactly_or_not_at_all(value in newtons(), text in "\\PC{0,24}") {
            prop_assert_eq!(parse_newtons(&value.to_string()).map(f32::to_bits), Some(value.to_bits()));
            prop_assert_eq!(parse_newtons(&format!(" {value} ")).map(f32::to_bits), Some(value.to_bits()));
            if let Some(v) = parse_newtons(&text) {
                prop_assert!(v.is_finite());
            }
        }
    }

    proptest! {
        // Each case writes files; fewer of them.
        #![proptest_config(cases(64))]

        #[test]
        fn opening_a_mutated_dataset_is_an_error_or_a_dataset(
            header_edits in proptest::option::of(edits()),
            manifest_edits in proptest::option::of(edits()),
        ) {
            let dir = folder("open");
            let header = match &header_edits {
                Some(e) => mutate(valid_header_bytes(), e),
                None => valid_header_bytes(),
            };
            let manifest = match &manifest_edits {
                Some(e) => mutate(valid_manifest_bytes(), e),
                None => valid_manifest_bytes(),
            };
            std::fs::write(dir.join(HEADER_FILE), header).unwrap();
            std::fs::write(dir.join(MANIFEST_FILE), manifest).unwrap();
            match Dataset::open(&dir) {
                Ok(dataset) => prop_assert_eq!(dataset.header.format, "hnet-dataset"),
                Err(e) => prop_assert!(e.to_string().contains(&dir.display().to_string()), "{}", e),
            }
        }

        #[test]
        fn datasets_written_then_opened_read_back_exactly(header in header(), rows in rows()) {
            let dir = folder("reopen");
            std::fs::write(dir.join(HEADER_FILE), header_json(&header)).unwrap();
            std::fs::write(dir.join(MANIFEST_FILE), manifest_csv(&rows)).unwrap();
            let dataset = Dataset::open(&dir).unwrap();
            prop_assert_eq!(dataset.header, header);
            prop_assert_eq!(dataset.rows, rows);
        }

        #[test]
        fn a_mutated_sample_record_is_an_error_or_a_record(record in sample_record(), edits in edits()) {
            let dir = folder("record");
            std::fs::write(dir.join(HEADER_FILE), valid_header_bytes()).unwrap();
            std::fs::write(dir.join(MANIFEST_FILE), valid_manifest_bytes()).unwrap();
            let dataset = Dataset::open(&dir).unwrap();
            let json = serde_json::json!({ "manifest": {}, "record": record });
            let bytes = mutate(serde_json::to_vec_pretty(&json).unwrap(), &edits);
            std::fs::write(dir.join(record_path("000001")), bytes).unwrap();
            if let Err(e) = read_sample_record(&dataset, "000001") {
                prop_assert!(e.to_string().contains("000001.json"), "{}", e);
            }
            // Arbitrary bytes, too.
            let bytes: Vec<u8> = record.arc_mm.iter().flat_map(|v| v.to_le_bytes()).collect();
            std::fs::write(dir.join(record_path("000002")), bytes).unwrap();
            prop_assert!(read_sample_record(&dataset, "000002").is_err());
        }
    }
}
