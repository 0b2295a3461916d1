//! The cine on the page's state: loading, playback, window/level, and the force trace over its
//! frames (each frame's estimate made as the force panel's verdict makes it).

use leptos::prelude::*;

use super::{ModelState, Studio};
use crate::browser::{download, now_ms};
use crate::catheter_3d::{FitMasks, PairGeometry, PairMasks, reconstruct_pair};
use crate::cine::CinePlayer;
use crate::cpu_pool::WorkersStatus;
use crate::engine::{Engine, Prediction};
use crate::error_text::with_causes;
use crate::workspace::{PairSource, View};
use futures::StreamExt;
use std::path::Path;

use hnet_twin::model_facts::recorded_name;
use hnet_twin::reconstruction::physics_force::TipForceEstimate;

/// The cine's state: its frames and windows, playback, and the force trace over its frames.
#[derive(Clone, Copy)]
pub struct CineStore {
    /// The DICOM cine, once loaded. Read it with `with`: it holds every frame.
    pub player: RwSignal<Option<CinePlayer>>,
    /// Counts loaded cines, so that a trace of an earlier one stops.
    pub serial: RwSignal<u64>,
    /// Whether the cine plays.
    pub playing: RwSignal<bool>,
    /// The cine's playback timer, while it plays.
    playback: StoredValue<Option<IntervalHandle>>,
    /// Frames traced and frames to trace, while H-Net runs over the cine.
    pub trace_progress: RwSignal<Option<(usize, usize)>>,
    /// The user asked to stop the trace.
    pub trace_cancelled: RwSignal<bool>,
    /// Whether a window/level drag changes both cine planes (else the dragged view's only).
    pub link_windows: RwSignal<bool>,
}

impl CineStore {
    /// No cine loaded.
    pub fn new() -> Self {
        Self {
            player: RwSignal::new(None),
            serial: RwSignal::new(0),
            playing: RwSignal::new(false),
            playback: StoredValue::new(None),
            trace_progress: RwSignal::new(None),
            trace_cancelled: RwSignal::new(false),
            link_windows: RwSignal::new(false),
        }
    }

    /// Whether a cine is loaded.
    pub fn loaded(&self) -> bool {
        self.player.with(Option::is_some)
    }

    /// Stops the trace after the frame in progress.
    pub fn cancel_trace(&self) {
        self.trace_cancelled.set(true);
    }

    /// Pauses the cine.
    pub fn stop_playback(&self) {
        if let Some(handle) = self.playback.try_update_value(Option::take).flatten() {
            handle.clear();
            self.playing.set(false);
        }
    }
}

impl Default for CineStore {
    fn default() -> Self {
        Self::new()
    }
}

impl Studio {
    /// Loads a cine in place of the previous one: playback and any trace stop, its first frame
    /// is shown and H-Net runs on it.
    pub fn load_cine(&self, player: CinePlayer) {
        self.cine.stop_playback();
        self.cine.trace_cancelled.set(true);
        self.cine.serial.update(|s| *s += 1);
        let frames = player.frame_count();
        let notes = player.notes.clone();
        self.cine.player.set(Some(player));
        self.show_cine_frame();
        self.run_model();
        let mut text = format!("cine loaded: {frames} frame pairs");
        if !notes.is_empty() {
            text = format!("{text}. {}", notes.join("; "));
        }
        self.notices.info(text);
    }

    /// Shows the cine's current frame as the draft (with a new id: its pixels follow the
    /// window), without running H-Net.
    pub fn show_cine_frame(&self) {
        let serial = self.pairs.next_draft_serial();
        let pair = self.cine.player.with_untracked(|cine| {
            cine.as_ref()
                .and_then(|c| c.pair(c.frame, format!("cine-{serial}")))
        });
        if pair.is_some() {
            self.replace_draft(pair);
        }
    }

    /// Moves the cine `delta` frames (pausing it), shows that frame and runs H-Net on it.
    pub fn step_cine(&self, delta: isize) {
        self.move_cine(|c| c.step(delta));
    }

