//! The `hnet` command end to end: simulate, train (killed and resumed), evaluate, report, and
//! clear errors for bad input.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Output, Stdio};
use std::time::{Duration, Instant};

use common::{config_json, fails, hnet, model_json, scratch, succeeds, train};
use hnet_units::mask::is_catheter_label;

fn run(args: &[&str]) -> Output {
    succeeds(hnet().args(args))
}

/// A small config for tests: H-Net at 48x32 (non-square, so that a width/height mix-up anywhere
/// from the dataset to the report fails), 8 filters, 2 levels; the baselines at 32x32.
fn tiny_config(dir: &Path, architecture: &str, epochs: usize) -> PathBuf {
    let size = if architecture == "hnet" {
        (48, 32)
    } else {
        (32, 32)
    };
    let path = dir.join(format!("{architecture}.json"));
    let model = model_json(architecture, 2, size);
    std::fs::write(&path, config_json(&model, size, 8, epochs)).unwrap();
    path
}

fn simulate(dir: &Path, samples: usize) -> PathBuf {
    let data = dir.join("data");
    run(&[
        "simulate",
        "--modality",
        "xray2",
        "--samples",
        &samples.to_string(),
        "--size",
        "32",
        "--seed",
        "5",
        "--out",
        data.to_str().unwrap(),
    ]);
    data
}

#[test]
fn info_reports_both_parameter_counts() {
    let out = run(&["info", "--json"]);
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(info["params"], 254_724);
    assert_eq!(info["params_unshared"], 486_725);
    assert_eq!(info["input"], serde_json::json!([3, 224, 224]));
}

