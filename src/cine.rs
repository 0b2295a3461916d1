//! A biplane DICOM cine in the page: both planes read from the files the user gives (with
//! [`hnet_dicom`], the reader of `hnet import` and `hnet trace`), each plane's window/level, the
//! frame on screen, any frame as a stereo pair at [`WORK_SIZE`] with the headers' geometry, and
//! H-Net's tip force per frame as a trace, exported in `hnet trace`'s CSV format.
//!
//! Privacy: what is kept is what [`hnet_dicom`] keeps (pixels, geometry, window, frame times) and
//! the file names for the player's caption; pairs made from frames keep no file name, and the
//! trace holds frame numbers, times and forces only.

use hnet_dicom::{
    BiplaneCine, DicomError, PairingError, Plane, PlaneSeries, TracePoint, WindowLevel,
    read_cine_file, trace_csv, twin_push_cine, write_xa,
};
use hnet_twin::dataset::resized;
use hnet_twin::reconstruction::physics_force::TipForceEstimate;
use hnet_twin::simulator::carm::Biplane;
use hnet_twin::simulator::scene::TwinError;

use crate::imaging::WORK_SIZE;
use crate::workspace::{LabeledPair, PairSource, View};

/// Largest DICOM input accepted per plane, bytes (all its files together): a long 1024 x 1024
/// 16-bit cine of about 250 frames.
pub const MAX_PLANE_BYTES: usize = 512 * 1024 * 1024;

/// Frames of the sample cine (1.6 s at 15 frames per second).
pub const SAMPLE_FRAMES: usize = 24;

/// Seed of the sample cine's scene.
pub const SAMPLE_SEED: u64 = 2024;

/// Name of the force trace's CSV download.
pub const TRACE_FILE: &str = "hnet-force-trace.csv";

/// Playback's frame interval when the headers give no frame times, milliseconds (15 frames per
/// second, a common fluoroscopy rate).
pub const DEFAULT_FRAME_MS: f64 = 1000.0 / 15.0;

/// The file names of the sample cine's planes.
pub const SAMPLE_FILES: [&str; 2] = ["twin-cine-plane-a.dcm", "twin-cine-plane-b.dcm"];

/// One file the user gave: its name and bytes.
pub type GivenFile = (String, Vec<u8>);