    /// Shows cine frame `frame` (pausing the cine) and runs H-Net on it.
    pub fn seek_cine(&self, frame: usize) {
        self.move_cine(|c| c.seek(frame));
    }

    /// Pauses the cine, moves it with `to`, shows the frame and runs H-Net on it.
    fn move_cine(&self, to: impl FnOnce(&mut CinePlayer)) {
        if !self.cine.player.with_untracked(Option::is_some) {
            return;
        }
        self.cine.stop_playback();
        self.cine.player.update(|c| {
            if let Some(c) = c {
                to(c);
            }
        });
        self.show_cine_frame();
        self.run_model();
    }

    /// Plays the cine at its frame rate, looping, or pauses it (and runs H-Net on the frame it
    /// stops at). H-Net does not run on every frame while it plays: trace the force for that.
    pub fn toggle_play(&self) {
        if self.cine.playback.with_value(Option::is_some) {
            self.cine.stop_playback();
            self.run_model();
            return;
        }
        let Some(interval_ms) = self
            .cine
            .player
            .with_untracked(|c| c.as_ref().map(CinePlayer::frame_interval_ms))
        else {
            return;
        };
        let studio = *self;
        let handle = set_interval_with_handle(
            move || {
                studio
                    .cine
                    .player
                    .update(|c| c.iter_mut().for_each(|c| c.step(1)));
                studio.show_cine_frame();
            },
            std::time::Duration::from_micros((interval_ms * 1000.0) as u64),
        );
        match handle {
            Ok(handle) => {
                self.cine.playback.set_value(Some(handle));
                self.cine.playing.set(true);
            }
            Err(e) => self.notices.error(format!("the cine cannot play: {e:?}")),
        }
    }

    /// Changes a plane's window as a drag on its view does (fractions of the view's side) and
    /// shows the frame again; H-Net runs when the drag ends.
    pub fn drag_window(&self, view: View, right: f64, down: f64) {
        let linked = self.cine.link_windows.get_untracked();
        self.cine.player.update(|c| {
            c.iter_mut()
                .for_each(|c| c.drag_window(view, right, down, linked))
        });
        self.show_cine_frame();
    }

    /// Both planes' windows back to the headers' and H-Net on the frame.
    pub fn reset_windows(&self) {
        self.cine
            .player
            .update(|c| c.iter_mut().for_each(CinePlayer::reset_windows));
        self.show_cine_frame();
        self.run_model();
    }

