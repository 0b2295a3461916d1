//! Writing, resuming and reading datasets, simulated and imported.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use hnet_twin::carm::triangulate;
use hnet_twin::dataset::{Dataset, Split};
use hnet_twin::import::{ImportOptions, MaskThreshold, import_recordings};
use hnet_twin::scene::{Backgrounds, Modality, TwinConfig};
use hnet_twin::simulate::{read_sample_record, simulate_dataset};

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
    let config = TwinConfig::new(Modality::Xray2, 48);
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
    let config = TwinConfig::new(Modality::Rgb, 48);
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
fn other_settings_or_foreign_folders_are_refused() {
    let config = TwinConfig::new(Modality::Xray1, 32);
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
    let config = TwinConfig::new(Modality::Xray1, 64);
    let out = scratch("read");
    simulate(&config, 20, 5, &out);
    let dataset = Dataset::open(&out).unwrap();
    assert_eq!(dataset.rows.len(), 20);
    assert_eq!(dataset.split(Split::Train).count(), 16);
    assert_eq!(dataset.split(Split::Val).count(), 2);
    assert_eq!(dataset.split(Split::Test).count(), 2);
    let row = &dataset.rows[0];
    assert!(row.force_n.iter().map(|f| f * f).sum::<f64>().sqrt() <= 0.4 + 1e-9);
    let pair = dataset.load_pair(row, None).unwrap();
    assert_eq!(pair.size, hnet_units::ImageSize::square(64));
    assert_eq!(pair.view_a.len(), 64 * 64 * 3);
    assert!(pair.mask_a.iter().any(|&m| m > 0.99));
    let resized = dataset
        .load_pair(row, Some(hnet_units::ImageSize::square(32)))
        .unwrap();
    assert_eq!(resized.mask_b.len(), 32 * 32);

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
    assert_eq!(row.force_n, [0.3, -0.1, 0.2]);
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