/// Why a cine could not be loaded. Every message names the file or the series.
#[derive(Debug, thiserror::Error)]
pub enum CineError {
    /// A plane was given no file.
    #[error("plane {plane}: no DICOM file given")]
    NoFiles {
        /// `A` or `B`.
        plane: &'static str,
    },
    /// A plane's files are larger than the page accepts.
    #[error(
        "plane {plane} ({series}): {megabytes} MB of DICOM; the page reads at most {limit} MB \
         per plane (use `hnet trace` or `hnet import` for longer runs)"
    )]
    TooLarge {
        /// `A` or `B`.
        plane: &'static str,
        /// The series' name.
        series: String,
        /// Its size, MB.
        megabytes: usize,
        /// The limit, MB.
        limit: usize,
    },
    /// A file cannot be read (the error names it and says why).
    #[error(transparent)]
    File(#[from] DicomError),
    /// The two planes cannot be paired frame by frame.
    #[error(transparent)]
    Pairing(#[from] PairingError),
    /// The twin could not make the sample cine.
    #[error("the sample cine could not be made")]
    Sample(#[source] TwinError),
}

/// The name a plane's series goes by: its file's name, or its files' count and first name.
fn series_name(files: &[GivenFile]) -> String {
    match files {
        [only] => only.0.clone(),
        [first, ..] => format!("{} files from {}", files.len(), first.0),
        [] => String::new(),
    }
}

/// Reads one plane's files (one multi-frame file, or single frames) into a series; the error
/// names the file or the series.
pub fn read_plane(plane: Plane, files: Vec<GivenFile>) -> Result<PlaneSeries, CineError> {
    let name = plane.name();
    if files.is_empty() {
        return Err(CineError::NoFiles { plane: name });
    }
    let series = series_name(&files);
    let bytes: usize = files.iter().map(|f| f.1.len()).sum();
    if bytes > MAX_PLANE_BYTES {
        return Err(CineError::TooLarge {
            plane: name,
            series,
            megabytes: bytes.div_ceil(1024 * 1024),
            limit: MAX_PLANE_BYTES / (1024 * 1024),
        });
    }
    let read = files
        .iter()
        .map(|(file, bytes)| read_cine_file(file, bytes))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(PlaneSeries::from_files(plane, &series, read)?)
}

/// The twin's sample cine ([`twin_push_cine`]: a catheter pushed against the wall and released,
/// seen by the default biplane) written as two XA files, plane A then plane B.
pub fn sample_files() -> Result<[GivenFile; 2], CineError> {
    let cine = twin_push_cine(WORK_SIZE, SAMPLE_FRAMES, SAMPLE_SEED).map_err(CineError::Sample)?;
    let [a, b] = cine.planes.each_ref().map(write_xa);
    Ok([(SAMPLE_FILES[0].into(), a), (SAMPLE_FILES[1].into(), b)])
}

/// A loaded cine and what the player shows of it.
#[derive(Debug, Clone, PartialEq)]
pub struct CinePlayer {
    /// Both planes and their frame pairs.
    pub cine: BiplaneCine,
    /// Both planes' C-arms at [`WORK_SIZE`].
    pub views: Biplane,
    /// The window of plane A and plane B.
    pub windows: [WindowLevel; 2],
    /// The frame on screen, 0-based.
    pub frame: usize,
    /// Each frame's tip-force estimate (the verdict's: combined where the rod was fitted to
    /// H-Net's masks, else H-Net's force head; with its 90 % intervals where the weights carry
    /// their calibration), or why it has none, once traced.
    pub estimates: Vec<Option<Result<TipForceEstimate, String>>>,
    /// The weights file (its name) the trace was made with.
    pub traced_with: String,
    /// What the user should know: geometry the headers lacked, how frames were paired.
    pub notes: Vec<String>,
}

impl CinePlayer {
    /// Reads plane A's files and plane B's (one multi-frame file, or single frames, each) and
    /// pairs them. Nothing is kept on failure; the error names the file or series.
    pub fn read(plane_a: Vec<GivenFile>, plane_b: Vec<GivenFile>) -> Result<Self, CineError> {
        Self::of_planes(
            read_plane(Plane::A, plane_a)?,
            read_plane(Plane::B, plane_b)?,
        )
    }

    /// Pairs two planes' series frame by frame.
    pub fn of_planes(plane_a: PlaneSeries, plane_b: PlaneSeries) -> Result<Self, CineError> {
        Ok(Self::new(BiplaneCine::pair(plane_a, plane_b)?))
    }

    /// The player of `cine`, on its first frame, each plane under its header's window (else the
    /// first frame's range).
    pub fn new(cine: BiplaneCine) -> Self {
        let at_work_size =
            |plane: Plane| cine.series(plane).geometry.carm.with_image_size(WORK_SIZE);
        Self {
            views: Biplane {
                a: at_work_size(Plane::A),
                b: at_work_size(Plane::B),
            },
            windows: Plane::BOTH.map(|plane| cine.series(plane).initial_window(0)),
            frame: 0,
            estimates: vec![None; cine.frame_count()],
            traced_with: String::new(),
            notes: cine.notes(),
            cine,
        }
    }

    /// Number of frame pairs.
    pub fn frame_count(&self) -> usize {
        self.cine.frame_count()
    }

    /// Frame `frame`'s time after plane A's first frame, seconds, when the headers give it.
    pub fn time_s(&self, frame: usize) -> Option<f64> {
        self.cine.pairing.pairs.get(frame).and_then(|p| p.time_s)
    }

    /// The mean interval between frames, milliseconds: from the frame times, else
    /// [`DEFAULT_FRAME_MS`]. Playback's pace.
    pub fn frame_interval_ms(&self) -> f64 {
        let pairs = &self.cine.pairing.pairs;
        match (
            pairs.first().and_then(|p| p.time_s),
            pairs.last().and_then(|p| p.time_s),
        ) {
            (Some(first), Some(last)) if pairs.len() > 1 && last > first => {
                (last - first) * 1000.0 / (pairs.len() - 1) as f64
            }
            _ => DEFAULT_FRAME_MS,
        }
    }

    /// Shows frame `frame` (clamped to the last).
    pub fn seek(&mut self, frame: usize) {
        self.frame = frame.min(self.frame_count().saturating_sub(1));
    }

    /// Moves `delta` frames, wrapping around at either end (as a cine loop does).
    pub fn step(&mut self, delta: isize) {
        let count = self.frame_count() as isize;
        if count > 0 {
            self.frame = (self.frame as isize + delta).rem_euclid(count) as usize;
        }
    }

    /// The plane shown as `view`.
    fn plane(view: View) -> Plane {
        match view {
            View::A => Plane::A,
            View::B => Plane::B,
        }
    }

    /// Frame `frame` of `view`'s plane under its window, as [`WORK_SIZE`] RGB.
    pub fn rgb(&self, view: View, frame: usize) -> Option<Vec<u8>> {
        let plane = Self::plane(view);
        let grey = self
            .cine
            .grey_frame(plane, frame, self.windows[view_slot(view)])?;
        let size = self.cine.series(plane).frames.size;
        let image = image::GrayImage::from_raw(size.width as u32, size.height as u32, grey)?;
        let image = resized(image.into(), WORK_SIZE);
        Some(image.into_rgb8().into_raw())
    }

    /// Frame `frame` as a stereo pair called `id`, with its time and both planes' geometry.
    pub fn pair(&self, frame: usize, id: String) -> Option<LabeledPair> {
        let source = PairSource::Dicom {
            frame,
            time_s: self.time_s(frame),
            views: self.views,
            missing_geometry: self.cine.planes.each_ref().map(|series| {
                series
                    .geometry
                    .missing
                    .iter()
                    .map(|tag| tag.keyword().to_string())
                    .collect()
            }),
        };
        Some(LabeledPair::new(
            id,
            source,
            self.rgb(View::A, frame)?,
            self.rgb(View::B, frame)?,
        ))
    }

    /// Changes `view`'s window as a drag on it does: `right` and `down` are the drag's distance
    /// as fractions of the view's side. Right widens the window (less contrast), down raises its
    /// centre (a darker image), each by the frame's value range per whole side.
    ///
    /// With `linked`, both planes' windows change with the drag, each by its own frame's range
    /// (as a viewer's linked planes do); otherwise only `view`'s plane.
    pub fn drag_window(&mut self, view: View, right: f64, down: f64, linked: bool) {
        let views = if linked {
            vec![View::A, View::B]
        } else {
            vec![view]
        };
        for view in views {
            let plane = Self::plane(view);
            let (min, max) = self
                .cine
                .series(plane)
                .frames
                .range(self.frame)
                .unwrap_or((0.0, 255.0));
            let span = (max - min).max(1.0);
            let slot = view_slot(view);
            self.windows[slot] = self.windows[slot].dragged(down * span, right * span);
        }
    }

    /// Each plane's window back to its header's (else the frame's range).
    pub fn reset_windows(&mut self) {
        self.windows = Plane::BOTH.map(|plane| self.cine.series(plane).initial_window(self.frame));
    }

    /// Records frame `frame`'s tip-force estimate, or why it has none.
    pub fn record_estimate(&mut self, frame: usize, estimate: Result<TipForceEstimate, String>) {
        if let Some(slot) = self.estimates.get_mut(frame) {
            *slot = Some(estimate);
        }
    }

    /// Starts a new trace with the weights file `weights` (its name): every frame's estimate is
    /// forgotten.
    pub fn start_trace(&mut self, weights: &str) {
        self.estimates.iter_mut().for_each(|f| *f = None);
        self.traced_with = weights.to_string();
    }

    /// The traced frames, in order: each with its estimate, or why it has none.
    pub fn trace(&self) -> Vec<TracePoint> {
        self.estimates
            .iter()
            .enumerate()
            .filter_map(|(frame, estimate)| {
                estimate.as_ref().map(|estimate| TracePoint {
                    frame,
                    time_s: self.time_s(frame),
                    estimate: estimate.clone(),
                })
            })
            .collect()
    }

    /// The force trace as CSV (`hnet trace`'s format, naming the weights that traced it): the
    /// traced frames, those without a force with why.
    pub fn trace_csv(&self) -> String {
        trace_csv(&self.trace(), &self.traced_with)
    }

    /// Traced frames without a force (each with why).
    pub fn frames_without_force(&self) -> usize {
        self.estimates
            .iter()
            .flatten()
            .filter(|e| e.is_err())
            .count()
    }

    /// The first frame not yet traced at or after `from`, wrapping around, if any.
    pub fn next_untraced(&self, from: usize) -> Option<usize> {
        let count = self.frame_count();
        (0..count)
            .map(|i| (from + i) % count)
            .find(|&frame| self.estimates[frame].is_none())
    }
}

/// Index of `view` in per-view arrays.
fn view_slot(view: View) -> usize {
    match view {
        View::A => 0,
        View::B => 1,
    }
}

// Native only: the export test reads the zip with the `zip` crate, a native dev-dependency.
#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;
    use hnet_dicom::{twin_cine, write_xa};
    use hnet_units::{ImageSize, TipForce};

    fn small_cine(frames: usize) -> [GivenFile; 2] {
        let cine = twin_cine(ImageSize::square(32), frames, 5).unwrap();
        let [a, b] = cine.planes.each_ref().map(write_xa);
        [("a.dcm".into(), a), ("b.dcm".into(), b)]
    }

    #[test]
    fn a_cine_gives_pairs_at_the_working_size_with_its_headers_geometry() {
        let [a, b] = small_cine(3);
        let player = CinePlayer::read(vec![a], vec![b]).unwrap();
        assert_eq!(player.frame_count(), 3);
        assert!(player.notes.is_empty(), "{:?}", player.notes);
        let views = hnet_dicom::cine_views(ImageSize::square(32));
        assert!((player.views.a.primary_deg - views.a.primary_deg).abs() < 1e-9);
        assert!((player.views.b.secondary_deg - views.b.secondary_deg).abs() < 1e-9);
        assert_eq!(player.views.a.image_size, WORK_SIZE);
        let pair = player.pair(2, "f3".into()).unwrap();
        assert_eq!(pair.view_a.len(), WORK_SIZE.pixels() * 3);
        let PairSource::Dicom {
            frame,
            time_s,
            views,
            missing_geometry,
        } = &pair.source
        else {
            panic!("{:?}", pair.source);
        };
        assert_eq!((*frame, *views), (2, player.views));
        assert!((time_s.unwrap() - 2.0 * 0.0667).abs() < 1e-9);
        assert_eq!(missing_geometry, &[Vec::<String>::new(), Vec::new()]);
        assert!(player.pair(3, "none".into()).is_none());
        assert!((player.frame_interval_ms() - 66.7).abs() < 1e-9);
    }

    #[test]
    fn dragging_changes_one_planes_window_or_both_linked_and_their_pixels() {
        let [a, b] = small_cine(2);
        let mut player = CinePlayer::read(vec![a], vec![b]).unwrap();
        let before = player.rgb(View::A, 0).unwrap();
        let other = player.rgb(View::B, 0).unwrap();
        let window = player.windows[0];
        player.drag_window(View::A, -0.5, 0.25, false);
        assert!(player.windows[0].width < window.width);
        assert!(player.windows[0].centre > window.centre);
        assert_ne!(player.rgb(View::A, 0).unwrap(), before);
        assert_eq!(player.rgb(View::B, 0).unwrap(), other);
        player.reset_windows();
        assert_eq!(player.windows[0], window);
        // Linked, a drag on view B changes both planes.
        let window_b = player.windows[1];
        player.drag_window(View::B, -0.5, 0.25, true);
        assert!(player.windows[0].width < window.width && player.windows[1].width < window_b.width);
        assert_ne!(player.rgb(View::A, 0).unwrap(), before);
        assert_ne!(player.rgb(View::B, 0).unwrap(), other);
    }

    #[test]
    fn the_trace_holds_estimated_frames_in_hnet_traces_format() {
        let [a, b] = small_cine(3);
        let mut player = CinePlayer::read(vec![a], vec![b]).unwrap();
        assert_eq!(player.next_untraced(1), Some(1));
        player.start_trace("hnet-cpu.bpk");
        player.record_estimate(
            1,
            Ok(TipForceEstimate::uncalibrated(TipForce::new(0.1, 0.0, 0.0))),
        );
        let combination = crate::force_reading::tests::bench_domain().combination;
        player.record_estimate(
            0,
            Ok(combination.estimate(TipForce::new(0.0, 0.0, 0.2), None)),
        );
        assert_eq!(player.next_untraced(1), Some(2));
        // A frame without a force is traced, with why.
        player.record_estimate(2, Err("why".into()));
        assert_eq!(player.next_untraced(1), None);
        assert_eq!(player.frames_without_force(), 1);
        assert_eq!(
            player.trace_csv(),
            "frame,time_s,fx_n,fy_n,fz_n,magnitude_n,fx_90_n,fy_90_n,fz_90_n,estimator,weights,note\n\
             1,0.0000,0.0000,0.0000,0.2000,0.2000,0.1217,0.1230,0.1133,H-Net force head,\"hnet-cpu.bpk\",\n\
             2,0.0667,0.1000,0.0000,0.0000,0.1000,,,,H-Net force head,\"hnet-cpu.bpk\",\n\
             3,0.1334,,,,,,,,,\"hnet-cpu.bpk\",\"why\"\n"
        );
        player.step(-1);
        assert_eq!(player.frame, 2);
        player.step(1);
        assert_eq!(player.frame, 0);
        player.start_trace("other.bpk");
        assert!(player.trace().is_empty());
    }

    #[test]
    fn a_kept_frame_exports_its_geometry_and_time_but_no_file_name() {
        let [a, b] = small_cine(2);
        let player = CinePlayer::read(vec![a], vec![b]).unwrap();
        let mut ws = crate::workspace::Workspace::default();
        ws.add(player.pair(1, ws.next_id()).unwrap());
        let id = ws.pairs[0].id.clone();
        let masks = [0, 1].map(|_| vec![0; WORK_SIZE.pixels()]);
        ws.set_masks(masks);
        // The small cine shows no catheter: its empty masks are labels only once said so.
        for view in crate::workspace::View::BOTH {
            ws.mark_no_catheter(&id, view, true);
        }
        ws.set_force(
            &id,
            Some((
                TipForce::new(0.1, 0.0, 0.0),
                hnet_twin::dataset::label_origin::LabelOrigin::Typed,
            )),
        );
        let export = crate::export::dataset_zip(&ws.pairs).unwrap();
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&export.zip[..])).unwrap();
        let mut text = |name: &str| {
            let mut file = zip.by_name(name).unwrap();
            let mut text = String::new();
            std::io::Read::read_to_string(&mut file, &mut text).unwrap();
            text
        };
        let manifest = text("hnet-studio-labels/manifest.csv");
        assert!(manifest.contains("source,frame,time_s"), "{manifest}");
        assert!(manifest.contains(",dicom,2,0.0667"), "{manifest}");
        let record = text(&format!("hnet-studio-labels/samples/{id}.json"));
        let record: serde_json::Value = serde_json::from_str(&record).unwrap();
        let views = &record["record"]["views"];
        let primary = views["b"]["carm"]["primary_deg"]
            .as_f64()
            .unwrap_or_else(|| panic!("{record}"));
        assert!(
            (primary - hnet_dicom::cine_views(ImageSize::square(32)).b.primary_deg).abs() < 1e-9
        );
        assert_eq!(views["a"]["missing_geometry"], serde_json::json!([]));
        assert!(!record.to_string().contains("a.dcm"), "{record}");
        // Its force reading names what differs from the bundled weights' data.
        let departures = crate::force_reading::tests::bench_domain().departures(&ws.pairs[0]);
        assert!(departures[0].contains("not the twin's"), "{departures:?}");
        assert!(
            departures
                .iter()
                .any(|d| d.starts_with("view A at -20°/+10°")),
            "{departures:?}"
        );
    }

    #[test]
    fn bad_planes_are_named_and_nothing_is_loaded() {
        let [a, b] = small_cine(3);
        let short = small_cine(2)[1].clone();
        let no_files = CinePlayer::read(vec![a.clone()], vec![]).unwrap_err();
        assert_eq!(no_files.to_string(), "plane B: no DICOM file given");
        let counts = CinePlayer::read(vec![a.clone()], vec![short]).unwrap_err();
        assert!(counts.to_string().contains("has 3 frames"), "{counts}");
        let text = ("notes.txt".to_string(), b"not a cine".to_vec());
        let not_dicom = CinePlayer::read(vec![text], vec![b.clone()]).unwrap_err();
        assert!(
            not_dicom
                .to_string()
                .starts_with("notes.txt: not a DICOM file"),
            "{not_dicom}"
        );
        let cut = ("cut.dcm".to_string(), a.1[..a.1.len() - 500].to_vec());
        let truncated = CinePlayer::read(vec![a], vec![cut]).unwrap_err();
        assert!(
            truncated.to_string().starts_with("cut.dcm: "),
            "{truncated}"
        );
    }
}
