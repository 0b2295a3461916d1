//! The catheter in 3D on the page's state: the reconstruction of the pair on screen and its rod
//! fit, kept up to date as the pair, its masks or the catheter settings change, and the
//! catheter's calibration from labelled pairs.

use leptos::prelude::*;

use super::Studio;
use crate::catheter_3d::{
    Catheter3d, FitMasks, PairGeometry, PairMasks, pair_views, reconstruct_pair,
};
use crate::catheter_calibration;
use crate::error_text::with_causes;
use crate::storage;
use crate::workspace::Workspace;
use hnet_twin::reconstruction::catalogue::StiffnessCalibration;
use hnet_twin::simulator::carm::Biplane;
use hnet_units::TipForce;

/// The catheter in 3D of one pair, as the page computed it ([`Studio::reconstruct_shown`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CatheterReading {
    /// The pair's id.
    pub id: String,
    /// The masks the rod was asked to be fitted to.
    pub fit_masks: FitMasks,
    /// H-Net's force estimate of the prediction on hand when it was made, newtons (whose masks
    /// it was fitted to, when it was fitted to H-Net's).
    pub prediction_force_n: Option<TipForce>,
    /// Its views (for drawing the C-arms).
    pub views: Biplane,
    /// The catheter and its physics force, or why there is none (with its causes).
    pub result: Result<Catheter3d, String>,
    /// Time of the centrelines, the reconstruction and the rod fit, milliseconds.
    pub millis: f64,
}

impl CatheterReading {
    /// The physics estimate to combine with H-Net's estimate `hnet_n`
    /// ([`Catheter3d::for_combination`]), when the rod was fitted to the masks of the prediction
    /// that gave `hnet_n` (not to an earlier prediction's, of other weights).
    pub fn physics_for(&self, hnet_n: TipForce) -> Option<(TipForce, Option<[f32; 3]>)> {
        if self.prediction_force_n != Some(hnet_n) {
            return None;
        }
        self.result.as_ref().ok()?.for_combination()
    }
}

impl Studio {
    /// Reconstructs the catheter of the pair on screen in 3D and fits the rod to it (the label
    /// masks, else H-Net's, or H-Net's as [`TwinStore::fit_masks`](super::TwinStore::fit_masks) asks), into
    /// [`TwinStore::catheter`](super::TwinStore::catheter). A failure is kept there as its message; nothing else changes.
    pub fn reconstruct_shown(&self) {
        let Some(pair) = self.pairs.shown_untracked() else {
            self.twin.catheter.set(None);
            return;
        };
        let prediction = self.network.predictions.with_untracked(|p| {
            p.get(&pair.id)
                .map(|p| (p.mask_a.clone(), p.mask_b.clone(), p.force_n))
        });
        let controls = self.twin.controls.get_untracked();
        let calibration = self.twin.calibration.get_untracked();
        let choice = self.twin.fit_masks.get_untracked();
        let clock = web_sys::window().and_then(|w| w.performance());
        let now = || clock.as_ref().map_or(0.0, |p| p.now());
        let start = now();
        let result =
            PairGeometry::of(&pair, &controls, calibration.as_ref()).and_then(|geometry| {
                let predicted = prediction.as_ref().map(|(a, b, _)| [&a[..], &b[..]]);
                reconstruct_pair(&geometry, &PairMasks::of(&pair, predicted, choice)?)
            });
        let millis = now() - start;
        self.twin.catheter.set(Some(CatheterReading {
            views: pair_views(&pair),
            id: pair.id,
            fit_masks: choice,
            prediction_force_n: prediction.and_then(|(_, _, force)| force),
            result: result.map_err(|e| with_causes(&e)),
            millis,
        }));
    }

    /// Calibrates the catheter's stiffness from the pairs' measured force labels
    /// ([`crate::catheter_calibration`]); the 3D step and the trace then read every pair with
    /// it. A refusal says why and keeps the previous calibration.
    pub fn calibrate_catheter(&self) {
        let controls = self.twin.controls.get_untracked();
        let outcome = self.pairs.workspace.with_untracked(|ws| {
            self.network.predictions.with_untracked(|predictions| {
                let predicted = |id: &str| {
                    predictions
                        .get(id)
                        .map(|p| [p.mask_a.clone(), p.mask_b.clone()])
                };
                catheter_calibration::calibrate_catheter(&ws.pairs, &predicted, &controls)
            })
        });
        match outcome {
            Ok(outcome) => {
                let mut text = format!(
                    "catheter calibrated: {}",
                    catheter_calibration::describe(&outcome.calibration)
                );
                if !outcome.left_out.is_empty() {
                    text = format!("{text}; left out: {}", outcome.left_out.join("; "));
                }
                self.set_calibration(Some(outcome.calibration));
                self.notices.info(text);
            }
            Err(e) => self.notices.error(with_causes(&e)),
        }
    }

    /// Uses `calibration` (`None`: the stiffness the page assumes) now and on the next visit:
    /// it is kept in the browser. A failed write says so; the calibration still applies to this
    /// visit.
    pub fn set_calibration(&self, calibration: Option<StiffnessCalibration>) {
        self.twin.calibration.set(calibration);
        let studio = *self;
        leptos::task::spawn_local(async move {
            if let Err(e) = storage::save_calibration(calibration.as_ref()).await {
                studio.notices.error(format!(
                    "the catheter calibration applies to this visit only: {}",
                    with_causes(&e)
                ));
            }
        });
    }
}

/// Keeps [`TwinStore::catheter`](super::TwinStore::catheter) up to date: after the pair on screen, its masks, H-Net's masks,
/// the masks the rod is to be fitted to or the twin's catheter settings change (not during a
/// brush stroke), the catheter is reconstructed again, once the changes have paused for a
/// moment (a slider being dragged renders many pairs).
pub fn install_reconstruction(studio: Studio) {
    let serial = StoredValue::new(0u64);
    Effect::new(move |_| {
        let shown = studio.pairs.shown_id();
        studio.network.predictions.track();
        studio.twin.controls.track();
        studio.twin.calibration.track();
        studio.twin.fit_masks.track();
        if studio.pairs.workspace.with(Workspace::is_stroking) {
            return;
        }
        if shown.is_none() {
            studio.twin.catheter.set(None);
            return;
        }
        serial.update_value(|s| *s += 1);
        let mine = serial.get_value();
        set_timeout(
            move || {
                if serial.get_value() == mine {
                    studio.reconstruct_shown();
                }
            },
            std::time::Duration::from_millis(40),
        );
    });
}
