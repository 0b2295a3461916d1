//! The digital twin: the catheter as a rod, its scenes, the two views and their renderers, and
//! the paper's X-ray backgrounds.
//!
//! - [`rod`]: the catheter's flexible section as a Kirchhoff rod under a tip force;
//!   [`catheter`]: how it looks (electrodes, attenuation, colour);
//! - [`carm`]: two perspective views (a biplane C-arm, or the bench's two cameras);
//! - [`render`]: the catheter's exact anti-aliased mask, X-ray attenuation and camera look, and
//!   the X-ray detector, on [`raster`]'s floating-point images and [`noise`]'s fast deviates;
//! - [`phantom`] and [`synthetic_xray`]: chest radiograph backgrounds cut into shuffled patches;
//! - [`scene`]: random scenes and complete stereo samples; [`sensor_plate`]: the paper's bench
//!   contact (the tip pressed against an actuated plate); [`off_bench`]: pairs off the bench
//!   (any catheter and pose, any C-arm angle the page offers, phantom or radiograph).

pub mod carm;
pub mod catheter;
pub mod noise;
pub mod off_bench;
pub mod phantom;
pub mod raster;
pub mod render;
pub mod rod;
pub mod scene;
pub mod sensor_plate;
pub mod synthetic_xray;
