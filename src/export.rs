//! The labeled pairs as a dataset zip, in exactly the format `hnet train` reads
//! (`docs/dataset-format.md`), built with the twin crate's [`DatasetArchive`].

use hnet_twin::dataset::archive::{ArchiveError, DatasetArchive};
use hnet_twin::dataset::{DatasetHeader, ImageRef, ManifestRow, Split};

use crate::imaging::WORK_SIZE;
use crate::workspace::{LabeledPair, PairSource, export_splits};

/// Name of the dataset folder inside the zip (and of the zip file, with `.zip`).
pub const DATASET_NAME: &str = "hnet-studio-labels";

/// A built dataset zip.
#[derive(Debug, Clone)]
pub struct Export {
    /// The zip's bytes.
    pub zip: Vec<u8>,
    /// Ids of the exported pairs.
    pub exported: Vec<String>,
    /// Pairs left out, with why.
    pub skipped: Vec<(String, &'static str)>,
    /// Splits that hold no exported pair.
    pub empty_splits: Vec<Split>,
}

impl Export {
    /// What the user should know about the export's splits, if anything: `hnet train` needs a
    /// training and a validation pair, and `hnet eval` a test pair.
    pub fn split_warning(&self) -> Option<String> {
        if self.empty_splits.is_empty() {
            return None;
        }
        let names: Vec<&str> = self.empty_splits.iter().map(|s| s.name()).collect();
        Some(format!(
            "no {} pair: `hnet train` needs train and val pairs and `hnet eval` test pairs; \
             export at least 4 complete pairs",
            names.join(" or ")
        ))
    }
}

/// Why nothing could be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// No pair has both masks labeled and a force label.
    #[error(
        "no pair is complete yet: a pair needs a catheter painted in both masks (or a view \
         marked as showing none) and a force label"
    )]
    NothingComplete,
    /// The archive could not be built.
    #[error(transparent)]
    Archive(#[from] ArchiveError),
}

/// An image at the working size.
fn image(pixels: &[u8], channels: usize) -> ImageRef<'_> {
    ImageRef {
        width: WORK_SIZE.width,
        height: WORK_SIZE.height,
        channels,
        pixels,
    }
}

/// The pair's manifest columns beyond id, split and force, and its record.
fn describe(pair: &LabeledPair) -> (Vec<(String, String)>, serde_json::Value) {
    match &pair.source {
        PairSource::Upload {
            view_a,
            view_b,
            views,
        } => {
            let mut record = serde_json::json!({
                "source": "upload", "view_a_file": view_a, "view_b_file": view_b,
            });
            // The C-arms the user stated, as a twin pair's record holds them; none when assumed.
            if let Some(views) = views {
                record["views"] = serde_json::json!({
                    "a": { "carm": views.a, "camera_matrix": views.a.camera_matrix() },
                    "b": { "carm": views.b, "camera_matrix": views.b.camera_matrix() },
                });
            }
            (
                vec![
                    ("source".into(), "upload".into()),
                    ("view_a_file".into(), view_a.clone()),
                    ("view_b_file".into(), view_b.clone()),
                ],
                record,
            )
        }
        PairSource::Twin {
            true_force_n,
            tip_mm,
            views,
            settings,
        } => (
            vec![("source".into(), "twin".into())],
            serde_json::json!({
                "source": "twin",
                "true_force_n": true_force_n,
                "tip_mm": tip_mm,
                "views": {
                    "a": { "carm": views.a, "camera_matrix": views.a.camera_matrix() },
                    "b": { "carm": views.b, "camera_matrix": views.b.camera_matrix() },
                },
                "twin": settings,
            }),
        ),
        PairSource::Dicom {
            frame,
            time_s,
            views,
            missing_geometry,
        } => {
            let view = |carm: &hnet_twin::simulator::carm::CArm, missing: &[String]| {
                serde_json::json!({
                    "carm": carm,
                    "camera_matrix": carm.camera_matrix(),
                    "missing_geometry": missing,
                })
            };
            (
                vec![
                    ("source".into(), "dicom".into()),
                    ("frame".into(), (frame + 1).to_string()),
                    (
                        "time_s".into(),
                        time_s.map(|t| format!("{t:.4}")).unwrap_or_default(),
                    ),
                ],
                serde_json::json!({
                    "source": "dicom",
                    "frame": frame + 1,
                    "time_s": time_s,
                    "views": {
                        "a": view(&views.a, &missing_geometry[0]),
                        "b": view(&views.b, &missing_geometry[1]),
                    },
                }),
            )
        }
    }
}