    /// Runs H-Net over every frame of the cine, under the current windows, into its force
    /// trace, each frame's estimate made as the verdict makes it (`Studio::frame_estimate`).
    /// As many frames are in flight as there are CPU workers (one on the page's thread or on
    /// WebGPU), and the trace fills in as each frame is done; the cine keeps playing meanwhile.
    /// The progress shows in [`CineStore::trace_progress`], and [`CineStore::cancel_trace`] stops it
    /// after the frames in progress (what was traced stays). Frames whose view a stopped worker
    /// left are read again by another, and the closing message names them.
    pub fn trace_cine(&self) {
        let ModelState::Ready(engine) = self.network.model.get_untracked() else {
            self.notices
                .error("H-Net is not loaded yet: trace the force once it is");
            return;
        };
        let Some(total) = self
            .cine
            .player
            .with_untracked(|c| c.as_ref().map(CinePlayer::frame_count))
        else {
            return;
        };
        if self.cine.trace_progress.get_untracked().is_some()
            || self.notices.busy.get_untracked().is_some()
        {
            self.notices
                .error("H-Net is busy: trace the force when it is done");
            return;
        }
        let entry = self.network.catheter_entry.get_untracked();
        if !entry.can_read_force() {
            self.notices.error(format!(
                "no tip force to trace with \"Catheter enters from\" set to {}: H-Net's force is \
                 not read for a view read turned (its force head learned catheters that come up \
                 from the bottom). Set it to the bottom, or to find it",
                entry.text()
            ));
            return;
        }
        let serial = self.cine.serial.get_untracked();
        self.cine.player.update(|c| {
            c.iter_mut()
                .for_each(|c| c.start_trace(&recorded_name(Path::new(&engine.weights_name))))
        });
        self.cine.trace_cancelled.set(false);
        self.cine.trace_progress.set(Some((0, total)));
        self.notices
            .busy
            .set(Some(format!("Tracing the tip force over {total} frames…")));
        // Each frame is two views: one frame per worker keeps them all busy while the page
        // joins the last frame's views and fits its rod.
        let in_flight = match self.network.cpu_workers.get_untracked() {
            WorkersStatus::Running { running, .. } => running.max(1),
            _ => 1,
        };
        let studio = *self;
        leptos::task::spawn_local(async move {
            let start = now_ms();
            let same_cine = || studio.cine.serial.get_untracked() == serial;
            let stopped = || studio.cine.trace_cancelled.get_untracked() || !same_cine();
            let engine = &engine;
            let frames = futures::stream::iter(0..total)
                .map(|frame| async move {
                    if stopped() {
                        return (frame, None);
                    }
                    let views = studio.cine.player.with_untracked(|c| {
                        let c = c.as_ref()?;
                        Some((c.rgb(View::A, frame)?, c.rgb(View::B, frame)?))
                    });
                    let Some((a, b)) = views else {
                        return (frame, None);
                    };
                    (frame, Some(engine.infer(&a, &b, entry).await))
                })
                .buffer_unordered(in_flight);
            futures::pin_mut!(frames);
            let mut done = 0;
            // Frames traced, with a force or with why it has none (the force head alone at C-arm
            // angles it was not trained at); under a search, a frame with a view read turned is
            // not traced.
            let mut traced = 0;
            // Why the first traced frame without a force has none.
            let mut withheld: Option<String> = None;
            let mut failure = None;
            // Frames read again after a worker stopped, and why the first one did.
            let mut redone: Vec<usize> = Vec::new();
            let mut redone_why = None;
            while let Some((frame, result)) = frames.next().await {
                match result {
                    None => {}
                    // A frame read turned has no force of H-Net's to trace.
                    Some(Ok(prediction)) if same_cine() => {
                        if let Some(why) = &prediction.redone {
                            redone.push(frame);
                            redone_why.get_or_insert_with(|| why.clone());
                        }
                        if let Some(estimate) = studio.frame_estimate(engine, frame, &prediction) {
                            if let Err(why) = &estimate {
                                withheld.get_or_insert_with(|| why.clone());
                            }
                            studio.cine.player.update(|c| {
                                c.iter_mut()
                                    .for_each(|c| c.record_estimate(frame, estimate.clone()))
                            });
                            traced += 1;
                        }
                        done += 1;
                        studio.cine.trace_progress.set(Some((done, total)));
                    }
                    Some(Ok(_)) => {}
                    Some(Err(e)) => {
                        failure.get_or_insert_with(|| {
                            studio.leave_webgpu_after(engine, &e);
                            format!("H-Net failed on frame {}: {}", frame + 1, with_causes(&e))
                        });
                        // The frames in flight finish; no new one starts.
                        studio.cine.trace_cancelled.set(true);
                    }
                }
            }
            studio.cine.trace_progress.set(None);
            studio.notices.busy.set(None);
            let seconds = (now_ms() - start) / 1000.0;
            let redone_text = redone_why.map(|why| {
                redone.sort_unstable();
                let frames: Vec<String> = redone.iter().map(|f| (f + 1).to_string()).collect();
                format!(
                    ". A CPU worker stopped ({why}) and was replaced: frame{} {} read again",
                    if frames.len() == 1 { "" } else { "s" },
                    frames.join(", ")
                )
            });
            let redone_text = redone_text.unwrap_or_default();
            let without = studio
                .cine
                .player
                .with_untracked(|c| c.as_ref().map_or(0, CinePlayer::frames_without_force));
            // What else the user should know: frames without a force, frames read again.
            let details = match withheld {
                Some(why) => format!(". {without} of them without a force ({why}){redone_text}"),
                None => redone_text,
            };
            match failure {
                Some(text) => studio
                    .notices
                    .error(format!("{text}; {done} of {total} frames traced{details}")),
                None if !same_cine() => {}
                None if done < total => studio.notices.info(format!(
                    "trace stopped: {done} of {total} frames traced in {seconds:.1} s{details}"
                )),
                None if traced < total => studio.notices.info(format!(
                    "tip force traced over {traced} of {total} frames in {seconds:.1} s: the \
                     other {} got no force (a view showed no catheter, or was read \
                     turned){details}",
                    total - traced
                )),
                None => studio.notices.info(format!(
                    "tip force traced over {total} frames in {seconds:.1} s ({:.0} ms per \
                     frame){details}",
                    seconds * 1000.0 / total.max(1) as f64
                )),
            }
            if studio.network.rerun.get_untracked() {
                studio.network.rerun.set(false);
                studio.run_model();
            }
        });
    }

