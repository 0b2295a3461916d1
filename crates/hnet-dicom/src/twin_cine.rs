//! Biplane XA cines rendered by the digital twin, with their true tip forces: the tests' DICOM
//! input, written by the project itself (never downloaded data).

use hnet_twin::carm::{Biplane, CArm};
use hnet_twin::scene::{Backgrounds, Modality, TwinConfig, TwinError, ViewPixels, generate};
use hnet_units::ImageSize;

use crate::frames::Monochrome;
use crate::geometry::Plane;
use crate::writer::{PatientIdentity, XaCine};

/// Bits Stored of the written frames: the twin's 8-bit grey scaled to 12 bits, as XA detectors
/// store them.
const BITS_STORED: u16 = 12;

/// Frame time of the written cines, ms (15 frames per second).
pub const FRAME_TIME_MS: f64 = 66.7;

/// Two planes of a twin cine and each frame's true tip force.
#[derive(Debug, Clone)]
pub struct TwinCine {
    /// Plane A and plane B.
    pub planes: [XaCine; 2],
    /// Each frame's tip force `(Fx, Fy, Fz)`, newtons.
    pub forces_n: Vec<[f64; 3]>,
}

/// The twin's biplane for the cines: off the default frontal/lateral angles, so that tests see
/// the headers' geometry being read.
pub fn cine_views(size: usize) -> Biplane {
    Biplane {
        a: CArm::cardiac(-20.0, 10.0, size),
        b: CArm::cardiac(70.0, -5.0, size),
    }
}

/// `frames` frames of `size` x `size` pixels from the twin (X-ray, easy backgrounds; each frame
/// a new scene of the run seeded `seed`) as two 12-bit XA cines with their geometry.
pub fn twin_cine(size: usize, frames: usize, seed: u64) -> Result<TwinCine, TwinError> {
    let mut config = TwinConfig::new(Modality::Xray1, size);
    config.views = cine_views(size);
    let backgrounds = Backgrounds::phantom(&config.views);
    let samples = (0..frames as u64)
        .map(|index| generate(&config, &backgrounds, seed, index))
        .collect::<Result<Vec<_>, _>>()?;
    let scale = |pixels: &ViewPixels| -> Vec<u16> {
        // 8-bit grey to 12 bits: 0 -> 8, 255 -> 4088.
        pixels
            .bytes()
            .iter()
            .map(|&g| u16::from(g) * 16 + 8)
            .collect()
    };
    let planes = [(Plane::A, config.views.a, 0), (Plane::B, config.views.b, 1)].map(
        |(plane, carm, view)| XaCine {
            plane,
            size: ImageSize::square(size),
            bits_stored: BITS_STORED,
            signed: false,
            monochrome: Monochrome::Two,
            frames: samples
                .iter()
                .map(|s| scale(&s.views[view].pixels))
                .collect(),
            carm: Some(carm),
            frame_time_ms: Some(FRAME_TIME_MS),
            acquisition_date_time: Some("20240501093000.000000".into()),
            // The full 12-bit range first, then a narrower one as a second choice.
            windows: vec![(2048.0, 4096.0), (1500.0, 1000.0)],
            rescale: None,
            patient: PatientIdentity::fictional(),
            uid_seed: seed * 2 + view as u64,
        },
    );
    Ok(TwinCine {
        planes,
        forces_n: samples.iter().map(|s| s.params.tip_force_n.0).collect(),
    })
}
