//! H-Net Studio in the browser: load or simulate a stereo pair of catheter images, run H-Net on
//! WebGPU or the CPU, correct the masks, label the tip force and export a dataset that `hnet
//! train` reads; or play a biplane DICOM cine and trace H-Net's force over its frames. Everything
//! runs in the page; no image leaves the machine.
//!
//! The page's logic that needs no browser builds natively too (and is tested with `cargo test`):
//!
//! - [`workspace`]: the labeled pairs, brush strokes with undo and redo, force labels;
//! - [`imaging`]: decoding uploads, the working resolution, overlays and force arrows;
//! - [`twin_live`]: the digital twin's sliders and the synthetic X-ray background composer;
//! - [`catheter_3d`]: the catheter in 3D from both masks and the physics-checked force of the
//!   rod fitted to it, and what the 3D view draws; [`orbit_camera`]: the 3D view's camera;
//!   [`catheter_calibration`]: the catheter's stiffness from the pairs' measured force labels;
//! - [`cine`]: a biplane DICOM cine: frames as pairs with the headers' geometry, window/level,
//!   the force trace;
//! - [`export`]: the labeled pairs as a dataset zip; [`stated_geometry`]: the C-arms a user
//!   states for an uploaded pair;
//! - [`force_label`]: force labels as typed or read from a CSV file;
//! - [`force_reading`]: what a force estimate can be said to show against the ablation band;
//! - [`webgpu_check`]: WebGPU's result on a check pair against the CPU's, before it is trusted;
//! - [`page_query`]: the diagnosis and test switches a page address's query can set;
//! - [`keymap`]: every keyboard shortcut, for the handlers, the help list and the tooltips;
//! - [`error_text`]: an error and its causes as one message.
//!
//! The rest exists only on wasm32: the page's state (`studio`), its components (`app`,
//! `components`), the network on the chosen backend (`engine`, `compute`, and
//! `gpu_worker`, the page's side of the WebGPU worker in crates/hnet-gpu), the browser's storage
//! (`storage`) and files (`browser`). `src/main.rs` mounts [`App`].

pub mod catheter_3d;
pub mod catheter_calibration;
pub mod cine;
pub mod error_text;
pub mod export;
pub mod fine_tune;
pub mod force_label;
pub mod force_reading;
pub mod imaging;
pub mod keymap;
pub mod orbit_camera;
pub mod page_query;
pub mod stated_geometry;
pub mod stored_pair;
pub mod twin_live;
pub mod webgpu_check;
pub mod workspace;

#[cfg(target_arch = "wasm32")]
pub mod app;
#[cfg(target_arch = "wasm32")]
pub mod browser;
#[cfg(target_arch = "wasm32")]
pub mod bundled;
#[cfg(target_arch = "wasm32")]
pub mod components;
#[cfg(target_arch = "wasm32")]
pub mod compute;
#[cfg(target_arch = "wasm32")]
pub mod cpu_pool;
#[cfg(target_arch = "wasm32")]
pub mod engine;
#[cfg(target_arch = "wasm32")]
pub mod gpu_worker;
#[cfg(target_arch = "wasm32")]
pub mod module_worker;
#[cfg(target_arch = "wasm32")]
pub mod storage;
#[cfg(target_arch = "wasm32")]
pub mod studio;

#[cfg(all(test, not(target_arch = "wasm32")))]
mod page_architecture;

#[cfg(target_arch = "wasm32")]
pub use app::App;