/// A dataset zip built pair by pair, so that the page can let the browser breathe between pairs
/// (an export of 1,000 pairs takes tens of seconds). The plan (which pairs, their splits) is
/// made once from the pairs then; each pair is then added by id from whatever the page holds.
pub struct ExportBuilder {
    /// The complete pairs' ids and splits, in export order.
    planned: Vec<(String, Split)>,
    /// Pairs left out, with why.
    skipped: Vec<(String, &'static str)>,
    /// The pairs added so far and their splits.
    added: Vec<(String, Split)>,
    archive: DatasetArchive,
}

impl ExportBuilder {
    /// Plans the export of every complete pair (masks labeled and a force label); the others
    /// are listed in [`Export::skipped`]. Pairs keep their ids and their splits
    /// ([`export_splits`]: a pair's split never changes once given).
    pub fn new(pairs: &[LabeledPair]) -> Result<Self, ExportError> {
        let mut skipped = Vec::new();
        let planned: Vec<(String, Split)> = pairs
            .iter()
            .zip(export_splits(pairs))
            .filter(|(p, _)| {
                if let Some(why) = p.incomplete_because() {
                    skipped.push((p.id.clone(), why));
                }
                p.is_complete()
            })
            .map(|(p, split)| (p.id.clone(), split.unwrap_or(Split::Train)))
            .collect();
        if planned.is_empty() {
            return Err(ExportError::NothingComplete);
        }
        Ok(Self {
            planned,
            skipped,
            added: Vec::new(),
            archive: DatasetArchive::new(DATASET_NAME),
        })
    }

    /// The ids of the pairs to export, in order.
    pub fn planned(&self) -> impl Iterator<Item = &str> {
        self.planned.iter().map(|(id, _)| id.as_str())
    }

    /// Adds planned pair number `index` as `pair` holds it now; `None` (the pair was deleted
    /// since) leaves it out, listed as skipped.
    pub fn add(&mut self, index: usize, pair: Option<&LabeledPair>) -> Result<(), ExportError> {
        let Some((id, split)) = self.planned.get(index).cloned() else {
            return Ok(());
        };
        let Some(pair) = pair.filter(|p| p.id == id && p.is_complete()) else {
            self.skipped
                .push((id, "deleted or changed during the export"));
            return Ok(());
        };
        let (mut extra, mut record) = describe(pair);
        // Where the force label came from: a model's estimate is marked as one, with its
        // weights, so that training can leave it out (`hnet train --labels`).
        extra.extend(pair.force_origin.columns());
        record["force_label"] = serde_json::json!({
            "origin": pair.force_origin.word(),
            "described": pair.force_origin.describe(),
            "made_by": &pair.force_origin,
        });
        record["no_catheter"] = serde_json::json!({
            "a": pair.no_catheter[0],
            "b": pair.no_catheter[1],
        });
        let force = pair.force_n.unwrap_or_default();
        let row = ManifestRow {
            id: id.clone(),
            split,
            force_n: force,
            extra,
        };
        self.archive.add_pair(
            row,
            [
                image(&pair.view_a, 3),
                image(&pair.view_b, 3),
                image(&pair.mask_a, 1),
                image(&pair.mask_b, 1),
            ],
            &record,
        )?;
        self.added.push((id, split));
        Ok(())
    }

    /// The zip of the pairs added.
    pub fn finish(self) -> Result<Export, ExportError> {
        if self.added.is_empty() {
            return Err(ExportError::NothingComplete);
        }
        let header = DatasetHeader::new(
            WORK_SIZE,
            self.added.len(),
            serde_json::json!({
                "generator": "hnet-studio",
                "version": env!("CARGO_PKG_VERSION"),
                "masks": "labeled in the browser app (0 background, 255 catheter)",
            }),
        );
        Ok(Export {
            zip: self.archive.finish(&header)?,
            empty_splits: [Split::Train, Split::Val, Split::Test]
                .into_iter()
                .filter(|s| self.added.iter().all(|(_, split)| split != s))
                .collect(),
            exported: self.added.into_iter().map(|(id, _)| id).collect(),
            skipped: self.skipped,
        })
    }
}

/// Builds the dataset zip of every complete pair at once ([`ExportBuilder`], pair by pair).
pub fn dataset_zip(pairs: &[LabeledPair]) -> Result<Export, ExportError> {
    let mut builder = ExportBuilder::new(pairs)?;
    let ids: Vec<String> = builder.planned().map(str::to_string).collect();
    for (index, id) in ids.iter().enumerate() {
        builder.add(index, pairs.iter().find(|p| &p.id == id))?;
    }
    builder.finish()
}

// Native tests (`cargo test`); the browser tests are in tests/web.rs.
#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;
    use crate::twin_live::{TwinControls, XrayBackground};
    use crate::workspace::Workspace;
    use hnet_twin::dataset::label_origin::LabelOrigin;
    use hnet_units::TipForce;

