//! Biplane XA cines rendered by the digital twin, with their true tip forces: the tests' DICOM
//! input and the page's sample cine, written by the project itself (never downloaded data).

use hnet_twin::simulator::carm::{Biplane, CArm};
use hnet_twin::simulator::rod;
use hnet_twin::simulator::scene::{
    Backgrounds, Modality, TwinConfig, TwinError, ViewPixels, generate, render_view, sample_rng,
};
use hnet_twin::simulator::synthetic_xray::PatchLayout;
use hnet_units::{ImageSize, TipForce};

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
    pub forces_n: Vec<TipForce>,
}

/// The twin's biplane for the cines, at `size`: off the default frontal/lateral angles, so that
/// tests see the headers' geometry being read.
pub fn cine_views(size: ImageSize) -> Biplane {
    Biplane {
        a: CArm::cardiac(-20.0, 10.0, size),
        b: CArm::cardiac(70.0, -5.0, size),
    }
}

/// `frames` frames of `size` from the twin (X-ray, easy backgrounds; each frame a new scene of
/// the run seeded `seed`) as two 12-bit XA cines with their geometry.
pub fn twin_cine(size: ImageSize, frames: usize, seed: u64) -> Result<TwinCine, TwinError> {
    let mut config = TwinConfig::new(Modality::Xray1, size);
    config.views = cine_views(size);
    let backgrounds = Backgrounds::phantom(&config.views);
    let samples = (0..frames as u64)
        .map(|index| generate(&config, &backgrounds, seed, index))
        .collect::<Result<Vec<_>, _>>()?;
    let frames = samples
        .iter()
        .map(|s| [&s.views[0].pixels, &s.views[1].pixels])
        .collect::<Vec<_>>();
    Ok(TwinCine {
        planes: xa_planes(config.views, size, &frames, seed),
        forces_n: samples.iter().map(|s| s.params.tip_force_n).collect(),
    })
}

/// Scene draws tried for a push that the rod solver settles.
const PUSH_DRAWS: u64 = 8;

/// A catheter pushed against the wall and released, as a biplane cine of `frames` frames of
/// `size`: one bench scene of the run seeded `seed` (the twin's default cardiac
/// biplane, XRay-2 look), whose tip force follows a half sine from zero to the scene's force and
/// back, on the same backgrounds throughout with fresh detector noise in every frame. What the
/// bundled model was trained on, moving as a cine does: the page's sample cine.
pub fn twin_push_cine(size: ImageSize, frames: usize, seed: u64) -> Result<TwinCine, TwinError> {
    let config = TwinConfig::new(Modality::Xray2, size);
    let backgrounds = Backgrounds::phantom(&config.views);
    let mut rng = sample_rng(seed, 0);
    let mut last = None;
    let mut scene = None;
    for _ in 0..PUSH_DRAWS {
        let params = config.scene.sample(&mut rng);
        let (rod_config, base) = params.rod(&config.rod);
        match rod::solve(&rod_config, &base, params.tip_force_n.into()) {
            Ok(_) => {
                scene = Some(params);
                break;
            }
            Err(e) => last = Some(e),
        }
    }
    let unsolvable = |last| TwinError::Unsolvable {
        index: 0,
        attempts: PUSH_DRAWS as usize,
        last,
    };
    let Some(scene) = scene else {
        return Err(unsolvable(last.expect("at least one draw")));
    };
    let layouts = [0, 1].map(|view| {
        let source = &backgrounds.per_view[view][0];
        let layout = PatchLayout::random(source, &config.anatomies, &config.patches, &mut rng);
        (source, layout)
    });
    let mut forces_n = Vec::with_capacity(frames);
    let mut pictures = Vec::with_capacity(frames);
    for frame in 0..frames {
        let phase = if frames > 1 {
            frame as f64 / (frames - 1) as f64
        } else {
            0.5
        };
        let mut params = scene;
        let envelope = (std::f64::consts::PI * phase).sin() as f32;
        params.tip_force_n = scene.tip_force_n.map(|f| f * envelope);
        let (rod_config, base) = params.rod(&config.rod);
        let shape =
            rod::solve(&rod_config, &base, params.tip_force_n.into()).map_err(unsolvable)?;
        let mut noise = sample_rng(seed, frame as u64 + 1);
        let [a, b] = [(&config.views.a, 0), (&config.views.b, 1)].map(|(view, i)| {
            let (source, layout) = &layouts[i];
            render_view(
                &config,
                &shape,
                view,
                Some((source, layout.clone())),
                &mut noise,
            )
            .pixels
        });
        pictures.push([a, b]);
        forces_n.push(params.tip_force_n);
    }
    let frames = pictures.iter().map(|[a, b]| [a, b]).collect::<Vec<_>>();
    Ok(TwinCine {
        planes: xa_planes(config.views, size, &frames, seed),
        forces_n,
    })
}

/// Both planes' frames as 12-bit XA cines with the views' geometry, 15 frames per second.
fn xa_planes(
    views: Biplane,
    size: ImageSize,
    frames: &[[&ViewPixels; 2]],
    seed: u64,
) -> [XaCine; 2] {
    let scale = |pixels: &ViewPixels| -> Vec<u16> {
        // 8-bit grey to 12 bits: 0 -> 8, 255 -> 4088.
        pixels
            .bytes()
            .iter()
            .map(|&g| u16::from(g) * 16 + 8)
            .collect()
    };
    [(Plane::A, views.a, 0), (Plane::B, views.b, 1)].map(|(plane, carm, view)| XaCine {
        plane,
        size,
        bits_stored: BITS_STORED,
        signed: false,
        monochrome: Monochrome::Two,
        frames: frames.iter().map(|f| scale(f[view])).collect(),
        carm: Some(carm),
        frame_time_ms: Some(FRAME_TIME_MS),
        acquisition_date_time: Some("20240501093000.000000".into()),
        // The full 12-bit range first, then a narrower one as a second choice.
        windows: vec![(2048.0, 4096.0), (1500.0, 1000.0)],
        rescale: None,
        patient: PatientIdentity::fictional(),
        uid_seed: seed * 2 + view as u64,
    })
}
