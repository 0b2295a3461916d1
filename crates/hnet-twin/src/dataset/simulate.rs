//! Generating a whole simulated dataset: samples in parallel, written crash-safely, resumable.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use hnet_units::ImageSize;
use rand::RngExt;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::dataset::shard::Shard;
use crate::dataset::{
    Dataset, DatasetError, DatasetHeader, DatasetWriter, ImageRef, ManifestRow, Split,
    assign_splits, sample_files,
};
use crate::reconstruction::catalogue::CatalogueCatheter;
use crate::reconstruction::physics_force::PhysicsSetup;
use crate::simulator::carm::{CArm, CameraMatrix, HeaderError};
use crate::simulator::off_bench::OffBench;
use crate::simulator::rod::RodConfig;
use crate::simulator::scene::{
    Backgrounds, NominalBase, SceneParams, SceneSampling, StereoSample, TwinConfig, generate,
    sample_rng,
};
use crate::simulator::synthetic_xray::PatchLayout;
use crate::vec3::Vec3;

/// The id of sample `index`.
pub fn sample_id(index: u64) -> String {
    format!("{index:06}")
}

/// The manifest row of a simulated sample.
pub fn manifest_row(sample: &StereoSample, split: Split) -> ManifestRow {
    let p = &sample.params;
    let background = |i: usize| {
        sample.views[i]
            .background
            .as_ref()
            .map(|(name, _)| name.clone())
            .unwrap_or_default()
    };
    let number = |v: f64| v.to_string();
    ManifestRow {
        id: sample_id(sample.index),
        split,
        force_n: p.tip_force_n,
        extra: vec![
            (
                "force_magnitude_n".into(),
                number(Vec3::from(p.tip_force_n).norm()),
            ),
            (
                "bending_stiffness_n_m2".into(),
                number(p.bending_stiffness_n_m2),
            ),
            ("length_mm".into(), number(p.length_mm)),
            ("precurvature_per_mm".into(), number(p.precurvature_per_mm)),
            ("base_x_mm".into(), number(p.base_position_mm[0])),
            ("base_y_mm".into(), number(p.base_position_mm[1])),
            ("base_z_mm".into(), number(p.base_position_mm[2])),
            ("base_tilt_deg".into(), number(p.base_tilt_deg)),
            ("base_azimuth_deg".into(), number(p.base_azimuth_deg)),
            ("base_roll_deg".into(), number(p.base_roll_deg)),
            ("background_a".into(), background(0)),
            ("background_b".into(), background(1)),
        ]
        .into_iter()
        .chain(p.plate.iter().flat_map(|contact| {
            [
                ("plate_tilt_deg".into(), number(contact.tilt_deg)),
                (
                    "plate_tilt_azimuth_deg".into(),
                    number(contact.tilt_azimuth_deg),
                ),
                ("plate_press_mm".into(), number(contact.press_mm)),
                ("plate_slide_mm".into(), number(contact.slide_mm)),
                (
                    "plate_slide_azimuth_deg".into(),
                    number(contact.slide_azimuth_deg),
                ),
                ("contact".into(), contact.state.name().to_string()),
            ]
        }))
        .collect(),
    }
}

/// The files of a simulated sample: images, masks and its record (scene, 3D centreline in mm,
/// both views' C-arm settings and camera matrices, background layouts).
pub fn simulated_sample_files(
    config: &TwinConfig,
    sample: &StereoSample,
    split: Split,
) -> Vec<(String, Vec<u8>)> {
    let size = config.image_size;
    let view = |i: usize| ImageRef {
        width: size.width,
        height: size.height,
        channels: sample.views[i].pixels.channels(),
        pixels: sample.views[i].pixels.bytes(),
    };
    let mask = |i: usize| ImageRef {
        width: size.width,
        height: size.height,
        channels: 1,
        pixels: &sample.views[i].mask,
    };
    let record = SampleRecord {
        scene: sample.params,
        rod: sample.params.rod(&config.rod).0,
        centreline_mm: sample.shape.points_mm.clone(),
        arc_mm: sample.shape.arc_mm.clone(),
        views: [0, 1].map(|i| ViewRecord {
            carm: *config.views.views()[i],
            camera_matrix: sample.views[i].camera,
            background: sample.views[i].background.clone(),
        }),
    };
    let record = serde_json::to_value(&record).expect("a sample record is plain data");
    sample_files(
        &manifest_row(sample, split),
        [view(0), view(1), mask(0), mask(1)],
        &record,
    )
}