#[test]
fn a_training_killed_mid_run_resumes_and_finishes() {
    let dir = scratch("resume");
    let data = simulate(&dir, 400);
    let config = tiny_config(&dir, "hnet", 8);
    let runs = dir.join("run");
    let mut child = train(&data, &runs, &config)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it (SIGKILL) as soon as the first epoch's checkpoint is complete.
    let start = Instant::now();
    while !runs.join("checkpoint/scheduler-1.bpk").exists() {
        assert!(start.elapsed() < Duration::from_secs(120), "no checkpoint");
        assert!(child.try_wait().unwrap().is_none(), "training ended early");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(
        !runs.join("model.bpk").exists(),
        "the run was not cut short"
    );

    // A plain second start refuses to overwrite the run.
    let again = fails(&mut train(&data, &runs, &config));
    assert!(again.contains("--resume"), "{again}");

    run(&["train", "--resume", "--out", runs.to_str().unwrap()]);
    let metrics = std::fs::read_to_string(runs.join("metrics.csv")).unwrap();
    for epoch in 1..=8 {
        for split in ["train", "valid"] {
            assert!(
                metrics.contains(&format!("\n{epoch},{split},")),
                "epoch {epoch} {split} missing:\n{metrics}"
            );
        }
    }
    assert!(runs.join("model.bpk").is_file());

    // The tables, as JSON, from the saved model.
    let out = run(&["eval", "--run", runs.to_str().unwrap(), "--json"]);
    let eval: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(eval["architecture"], "hnet");
    assert_eq!(
        eval["image_size"],
        serde_json::json!({"width": 48, "height": 32})
    );
    assert_eq!(eval["force"]["samples"], 40);
    // Blind by default: the catalogue's bench catheter, never the pairs' own records.
    assert_eq!(eval["estimator"], "blind");
    assert_eq!(eval["catheter"]["name"], "twin-bench-7f");
    // The physics check: from the dataset's own 32x32 masks and from the network's 48x32 ones,
    // every pair fitted or counted as a failure of a named step.
    let physics = eval["physics"].as_array().unwrap();
    assert_eq!(physics[0]["masks"], "true");
    assert_eq!(
        physics[1]["size"],
        serde_json::json!({"width": 48, "height": 32})
    );
    for check in physics {
        let failed: u64 = check["failures"]
            .as_object()
            .unwrap()
            .values()
            .map(|n| n.as_u64().unwrap())
            .sum();
        assert_eq!(check["fitted"].as_u64().unwrap() + failed, 40, "{check}");
    }
    // No combined force from the true masks (the physics estimate there is near exact). This
    // small network's masks give no centreline, so the combined force from its masks is tested
    // in physics_check.rs on pairs that fit.
    assert!(physics[0]["combined_force"].is_null());
    assert!(eval["force"]["axes"][2]["rmse"].as_f64().unwrap() >= 0.0);
    assert!(eval["segmentation"][1]["mdice"].as_f64().unwrap() > 0.0);
    assert!(runs.join("eval-test.md").is_file());
    // The run's weights name the twin data their force learned from, and `--record` adds what
    // was measured, parameters unchanged (the tables below read the same).
    let facts = |path: &Path| String::from_utf8_lossy(&std::fs::read(path).unwrap()).into_owned();
    let model = runs.join("model.bpk");
    assert!(facts(&model).contains(r#""force_domain":{"data":"#));
    assert!(!facts(&model).contains(r#""measured""#));
    run(&[
        "eval",
        "--run",
        runs.to_str().unwrap(),
        "--no-physics",
        "--record",
    ]);
    assert!(facts(&model).contains(r#""measured":{"data":"#));
    assert!(facts(&model).contains(r#""force_domain""#));
    // Recorded reading each view twice, the weights are read so by default, and the file says
    // so only while it is not one reading.
    let record = |averaging: &str| {
        let args = [
            "eval",
            "--run",
            runs.to_str().unwrap(),
            "--no-physics",
            "--record",
        ];
        run(&[&args[..], &["--mask-averaging", averaging]].concat());
    };
    record("mirrored");
    assert!(facts(&model).contains(r#""mask_averaging":"mirrored""#));
    let read = run(&[
        "eval",
        "--run",
        runs.to_str().unwrap(),
        "--no-physics",
        "--json",
    ]);
    let read: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    assert_eq!(read["mask_averaging"], "mirrored");
    record("single");
    assert!(!facts(&model).contains(r#""mask_averaging""#));

    // Any weights file on any data: the same tables from the weights alone.
    let weights = runs.join("model.bpk");
    let predictions = runs.with_extension("predictions.csv");
    let masks = runs.with_extension("masks");
    let out = run(&[
        "eval",
        "--weights",
        weights.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--json",
        "--predictions",
        predictions.to_str().unwrap(),
        "--masks",
        masks.to_str().unwrap(),
    ]);
    let alone: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(alone["force"], eval["force"]);
    // Per pair: the true force, the network's, and the physics estimate from its masks with its
    // fit's standard error wherever the rod was fitted (the combined estimate where a
    // combination was calibrated), and its masks' catheter IoU in each view; the same file as
    // the run folder keeps.
    let csv = std::fs::read_to_string(&predictions).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some(
            "id,fx,fy,fz,fx_pred,fy_pred,fz_pred,fx_physics,fy_physics,fz_physics,\
             fx_physics_sd,fy_physics_sd,fz_physics_sd,physics_corr_xy,physics_corr_xz,\
             physics_corr_yz,fx_combined,fy_combined,fz_combined,fx_combined_sd,fy_combined_sd,\
             fz_combined_sd,fx_combined_90,fy_combined_90,fz_combined_90,catheter_iou_a,\
             catheter_iou_b,estimator"
        )
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 40);
    assert!(rows.iter().all(|r| r.len() == 28 && r[27] == "blind"));
    assert!(rows.iter().all(|r| r[25..27].iter().all(|v| {
        let iou: f64 = v.parse().unwrap();
        (0.0..=1.0).contains(&iou)
    })));
    // Each pair's predicted masks at the network's input size, and error maps whose colours
    // count the same IoU (white found, blue missed, red spurious).
    assert_eq!(std::fs::read_dir(&masks).unwrap().count(), 40 * 4);
    for row in &rows {
        for (view, iou) in ["a", "b"].iter().zip(&row[25..27]) {
            let mask =
                image::open(masks.join(format!("{}_predicted_mask_{view}.png", row[0]))).unwrap();
            assert_eq!((mask.width(), mask.height()), (48, 32));
            let errors = image::open(masks.join(format!("{}_errors_{view}.png", row[0])))
                .unwrap()
                .to_rgb8();
            let count = |rgb: [u8; 3]| errors.pixels().filter(|p| p.0 == rgb).count() as f64;
            let [found, missed, spurious] =
                [[255, 255, 255], [64, 128, 255], [255, 64, 64]].map(count);
            let union = found + missed + spurious;
            let from_map = if union == 0.0 { 1.0 } else { found / union };
            assert!(
                (from_map - iou.parse::<f64>().unwrap()).abs() < 1e-4,
                "{row:?}"
            );
        }
    }
    let with_physics = rows.iter().filter(|r| !r[7].is_empty()).count() as u64;
    assert_eq!(with_physics, physics[1]["fitted"].as_u64().unwrap());
    // The fit's correlations between axes, wherever it has a standard error.
    assert!(rows.iter().filter(|r| !r[10].is_empty()).all(|r| {
        r[13..16]
            .iter()
            .all(|v| (-1.0..=1.0).contains(&v.parse::<f64>().unwrap()))
    }));
    assert_eq!(
        csv,
        std::fs::read_to_string(runs.join("predictions-test.csv")).unwrap()
    );
    // The force in its pooled features, beside its head's (the same test pairs).
    let out = run(&[
        "study",
        "features",
        "--weights",
        weights.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
    ]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("40 test pairs; 48 features"), "{table}");
    assert!(
        table.contains("| kernel ridge on its pooled features |"),
        "{table}"
    );
    // Not weights, weights of another size, or a turn that needs a square network: named, and
    // the run folder left as it was.
    let files_before = std::fs::read_dir(&runs).unwrap().count();
    for (args, message) in [
        (
            vec!["--weights", config.to_str().unwrap()],
            "this is a text file",
        ),
        (
            vec!["--weights", "/nonexistent/model.bpk"],
            "cannot read weights file '/nonexistent/model.bpk'",
        ),
        (
            vec!["--weights", weights.to_str().unwrap(), "--size", "64"],
            "takes 48×32 images, not 64×64",
        ),
        (
            vec!["--weights", weights.to_str().unwrap(), "--turn-views", "1"],
            "--turn-views needs a square network; this one takes 48×32 images",
        ),
        (
            vec![
                "--weights",
                weights.to_str().unwrap(),
                "--catheter-entry",
                "left",
            ],
            "--catheter-entry needs a square network; this one takes 48×32 images",
        ),
        (
            vec![
                "--weights",
                weights.to_str().unwrap(),
                "--catheter-entry",
                "up",
            ],
            "`up` is not auto, an edge (bottom, left, top, right) or two edges `A,B`",
        ),
        (
            vec![
                "--weights",
                weights.to_str().unwrap(),
                "--catheter",
                "no-such-7f",
            ],
            "no catheter `no-such-7f` in the catalogue (twin-bench-7f, twin-varied-mid-7f)",
        ),
    ] {
        let stderr = fails(hnet().arg("eval").args(&args).arg("--data").arg(&data));
        // Said once: the file's name and its problem, not the problem again as its cause.
        assert_eq!(stderr.matches(message).count(), 1, "{stderr}");
    }
    assert_eq!(std::fs::read_dir(&runs).unwrap().count(), files_before);

    run(&["report", "--run", runs.to_str().unwrap()]);
    for figure in [
        "fig3-samples.png",
        "fig4-force-z.svg",
        "fig4-force-z.png",
        "fig5-error-x.png",
        "fig5-loss.svg",
        "fig5-miou.png",
    ] {
        assert!(runs.join("report").join(figure).is_file(), "{figure}");
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn every_baseline_trains_and_evaluates_in_the_same_harness() {
    let dir = scratch("baselines");
    let data = simulate(&dir, 60);
    for (architecture, segments, force) in [
        ("unet", true, false),
        ("fcn", true, false),
        ("hrnet", true, false),
        ("ynet", false, true),
    ] {
        let config = tiny_config(&dir, architecture, 1);
        let runs = dir.join(architecture);
        succeeds(train(&data, &runs, &config).args(["--seed", "9"]));
        // The run folder keeps the settings it ran with, the seed override included.
        let saved: serde_json::Value =
            serde_json::from_slice(&std::fs::read(runs.join("config.json")).unwrap()).unwrap();
        assert_eq!(saved["seed"], 9, "{architecture}");
        let out = run(&[
            "eval",
            "--run",
            runs.to_str().unwrap(),
            "--json",
            "--no-physics",
        ]);
        let eval: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(eval["architecture"], architecture);
        assert!(eval.get("physics").is_none(), "{architecture}");
        assert_eq!(!eval["segmentation"].is_null(), segments, "{architecture}");
        assert_eq!(!eval["force"].is_null(), force, "{architecture}");
        // One row per pair whatever the heads: its force where the network estimates one, its
        // masks' IoU where it segments.
        let csv = std::fs::read_to_string(runs.join("predictions-test.csv")).unwrap();
        let column = |name: &str| {
            csv.lines()
                .next()
                .unwrap()
                .split(',')
                .position(|c| c == name)
                .unwrap()
        };
        let (predicted, iou) = (column("fx_pred"), column("catheter_iou_a"));
        let rows: Vec<Vec<&str>> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect())
            .collect();
        assert!(!rows.is_empty(), "{architecture}");
        for row in &rows {
            assert_eq!(!row[predicted].is_empty(), force, "{architecture}: {row:?}");
            assert_eq!(!row[iou].is_empty(), segments, "{architecture}: {row:?}");
        }
        if architecture == "unet" {
            // Masks of views turned a quarter turn clockwise, each with its label mask: no
            // force, and the run's own tables left as they were.
            let tables = std::fs::read(runs.join("eval-test.json")).unwrap();
            let masks = dir.join("unet-turned-masks");
            let eval_turned = |more: &[&str]| {
                let mut args = vec![
                    "eval",
                    "--run",
                    runs.to_str().unwrap(),
                    "--json",
                    "--turn-views",
                    "1",
                ];
                args.extend_from_slice(more);
                run(&args)
            };
            let out = eval_turned(&["--masks", masks.to_str().unwrap()]);
            let turned: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            assert_eq!(turned["view_turns"], 1);
            assert!(turned["force"].is_null() && !turned["segmentation"].is_null());
            assert_eq!(std::fs::read(runs.join("eval-test.json")).unwrap(), tables);
            // Turned a quarter clockwise, the catheter enters from the left: read for that edge,
            // the network sees the views as they were and its masks, turned back onto the turned
            // labels, score as the untouched views' did.
            let untouched: serde_json::Value = serde_json::from_slice(&tables).unwrap();
            for (entry, read_turned) in [("left", Some(rows.len())), ("auto", None)] {
                let out = eval_turned(&["--catheter-entry", entry]);
                let read: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
                assert_eq!(read["catheter_entry"]["setting"], entry);
                assert_eq!(read["catheter_entry"]["pairs"], rows.len());
                if let Some(n) = read_turned {
                    assert_eq!(
                        read["catheter_entry"]["views_read_turned"],
                        serde_json::json!([n, n])
                    );
                    // Read at the edge the turn took the catheter to, each view once.
                    for counted in ["views_placed_right", "view_readings"] {
                        assert_eq!(read["catheter_entry"][counted], serde_json::json!([n, n]));
                    }
                    assert_eq!(read["segmentation"], untouched["segmentation"]);
                }
            }
            assert_eq!(std::fs::read(runs.join("eval-test.json")).unwrap(), tables);
            // The error maps' catheter (found or missed) is the label mask turned.
            for row in &rows {
                let label =
                    image::open(data.join("samples").join(format!("{}_mask_a.png", row[0])))
                        .unwrap()
                        .to_luma8();
                let errors = image::open(masks.join(format!("{}_errors_a.png", row[0])))
                    .unwrap()
                    .to_rgb8();
                let catheter =
                    |p: &image::Rgb<u8>| [[255, 255, 255], [64, 128, 255]].contains(&p.0);
                let turned_label = image::imageops::rotate90(&label);
                assert!(
                    turned_label
                        .pixels()
                        .zip(errors.pixels())
                        .all(|(l, e)| is_catheter_label(l.0[0]) == catheter(e)),
                    "pair {}",
                    row[0]
                );
            }
        }
        // Each epoch logs the metrics of the heads the network has, and no others.
        for split in ["train", "valid"] {
            let logs = runs.join(split).join("epoch-1");
            for (metric, logged) in [
                ("Loss", true),
                ("BCE_A", segments),
                ("mIoU", segments),
                ("Force_MSE", force),
                ("Force_MAE", force),
            ] {
                let log = logs.join(format!("{metric}.log"));
                assert_eq!(log.is_file(), logged, "{architecture}: {}", log.display());
            }
        }
        // The report draws what the network has: sample masks only for those that segment.
        let out = run(&["report", "--run", runs.to_str().unwrap()]);
        let report = runs.join("report");
        assert!(report.join("fig5-loss.png").is_file(), "{architecture}");
        assert_eq!(
            report.join("fig3-samples.png").is_file(),
            segments,
            "{architecture}"
        );
        assert_eq!(
            report.join("fig4-force-x.png").is_file(),
            force,
            "{architecture}"
        );
        let said = String::from_utf8_lossy(&out.stderr);
        assert_eq!(said.contains("and fig3-samples.png"), segments, "{said}");
        if !segments {
            // No masks to write: refused before anything is created.
            let masks = dir.join(format!("{architecture}-masks"));
            let err = fails(
                hnet()
                    .args(["eval", "--no-physics", "--run"])
                    .arg(&runs)
                    .arg("--masks")
                    .arg(&masks),
            );
            assert!(err.contains("gives no masks"), "{err}");
            assert!(!masks.exists());
        }
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn bad_input_gets_a_clear_error_naming_the_file() {
    let dir = scratch("errors");
    // Not a dataset.
    let err = fails(
        hnet()
            .args(["train", "--out"])
            .arg(dir.join("run"))
            .arg("--data")
            .arg(dir.join("nowhere")),
    );
    assert!(
        err.contains("nowhere") && err.contains("dataset.json"),
        "{err}"
    );

    // A patch grid asked of a modality without patches, before anything is written.
    let err = fails(
        hnet()
            .args([
                "simulate",
                "--modality",
                "rgb",
                "--random-patch-grid",
                "--out",
            ])
            .arg(dir.join("rgb")),
    );
    assert!(err.contains("--random-patch-grid"), "{err}");
    assert!(!dir.join("rgb").exists());

    // A corrupt weights file.
    let run_dir = dir.join("corrupt");
    std::fs::create_dir_all(&run_dir).unwrap();
    std::fs::write(run_dir.join("model.bpk"), b"not weights").unwrap();
    let err = fails(
        hnet()
            .args(["eval", "--run"])
            .arg(&run_dir)
            .arg("--data")
            .arg(&dir),
    );
    assert!(err.contains("model.bpk"), "{err}");

    // A forces CSV with a NaN.
    let (a, b) = (dir.join("a"), dir.join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    image::GrayImage::new(8, 8).save(a.join("f.png")).unwrap();
    image::GrayImage::new(8, 8).save(b.join("f.png")).unwrap();
    std::fs::write(dir.join("forces.csv"), "image,fx,fy,fz\nf.png,0,NaN,0\n").unwrap();
    let err = fails(
        hnet()
            .args(["import", "--view-a"])
            .arg(&a)
            .arg("--view-b")
            .arg(&b)
            .arg("--forces")
            .arg(dir.join("forces.csv"))
            .arg("--out")
            .arg(dir.join("imported")),
    );
    assert!(
        err.contains("forces.csv") && err.contains("line 2"),
        "{err}"
    );

    // A background folder that is not there (a config's relative path read from elsewhere).
    let err = fails(
        hnet()
            .current_dir(&dir)
            .args(["simulate", "--samples", "1", "--size", "32", "--background"])
            .arg("../no-such-radiographs")
            .arg("--out")
            .arg(dir.join("sim")),
    );
    assert!(
        err.contains("'../no-such-radiographs' does not exist")
            && err.contains("working directory"),
        "{err}"
    );

    // A scene sampling that cannot be drawn: the file and the field named, nothing written.
    let sampling = dir.join("sideways.json");
    let mut scenes = serde_json::json!({
        "bending_stiffness_n_m2": [0.0004, 0.0009], "length_mm": [60.0, 40.0],
        "precurvature_per_mm": [0.0, 0.028], "force_magnitude_n": [0.0, 0.4],
        "force_cone_deg": 80.0, "base_position_mm": [0.0, 0.0, -35.0], "base_jitter_mm": 6.0,
        "base_tilt_deg": 70.0, "base_roll_deg": [0.0, 360.0]
    });
    std::fs::write(&sampling, scenes.to_string()).unwrap();
    let simulate_with = |sampling: &Path, out: &Path| {
        let mut command = hnet();
        command
            .args([
                "simulate",
                "--samples",
                "2",
                "--size",
                "32",
                "--scenes",
                "off-bench",
            ])
            .arg("--scene-sampling")
            .arg(sampling)
            .arg("--out")
            .arg(out);
        command
    };
    let err = fails(&mut simulate_with(&sampling, &dir.join("reversed")));
    assert!(
        err.contains("sideways.json") && err.contains("length_mm"),
        "{err}"
    );
    assert!(!dir.join("reversed").exists());
    // A valid one is drawn from, and the header records it.
    scenes["length_mm"] = serde_json::json!([40.0, 60.0]);
    std::fs::write(&sampling, scenes.to_string()).unwrap();
    succeeds(&mut simulate_with(&sampling, &dir.join("sideways")));
    let header: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("sideways/dataset.json")).unwrap()).unwrap();
    assert_eq!(header["source"]["twin"]["scene"]["base_tilt_deg"], 70.0);
    // The paper's bench: a plate that starts through the unloaded tip is refused, naming the
    // setting, before anything is written; its own preset simulates, the contact in the manifest.
    let mut bench =
        serde_json::to_value(hnet_twin::simulator::scene::SceneSampling::paper_bench()).unwrap();
    bench["plate"]["standoff_mm"] = (-1.0).into();
    let through = dir.join("through.json");
    std::fs::write(&through, bench.to_string()).unwrap();
    let paper_bench = |sampling: Option<&Path>, out: &Path| {
        let mut command = hnet();
        command.args([
            "simulate",
            "--samples",
            "3",
            "--size",
            "32",
            "--scenes",
            "paper-bench",
        ]);
        if let Some(sampling) = sampling {
            command.arg("--scene-sampling").arg(sampling);
        }
        command.arg("--out").arg(out);
        command
    };
    let err = fails(&mut paper_bench(Some(&through), &dir.join("through")));
    assert!(err.contains("plate.standoff_mm"), "{err}");
    assert!(!dir.join("through").exists());
    succeeds(&mut paper_bench(None, &dir.join("paper-bench")));
    let manifest = std::fs::read_to_string(dir.join("paper-bench/manifest.csv")).unwrap();
    assert!(
        manifest.lines().next().unwrap().ends_with(",contact"),
        "{manifest}"
    );
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_time_budget_ends_training_cleanly_with_the_best_checkpoint() {
    let dir = scratch("time-budget");
    let data = simulate(&dir, 60);
    let config = tiny_config(&dir, "hnet", 5);
    let runs = dir.join("run");
    let out = succeeds(train(&data, &runs, &config).args(["--time-budget", "0s"]));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(
            "stopping after epoch 1: another epoch would not end within the time budget (0s)"
        ),
        "{stderr}"
    );
    let metrics = std::fs::read_to_string(runs.join("metrics.csv")).unwrap();
    assert!(
        metrics.contains("\n1,valid,") && !metrics.contains("\n2,"),
        "{metrics}"
    );
    assert!(runs.join("model.bpk").is_file());
    // A second stage starts from the first's network (recorded in its config.json); weights of
    // another network are refused, naming the file, before a run folder exists.
    let first = runs.join("model.bpk");
    succeeds(
        train(&data, &dir.join("second"), &config)
            .args(["--time-budget", "0s", "--init"])
            .arg(&first),
    );
    assert!(dir.join("second/model.bpk").is_file());
    let saved = std::fs::read_to_string(dir.join("second/config.json")).unwrap();
    assert!(saved.contains("\"init_weights\""), "{saved}");
    // Stopped before its first checkpoint, such a stage starts again from those weights, not
    // from fresh ones.
    let stopped = dir.join("stopped");
    std::fs::create_dir_all(&stopped).unwrap();
    for file in ["config.json", "run.json"] {
        std::fs::copy(dir.join("second").join(file), stopped.join(file)).unwrap();
    }
    let out = succeeds(
        hnet()
            .args(["train", "--resume", "--time-budget", "0s", "--out"])
            .arg(&stopped),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("starting from the first epoch, from the initial weights")
            && stderr.contains("model.bpk"),
        "{stderr}"
    );
    // (Another size as well does not make it the same network.)
    let wider = edited_config(&dir, "wider", |c| {
        let size = serde_json::json!({"width": 24, "height": 16});
        c["image_size"] = size.clone();
        c["model"]["image_size"] = size;
        c["model"]["filters"] = 16.into();
    });
    let err = fails(
        train(&data, &dir.join("third"), &wider)
            .arg("--init")
            .arg(&first),
    );
    assert!(
        err.contains("init_weights")
            && err.contains("model.bpk")
            && err.contains("another network"),
        "{err}"
    );
    assert!(!dir.join("third").exists());
    // H-Net's parameters do not depend on the input size: a stage at another size starts from
    // the first's weights and says so; its own weights file records the new size.
    let smaller = edited_config(&dir, "smaller", |c| {
        let size = serde_json::json!({"width": 24, "height": 16});
        c["image_size"] = size.clone();
        c["model"]["image_size"] = size;
    });
    let out = succeeds(
        train(&data, &dir.join("resized"), &smaller)
            .args(["--time-budget", "0s", "--init"])
            .arg(&first),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("was trained at 48×32; its weights go on training at 24×16"),
        "{stderr}"
    );
    let out = succeeds(
        hnet()
            .args([
                "eval",
                "--no-physics",
                "--json",
                "--split",
                "val",
                "--weights",
            ])
            .arg(dir.join("resized/model.bpk"))
            .arg("--data")
            .arg(&data),
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        report["image_size"],
        serde_json::json!({"width": 24, "height": 16})
    );
    // A training split larger than the memory budget is read from disk batch by batch.
    let from_disk = edited_config(&dir, "from-disk", |c| c["max_memory_mib"] = 0.into());
    let out = succeeds(train(&data, &dir.join("disk"), &from_disk).args(["--time-budget", "0s"]));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("from disk batch by batch") && stderr.contains("max_memory_mib 0"),
        "{stderr}"
    );
    assert!(dir.join("disk/model.bpk").is_file());
    // A bad budget is refused before anything is written.
    let bad = fails(
        hnet()
            .args(["train", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(dir.join("other"))
            .args(["--time-budget", "ten minutes"]),
    );
    assert!(bad.contains("is not a duration"), "{bad}");
    assert!(!dir.join("other").exists());
    std::fs::remove_dir_all(dir).ok();
}

/// `tiny_config`'s settings for H-Net, edited by `edit`, written to `dir/NAME.json`.
fn edited_config(dir: &Path, name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> PathBuf {
    let text = std::fs::read_to_string(tiny_config(dir, "hnet", 2)).unwrap();
    let mut config: serde_json::Value = serde_json::from_str(&text).unwrap();
    edit(&mut config);
    let path = dir.join(format!("{name}.json"));
    std::fs::write(&path, config.to_string()).unwrap();
    path
}

#[test]
fn a_stream_trains_on_fresh_twin_pairs_and_a_diverged_run_stops_at_its_step() {
    let dir = scratch("stream");
    let data = simulate(&dir, 40);
    // A small radiograph for the off-bench pairs (the phantom is slow to render in a debug build).
    let radiograph = dir.join("radiograph.png");
    image::GrayImage::from_fn(64, 64, |x, y| image::Luma([(x * 2 + y) as u8]))
        .save(&radiograph)
        .unwrap();
    let stream = |seed: u64| {
        serde_json::json!({"pairs_per_epoch": 16, "seed": seed, "off_bench": {
            "fraction": 0.5, "radiographs": [radiograph], "radiograph_fraction": 1.0}})
    };
    let config = edited_config(&dir, "stream", |c| c["stream"] = stream(99));
    let runs = dir.join("run");
    let out = succeeds(&mut train(&data, &runs, &config));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(
            "16 fresh twin pairs per epoch (stream seed 99, 50 % off the bench (1 radiographs))"
        ),
        "{stderr}"
    );
    let metrics = std::fs::read_to_string(runs.join("metrics.csv")).unwrap();
    assert!(metrics.contains("\n2,train,"), "{metrics}");
    assert!(runs.join("model.bpk").is_file());

    // The dataset's own seed would train on its val and test pairs: refused, no run folder made.
    let same_seed = edited_config(&dir, "same-seed", |c| c["stream"] = stream(5));
    let err = fails(&mut train(&data, &dir.join("refused"), &same_seed));
    assert!(err.contains("stream.seed 5"), "{err}");
    assert!(!dir.join("refused").exists());

    // Weights that blow up: the run stops at the first step whose loss is not finite, within
    // the first epoch (four steps), not at the epoch's end, and writes no checkpoint of that
    // epoch, so that neither `--resume` nor the export can use it.
    let diverging = edited_config(&dir, "diverging", |c| c["learning_rate"] = 1e30.into());
    let runs = dir.join("diverged");
    let err = fails(&mut train(&data, &runs, &diverging));
    assert!(err.contains("stopping in the middle of an epoch"), "{err}");
    assert!(err.contains("loss is not finite"), "{err}");
    assert!(err.contains("stopped before its checkpoint"), "{err}");
    assert!(err.contains("no usable checkpoint"), "{err}");
    let checkpoints = runs.join("checkpoint");
    assert!(!checkpoints.join("model-1.bpk").exists());
    assert!(!checkpoints.join("model-1.bpk.non-finite").exists());
    std::fs::remove_dir_all(dir).ok();
}

/// Runs `command`, which must fail with exit code 1 (an error, not a panic or an abort): what
/// it says.
fn fails_cleanly(command: &mut std::process::Command) -> String {
    let output = command.output().expect("hnet runs");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(1), "{command:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

#[test]
fn a_training_config_claiming_a_huge_network_is_refused_naming_the_file() {
    let dir = scratch("huge-config");
    // Each would be built (or its images loaded) and abort on the allocation if it got that far.
    let huge = 1usize << 40;
    for (name, model, size, setting) in [
        (
            "unet-depth",
            model_json("unet", huge, (32, 32)),
            (32, 32),
            "`model.depth` = 1099511627776 is outside 1..=16 for unet",
        ),
        (
            "hnet-filters",
            model_json("hnet", 2, (32, 32))
                .replace("\"filters\": 8", &format!("\"filters\": {huge}")),
            (32, 32),
            "`model.filters` = 1099511627776 is outside 1..=4096 for hnet",
        ),
        (
            "fcn-image",
            model_json("fcn", 1, (32, 32)),
            (1 << 20, 32),
            "`image_size` 1048576×32 is larger than 8192×8192 pixels",
        ),
    ] {
        let config = dir.join(format!("{name}.json"));
        std::fs::write(&config, config_json(&model, size, 8, 1)).unwrap();
        let err = fails_cleanly(
            hnet()
                .args(["train", "--config"])
                .arg(&config)
                .arg("--data")
                .arg(dir.join("no-data"))
                .arg("--out")
                .arg(dir.join("run")),
        );
        assert!(
            err.contains(&format!("training config '{}'", config.display()))
                && err.contains(setting),
            "{err}"
        );
        assert!(!dir.join("run").exists());
    }
    std::fs::remove_dir_all(dir).ok();
}

/// `hnet train --resume --out RUNS`.
fn resume_training(runs: &Path) -> std::process::Command {
    let mut command = hnet();
    command.args(["train", "--resume", "--out"]).arg(runs);
    command
}

/// The files of a run's checkpoint folder, by name.
fn checkpoint_files(runs: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(runs.join("checkpoint"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .collect()
}

#[test]
fn a_checkpoint_or_model_that_cannot_be_written_stops_the_run_and_resume_continues() {
    let dir = scratch("write-faults");
    let data = simulate(&dir, 60);
    let config = tiny_config(&dir, "hnet", 3);
    let runs = dir.join("run");
    let resume = || resume_training(&runs);
    // One epoch of three (the time budget stops it there).
    succeeds(train(&data, &runs, &config).args(["--time-budget", "0s"]));
    let epoch_1 = checkpoint_files(&runs);
    // Three parts, each with its checksum.
    assert_eq!(epoch_1.len(), 6, "{:?}", epoch_1.keys());
    assert_eq!(
        epoch_1.keys().filter(|n| n.ends_with(".bpk.crc32")).count(),
        3,
        "{:?}",
        epoch_1.keys()
    );
    let model_1 = std::fs::read(runs.join("model.bpk")).unwrap();

    // Epoch 2's network checkpoint cannot be written: a folder is in its place (a fault that
    // root meets too, unlike permissions). The run stops, naming the file, with exit code 1.
    let blocked = runs.join("checkpoint/model-2.bpk");
    std::fs::create_dir_all(blocked.join("in-the-way")).unwrap();
    let err = fails_cleanly(&mut resume());
    assert!(
        err.contains(&format!("cannot write checkpoint '{}'", blocked.display())),
        "{err}"
    );
    assert!(
        err.contains("epoch 1's checkpoint is complete") && err.contains("--resume"),
        "{err}"
    );
    // Epoch 1's checkpoint is as it was, no temporary file is left, model.bpk is untouched.
    let after = checkpoint_files(&runs);
    for (name, bytes) in &epoch_1 {
        assert_eq!(after.get(name), Some(bytes), "{name}");
    }
    assert!(
        after
            .keys()
            .all(|name| name.ends_with(".bpk") || name.ends_with(".bpk.crc32")),
        "{:?}",
        after.keys()
    );
    assert_eq!(std::fs::read(runs.join("model.bpk")).unwrap(), model_1);

    // Unblocked, `--resume` continues from epoch 1; now model.bpk cannot be written (a folder
    // in its place): the three epochs' checkpoints are kept, the message names the file.
    std::fs::remove_dir_all(&blocked).unwrap();
    std::fs::remove_file(runs.join("model.bpk")).unwrap();
    std::fs::create_dir_all(runs.join("model.bpk/in-the-way")).unwrap();
    let err = fails_cleanly(&mut resume());
    assert!(err.contains("resuming after epoch 1"), "{err}");
    assert!(
        err.contains(&format!(
            "cannot write '{}'",
            runs.join("model.bpk").display()
        )),
        "{err}"
    );
    assert!(err.contains("epoch 3's, is complete"), "{err}");
    assert!(!runs.join("model.bpk.partial").exists());

    // Unblocked again, `--resume` writes model.bpk from the checkpoints.
    std::fs::remove_dir_all(runs.join("model.bpk")).unwrap();
    let out = succeeds(&mut resume());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("resuming after epoch 3"), "{said}");
    assert!(runs.join("model.bpk").is_file());
    let metrics = std::fs::read_to_string(runs.join("metrics.csv")).unwrap();
    assert!(metrics.contains("\n3,valid,"), "{metrics}");

    // A checkpoint damaged after it was written (cut short): `--resume` names it, sets it aside
    // and continues from an earlier one, never a panic.
    let optim_3 = runs.join("checkpoint/optim-3.bpk");
    let bytes = std::fs::read(&optim_3).unwrap();
    std::fs::write(&optim_3, &bytes[..bytes.len() / 2]).unwrap();
    let out = succeeds(&mut resume());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains(&format!(
            "checkpoint '{}' cannot be read",
            optim_3.display()
        )),
        "{said}"
    );
    assert!(runs.join("checkpoint/optim-3.bpk.damaged").is_file());
    assert!(!said.contains("resuming after epoch 3"), "{said}");

    // A checkpoint garbled without being cut (one byte of its tensor data changed, so that it
    // still loads) is caught by the checksum written beside it.
    let last = std::fs::read_dir(runs.join("checkpoint"))
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            name.strip_prefix("model-")?
                .strip_suffix(".bpk")?
                .parse::<usize>()
                .ok()
        })
        .max()
        .expect("a checkpoint");
    assert!(
        runs.join(format!("checkpoint/model-{last}.bpk.crc32"))
            .is_file()
    );
    let model_last = runs.join(format!("checkpoint/model-{last}.bpk"));
    let mut bytes = std::fs::read(&model_last).unwrap();
    let at = bytes.len() * 3 / 4;
    bytes[at] ^= 0x10;
    std::fs::write(&model_last, &bytes).unwrap();
    let out = succeeds(&mut resume());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains(&format!(
            "checkpoint '{}' cannot be read (it does not match its checksum",
            model_last.display()
        )),
        "{said}"
    );
    assert!(
        runs.join(format!("checkpoint/model-{last}.bpk.damaged"))
            .is_file()
    );
    std::fs::remove_dir_all(dir).ok();
}

/// A metric log that cannot be written (a full disk, a file in the way) stops the run after that
/// epoch with a message naming the file, where burn-train's own logger panicked; `--resume`
/// then continues from the last complete checkpoint.
#[test]
fn a_metric_log_that_cannot_be_written_stops_the_run_and_resume_continues() {
    let dir = scratch("metric-log-fault");
    let data = simulate(&dir, 40);
    let config = tiny_config(&dir, "hnet", 2);
    let runs = dir.join("run");
    let resume = || resume_training(&runs);
    // One epoch of two (the time budget stops it there); then a folder where epoch 2's
    // training loss log goes.
    succeeds(train(&data, &runs, &config).args(["--time-budget", "0s"]));
    let blocked = runs.join("train/epoch-2/Loss.log");
    std::fs::create_dir_all(blocked.join("in-the-way")).unwrap();
    let err = fails_cleanly(&mut resume());
    assert!(
        err.contains(&format!("cannot write metric log '{}'", blocked.display())),
        "{err}"
    );
    assert!(err.contains("--resume"), "{err}");
    assert!(runs.join("train/epoch-1/Loss.log").is_file());
    // Epoch 2's checkpoint was written (its weights are whole; its logs stop at the failure):
    // unblocked, `--resume` finds the run complete and writes model.bpk.
    std::fs::remove_dir_all(&blocked).unwrap();
    let out = succeeds(&mut resume());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("resuming after epoch 2"), "{said}");
    assert!(runs.join("model.bpk").is_file());
    std::fs::remove_dir_all(dir).ok();
}

// Property tests (issue #13, docs/reliability.md): `hnet train --config FILE` with arbitrary or
// mutated settings ends with an error naming the file (or, for valid settings, goes on to the
// data), never a panic. Through the binary: `TrainingConfig::load` has no library path.
mod config_properties {
    use crate::common::{config_json, hnet, model_json, scratch};
    use hnet_mutations::{cases, mutate};
    use proptest::prelude::*;

    /// Runs `hnet train` on a config file holding `bytes`, with no dataset: what it says.
    fn train_with_config(dir: &std::path::Path, bytes: &[u8]) -> Result<String, TestCaseError> {
        let config = dir.join("config.json");
        std::fs::write(&config, bytes).unwrap();
        let out = hnet()
            .args(["train", "--config"])
            .arg(&config)
            .arg("--data")
            .arg(dir.join("no-data"))
            .arg("--out")
            .arg(dir.join("run"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        prop_assert!(!out.status.success());
        prop_assert!(out.status.code() == Some(1), "{:?}: {}", out.status, stderr);
        prop_assert!(!stderr.contains("panicked"), "{}", stderr);
        Ok(stderr)
    }

    fn edits() -> impl Strategy<Value = Vec<hnet_mutations::Edit>> {
        // Digits and JSON punctuation make the edits land as other numbers and shapes.
        hnet_mutations::edits_writing(prop_oneof![
            any::<u8>(),
            proptest::sample::select(b"0123456789-.e,:{}[]\"".to_vec())
        ])
    }

    proptest! {
        #![proptest_config(cases(48))]

        #[test]
        fn any_bytes_as_a_training_config_are_an_error_naming_it(
            bytes in proptest::collection::vec(any::<u8>(), 0..256)
        ) {
            let dir = scratch("prop-config-bytes");
            let stderr = train_with_config(&dir, &bytes)?;
            prop_assert!(stderr.contains("config.json"), "{}", stderr);
        }

        #[test]
        fn a_mutated_training_config_is_an_error_never_a_panic(edits in edits(), depth in 1usize..4) {
            let dir = scratch("prop-config-mutated");
            let size = (16 << depth, 8 << depth);
            let text = config_json(&model_json("hnet", depth, size), size, 2, 1);
            let stderr = train_with_config(&dir, &mutate(text.into_bytes(), &edits))?;
            // Either the settings are refused (naming the file) or they are fine and the
            // missing data is what stops the run.
            prop_assert!(stderr.contains("config.json") || stderr.contains("no-data"), "{}", stderr);
        }

        #[test]
        fn valid_training_configs_load(
            depth in 1usize..5,
            [w, h] in [1usize..8, 1usize..8],
            batch in 1usize..64,
            epochs in 1usize..1000,
            architecture in proptest::sample::select(vec!["hnet", "unet", "fcn", "hrnet", "ynet"]),
        ) {
            let dir = scratch("prop-config-valid");
            // Sizes each network can take: divisible by what it halves them by.
            let size = match architecture {
                "hnet" | "unet" => (w << depth, h << depth),
                "fcn" => (32 * w, 32 * h),
                "hrnet" => (16 * w, 16 * h),
                _ => (8 * w, 8 * h),
            };
            let model = model_json(architecture, depth, size);
            let stderr = train_with_config(&dir, config_json(&model, size, batch, epochs).as_bytes())?;
            // The settings were accepted: what stops the run is the missing dataset.
            prop_assert!(stderr.contains("no-data") && !stderr.contains("not a valid training config"), "{}", stderr);
        }
    }
}

/// A biplane DICOM cine (XA, written here from the twin's frames): imported into a dataset with
/// its geometry, traced by the bundled model, and neither output carries a patient identifier.
#[test]
fn a_biplane_dicom_cine_imports_and_traces_without_patient_identifiers() {
    let dir = scratch("dicom");
    let cine = hnet_dicom::twin_cine(hnet_units::ImageSize::square(32), 4, 9).unwrap();
    let (plane_a, folder_b) = (dir.join("plane-a.dcm"), dir.join("DOE_JANE_plane_b"));
    std::fs::create_dir_all(&folder_b).unwrap();
    std::fs::write(&plane_a, hnet_dicom::write_xa(&cine.planes[0])).unwrap();
    std::fs::write(
        folder_b.join("0001.dcm"),
        hnet_dicom::write_xa(&cine.planes[1]),
    )
    .unwrap();
    let mut forces = String::from("frame,fx,fy,fz\n");
    for (i, f) in cine.forces_n.iter().enumerate() {
        forces += &format!("{},{},{},{}\n", i + 1, f[0], f[1], f[2]);
    }
    std::fs::write(dir.join("forces.csv"), forces).unwrap();
    let data = dir.join("data");
    run(&[
        "import",
        "--dicom-a",
        plane_a.to_str().unwrap(),
        "--dicom-b",
        folder_b.to_str().unwrap(),
        "--forces",
        dir.join("forces.csv").to_str().unwrap(),
        "--out",
        data.to_str().unwrap(),
    ]);
    let dataset = hnet_twin::dataset::Dataset::open(&data).unwrap();
    assert_eq!(dataset.rows.len(), 4);
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dataset.record_file("frame00002")).unwrap()).unwrap();
    let views = &record["record"]["views"];
    assert_eq!(views[0]["carm"]["primary_deg"], -20.0);
    assert_eq!(views[1]["carm"]["primary_deg"], 70.0);

    let trace = dir.join("trace.csv");
    let weights = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/hnet-cpu.bpk");
    // The bundled weights carry their facts: the data their force learned from and the
    // calibration of both estimates' intervals (`hnet eval --record`, assets/MODEL.md).
    let bundled = String::from_utf8_lossy(&std::fs::read(&weights).unwrap()).into_owned();
    assert!(bundled.contains(r#""force_domain":{"data":"xray2-bench-224-s7""#));
    assert!(bundled.contains(r#""network_interval_90_n":["#));
    let traced = |out: &Path, plane_b: &Path| {
        let mut command = hnet();
        command
            .arg("trace")
            .arg("--weights")
            .arg(&weights)
            .arg("--dicom-a")
            .arg(&plane_a)
            .arg("--dicom-b")
            .arg(plane_b)
            .arg("--out")
            .arg(out);
        command
    };
    succeeds(&mut traced(&trace, &folder_b));
    let text = std::fs::read_to_string(&trace).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "frame,time_s,fx_n,fy_n,fz_n,magnitude_n,fx_90_n,fy_90_n,fz_90_n,estimator,weights,note"
    );
    assert_eq!(lines.len(), 5);
    // Every frame is in the trace, with its time. These 32 px frames, blown up to the model's
    // 224 px, show the bundled model no catheter in one view or both: each gets no force, and
    // says which view and why.
    for (i, line) in lines[1..].iter().enumerate() {
        assert!(line.starts_with(&format!("{},", i + 1)), "{line}");
        assert!(
            line.contains(",,,,,,,,,\"hnet-cpu.bpk\",\"view ")
                && line.contains(": no catheter found"),
            "{line}"
        );
    }
    assert!(lines[2].starts_with("2,0.0667,"), "{}", lines[2]);
    // Each view read twice with weights calibrated reading it once: allowed, and said.
    let twice = succeeds(
        traced(&dir.join("trace-twice.csv"), &folder_b).args(["--mask-averaging", "mirrored"]),
    );
    let said = String::from_utf8_lossy(&twice.stderr);
    assert!(
        said.contains("reading each view `mirrored`, while")
            && said.contains("calibrated reading them `single`"),
        "{said}"
    );

    // No output names the patient, the hospital or the folders (which may be named after them).
    let mut outputs = vec![trace.clone()];
    for folder in [data.clone(), data.join("samples")] {
        for entry in std::fs::read_dir(folder).unwrap() {
            outputs.push(entry.unwrap().path());
        }
    }
    for path in outputs.iter().filter(|p| p.is_file()) {
        let bytes = String::from_utf8_lossy(&std::fs::read(path).unwrap()).into_owned();
        for identifier in ["DOE", "PID-0042", "19611224", "ACC-7731", "Twin General"] {
            assert!(
                !bytes.contains(identifier),
                "{} holds {identifier}",
                path.display()
            );
        }
    }

    // Planes of different lengths: an error naming both, and nothing written.
    let mut short = cine.planes[1].clone();
    short.frames.truncate(3);
    let plane_b_short = dir.join("plane-b-short.dcm");
    std::fs::write(&plane_b_short, hnet_dicom::write_xa(&short)).unwrap();
    let err = fails(&mut traced(&dir.join("none.csv"), &plane_b_short));
    assert!(
        err.contains("plane-a.dcm")
            && err.contains("plane-b-short.dcm")
            && err.contains("4 frames"),
        "{err}"
    );
    assert!(!dir.join("none.csv").exists());
    std::fs::remove_dir_all(dir).ok();
}

/// `hnet calibrate`: bench pairs of a catheter 30 % stiffer than the catalogue's, read blind from
/// their masks, give its stiffness back from 10 labelled pairs; too few pairs and an impossible
/// catheter file are refused, naming the problem, and nothing is written.
#[test]
fn a_stiffer_catheter_is_calibrated_from_ten_labelled_pairs() {
    let dir = scratch("calibrate");
    let sampling = dir.join("stiff.json");
    let mut scenes: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../configs/mismatch/stiff-anywhere.json"),
        )
        .unwrap(),
    )
    .unwrap();
    // The bench fixture's pose: this test is about the stiffness.
    scenes["base_jitter_mm"] = 1.0.into();
    scenes["base_tilt_deg"] = 2.0.into();
    std::fs::write(&sampling, scenes.to_string()).unwrap();
    let data = dir.join("stiff");
    run(&[
        "simulate",
        "--samples",
        "12",
        "--size",
        "128",
        "--seed",
        "3",
        "--scene-sampling",
        sampling.to_str().unwrap(),
        "--out",
        data.to_str().unwrap(),
    ]);
    let out = dir.join("catheter.json");
    let calibrate = |extra: &[&str]| {
        let mut command = hnet();
        command.args([
            "calibrate",
            "--data",
            data.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        command.args(extra);
        command
    };
    succeeds(&mut calibrate(&["--pairs", "10"]));
    let catheter: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let scale = catheter["calibration"]["scale"].as_f64().unwrap();
    assert!((scale - 1.3).abs() < 0.05, "{catheter}");
    assert_eq!(catheter["calibration"]["pairs"], 10);
    std::fs::remove_file(&out).unwrap();
    // From a network's masks instead of the labels (pairs labelled with a force only): the
    // bundled weights read these 128 px pairs at their 224 px. Whatever scale they give, it is
    // a calibration of the same catheter, or a refusal saying why.
    let weights = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/hnet-cpu.bpk");
    let output = calibrate(&["--pairs", "10", "--weights", weights.to_str().unwrap()])
        .output()
        .unwrap();
    if output.status.success() {
        let catheter: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
        assert_eq!(catheter["name"], "twin-bench-7f");
        std::fs::remove_file(&out).unwrap();
    } else {
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains("cannot calibrate catheter"), "{stderr}");
    }

    let stderr = fails(&mut calibrate(&["--pairs", "2"]));
    assert!(stderr.contains("at least 3 are needed"), "{stderr}");
    let impossible = dir.join("impossible.json");
    std::fs::write(
        &impossible,
        r#"{"name":"x","description":"","bending_stiffness_n_m2":0.0006,
            "flexible_length_mm":50,"precurvature_per_mm":-1,"diameter_mm":2.33}"#,
    )
    .unwrap();
    let stderr = fails(&mut calibrate(&[
        "--catheter",
        impossible.to_str().unwrap(),
    ]));
    assert!(
        stderr.contains("precurvature_per_mm = -1 is impossible"),
        "{stderr}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(dir).ok();
}
