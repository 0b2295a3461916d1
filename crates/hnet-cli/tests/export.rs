//! The page's export trains as it is: pairs labeled in the app (here made with the app's own
//! live twin and export code) are zipped, unzipped and given to `hnet train` and `hnet eval`.

mod common;

use common::{config_json, hnet, model_json, scratch, succeeds, train};
use hnet_studio::export::{DATASET_NAME, dataset_zip};
use hnet_studio::twin_live::{TwinControls, XrayBackground};
use hnet_studio::workspace::Workspace;
use hnet_twin::dataset::label_origin::LabelOrigin;

#[test]
fn the_page_export_trains_and_evaluates() {
    let dir = scratch("export");

    let mut ws = Workspace::default();
    let background = XrayBackground::phantom();
    for i in 0..10 {
        let controls = TwinControls {
            force_n: hnet_units::TipForce::new(0.04 * i as f32 - 0.2, 0.1, -0.05),
            noise_seed: i,
            ..TwinControls::default()
        };
        ws.add(controls.render(ws.next_id(), &background).unwrap());
    }
    // Two labels copied from a model's estimate (both in the train split): they are marked as
    // such, and training leaves them out of the force head unless asked.
    for id in ["pair-0001", "pair-0002"] {
        let force = ws.pair(id).unwrap().force_n.unwrap();
        let estimate = LabelOrigin::Estimate {
            weights: "hnet-cpu.bpk".into(),
            estimator: "combined".into(),
        };
        ws.set_force(id, Some((force, estimate)));
    }
    let export = dataset_zip(&ws.pairs).unwrap();
    assert_eq!(export.exported.len(), 10);
    zip::ZipArchive::new(std::io::Cursor::new(export.zip))
        .unwrap()
        .extract(&dir)
        .unwrap();
    let data = dir.join(DATASET_NAME);

    let config = dir.join("tiny.json");
    let size = (32, 32);
    std::fs::write(
        &config,
        config_json(&model_json("hnet", 2, size), size, 4, 2),
    )
    .unwrap();
    let manifest = std::fs::read_to_string(data.join("manifest.csv")).unwrap();
    assert!(
        manifest.contains(",estimate,hnet-cpu.bpk,combined") && manifest.contains(",simulated,"),
        "{manifest}"
    );
    let run = dir.join("run");
    let output = succeeds(&mut train(&data, &run, &config));
    assert!(run.join("model.bpk").is_file());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("2 training pair(s) train their masks only"),
        "{stderr}"
    );
    // `--labels all` learns the estimates too; a word that is no origin is refused.
    let output = succeeds(train(&data, &dir.join("run-all"), &config).args(["--labels", "all"]));
    assert!(!String::from_utf8_lossy(&output.stderr).contains("masks only"));
    let output = train(&data, &dir.join("run-bad"), &config)
        .args(["--labels", "guessed"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success() && stderr.contains("label_origin `guessed`"),
        "{stderr}"
    );
    assert!(
        !dir.join("run-bad").exists(),
        "nothing is written for a refused setting"
    );
    let eval = succeeds(hnet().args(["eval", "--json", "--run"]).arg(&run));
    let tables: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    assert_eq!(tables["force"]["samples"], 1);
    std::fs::remove_dir_all(dir).ok();
}