/// The record (`record.json`) of a simulated pair: everything needed to rebuild it, to
/// reconstruct it in 3D and to check a force estimate against physics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleRecord {
    /// The scene's random draws.
    pub scene: SceneParams,
    /// The rod as solved (the twin's rod with the scene's length, stiffness and pre-curvature).
    pub rod: RodConfig,
    /// The solved centreline from the clamped base to the tip, world frame, mm.
    pub centreline_mm: Vec<Vec3>,
    /// Arc length of each centreline point from the base, mm.
    pub arc_mm: Vec<f64>,
    /// View A and view B.
    pub views: [ViewRecord; 2],
}

impl SampleRecord {
    /// What [`crate::reconstruction::physics_force::physics_estimate`] needs to read this pair's masks at `size`
    /// (the dataset's size, or the size they were resized to, in either direction): both views'
    /// cameras scaled to that size, and the rod and base exactly as simulated.
    pub fn physics_setup(&self, size: ImageSize) -> PhysicsSetup {
        let (rod, base) = self.scene.rod(&self.rod);
        PhysicsSetup::new(
            self.views
                .each_ref()
                .map(|view| scale_camera(view.camera_matrix, view.carm.image_size, size)),
            rod,
            base,
        )
    }

    /// What a blind estimate reads this pair's masks at `size` with ([`PhysicsSetup::blind`]):
    /// the cameras rebuilt from the C-arms' settings alone (what a DICOM header gives:
    /// angles, distances, pixel spacing), the catalogue's `catheter` and the `nominal_base`.
    /// Nothing of the pair's own scene.
    pub fn blind_setup(
        &self,
        size: ImageSize,
        catheter: &CatalogueCatheter,
        nominal_base: &NominalBase,
    ) -> PhysicsSetup {
        self.blind_setup_misread(size, catheter, nominal_base, &HeaderError::default(), 0)
    }

    /// [`Self::blind_setup`] with the C-arms read as a header off by `error` would record them
    /// (the draw seeded by `seed`, one per pair).
    pub fn blind_setup_misread(
        &self,
        size: ImageSize,
        catheter: &CatalogueCatheter,
        nominal_base: &NominalBase,
        error: &HeaderError,
        seed: u64,
    ) -> PhysicsSetup {
        let mut rng = sample_rng(seed, 0);
        let carms = self
            .views
            .each_ref()
            .map(|view| error.misread(&view.carm, || rng.random::<f64>()));
        let mut cameras = blind_cameras(&carms, size);
        if error.isocentre_mm > 0.0 {
            let mut off = || error.isocentre_mm * (2.0 * rng.random::<f64>() - 1.0);
            let offset = [off(), off(), off()];
            cameras[1] = HeaderError::with_isocentre_offset(cameras[1], offset);
        }
        PhysicsSetup::blind(cameras, catheter, nominal_base)
    }

    /// The tip of the solved centreline, mm.
    pub fn tip_mm(&self) -> Option<Vec3> {
        self.centreline_mm.last().copied()
    }
}

/// `camera` (for images of `from`) for images of `to`: pixel coordinates scale with the image,
/// `u' = u·W'/W`, `v' = v·H'/H`.
pub fn scale_camera(camera: CameraMatrix, from: ImageSize, to: ImageSize) -> CameraMatrix {
    let scale = [
        to.width as f64 / from.width as f64,
        to.height as f64 / from.height as f64,
        1.0,
    ];
    let mut camera = camera;
    for (row, s) in camera.iter_mut().zip(scale) {
        row.iter_mut().for_each(|v| *v *= s);
    }
    camera
}

/// The cameras of `carms` for images of `size`, rebuilt from the C-arms' settings alone (what a
/// DICOM header gives: angles, distances, pixel spacing), never from a recorded matrix.
pub fn blind_cameras(carms: &[CArm; 2], size: ImageSize) -> [CameraMatrix; 2] {
    carms
        .each_ref()
        .map(|carm| scale_camera(carm.camera_matrix(), carm.image_size, size))
}

