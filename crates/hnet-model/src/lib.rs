//! H-Net: one small network that segments a catheter in two simultaneous views (biplane
//! fluoroscopy or two bench cameras) and estimates the 3D force at its tip.
//!
//! Fekri, Zadeh, Dargahi, "H-Net: A Multitask Architecture for Simultaneous 3D Force
//! Estimation and Stereo Semantic Segmentation in Intracardiac Catheters", IEEE RA-L 2024.
//!
//! This crate holds everything about the network that the command-line tool, the browser app
//! and the tests share, written once:
//!
//! - [`model`]: the architecture and its configuration ([`HNetConfig`], [`HNet`]);
//! - [`loss`]: the paper's multitask loss (eq. 7);
//! - [`metrics`]: the paper's force and segmentation metrics (section III.B), on plain slices so
//!   they need no backend;
//! - [`inference`]: turning RGB pixel buffers into input tensors and outputs into masks and a
//!   tip force;
//! - [`training`]: one training step (a batch of labelled pairs, the forward pass and its loss)
//!   and the recipe's optimiser, for `hnet train` and the page's [`fine_tune`] (feature
//!   `training`);
//! - [`predictor`]: any network of the registry loaded from its weights file and run on pairs,
//!   with turned-view reading: the one inference API of the command-line tool;
//! - [`catheter_entry`]: reading a view whose catheter enters through another edge than the
//!   bottom, as every training scene had it, by turning it;
//! - [`mask_averaging`]: reading each view and its mirror image and averaging the masks;
//! - [`weights`]: saving and loading trained weights as a single self-describing burnpack file;
//! - [`baselines`] and [`architectures`]: the networks H-Net is compared with, and one type for
//!   all of them so that training and evaluation are written once.
//!
//! The code has no backend type parameter: Burn 0.22 picks the backend from the [`Device`]
//! (`Device::flex()` on the CPU, `Device::wgpu(..)` on a GPU or in the browser).
//!
//! Units: forces are in newtons, images in pixels, masks are probabilities in `[0, 1]` of a pixel
//! showing the catheter.
//!
//! [`Device`]: burn::tensor::Device
#![cfg_attr(not(feature = "std"), no_std)]

extern crate alloc;

pub mod architectures;
pub mod baselines;
pub mod catheter_entry;
pub mod fine_tune;
pub mod inference;
pub mod loss;
pub mod mask_averaging;
pub mod metrics;
pub mod model;
pub mod predictor;
pub mod training;
pub mod weights;

pub use loss::{HNetLoss, HNetLossConfig, LossTerms};
pub use model::{HNet, HNetConfig, HNetConfigError, HNetOutput};
