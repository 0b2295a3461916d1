//! The page's export trains as it is: pairs labeled in the app (here made with the app's own
//! live twin and export code) are zipped, unzipped and given to `hnet train` and `hnet eval`.

use std::process::Command;

use hnet_studio::export::{DATASET_NAME, dataset_zip};
use hnet_studio::twin_live::{TwinControls, XrayBackground};
use hnet_studio::workspace::Workspace;

#[test]
fn the_page_export_trains_and_evaluates() {
    let dir = std::env::temp_dir().join(format!("hnet-cli-export-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();

    let mut ws = Workspace::default();
    let background = XrayBackground::phantom();
    for i in 0..10 {
        let controls = TwinControls {
            force_n: [0.04 * i as f64 - 0.2, 0.1, -0.05],
            noise_seed: i,
            ..TwinControls::default()
        };
        ws.add(controls.render(ws.next_id(), &background).unwrap());
    }
    let export = dataset_zip(&ws.pairs).unwrap();
    assert_eq!(export.exported.len(), 10);
    zip::ZipArchive::new(std::io::Cursor::new(export.zip))
        .unwrap()
        .extract(&dir)
        .unwrap();
    let data = dir.join(DATASET_NAME);

    let config = dir.join("tiny.json");
    std::fs::write(
        &config,
        r#"{"name": "tiny", "model": {"architecture": "hnet", "in_channels": 3, "filters": 4,
            "depth": 2, "image_size": {"width": 32, "height": 32}, "share_weights": true, "force_hidden": [8, 8]},
            "image_size": {"width": 32, "height": 32}, "loss": {"beta_a": 1.0, "beta_b": 1.0, "beta_force": 1.0},
            "learning_rate": 0.001, "rmsprop_alpha": 0.9, "rmsprop_momentum": 0.0,
            "rmsprop_epsilon": 1e-7, "batch_size": 4, "epochs": 2, "patience": 5, "seed": 1,
            "max_train_samples": null, "max_valid_samples": null, "num_workers": 1}"#,
    )
    .unwrap();
    let run = dir.join("run");
    let hnet = env!("CARGO_BIN_EXE_hnet");
    let train = Command::new(hnet)
        .args(["train", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(&run)
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    assert!(
        train.status.success(),
        "{}",
        String::from_utf8_lossy(&train.stderr)
    );
    assert!(run.join("model.bpk").is_file());
    let eval = Command::new(hnet)
        .args(["eval", "--json", "--run"])
        .arg(&run)
        .output()
        .unwrap();
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let tables: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    assert_eq!(tables["force"]["samples"], 1);
    std::fs::remove_dir_all(dir).ok();
}