/// One view of a [`SampleRecord`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewRecord {
    /// The C-arm (or bench camera) settings.
    pub carm: CArm,
    /// Its projection matrix `K [R | t]`: world mm to pixels.
    pub camera_matrix: CameraMatrix,
    /// The background radiograph's name and layout (X-ray modalities).
    pub background: Option<(String, PatchLayout)>,
}

/// Reads the record of the simulated pair `id` of `dataset`.
pub fn read_sample_record(dataset: &Dataset, id: &str) -> Result<SampleRecord, DatasetError> {
    let path = dataset.record_file(id);
    let bytes =
        std::fs::read(&path).map_err(|e| DatasetError::caused_by(&path, "cannot be read", e))?;
    /// The file holds the manifest row beside the record ([`sample_files`]).
    #[derive(Deserialize)]
    struct File {
        record: SampleRecord,
    }
    serde_json::from_slice::<File>(&bytes)
        .map(|file| file.record)
        .map_err(|e| {
            DatasetError::caused_by(
                &path,
                "is not the record of a simulated pair (made by `hnet simulate`)",
                e,
            )
        })
}

/// The two C-arms of pair `id` as its record gives them (a simulated pair's, or a DICOM import's
/// header geometry): what a blind estimate may read of a pair.
pub fn read_pair_carms(dataset: &Dataset, id: &str) -> Result<[CArm; 2], DatasetError> {
    let path = dataset.record_file(id);
    let bytes =
        std::fs::read(&path).map_err(|e| DatasetError::caused_by(&path, "cannot be read", e))?;
    #[derive(Deserialize)]
    struct View {
        carm: CArm,
    }
    #[derive(Deserialize)]
    struct Record {
        views: [View; 2],
    }
    #[derive(Deserialize)]
    struct File {
        record: Record,
    }
    serde_json::from_slice::<File>(&bytes)
        .map(|file| file.record.views.map(|view| view.carm))
        .map_err(|e| DatasetError::caused_by(&path, "does not record the pair's two C-arms", e))
}

/// The base pose a blind estimate starts from for pairs of `dataset`: the nominal pose of the
/// scenes it was simulated with ([`crate::simulator::scene::SceneSampling::nominal_base`]), or of the
/// twin's bench for other datasets.
pub fn nominal_base(dataset: &Dataset) -> NominalBase {
    dataset
        .header
        .source
        .get("twin")
        .and_then(|twin| twin.get("scene"))
        .and_then(|scene| serde_json::from_value::<SceneSampling>(scene.clone()).ok())
        .unwrap_or_default()
        .nominal_base()
}

/// What a generation did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SimulationReport {
    /// Samples generated by this run.
    pub generated: usize,
    /// Samples found complete from an earlier run.
    pub resumed: usize,
    /// Scene draws of this run dropped because their rod or contact could not be solved (each
    /// pair was drawn again, from its own generator, so that the dataset stays complete).
    pub dropped_draws: usize,
}

