//! The page's state layout, checked on its sources: every component module reads the store of
//! its own concern and at most one other (docs: DEVELOPERS.md, `src/`); what else it shows comes
//! as narrow signals. [`Notices`](crate::studio) is the channel every module reports through and
//! is not counted. `app.rs` creates every store and hands them out; `studio/` owns them.

/// Each component module, and the store of its concern (`None`: it shows only its props).
const OWNERS: &[(&str, Option<&str>)] = &[
    ("catheter_view.rs", Some("TwinStore")),
    ("cine_panel.rs", Some("CineStore")),
    ("composer.rs", Some("TwinStore")),
    ("fine_tune_panel.rs", Some("TuningStore")),
    ("force_panel.rs", Some("NetworkStore")),
    ("force_trace.rs", Some("CineStore")),
    ("model_bar.rs", Some("NetworkStore")),
    ("pair_list.rs", Some("PairStore")),
    ("shortcuts.rs", Some("DisplaySettings")),
    ("sources.rs", Some("TwinStore")),
    ("stereo_view.rs", Some("DisplaySettings")),
    ("upload_geometry.rs", None),
];

/// The stores a component can be handed.
const STORES: &[&str] = &[
    "PairStore",
    "NetworkStore",
    "DisplaySettings",
    "TwinStore",
    "CineStore",
    "TuningStore",
];

#[test]
fn every_component_reads_its_own_store_and_at_most_one_other() {
    let folder = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/components");
    let mut modules: Vec<String> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(".rs") && name != "mod.rs")
        .collect();
    modules.sort();
    let listed: Vec<&str> = OWNERS.iter().map(|(m, _)| *m).collect();
    assert_eq!(
        modules, listed,
        "a component module without its concern in OWNERS"
    );
    for (module, owner) in OWNERS {
        let source = std::fs::read_to_string(folder.join(module)).unwrap();
        assert!(
            !source.contains("expect_context") && !source.contains("use_context"),
            "{module} reads a context: hand it what it shows as props"
        );
        let foreign: Vec<&str> = STORES
            .iter()
            .copied()
            .filter(|store| Some(*store) != *owner && source.contains(store))
            .collect();
        assert!(
            foreign.len() <= 1,
            "{module} reads {foreign:?} besides its own {owner:?}: hand it narrow signals"
        );
    }
}
