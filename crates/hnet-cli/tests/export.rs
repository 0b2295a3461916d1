//! The page's export trains as it is: pairs labeled in the app (here made with the app's own
//! live twin and export code) are zipped, unzipped and given to `hnet train` and `hnet eval`.

mod common;

use common::{config_json, hnet, model_json, scratch, succeeds, train};
use hnet_studio::export::{DATASET_NAME, dataset_zip};
use hnet_studio::twin_live::{TwinControls, XrayBackground};
use hnet_studio::workspace::Workspace;

#[test]
fn the_page_export_trains_and_evaluates() {
    let dir = scratch("export");

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
    let size = (32, 32);
    std::fs::write(
        &config,
        config_json(&model_json("hnet", 2, size), size, 4, 2),
    )
    .unwrap();
    let run = dir.join("run");
    succeeds(&mut train(&data, &run, &config));
    assert!(run.join("model.bpk").is_file());
    let eval = succeeds(hnet().args(["eval", "--json", "--run"]).arg(&run));
    let tables: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    assert_eq!(tables["force"]["samples"], 1);
    std::fs::remove_dir_all(dir).ok();
}
