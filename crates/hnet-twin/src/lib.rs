//! The catheter digital twin: a faithful simulation of the H-Net paper's bench and of its
//! synthetic X-ray generator, producing stereo image pairs with exact masks and tip-force labels.
//!
//! - [`rod`]: the catheter's flexible section as a Kirchhoff rod under a tip force;
//! - [`carm`]: two perspective views (a biplane C-arm, or the bench's two cameras);
//! - [`render`]: the catheter's exact anti-aliased mask, X-ray attenuation and camera look;
//! - [`phantom`] and [`synthetic_xray`]: chest radiograph backgrounds cut into shuffled patches;
//! - [`scene`]: random scenes and complete stereo samples; [`sensor_plate`]: the paper's bench
//!   contact (the tip pressed against an actuated plate); [`off_bench`]: pairs off the bench
//!   (any catheter and pose, any C-arm angle the page offers, phantom or radiograph);
//! - [`centreline`], [`reconstruction`] and [`rod_fit`]: the catheter in 3D from its two masks
//!   (sub-pixel centrelines, epipolar matching and triangulation) and the tip force of the rod
//!   that fits it (a physics-checked force, no training); [`physics_force`] runs the three on a
//!   pair's masks in one call;
//! - [`catalogue`]: the named catheters a blind force estimate assumes, and their calibration
//!   from pairs with a measured force;
//! - [`dataset`]: the on-disk format; [`force_table`]: force tables in CSV (imports and the page's
//!   labels); [`label_origin`]: where each force label came from; [`model_facts`]: what a
//!   weights file says about the data its force was trained on and its measured error; natively also [`simulate`]
//!   (and [`shard`], a simulation in parts), [`import`] and [`files`] (atomic writes).
//!
//! Units: millimetres, newtons, degrees for angles. World frame: `x` towards the patient's left,
//! `y` anterior, `z` cranial, origin at the C-arm's isocentre.
//!
//! Everything compiles for wasm32 (the browser app runs the twin live) except the folder
//! writing, which uses threads (rayon) natively.

pub mod archive;
pub mod carm;
pub mod catalogue;
pub mod catheter;
pub mod centreline;
pub mod dataset;
#[cfg(not(target_arch = "wasm32"))]
pub mod files;
pub mod force_table;
#[cfg(not(target_arch = "wasm32"))]
pub mod import;
pub mod label_origin;
pub mod model_facts;
pub mod noise;
pub mod off_bench;
pub mod phantom;
pub mod physics_force;
pub mod raster;
pub mod reconstruction;
pub mod render;
pub mod rod;
pub mod rod_fit;
pub mod scene;
pub mod sensor_plate;
#[cfg(not(target_arch = "wasm32"))]
pub mod shard;
#[cfg(not(target_arch = "wasm32"))]
pub mod simulate;
pub mod synthetic_xray;
pub mod vec3;
