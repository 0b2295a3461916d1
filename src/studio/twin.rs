//! The twin and the catheter in 3D: the live twin's sliders and X-ray background, the catheter
//! (its stiffness calibration), the reconstruction of the pair on screen with its rod fit, and
//! the 3D view's camera.

use leptos::prelude::*;

use super::CatheterReading;
use crate::catheter_3d::FitMasks;
use crate::orbit_camera::OrbitCamera;
use crate::twin_live::{TwinControls, XrayBackground};
use hnet_twin::reconstruction::catalogue::StiffnessCalibration;

/// The twin's and the 3D view's state.
#[derive(Clone, Copy)]
pub struct TwinStore {
    /// The twin's sliders (and the catheter and C-arms the page assumes for every pair).
    pub controls: RwSignal<TwinControls>,
    /// The synthetic X-ray background.
    pub background: RwSignal<XrayBackground>,
    /// The catheter's stiffness calibrated from the pairs' measured force labels
    /// ([`crate::catheter_calibration`]); `None`: the stiffness the page assumes.
    pub calibration: RwSignal<Option<StiffnessCalibration>>,
    /// The catheter in 3D and its physics force, for the pair on screen.
    pub catheter: RwSignal<Option<CatheterReading>>,
    /// Which masks the rod is fitted to.
    pub fit_masks: RwSignal<FitMasks>,
    /// The 3D view's camera (its target and framing follow the catheter).
    pub orbit: RwSignal<OrbitCamera>,
}

impl TwinStore {
    /// The twin's defaults on the phantom background, the nominal catheter, nothing
    /// reconstructed yet.
    pub fn new() -> Self {
        Self {
            controls: RwSignal::new(TwinControls::default()),
            background: RwSignal::new(XrayBackground::phantom()),
            calibration: RwSignal::new(None),
            catheter: RwSignal::new(None),
            fit_masks: RwSignal::new(FitMasks::default()),
            orbit: RwSignal::new(OrbitCamera::default()),
        }
    }
}

impl Default for TwinStore {
    fn default() -> Self {
        Self::new()
    }
}
