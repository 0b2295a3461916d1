//! From pixels to H-Net's input tensors, and from its outputs to masks and tip forces.
//!
//! Images enter as 8-bit RGB, row-major, `height·width·3` bytes, already resized to the model's
//! input size (resizing belongs to whoever decodes the image: the dataset loader natively, the
//! page in the browser). Grey X-ray images are passed with the grey value in all three channels.

use alloc::vec::Vec;

use burn::tensor::{DataError, Device, ExecutionError, Tensor, TensorData, Transaction};
use hnet_units::{ImageSize, TipForce, View};

use crate::mask_averaging::{MaskAveraging, average_with_mirror, mirrored};
use crate::model::{HNet, HNetOutput};
use burn::tensor::activation::sigmoid;

/// One stereo pair of 8-bit RGB images of the same size.
#[derive(Debug, Clone, Copy)]
pub struct StereoPair<'a> {
    /// View A pixels, `height·width·3` bytes.
    pub view_a: &'a [u8],
    /// View B pixels, `height·width·3` bytes.
    pub view_b: &'a [u8],
}

/// A buffer does not hold an image of the expected size.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "pair {pair} view {view}: {found} bytes, expected {expected} (an RGB image of the model's input size)"
)]
pub struct InputSizeError {
    /// Index of the pair in the batch.
    pub pair: usize,
    /// `"A"` or `"B"`.
    pub view: &'static str,
    /// Bytes found.
    pub found: usize,
    /// Bytes expected (`height·width·3`).
    pub expected: usize,
}

/// What H-Net says about one stereo pair.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoPrediction {
    /// Input size in pixels: the size of both masks.
    pub size: ImageSize,
    /// View A catheter probability per pixel, row-major.
    pub mask_a: Vec<f32>,
    /// View B catheter probability per pixel, row-major.
    pub mask_b: Vec<f32>,
    /// Tip force `(Fx, Fy, Fz)` in newtons.
    pub force: TipForce,
}

impl StereoPrediction {
    /// The prediction as one buffer: view A's mask, view B's mask (row-major, `size.pixels()`
    /// values each), then `(Fx, Fy, Fz)` in newtons. How the page's WebGPU worker hands a
    /// prediction to the page (crates/hnet-gpu).
    pub fn to_packed(&self) -> Vec<f32> {
        let mut values = Vec::with_capacity(self.mask_a.len() + self.mask_b.len() + 3);
        values.extend_from_slice(&self.mask_a);
        values.extend_from_slice(&self.mask_b);
        values.extend_from_slice(&self.force.newtons());
        values
    }

    /// The prediction in a [`StereoPrediction::to_packed`] buffer for images of `size`; `None`
    /// when the buffer's length is not that of such a prediction.
    pub fn from_packed(values: &[f32], size: ImageSize) -> Option<Self> {
        let pixels = size.pixels();
        if values.len() != 2 * pixels + 3 {
            return None;
        }
        let (mask_a, rest) = values.split_at(pixels);
        let (mask_b, force) = rest.split_at(pixels);
        Some(Self {
            size,
            mask_a: mask_a.to_vec(),
            mask_b: mask_b.to_vec(),
            force: TipForce::new(force[0], force[1], force[2]),
        })
    }
}

/// Appends an interleaved 8-bit RGB image as planar channels scaled to `[0, 1]` (the network's
/// `[3, H, W]` input layout). The one conversion of images to network input, used by inference
/// here and by `hnet`'s training batches.
pub fn push_planar(pixels: &[u8], out: &mut Vec<f32>) {
    for channel in 0..3 {
        out.extend(
            pixels
                .iter()
                .skip(channel)
                .step_by(3)
                .map(|&v| f32::from(v) / 255.0),
        );
    }
}

/// Appends an 8-bit mask (255 = catheter) scaled to `[0, 1]`: the one conversion of masks to
/// network input (Y-Net reads masks), used by the predictor and `hnet`'s training batches.
pub fn push_mask(mask: &[u8], out: &mut Vec<f32>) {
    out.extend(mask.iter().map(|&v| f32::from(v) / 255.0));
}

