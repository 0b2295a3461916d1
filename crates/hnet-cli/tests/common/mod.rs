//! What the `hnet` command's test binaries share: running it, a scratch folder, and the text of
//! a small training config. Each binary uses a part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `hnet` binary under test.
pub fn hnet() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hnet"))
}

/// Runs `command`, which must succeed: its output.
pub fn succeeds(command: &mut Command) -> Output {
    let output = command.output().expect("hnet runs");
    assert!(
        output.status.success(),
        "{command:?} failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// Runs `command`, which must fail: what it says.
pub fn fails(command: &mut Command) -> String {
    let output = command.output().expect("hnet runs");
    assert!(!output.status.success(), "{command:?} succeeded");
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// `hnet train --data DATA --out RUNS --config CONFIG`, to add to and run.
pub fn train(data: &Path, runs: &Path, config: &Path) -> Command {
    let mut command = hnet();
    command
        .args(["train", "--data"])
        .arg(data)
        .arg("--out")
        .arg(runs)
        .arg("--config")
        .arg(config);
    command
}

/// An empty folder `hnet-cli-NAME-PID` in the temporary folder.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hnet-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The `model` settings of a small `architecture` for `(width, height)` images, with `depth`
/// levels where the network has a depth.
pub fn model_json(architecture: &str, depth: usize, (width, height): (usize, usize)) -> String {
    match architecture {
        "hnet" => format!(
            r#"{{"architecture": "hnet", "in_channels": 3, "filters": 8, "depth": {depth},
                 "image_size": {{"width": {width}, "height": {height}}}, "share_weights": true,
                 "force_hidden": [16, 8]}}"#
        ),
        "unet" => format!(r#"{{"architecture": "unet", "base_filters": 4, "depth": {depth}}}"#),
        "fcn" => r#"{"architecture": "fcn", "base_filters": 4}"#.to_string(),
        "hrnet" => r#"{"architecture": "hrnet", "width": 4}"#.to_string(),
        "ynet" => r#"{"architecture": "ynet", "base_filters": 4, "hidden": [16, 8]}"#.to_string(),
        other => panic!("{other}"),
    }
}

/// A training config's text: `model` on `(width, height)` images.
pub fn config_json(
    model: &str,
    (width, height): (usize, usize),
    batch: usize,
    epochs: usize,
) -> String {
    format!(
        r#"{{"name": "tiny", "model": {model}, "image_size": {{"width": {width}, "height": {height}}},
          "loss": {{"beta_a": 1.0, "beta_b": 1.0, "beta_force": 1.0}},
          "learning_rate": 0.001, "rmsprop_alpha": 0.9, "rmsprop_momentum": 0.0,
          "rmsprop_epsilon": 1e-7, "batch_size": {batch}, "epochs": {epochs}, "patience": 20,
          "seed": 1, "max_train_samples": null, "max_valid_samples": null, "num_workers": 1}}"#
    )
}