    #[test]
    fn complete_pairs_export_and_incomplete_ones_are_listed() {
        let mut ws = Workspace::default();
        let background = XrayBackground::phantom();
        for fx in [0.1, -0.1, 0.2] {
            let controls = TwinControls {
                force_n: TipForce::new(fx, 0.0, -0.1),
                ..TwinControls::default()
            };
            ws.add(controls.render(ws.next_id(), &background).unwrap());
        }
        let id = ws.pairs[1].id.clone();
        ws.set_force(&id, None);
        // A model's estimate accepted as pair 3's label.
        let estimate = LabelOrigin::Estimate {
            weights: "hnet-cpu.bpk".into(),
            estimator: "combined".into(),
        };
        ws.set_force(
            "pair-0003",
            Some((TipForce::new(0.2, 0.0, -0.1), estimate.clone())),
        );

        let export = dataset_zip(&ws.pairs).unwrap();
        assert_eq!(export.exported, vec!["pair-0001", "pair-0003"]);
        assert_eq!(export.skipped, vec![(id.clone(), "no force label")]);
        // Two pairs: both train, and the export says what is missing.
        assert_eq!(export.empty_splits, vec![Split::Val, Split::Test]);
        assert!(
            export
                .split_warning()
                .unwrap()
                .starts_with("no val or test pair")
        );

        let dir = std::env::temp_dir().join(format!("hnet-studio-export-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut zip = zip_reader(&export.zip);
        zip.extract(&dir).unwrap();
        let dataset = hnet_twin::dataset::Dataset::open(&dir.join(DATASET_NAME)).unwrap();
        assert_eq!(dataset.rows.len(), 2);
        let row = &dataset.rows[0];
        assert_eq!(row.force_n, TipForce::new(0.1, 0.0, -0.1));
        // The twin's label is its exact force; the accepted estimate says what it is.
        assert_eq!(row.label_origin(), Ok(LabelOrigin::Simulated));
        assert_eq!(dataset.rows[1].label_origin(), Ok(estimate));
        assert_eq!(
            dataset.rows[1].column("label_weights"),
            Some("hnet-cpu.bpk")
        );
        let loaded = dataset.load_pair(row, None).unwrap();
        assert_eq!(loaded.size, WORK_SIZE);
        let catheter = loaded
            .mask_a
            .iter()
            .filter(|&&m| hnet_units::mask::is_catheter(m))
            .count();
        assert_eq!(
            catheter,
            ws.pairs[0].labeled_pixels(crate::workspace::View::A)
        );
        std::fs::remove_dir_all(dir).ok();

        let none: Vec<LabeledPair> = Vec::new();
        assert!(matches!(
            dataset_zip(&none).unwrap_err(),
            ExportError::NothingComplete
        ));

        // Built pair by pair (as the page does), a pair deleted meanwhile is left out and named.
        let mut builder = ExportBuilder::new(&ws.pairs).unwrap();
        let planned: Vec<String> = builder.planned().map(str::to_string).collect();
        assert_eq!(planned, vec!["pair-0001", "pair-0003"]);
        builder.add(0, ws.pair("pair-0001")).unwrap();
        builder.add(1, None).unwrap();
        let export = builder.finish().unwrap();
        assert_eq!(export.exported, vec!["pair-0001"]);
        assert!(
            export
                .skipped
                .contains(&("pair-0003".into(), "deleted or changed during the export")),
            "{:?}",
            export.skipped
        );
    }

    #[test]
    fn an_uploads_stated_c_arms_go_into_its_record_as_a_twin_pairs_do() {
        let views = crate::stated_geometry::StatedGeometry {
            views_deg: [[-30.0, 0.0], [60.0, 10.0]],
            source_to_isocentre_mm: 700.0,
            source_to_detector_mm: 1100.0,
            detector_width_mm: 200.0,
        }
        .views();
        let mut source = PairSource::Upload {
            view_a: "a.png".into(),
            view_b: "b.png".into(),
            views: Some(views),
        };
        let pair =
            |source: &PairSource| LabeledPair::new("u".into(), source.clone(), vec![], vec![]);
        let (_, record) = describe(&pair(&source));
        assert_eq!(record["views"]["b"]["carm"]["primary_deg"], 60.0);
        assert_eq!(
            record["views"]["a"]["carm"]["source_to_isocentre_mm"],
            700.0
        );
        assert!(
            record["views"]["a"]["camera_matrix"].is_object()
                || record["views"]["a"]["camera_matrix"].is_array()
        );
        if let PairSource::Upload { views, .. } = &mut source {
            *views = None;
        }
        assert!(describe(&pair(&source)).1.get("views").is_none());
    }

    #[test]
    fn a_pairs_split_stays_as_pairs_are_added() {
        let background = XrayBackground::phantom();
        let mut ws = Workspace::default();
        let mut seen: Vec<(String, Split)> = Vec::new();
        for i in 0..12 {
            let controls = TwinControls {
                force_n: TipForce::new(0.02 * i as f32, 0.0, -0.1),
                ..TwinControls::default()
            };
            ws.add(controls.render(ws.next_id(), &background).unwrap());
            ws.assign_splits();
            let export = dataset_zip(&ws.pairs).unwrap();
            let manifest = manifest_of(&export.zip);
            for (id, split) in &seen {
                assert_eq!(manifest[id], *split, "{id} moved after {} pairs", i + 1);
            }
            seen = manifest.into_iter().collect();
            assert_eq!(export.empty_splits.is_empty(), i >= 3, "{} pairs", i + 1);
        }
        // A pair keeps its split when its label is cleared and given again.
        let before = ws.pairs[2].split;
        ws.set_force("pair-0003", None);
        assert!(ws.assign_splits().is_empty());
        ws.set_force(
            "pair-0003",
            Some((TipForce::new(0.1, 0.0, 0.0), LabelOrigin::Typed)),
        );
        assert_eq!(ws.pairs[2].split, before);
    }

    #[test]
    fn a_pair_with_one_view_painted_is_not_exported_as_complete() {
        use crate::workspace::{Tool, View};
        let mut ws = crate::workspace::tests::workspace(2);
        for id in ["pair-0001", "pair-0002"] {
            ws.select(ws.pairs.iter().position(|p| p.id == id).unwrap());
            ws.set_force(id, Some((TipForce::new(0.1, 0.0, 0.0), LabelOrigin::Typed)));
            ws.begin_stroke(View::A, None);
            ws.stroke_to([10.0, 10.0], [100.0, 10.0], 3.0, Tool::Brush);
            ws.end_stroke();
        }
        // Only view A holds a catheter: nothing is complete, and the export says why.
        let err = dataset_zip(&ws.pairs).unwrap_err();
        assert!(matches!(err, ExportError::NothingComplete), "{err}");
        // Pair 2's view B marked as showing no catheter: it exports, pair 1 is named.
        ws.mark_no_catheter("pair-0002", View::B, true);
        let export = dataset_zip(&ws.pairs).unwrap();
        assert_eq!(export.exported, vec!["pair-0002"]);
        assert_eq!(export.skipped.len(), 1);
        assert_eq!(export.skipped[0].0, "pair-0001");
        assert!(export.skipped[0].1.starts_with("view B's mask is empty"));
    }

    fn manifest_of(zip: &[u8]) -> std::collections::HashMap<String, Split> {
        let mut zip = zip_reader(zip);
        let mut text = String::new();
        std::io::Read::read_to_string(
            &mut zip
                .by_name(&format!("{DATASET_NAME}/manifest.csv"))
                .unwrap(),
            &mut text,
        )
        .unwrap();
        hnet_twin::dataset::parse_manifest(text.as_bytes(), std::path::Path::new("m.csv"))
            .unwrap()
            .into_iter()
            .map(|r| (r.id, r.split))
            .collect()
    }

    fn zip_reader(bytes: &[u8]) -> zip::ZipArchive<std::io::Cursor<&[u8]>> {
        zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap()
    }
}

// Property tests (issue #13, docs/reliability.md): whatever pairs the page holds, the export is
// a zip that hnet_twin's reader opens with the same ids, splits, forces, pixels and masks.
#[cfg(all(test, not(target_arch = "wasm32")))]
pub(crate) mod properties {
    use super::*;
    use crate::imaging::properties::cases;
    use hnet_twin::dataset::label_origin::LabelOrigin;
    use proptest::prelude::*;

    /// Deterministic pixels from a seed (random bytes per case would be slow to shrink).
    fn pixels(seed: u64, len: usize, mask: bool) -> Vec<u8> {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..len)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let v = (state >> 24) as u8;
                if mask {
                    if v > 200 { 255 } else { 0 }
                } else {
                    v
                }
            })
            .collect()
    }

    fn component() -> impl Strategy<Value = f32> {
        prop_oneof![-0.5f32..0.5, Just(0.0), Just(-0.0)]
    }

    /// Any pair the page may hold (also the stored record's property tests).
    pub(crate) fn pair() -> impl Strategy<Value = LabeledPair> {
        (
            any::<u64>(),
            ("\\PC{0,16}", "\\PC{0,16}"),
            any::<bool>(),
            proptest::option::of([component(), component(), component()]),
            proptest::option::of(prop_oneof![
                Just(Split::Train),
                Just(Split::Val),
                Just(Split::Test)
            ]),
        )
            .prop_map(|(seed, (a, b), masks_labeled, force_n, split)| {
                let rgb = WORK_SIZE.pixels() * 3;
                let grey = WORK_SIZE.pixels();
                LabeledPair {
                    id: String::new(),
                    source: PairSource::Upload {
                        view_a: a,
                        view_b: b,
                        views: None,
                    },
                    view_a: pixels(seed, rgb, false),
                    view_b: pixels(seed ^ 1, rgb, false),
                    mask_a: pixels(seed ^ 2, grey, true),
                    mask_b: pixels(seed ^ 3, grey, true),
                    masks_labeled,
                    force_n: force_n.map(hnet_units::TipForce::from_newtons),
                    force_origin: LabelOrigin::Typed,
                    no_catheter: [false; 2],
                    split,
                }
            })
    }

    proptest! {
        // Each case encodes and decodes four 224x224 PNGs per pair: few cases.
        #![proptest_config(cases(12))]

        #[test]
        fn exported_pairs_read_back_exactly(mut pairs in proptest::collection::vec(pair(), 1..5)) {
            for (i, pair) in pairs.iter_mut().enumerate() {
                pair.id = format!("pair-{:04}", i + 1);
            }
            let complete: Vec<&LabeledPair> = pairs.iter().filter(|p| p.is_complete()).collect();
            let export = match dataset_zip(&pairs) {
                Ok(export) => export,
                Err(ExportError::NothingComplete) => {
                    prop_assert!(complete.is_empty());
                    return Ok(());
                }
                Err(e) => return Err(TestCaseError::fail(e.to_string())),
            };
            let dir = std::env::temp_dir().join(format!("hnet-studio-prop-export-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            zip::ZipArchive::new(std::io::Cursor::new(&export.zip[..]))
                .unwrap()
                .extract(&dir)
                .unwrap();
            let dataset = hnet_twin::dataset::Dataset::open(&dir.join(DATASET_NAME)).unwrap();
            prop_assert_eq!(dataset.header.samples, complete.len());
            prop_assert_eq!(dataset.rows.len(), complete.len());
            let splits = export_splits(&pairs);
            for row in &dataset.rows {
                let index = pairs.iter().position(|p| p.id == row.id).unwrap();
                let pair = &pairs[index];
                prop_assert_eq!(Some(row.split), splits[index]);
                let want = pair.force_n.unwrap();
                prop_assert_eq!(row.force_n.newtons().map(f32::to_bits), want.newtons().map(f32::to_bits));
                let PairSource::Upload { view_a, view_b, .. } = &pair.source else { unreachable!() };
                prop_assert_eq!(&row.extra[1], &("view_a_file".to_string(), view_a.clone()));
                prop_assert_eq!(&row.extra[2], &("view_b_file".to_string(), view_b.clone()));
                let loaded = dataset.load_pair(row, None).unwrap();
                prop_assert!(loaded.view_a == pair.view_a && loaded.view_b == pair.view_b);
                let mask = |m: &[f32]| m.iter().map(|v| (v * 255.0).round() as u8).collect::<Vec<u8>>();
                prop_assert!(mask(&loaded.mask_a) == pair.mask_a && mask(&loaded.mask_b) == pair.mask_b);
            }
            std::fs::remove_dir_all(dir).ok();
        }
    }
}
