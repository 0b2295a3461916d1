//! From a stereo pair's two masks to the catheter in 3D and its physics-checked tip force, in one
//! call that `hnet eval`, the page and the tests share: a centreline in each view
//! ([`crate::centreline`]), their epipolar matching and triangulation
//! ([`crate::reconstruction`]), and the twin's rod fitted to the result ([`crate::rod_fit`]).

use crate::carm::CameraMatrix;
use crate::centreline::{
    Centreline, CentrelineError, CentrelineSettings, Mask, extract_centreline,
};
use crate::reconstruction::{
    Reconstruction, ReconstructionError, ReconstructionSettings, proximal_hint_px, reconstruct,
};
use crate::rod::{RodBase, RodConfig};
use crate::rod_fit::{RodFit, RodFitError, RodFitSettings, fit_rod_to_reconstruction};

/// What the masks are read with: both views' cameras, the catheter as the rod model knows it,
/// and how each step works.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicsSetup {
    /// Projection matrices of view A and view B at the masks' size (world mm to pixels).
    pub cameras: [CameraMatrix; 2],
    /// The catheter's flexible section (length, stiffness, pre-curvature).
    pub rod: RodConfig,
    /// Where and how it is clamped (exact for twin pairs; fit it with
    /// [`RodFitSettings::fit_base_position`] when it is only roughly known).
    pub base: RodBase,
    /// Centreline extraction (its proximal hint is set from the base for each view).
    pub centreline: CentrelineSettings,
    /// Matching and triangulation.
    pub reconstruction: ReconstructionSettings,
    /// What is fitted.
    pub fit: RodFitSettings,
}

impl PhysicsSetup {
    /// The default settings of every step for these cameras and this catheter.
    pub fn new(cameras: [CameraMatrix; 2], rod: RodConfig, base: RodBase) -> Self {
        Self {
            cameras,
            rod,
            base,
            centreline: CentrelineSettings::default(),
            reconstruction: ReconstructionSettings::default(),
            fit: RodFitSettings::default(),
        }
    }
}

/// The catheter in 3D and the force of the rod that fits it.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicsEstimate {
    /// The centreline of view A and of view B, pixels.
    pub centrelines: [Centreline; 2],
    /// The triangulated 3D centreline, mm.
    pub reconstruction: Reconstruction,
    /// The fitted rod: its tip force (N), shape and distance from the reconstruction.
    pub fit: RodFit,
}

/// Which step could not be done, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// A mask gives no centreline (empty, several blobs, not a tube, too short).
    #[error(transparent)]
    Centreline(#[from] CentrelineError),
    /// The two centrelines cannot be matched in 3D.
    #[error(transparent)]
    Reconstruction(#[from] ReconstructionError),
    /// No rod fits the reconstruction.
    #[error(transparent)]
    Fit(#[from] RodFitError),
}

impl PhysicsError {
    /// A short name of the failing step (`centreline`, `reconstruction`, `fit`), for counts.
    pub fn step(&self) -> &'static str {
        match self {
            Self::Centreline(_) => "centreline",
            Self::Reconstruction(_) => "reconstruction",
            Self::Fit(_) => "fit",
        }
    }
}

/// Reconstructs the catheter of `masks` (view A, view B) in 3D and fits the rod to it.
pub fn physics_estimate(
    masks: [Mask<'_>; 2],
    setup: &PhysicsSetup,
) -> Result<PhysicsEstimate, PhysicsError> {
    let [mask_a, mask_b] = masks;
    let centreline = |mask: &Mask<'_>, view: usize, name: &str| {
        let settings = CentrelineSettings {
            proximal_hint_px: proximal_hint_px(&setup.cameras[view], &setup.base),
            ..setup.centreline.clone()
        };
        extract_centreline(mask, name, &settings)
    };
    let centrelines = [centreline(&mask_a, 0, "A")?, centreline(&mask_b, 1, "B")?];
    let reconstruction = reconstruct(
        &centrelines[0],
        &setup.cameras[0],
        &centrelines[1],
        &setup.cameras[1],
        &setup.reconstruction,
    )?;
    let fit = fit_rod_to_reconstruction(&setup.rod, &setup.base, &reconstruction, &setup.fit)?;
    Ok(PhysicsEstimate {
        centrelines,
        reconstruction,
        fit,
    })
}

/// The tip force combined from a network's estimate `network_n` and the physics estimate
/// `physics_n` of the same pair (its rod fitted to the network's masks), newtons: Fx and Fy from
/// the physics estimate, Fz the mean of both.
///
/// Measured on fresh bench pairs with the rod fitted to the network's own masks, the exact base
/// and the known catheter (docs/results.md, "The combined estimate"): across the catheter the
/// physics estimate is far better than H-Net's head (R² 0.90-0.97 against 0.63-0.69 on x and y,
/// three seeds); along it both are coarse (R² 0.49-0.51 for the head, 0.42-0.71 for physics),
/// but their Fz errors are uncorrelated (correlation within ±0.05 for three seeds, on bench and
/// radiograph backgrounds), so their mean has less error variance than either (half, when the
/// two are equal): Fz R² 0.74-0.80 on the bench.
pub fn combined_force_n(network_n: [f32; 3], physics_n: [f32; 3]) -> [f32; 3] {
    [
        physics_n[0],
        physics_n[1],
        (network_n[2] + physics_n[2]) / 2.0,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reconstruction::tests::bench_sample;

    #[test]
    fn the_combined_force_takes_x_and_y_from_physics_and_averages_z() {
        assert_eq!(
            combined_force_n([0.3, -0.2, -0.1], [0.1, 0.05, -0.3]),
            [0.1, 0.05, -0.2]
        );
    }

    #[test]
    fn a_twin_pair_gives_its_force_back_and_an_empty_mask_is_named() {
        let (config, sample) = bench_sample(128, 11, 0);
        let (rod, base) = sample.params.rod(&config.rod);
        let setup = PhysicsSetup::new(
            [
                config.views.a.camera_matrix(),
                config.views.b.camera_matrix(),
            ],
            rod,
            base,
        );
        let mask = |i: usize| Mask::coverage8(128, 128, &sample.views[i].mask);
        let estimate = physics_estimate([mask(0), mask(1)], &setup).unwrap();
        let error = (estimate.fit.force_n - sample.params.tip_force_n).norm();
        assert!(error < 0.03, "force off by {error} N");

        let empty = vec![0u8; 128 * 128];
        let err =
            physics_estimate([mask(0), Mask::coverage8(128, 128, &empty)], &setup).unwrap_err();
        assert_eq!(err.step(), "centreline");
        assert!(err.to_string().starts_with("view B"), "{err}");
    }
}
