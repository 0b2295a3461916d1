//! From pixels to H-Net's input tensors, and from its outputs to masks and tip forces.
//!
//! Images enter as 8-bit RGB, row-major, `height·width·3` bytes, already resized to the model's
//! input size (resizing belongs to whoever decodes the image: the dataset loader natively, the
//! page in the browser). Grey X-ray images are passed with the grey value in all three channels.

use alloc::vec::Vec;

use burn::tensor::{DataError, Device, ExecutionError, Tensor, TensorData, Transaction};
use hnet_units::ImageSize;

use crate::model::{HNet, HNetOutput};

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
    pub force: [f32; 3],
}

impl StereoPrediction {
    /// Magnitude of the tip force in newtons.
    pub fn force_magnitude(&self) -> f32 {
        force_magnitude(self.force)
    }

    /// The prediction as one buffer: view A's mask, view B's mask (row-major, `size.pixels()`
    /// values each), then `(Fx, Fy, Fz)` in newtons. How the page's WebGPU worker hands a
    /// prediction to the page (crates/hnet-gpu).
    pub fn to_packed(&self) -> Vec<f32> {
        let mut values = Vec::with_capacity(self.mask_a.len() + self.mask_b.len() + 3);
        values.extend_from_slice(&self.mask_a);
        values.extend_from_slice(&self.mask_b);
        values.extend_from_slice(&self.force);
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
            force: [force[0], force[1], force[2]],
        })
    }
}

pub use hnet_units::force_magnitude;

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
    let shape = [pairs.len(), 3, size.height, size.width];
    Ok((
        Tensor::from_data(TensorData::new(a, shape), device),
        Tensor::from_data(TensorData::new(b, shape), device),
    ))
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
            force: [f[0], f[1], f[2]],
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
/// (`read`: what the device returned), split per pair. (Burn returns every registered output;
/// one that were missing would read as empty, giving no predictions rather than a panic.)
fn read_predictions(
    size: ImageSize,
    read: Result<Vec<TensorData>, ExecutionError>,
) -> Result<Vec<StereoPrediction>, PredictError> {
    let mut outputs = read.map_err(ReadbackError::Device)?.into_iter().map(to_vec);
    let mut next = || outputs.next().unwrap_or_else(|| Ok(Vec::new()));
    let (mask_a, mask_b, force) = (next()?, next()?, next()?);
    Ok(split_predictions(size, mask_a, mask_b, force))
}

impl HNet {
    /// Runs a batch of `pairs` and registers, for one read-back, the mask probabilities
    /// `[B, H·W]` of both views and the force `[B, 3]`.
    fn forward_batch(
        &self,
        pairs: &[StereoPair<'_>],
        size: ImageSize,
        device: &Device,
    ) -> Result<Transaction, InputSizeError> {
        let (a, b) = stereo_batch(pairs, size, device)?;
        let output: HNetOutput = self.forward(a, b);
        let batch = pairs.len() as i32;
        Ok(Transaction::default()
            .register(output.mask_a().reshape([batch, -1]))
            .register(output.mask_b().reshape([batch, -1]))
            .register(output.force))
    }

    /// Runs `pairs` (each image of `size`) and reads the results back, blocking until the device
    /// is done. Use [`HNet::predict_async`] in the browser.
    pub fn predict(
        &self,
        pairs: &[StereoPair<'_>],
        size: ImageSize,
        device: &Device,
    ) -> Result<Vec<StereoPrediction>, PredictError> {
        read_predictions(size, self.forward_batch(pairs, size, device)?.try_execute())
    }

    /// Like [`HNet::predict`], but waits for the device asynchronously (required on WebGPU in
    /// the browser, where the page must not block).
    pub async fn predict_async(
        &self,
        pairs: &[StereoPair<'_>],
        size: ImageSize,
        device: &Device,
    ) -> Result<Vec<StereoPrediction>, PredictError> {
        let read = self.forward_batch(pairs, size, device)?.execute_async();
        read_predictions(size, read.await)
    }
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