    /// Offers the cine's force trace as a CSV download (`hnet trace`'s format).
    pub fn export_trace(&self) {
        let Some(csv) = self
            .cine
            .player
            .with_untracked(|c| c.as_ref().map(CinePlayer::trace_csv))
        else {
            return;
        };
        match download(crate::cine::TRACE_FILE, csv.as_bytes(), "text/csv") {
            Ok(()) => self
                .notices
                .info(format!("force trace saved as {}", crate::cine::TRACE_FILE)),
            Err(e) => self.notices.error(with_causes(&e)),
        }
    }

    /// Frame `frame`'s tip-force estimate from H-Net's `prediction` of it, as the force panel's
    /// verdict reads a pair: combined with the physics estimate where the rod could be fitted to
    /// H-Net's masks with the frame's C-arms (the twin tab's catheter, the base fitted) and the
    /// weights carry their calibration, else H-Net's force head with its interval (none for
    /// weights without recorded facts), or why there is none where that would be the head alone
    /// on frames unlike those it was trained on (`TrainingDomain::estimate_at`). `None` where
    /// H-Net's force is not read (a view shows no catheter, or was read turned).
    fn frame_estimate(
        &self,
        engine: &Engine,
        frame: usize,
        prediction: &Prediction,
    ) -> Option<Result<TipForceEstimate, String>> {
        let force = prediction.force_n?;
        let Some(combination) = &engine.combination else {
            return Some(Ok(TipForceEstimate::uncalibrated(force)));
        };
        let pair = self
            .cine
            .player
            .with_untracked(|c| c.as_ref()?.pair(frame, format!("trace-{frame}")))?;
        let estimate = |physics| match &engine.domain {
            Some(domain) => domain.estimate_at(force, physics, &pair),
            None => Ok(combination.estimate(force, physics)),
        };
        // Headers without the geometry: the C-arms are the defaults, and the physics estimate
        // would only reflect them (`hnet trace` does the same).
        if let PairSource::Dicom {
            missing_geometry, ..
        } = &pair.source
            && missing_geometry.iter().any(|m| !m.is_empty())
        {
            return Some(estimate(None));
        }
        let controls = self.twin.controls.get_untracked();
        let calibration = self.twin.calibration.get_untracked();
        let physics = PairGeometry::of(&pair, &controls, calibration.as_ref())
            .and_then(|geometry| {
                let predicted = [&prediction.mask_a[..], &prediction.mask_b[..]];
                reconstruct_pair(
                    &geometry,
                    &PairMasks::of(&pair, Some(predicted), FitMasks::Hnet)?,
                )
            })
            .ok()
            .and_then(|catheter| catheter.for_combination());
        Some(estimate(physics))
    }
}
