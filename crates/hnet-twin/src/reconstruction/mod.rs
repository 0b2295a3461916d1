//! The catheter in 3D from its two masks, and the tip force of the rod that fits it (a
//! physics-checked force, no training).
//!
//! - [`centreline`]: each view's sub-pixel centreline (and whether a view shows a catheter);
//! - [`epipolar`]: epipolar matching of the two centrelines and triangulation;
//! - [`rod_fit`]: the twin's rod fitted to the 3D curve, the force its fit implies;
//! - [`physics_force`]: the three on a pair's masks in one call, with the oracle or the blind
//!   setup;
//! - [`catalogue`]: the named catheters a blind estimate assumes, and their calibration from
//!   pairs with a measured force.

pub mod catalogue;
pub mod centreline;
pub mod epipolar;
pub mod physics_force;
pub mod rod_fit;
