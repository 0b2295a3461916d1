//! The catheter digital twin: a faithful simulation of the H-Net paper's bench and of its
//! synthetic X-ray generator, producing stereo image pairs with exact masks and tip-force labels.
//!
//! Three concerns, each in its own folder:
//!
//! - [`simulator`]: the twin (the rod, the scenes, the C-arm views, the renderers and the
//!   paper's X-ray backgrounds);
//! - [`reconstruction`]: the catheter in 3D from its two masks and the rod fitted to it (the
//!   physics estimate of the force, blind or with the twin's answers), and the catheter catalogue;
//! - [`dataset`]: the on-disk format, its readers and writers, simulated datasets and imports.
//!
//! Beside them, [`vec3`] (the small 3D geometry all three use) and [`model_facts`] (what a weights
//! file says about the data its force was trained on and its measured error).
//!
//! Units: millimetres, newtons, degrees for angles. World frame: `x` towards the patient's left,
//! `y` anterior, `z` cranial, origin at the C-arm's isocentre.
//!
//! Everything compiles for wasm32 (the browser app runs the twin live) except the folder
//! writing, which uses threads (rayon) natively.

pub mod dataset;
pub mod model_facts;
pub mod reconstruction;
pub mod simulator;
pub mod vec3;
