//! Any network of the registry ([`crate::architectures`]) loaded from its weights file and run
//! on stereo pairs: the one inference API of `hnet eval`, `trace`, `study`, `report`,
//! `calibrate` and the mismatch suite. (The page runs H-Net alone, through
//! [`HNet::predict_async`](crate::HNet::predict_async) and the same turned-view reading.)
//!
//! Images enter as 8-bit RGB, row-major, `height·width·3` bytes at the network's input size;
//! masks (read only by networks that take masks, Y-Net) as one byte per pixel, 0-255. Mask
//! outputs are catheter probabilities per pixel, row-major; forces are `(Fx, Fy, Fz)` in newtons.

use alloc::string::{String, ToString};
use alloc::vec;
use alloc::vec::Vec;

use burn::tensor::activation::sigmoid;
use burn::tensor::{Device, Tensor, TensorData, Transaction};
use hnet_units::turn::TurnError;
use hnet_units::{ImageSize, TipForce};

use crate::architectures::{ModelSpec, StereoModel, StereoOutputs};
use crate::catheter_entry::{CatheterEntry, EntrySearch, EntrySetting, TurnedOutput, turned_pair};
use crate::inference::{InputSizeError, PredictError, ReadbackError, push_mask, push_planar};
use crate::mask_averaging::{MaskAveraging, average_with_mirror, mirrored};
use crate::weights::{WeightsError, WeightsHeader};

/// A network ready to read pairs: its weights, its settings and the input size it takes.
pub struct Predictor {
    /// The network.
    pub net: StereoModel,
    /// Its architecture and settings.
    pub spec: ModelSpec,
    /// Input size, pixels.
    pub image_size: ImageSize,
    /// The weights file's header (architecture, settings, provenance).
    pub header: WeightsHeader,
    /// How many ways each view is read for its mask ([`crate::mask_averaging`]); one by default.
    pub mask_averaging: MaskAveraging,
}

/// Why a weights file gives no [`Predictor`].
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file is not a readable weights file.
    #[error(transparent)]
    Weights(#[from] WeightsError),
    /// An H-Net records its input size; another was asked for.
    #[error("weights file '{source_name}': this H-Net takes {network} images, not {asked}")]
    OtherSize {
        /// The weights' name.
        source_name: String,
        /// The size the network was built for.
        network: ImageSize,
        /// The size asked for.
        asked: ImageSize,
    },
    /// A baseline's file does not record its input size, and none was given.
    #[error(
        "weights file '{source_name}' holds a `{architecture}` network, whose input size is not \
         recorded: give its size"
    )]
    SizeUnknown {
        /// The weights' name.
        source_name: String,
        /// The network's architecture.
        architecture: &'static str,
    },
    /// The size is not one the architecture can take.
    #[error(
        "weights file '{source_name}': the size must be a positive multiple of {multiple} for \
         `{architecture}`, not {asked}"
    )]
    BadSize {
        /// The weights' name.
        source_name: String,
        /// The architecture's size rule.
        multiple: usize,
        /// The network's architecture.
        architecture: &'static str,
        /// The size asked for.
        asked: ImageSize,
    },
}

/// The inputs of one pair.
#[derive(Debug, Clone, Copy)]
pub struct PairInput<'a> {
    /// View A, RGB, `height·width·3` bytes.
    pub view_a: &'a [u8],
    /// View B, RGB.
    pub view_b: &'a [u8],
    /// The catheter masks of views A and B, `height·width` bytes each (0-255), for networks
    /// that read masks; `None` reads as empty masks.
    pub masks: Option<[&'a [u8]; 2]>,
}

/// What a network made of one pair.
#[derive(Debug, Clone, PartialEq)]
pub struct PairOutput {
    /// Catheter probability per pixel of views A and B, for networks that segment.
    pub masks: Option<[Vec<f32>; 2]>,
    /// Tip force `(Fx, Fy, Fz)`, newtons, for networks that estimate it (and, when views were
    /// turned for their catheter's entry edge, only for pairs read as they are).
    pub force: Option<TipForce>,
}