/// Builds the two input tensors `[B, 3, H, W]` (values in `[0, 1]`) of a batch of pairs.
pub fn stereo_batch(
    pairs: &[StereoPair<'_>],
    size: ImageSize,
    device: &Device,
) -> Result<(Tensor<4>, Tensor<4>), InputSizeError> {
    let [a, b] = stereo_planes(pairs, size)?;
    let shape = [pairs.len(), 3, size.height, size.width];
    Ok((
        Tensor::from_data(TensorData::new(a, shape), device),
        Tensor::from_data(TensorData::new(b, shape), device),
    ))
}

/// Views A and B of a batch of pairs as planar values in `[0, 1]`, `[B, 3, H, W]` each.
fn stereo_planes(
    pairs: &[StereoPair<'_>],
    size: ImageSize,
) -> Result<[Vec<f32>; 2], InputSizeError> {
    let expected = size.pixels() * 3;
    let mut a = Vec::with_capacity(pairs.len() * expected);
    let mut b = Vec::with_capacity(pairs.len() * expected);
    for (index, pair) in pairs.iter().enumerate() {
        for (view, pixels) in [("A", pair.view_a), ("B", pair.view_b)] {
            if pixels.len() != expected {
                return Err(InputSizeError {
                    pair: index,
                    view,
                    found: pixels.len(),
                    expected,
                });
            }
        }
        push_planar(pair.view_a, &mut a);
        push_planar(pair.view_b, &mut b);
    }
    Ok([a, b])
}

/// Host copies of a batch's outputs, split per pair.
fn split_predictions(
    size: ImageSize,
    mask_a: Vec<f32>,
    mask_b: Vec<f32>,
    force: Vec<f32>,
) -> Vec<StereoPrediction> {
    let pixels = size.pixels();
    mask_a
        .chunks_exact(pixels)
        .zip(mask_b.chunks_exact(pixels))
        .zip(force.chunks_exact(3))
        .map(|((a, b), f)| StereoPrediction {
            size,
            mask_a: a.to_vec(),
            mask_b: b.to_vec(),
            force: TipForce::new(f[0], f[1], f[2]),
        })
        .collect()
}

/// Reading a result back from the device failed.
#[derive(Debug, thiserror::Error)]
pub enum ReadbackError {
    /// The device failed while computing or transferring the result.
    #[error("could not read the result back from the device")]
    Device(#[source] ExecutionError),
    /// The device returned data of another type than `f32`.
    #[error("the device returned the result in an unexpected form")]
    Data(#[source] DataError),
}

/// A tensor's values read back to the host as `f32`s (the one read-back of the model, the CLI
/// and the page).
pub fn host_values<const D: usize>(tensor: Tensor<D>) -> Result<Vec<f32>, ReadbackError> {
    to_vec(tensor.into_data())
}

fn to_vec(data: TensorData) -> Result<Vec<f32>, ReadbackError> {
    data.try_into_vec::<f32>().map_err(ReadbackError::Data)
}

/// Host copies of a batch's outputs as [`HNet::forward_batch`] registered them for reading
/// (`read`: what the device returned), split per pair; with `averaging` mirrored, the batch's
/// second half is the mirror images of its first `pairs`, whose masks it averages. (Burn returns
/// every registered output; one that were missing would read as empty, giving no predictions
/// rather than a panic.)
fn read_predictions(
    size: ImageSize,
    pairs: usize,
    averaging: MaskAveraging,
    read: Result<Vec<TensorData>, ExecutionError>,
) -> Result<Vec<StereoPrediction>, PredictError> {
    let mut outputs = read.map_err(ReadbackError::Device)?.into_iter().map(to_vec);
    let mut next = || outputs.next().unwrap_or_else(|| Ok(Vec::new()));
    let (mut mask_a, mut mask_b, mut force) = (next()?, next()?, next()?);
    if averaging == MaskAveraging::Mirrored {
        let given = (pairs * size.pixels()).min(mask_a.len()).min(mask_b.len());
        for mask in [&mut mask_a, &mut mask_b] {
            let (mask, mirror) = mask.split_at_mut(given);
            average_with_mirror(mask, mirror, size);
        }
        mask_a.truncate(given);
        mask_b.truncate(given);
        force.truncate(pairs * 3);
    }
    Ok(split_predictions(size, mask_a, mask_b, force))
}

impl HNet {
    /// Runs a batch of `pairs` (followed by their mirror images when `averaging` is mirrored)
    /// and registers, for one read-back, the mask probabilities `[B, H·W]` of both views and
    /// the force `[B, 3]`.
    fn forward_batch(
        &self,
        pairs: &[StereoPair<'_>],
        size: ImageSize,
        device: &Device,
        averaging: MaskAveraging,
    ) -> Result<Transaction, InputSizeError> {
        let mut planes = stereo_planes(pairs, size)?;
        if averaging == MaskAveraging::Mirrored {
            for views in &mut planes {
                let mirror = mirrored(views, size);
                views.extend(mirror);
            }
        }
        let rows = pairs.len() * averaging.readings();
        let shape = [rows, 3, size.height, size.width];
        let [a, b] = planes.map(|v| Tensor::from_data(TensorData::new(v, shape), device));
        let output: HNetOutput = self.forward(a, b);
        let rows = rows as i32;
        Ok(Transaction::default()
            .register(output.mask_a().reshape([rows, -1]))
            .register(output.mask_b().reshape([rows, -1]))
            .register(output.force))
    }

    /// Runs `pairs` (each image of `size`) and reads the results back, blocking until the device
    /// is done. Each view is read as `averaging` says ([`crate::mask_averaging`]; the force
    /// always from the views as given). Use [`HNet::predict_async`] in the browser.
    pub fn predict(
        &self,
        pairs: &[StereoPair<'_>],
        size: ImageSize,
        device: &Device,
        averaging: MaskAveraging,
    ) -> Result<Vec<StereoPrediction>, PredictError> {
        let read = self
            .forward_batch(pairs, size, device, averaging)?
            .try_execute();
        read_predictions(size, pairs.len(), averaging, read)
    }

    /// Like [`HNet::predict`], but waits for the device asynchronously (required on WebGPU in
    /// the browser, where the page must not block).
    pub async fn predict_async(
        &self,
        pairs: &[StereoPair<'_>],
        size: ImageSize,
        device: &Device,
        averaging: MaskAveraging,
    ) -> Result<Vec<StereoPrediction>, PredictError> {
        let read = self
            .forward_batch(pairs, size, device, averaging)?
            .execute_async();
        read_predictions(size, pairs.len(), averaging, read.await)
    }
}

/// What one view's branch says about one image: its catheter probabilities and the pooled
/// features it hands the force head. Two of them, joined by [`HNet::join_views`], make the
/// pair's [`StereoPrediction`]: how the page reads a pair's views on two workers at once.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewReading {
    /// Input size in pixels: the mask's size.
    pub size: ImageSize,
    /// Catheter probability per pixel, row-major.
    pub mask: Vec<f32>,
    /// The branch's global average pools `[(depth+1)·filters]` (the force head's half input).
    pub pooled: Vec<f32>,
}

impl ViewReading {
    /// The reading as one buffer: the mask (`size.pixels()` values), then the pooled features.
    /// How the page's CPU workers hand a view to the page (crates/hnet-cpu).
    pub fn to_packed(&self) -> Vec<f32> {
        let mut values = Vec::with_capacity(self.mask.len() + self.pooled.len());
        values.extend_from_slice(&self.mask);
        values.extend_from_slice(&self.pooled);
        values
    }

    /// The reading in a [`ViewReading::to_packed`] buffer of a view of `size` whose branch
    /// pools `pooled` features; `None` when the buffer's length is not that.
    pub fn from_packed(values: &[f32], size: ImageSize, pooled: usize) -> Option<Self> {
        if values.len() != size.pixels() + pooled {
            return None;
        }
        let (mask, pooled) = values.split_at(size.pixels());
        Some(Self {
            size,
            mask: mask.to_vec(),
            pooled: pooled.to_vec(),
        })
    }
}

/// Two view readings that do not make a pair.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "view A's reading ({size_a}, {pooled_a} pooled features) and view B's ({size_b}, {pooled_b}) \
     do not make a pair for this network ({pooled} pooled features per view)"
)]
pub struct ViewsMismatch {
    /// View A's mask size.
    pub size_a: ImageSize,
    /// View B's mask size.
    pub size_b: ImageSize,
    /// View A's pooled features.
    pub pooled_a: usize,
    /// View B's pooled features.
    pub pooled_b: usize,
    /// What the network's force head takes per view.
    pub pooled: usize,
}

impl HNet {
    /// Runs `view`'s branch on one 8-bit RGB image of `size` and reads its mask and pooled
    /// features back, blocking until the device is done (the page's CPU workers). With
    /// `averaging` mirrored the branch also reads the mirror image, in the same batch, and the
    /// mask is the two readings' mean; the pooled features are always the image as given's.
    pub fn read_view(
        &self,
        view: View,
        image: &[u8],
        size: ImageSize,
        device: &Device,
        averaging: MaskAveraging,
    ) -> Result<ViewReading, PredictError> {
        let expected = size.pixels() * 3;
        if image.len() != expected {
            return Err(InputSizeError {
                pair: 0,
                view: view.letter(),
                found: image.len(),
                expected,
            }
            .into());
        }
        let readings = averaging.readings();
        let mut planar = Vec::with_capacity(readings * expected);
        push_planar(image, &mut planar);
        if averaging == MaskAveraging::Mirrored {
            let mirror = mirrored(&planar, size);
            planar.extend(mirror);
        }
        let input = Tensor::from_data(
            TensorData::new(planar, [readings, 3, size.height, size.width]),
            device,
        );
        let branch = self.forward_view(view, input);
        let read = Transaction::default()
            .register(sigmoid(branch.mask_logits).reshape([readings as i32, -1]))
            .register(branch.pooled)
            .try_execute();
        let mut outputs = read.map_err(ReadbackError::Device)?.into_iter().map(to_vec);
        let mut next = || outputs.next().unwrap_or_else(|| Ok(Vec::new()));
        let (mut mask, mut pooled) = (next()?, next()?);
        if averaging == MaskAveraging::Mirrored {
            let given = size.pixels().min(mask.len());
            let (as_given, mirror) = mask.split_at_mut(given);
            average_with_mirror(as_given, mirror, size);
            mask.truncate(given);
            pooled.truncate(pooled.len() / readings);
        }
        Ok(ViewReading { size, mask, pooled })
    }

    /// The pair's prediction from its two views' readings ([`HNet::read_view`]): their masks,
    /// and the force head's tip force in newtons on both views' pooled features.
    pub fn join_views(
        &self,
        a: ViewReading,
        b: ViewReading,
        device: &Device,
    ) -> Result<StereoPrediction, JoinViewsError> {
        let pooled = self.pooled_per_view();
        if a.size != b.size || a.pooled.len() != pooled || b.pooled.len() != pooled {
            return Err(JoinViewsError::Mismatch(ViewsMismatch {
                size_a: a.size,
                size_b: b.size,
                pooled_a: a.pooled.len(),
                pooled_b: b.pooled.len(),
                pooled,
            }));
        }
        let mut features = a.pooled;
        features.extend_from_slice(&b.pooled);
        let features = Tensor::from_data(TensorData::new(features, [1, 2 * pooled]), device);
        let force = host_values(self.force_of_features(features))
            .map_err(|e| JoinViewsError::Predict(e.into()))?;
        let force = <[f32; 3]>::try_from(&force[..])
            .map(TipForce::from_newtons)
            .map_err(|_| JoinViewsError::ForceValues(force.len()))?;
        Ok(StereoPrediction {
            size: a.size,
            mask_a: a.mask,
            mask_b: b.mask,
            force,
        })
    }
}

/// Why two view readings gave no pair prediction.
#[derive(Debug, thiserror::Error)]
pub enum JoinViewsError {
    /// The readings are not of this network's two views.
    #[error(transparent)]
    Mismatch(#[from] ViewsMismatch),
    /// The force head could not be run.
    #[error(transparent)]
    Predict(#[from] PredictError),
    /// The force head returned another number of values than `(Fx, Fy, Fz)`.
    #[error("the force head returned {0} values, not (Fx, Fy, Fz)")]
    ForceValues(usize),
}

/// Why a prediction failed.
#[derive(Debug, thiserror::Error)]
pub enum PredictError {
    /// An input image has the wrong size.
    #[error(transparent)]
    Input(#[from] InputSizeError),
    /// The device could not return the result.
    #[error(transparent)]
    Readback(#[from] ReadbackError),
}