/// Why a generation stopped.
#[derive(Debug, thiserror::Error)]
pub enum SimulationError {
    /// Writing the dataset failed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// A sample could not be made.
    #[error(transparent)]
    Twin(#[from] crate::simulator::scene::TwinError),
}

/// Generates `samples` stereo pairs into `out` (or completes an interrupted generation there).
/// `progress` is called with the number of finished samples (including resumed ones).
pub fn simulate_dataset(
    config: &TwinConfig,
    backgrounds: &Backgrounds,
    background_names: &[String],
    samples: usize,
    seed: u64,
    out: &Path,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SimulationReport, SimulationError> {
    let part = Part::whole(samples, seed);
    simulate_dataset_part(config, backgrounds, background_names, part, out, progress)
}

/// Which pairs a run writes: part `shard` of a simulation of `samples` pairs seeded `seed`
/// ([`crate::dataset::shard`]: the parts' union, merged, is byte for byte the whole dataset).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Part {
    /// Pairs of the whole simulation.
    pub samples: usize,
    /// Its seed.
    pub seed: u64,
    /// Which part this run writes.
    pub shard: Shard,
}

impl Part {
    /// The whole simulation.
    pub fn whole(samples: usize, seed: u64) -> Self {
        Self {
            samples,
            seed,
            shard: Shard::WHOLE,
        }
    }
}

/// [`simulate_dataset`]'s `part` of its pairs.
pub fn simulate_dataset_part(
    config: &TwinConfig,
    backgrounds: &Backgrounds,
    background_names: &[String],
    part: Part,
    out: &Path,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SimulationReport, SimulationError> {
    let source = header_source(config, background_names, part.seed, None);
    write_samples(config, source, part, out, progress, &|index| {
        Ok((
            config.clone(),
            generate(config, backgrounds, part.seed, index)?,
        ))
    })
}

/// Generates `part` of a simulation off the bench ([`OffBench`]: varied catheters and poses,
/// the page's C-arm angle ranges, phantom or radiographs) into `out`, each pair's record holding
/// its own views. The header marks the dataset `"views": "off-bench"`: its `twin` settings give
/// the look and the scenes drawn ([`OffBench::twin`], what a blind estimate's nominal base is
/// read from: [`nominal_base`]), not the views.
pub fn simulate_off_bench_dataset(
    off_bench: &OffBench,
    background_names: &[String],
    part: Part,
    out: &Path,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SimulationReport, SimulationError> {
    let twin = off_bench.twin();
    let source = header_source(twin, background_names, part.seed, Some(OFF_BENCH_VIEWS));
    write_samples(twin, source, part, out, progress, &|index| {
        Ok(off_bench.generate(part.seed, index)?)
    })
}

/// What a simulated dataset's header records of its making (`source` in `dataset.json`):
/// generator, version, seed, backgrounds, twin settings, and `views` when they vary per pair.
fn header_source(
    twin: &TwinConfig,
    background_names: &[String],
    seed: u64,
    views: Option<&str>,
) -> serde_json::Value {
    let mut source = json!({
        "generator": "hnet-twin",
        "version": env!("CARGO_PKG_VERSION"),
        "seed": seed,
        "backgrounds": background_names,
        "twin": twin,
    });
    if let Some(views) = views {
        source["views"] = views.into();
    }
    source
}

/// The header's `views` value of an off-bench dataset.
pub const OFF_BENCH_VIEWS: &str = "off-bench";

/// Writes the samples `make` generates (with the twin settings each was made with), in parallel,
/// crash-safely, skipping those already complete.
fn write_samples(
    config: &TwinConfig,
    source: serde_json::Value,
    part: Part,
    out: &Path,
    progress: &(dyn Fn(usize) + Sync),
    make: &(dyn Fn(u64) -> Result<(TwinConfig, StereoSample), SimulationError> + Sync),
) -> Result<SimulationReport, SimulationError> {
    let whole = DatasetHeader::new(config.image_size, part.samples, source);
    let header = part.shard.header(&whole);
    let writer = DatasetWriter::create_or_resume(out, &header)?;
    // Splits are drawn over every pair of the whole simulation, so that each part's pairs get
    // the splits they have in it.
    let splits = assign_splits(part.samples, part.seed);
    let range = part.shard.range(part.samples);
    let pending: Vec<u64> = range
        .clone()
        .filter(|&i| !writer.has_sample(&sample_id(i)))
        .collect();
    let resumed = (range.end - range.start) as usize - pending.len();
    let done = AtomicUsize::new(resumed);
    let dropped = AtomicUsize::new(0);
    progress(resumed);
    pending.par_iter().try_for_each(|&index| {
        let (twin, sample) = make(index)?;
        dropped.fetch_add(sample.dropped_draws, Ordering::Relaxed);
        let files = simulated_sample_files(&twin, &sample, splits[index as usize]);
        writer.write_sample(&sample_id(index), &files)?;
        progress(done.fetch_add(1, Ordering::Relaxed) + 1);
        Ok::<(), SimulationError>(())
    })?;
    writer.finish()?;
    Ok(SimulationReport {
        generated: pending.len(),
        resumed,
        dropped_draws: dropped.into_inner(),
    })
}