/// A pair read with its views turned for their catheter's entry edge.
#[derive(Debug, Clone, PartialEq)]
pub struct EntryOutput {
    /// The masks (turned back to the views as given) and force.
    pub output: PairOutput,
    /// The entry edge kept for views A and B.
    pub entry: [CatheterEntry; 2],
    /// Readings of views A and B the search took: 1 when a view was read once.
    pub readings: [usize; 2],
}

impl Predictor {
    /// Rebuilds the network in a weights file's `bytes` (named `source` in errors). H-Net's
    /// weights record their input size: `size` must be `None` or that size. A baseline's come
    /// at `size`.
    pub fn from_weights_bytes(
        bytes: &[u8],
        size: Option<ImageSize>,
        device: &Device,
        source: &str,
    ) -> Result<Self, LoadError> {
        let (net, spec, header) = StereoModel::from_weights_bytes(bytes, device, source)?;
        let source_name = || source.to_string();
        let image_size = match (&spec, size) {
            (ModelSpec::Hnet(config), None) => config.image_size,
            (ModelSpec::Hnet(config), Some(asked)) if asked != config.image_size => {
                return Err(LoadError::OtherSize {
                    source_name: source_name(),
                    network: config.image_size,
                    asked,
                });
            }
            (_, Some(asked)) => asked,
            (spec, None) => {
                return Err(LoadError::SizeUnknown {
                    source_name: source_name(),
                    architecture: spec.name(),
                });
            }
        };
        let multiple = spec.size_multiple();
        if ![image_size.width, image_size.height]
            .iter()
            .all(|s| *s > 0 && s % multiple == 0)
        {
            return Err(LoadError::BadSize {
                source_name: source_name(),
                multiple,
                architecture: spec.name(),
                asked: image_size,
            });
        }
        Ok(Self {
            net,
            spec,
            image_size,
            header,
            mask_averaging: MaskAveraging::Single,
        })
    }

    /// Whether the network segments (has mask heads).
    pub fn segments(&self) -> bool {
        self.spec.heads().0
    }

    /// Runs the network on `pairs` as one batch and reads the results back, blocking until the
    /// device is done. With [`Self::mask_averaging`] `Mirrored`, the mirror images are one more
    /// batch and each mask is the mean of the two readings.
    pub fn predict(
        &self,
        pairs: &[PairInput<'_>],
        device: &Device,
    ) -> Result<Vec<PairOutput>, PredictError> {
        if pairs.is_empty() {
            return Ok(Vec::new());
        }
        let size = self.image_size;
        let (n, pixels) = (pairs.len(), size.pixels());
        let mut views = [
            Vec::with_capacity(n * 3 * pixels),
            Vec::with_capacity(n * 3 * pixels),
        ];
        let mut masks = [
            Vec::with_capacity(n * pixels),
            Vec::with_capacity(n * pixels),
        ];
        for (index, pair) in pairs.iter().enumerate() {
            let given = [pair.view_a, pair.view_b];
            for (view, (name, pixels_of)) in ["A", "B"].into_iter().zip(given).enumerate() {
                if pixels_of.len() != 3 * pixels {
                    return Err(InputSizeError {
                        pair: index,
                        view: name,
                        found: pixels_of.len(),
                        expected: 3 * pixels,
                    }
                    .into());
                }
                push_planar(pixels_of, &mut views[view]);
                match pair.masks.map(|m| m[view]) {
                    Some(mask) if mask.len() == pixels => {
                        push_mask(mask, &mut masks[view]);
                    }
                    Some(mask) => {
                        return Err(InputSizeError {
                            pair: index,
                            view: name,
                            found: mask.len(),
                            expected: pixels,
                        }
                        .into());
                    }
                    None => masks[view].extend(core::iter::repeat_n(0.0, pixels)),
                }
            }
        }
        // The mirror images' catheter probabilities, as read (one more batch).
        let mirror_masks = if self.segments() && self.mask_averaging == MaskAveraging::Mirrored {
            let mirror = |planes: &[Vec<f32>; 2]| planes.each_ref().map(|p| mirrored(p, size));
            Some(self.read_masks(mirror(&views), mirror(&masks), n, size, device)?)
        } else {
            None
        };
        let out = self.forward(views, masks, n, size, device);
        let segments = out.mask_logits.is_some();
        let estimates_force = out.force.is_some();
        let mut read = Transaction::default();
        if let Some([a, b]) = out.mask_logits {
            read = read
                .register(sigmoid(a).reshape([n as i32, -1]))
                .register(sigmoid(b).reshape([n as i32, -1]));
        }
        if let Some(force) = out.force {
            read = read.register(force);
        }
        let mut values = read
            .try_execute()
            .map_err(ReadbackError::Device)?
            .into_iter()
            .map(|data| data.try_into_vec::<f32>().map_err(ReadbackError::Data));
        let mut next = || values.next().unwrap_or_else(|| Ok(Vec::new()));
        let masks = if segments {
            let mut masks = [next()?, next()?];
            if let Some(mirror_masks) = &mirror_masks {
                for (mask, mirror_mask) in masks.iter_mut().zip(mirror_masks) {
                    average_with_mirror(mask, mirror_mask, size);
                }
            }
            Some(masks)
        } else {
            None
        };
        let forces = if estimates_force { Some(next()?) } else { None };
        Ok((0..n)
            .map(|i| PairOutput {
                masks: masks.as_ref().map(|[a, b]| {
                    [
                        a[i * pixels..(i + 1) * pixels].to_vec(),
                        b[i * pixels..(i + 1) * pixels].to_vec(),
                    ]
                }),
                force: forces
                    .as_ref()
                    .map(|f| TipForce::new(f[i * 3], f[i * 3 + 1], f[i * 3 + 2])),
            })
            .collect())
    }

    /// The network on `n` pairs' planar views and masks of views A and B (`[n, 3, h, w]` and
    /// `[n, 1, h, w]` values each).
    fn forward(
        &self,
        [view_a, view_b]: [Vec<f32>; 2],
        [mask_a, mask_b]: [Vec<f32>; 2],
        n: usize,
        size: ImageSize,
        device: &Device,
    ) -> StereoOutputs {
        let [h, w] = size.height_width();
        let image = |data: Vec<f32>| Tensor::from_data(TensorData::new(data, [n, 3, h, w]), device);
        let mask = |data: Vec<f32>| Tensor::from_data(TensorData::new(data, [n, 1, h, w]), device);
        self.net
            .forward([image(view_a), image(view_b)], [mask(mask_a), mask(mask_b)])
    }

    /// The catheter probabilities of `n` pairs' planar views and masks (`[n, 3, h, w]` and
    /// `[n, 1, h, w]` each), read back as views A and B, `n · h · w` values each.
    fn read_masks(
        &self,
        views: [Vec<f32>; 2],
        masks: [Vec<f32>; 2],
        n: usize,
        size: ImageSize,
        device: &Device,
    ) -> Result<[Vec<f32>; 2], PredictError> {
        let out = self.forward(views, masks, n, size, device);
        let Some([a, b]) = out.mask_logits else {
            return Ok([Vec::new(), Vec::new()]);
        };
        let mut values = Transaction::default()
            .register(sigmoid(a).reshape([n as i32, -1]))
            .register(sigmoid(b).reshape([n as i32, -1]))
            .try_execute()
            .map_err(ReadbackError::Device)?
            .into_iter()
            .map(|data| data.try_into_vec::<f32>().map_err(ReadbackError::Data));
        let mut next = || values.next().unwrap_or_else(|| Ok(Vec::new()));
        Ok([next()?, next()?])
    }

    /// [`Predictor::predict`] with each pair's views read under `entry`
    /// ([`crate::catheter_entry`]): each view turned for every candidate edge, the masks of the
    /// edge with the most catheter turned back, and the force only for pairs whose views were
    /// both read as they are. Without turns this is [`Predictor::predict`] with the bottom edge.
    pub fn predict_entry(
        &self,
        pairs: &[PairInput<'_>],
        device: &Device,
        entry: EntrySetting,
    ) -> Result<Vec<EntryOutput>, EntryError> {
        let bottom = |output| EntryOutput {
            output,
            entry: [CatheterEntry::Bottom; 2],
            readings: [1, 1],
        };
        if !entry.turns_views() {
            return Ok(self
                .predict(pairs, device)?
                .into_iter()
                .map(bottom)
                .collect());
        }
        let size = self.image_size;
        if !self.segments() {
            return Err(EntryError::NoMasks(self.spec.name()));
        }
        if !size.is_square() {
            return Err(EntryError::NotSquare(size));
        }
        // Every pair's first reading in one batch, then each further edge's pairs in one.
        let run = |edges: &[[CatheterEntry; 2]], pairs: &[&PairInput<'_>]| {
            let turned = pairs
                .iter()
                .zip(edges)
                .map(|(pair, edge)| turned_pair(pair.view_a, pair.view_b, size, *edge))
                .collect::<Result<Vec<_>, TurnError>>()?;
            let inputs: Vec<PairInput<'_>> = turned
                .iter()
                .map(|t| PairInput {
                    view_a: &t.view_a,
                    view_b: &t.view_b,
                    masks: None,
                })
                .collect();
            let outputs = self.predict(&inputs, device)?;
            Ok::<_, EntryError>(
                edges
                    .iter()
                    .zip(outputs)
                    .map(|(edge, output)| TurnedOutput {
                        entry: *edge,
                        masks: output.masks.unwrap_or_default(),
                        force: output.force,
                    })
                    .collect::<Vec<_>>(),
            )
        };
        let all: Vec<&PairInput<'_>> = pairs.iter().collect();
        let first = vec![entry.first_reading(); pairs.len()];
        let mut searches: Vec<EntrySearch> = run(&first, &all)?
            .into_iter()
            .map(|output| EntrySearch::new(entry, size, output))
            .collect();
        for edge in [
            CatheterEntry::Right,
            CatheterEntry::Top,
            CatheterEntry::Left,
        ] {
            let asking: Vec<usize> = (0..pairs.len())
                .filter(|&i| searches[i].further_pairs().contains(&[edge; 2]))
                .collect();
            if asking.is_empty() {
                continue;
            }
            let chosen: Vec<&PairInput<'_>> = asking.iter().map(|&i| &pairs[i]).collect();
            let outputs = run(&vec![[edge; 2]; asking.len()], &chosen)?;
            for (i, output) in asking.into_iter().zip(outputs) {
                searches[i].add_pair(output);
            }
        }
        searches
            .into_iter()
            .map(|search| {
                let readings = search.readings();
                let reading = search.finish()?;
                Ok(EntryOutput {
                    output: PairOutput {
                        masks: Some(reading.masks),
                        force: reading.force,
                    },
                    entry: reading.entry,
                    readings,
                })
            })
            .collect()
    }
}

/// Why pairs could not be read with their views turned.
#[derive(Debug, thiserror::Error)]
pub enum EntryError {
    /// The network has no mask heads, and the entry edge is chosen by the masks.
    #[error("reading turned views needs masks; a `{0}` network gives none")]
    NoMasks(&'static str),
    /// Quarter turns keep only a square image's size.
    #[error("reading turned views needs a square network; this one takes {0} images")]
    NotSquare(ImageSize),
    /// The network could not be run.
    #[error(transparent)]
    Predict(#[from] PredictError),
    /// A view or a mask could not be turned.
    #[error(transparent)]
    Turn(#[from] TurnError),
}
