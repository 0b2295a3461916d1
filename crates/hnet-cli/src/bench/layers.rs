//! `hnet bench layers`: where a training step's convolution time goes, layer by layer.
//!
//! Times every convolution of H-Net's shared encoder-decoder at the shapes one training step
//! gives it (both views of each pair run through the shared branch, so a batch of `B` pairs is
//! `2B` images): the forward pass, the gradient with respect to the weights, and the gradient with
//! respect to the input, each through the model's convolution calls (`hnet_conv`: the project's
//! kernels on flex, or Burn's own with `--kernels burn`) with autodiff tracking only the tensor
//! whose gradient is timed. `bench/pytorch_hnet.py --layers` times the same list.

use std::time::Instant;

use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Device, Distribution, Tensor};
use hnet_conv::{conv_transpose2d, conv2d};
use hnet_model::HNetConfig;
use hnet_units::ImageSize;
use serde::Serialize;

use super::Kernels;
use crate::backend::BackendChoice;

/// How a layer convolves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ConvKind {
    /// Stride 1, "same" padding.
    Same,
    /// Transposed, stride 2: doubles height and width.
    TransposedStride2,
}

/// One convolution of H-Net's shared encoder-decoder, with the input size it sees.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConvLayer {
    /// Where it sits (`encoder1.first`, `decoder2.up`, `head`, ...).
    pub name: String,
    pub kind: ConvKind,
    pub channels_in: usize,
    pub channels_out: usize,
    /// Square kernel side.
    pub kernel: usize,
    /// Input `[height, width]` in pixels.
    pub input_size: ImageSize,
    /// Whether training computes the gradient with respect to the input: not for the first
    /// layer, whose input is the images.
    pub input_grad: bool,
}

impl ConvLayer {
    /// Weights plus biases.
    pub fn params(&self) -> usize {
        self.channels_in * self.channels_out * self.kernel * self.kernel + self.channels_out
    }

    fn output_size(&self) -> ImageSize {
        match self.kind {
            ConvKind::Same => self.input_size,
            ConvKind::TransposedStride2 => {
                ImageSize::new(2 * self.input_size.width, 2 * self.input_size.height)
            }
        }
    }
}

/// The convolutions of one H-Net branch in the order a forward pass runs them.
pub fn hnet_convolutions(config: &HNetConfig) -> Vec<ConvLayer> {
    let f = config.filters;
    let at = |level: usize| {
        ImageSize::new(
            config.image_size.width >> level,
            config.image_size.height >> level,
        )
    };
    let same = |name: String, channels_in: usize, input_size: ImageSize| ConvLayer {
        input_grad: true,
        name,
        kind: ConvKind::Same,
        channels_in,
        channels_out: f,
        kernel: 3,
        input_size,
    };
    let mut layers = Vec::new();
    for level in 0..config.depth {
        let block = format!("encoder{}", level + 1);
        if level == 0 {
            // Its input is the images, which need no gradient.
            layers.push(ConvLayer {
                input_grad: false,
                ..same(format!("{block}.first"), config.in_channels, at(0))
            });
        } else {
            layers.push(same(format!("{block}.first"), f, at(level)));
        }
        layers.push(same(format!("{block}.second"), f, at(level)));
    }
    layers.push(same("bottleneck.first".into(), f, at(config.depth)));
    layers.push(same("bottleneck.second".into(), f, at(config.depth)));
    for block in 0..config.depth {
        let below = at(config.depth - block);
        let name = format!("decoder{}", block + 1);
        layers.push(ConvLayer {
            name: format!("{name}.up"),
            kind: ConvKind::TransposedStride2,
            channels_in: f,
            channels_out: f,
            kernel: 3,
            input_size: below,
            input_grad: true,
        });
        let size = at(config.depth - block - 1);
        layers.push(same(format!("{name}.first"), 2 * f, size));
        layers.push(same(format!("{name}.second"), f, size));
    }
    layers.push(ConvLayer {
        name: "head".into(),
        kind: ConvKind::Same,
        channels_in: f,
        channels_out: 1,
        kernel: 1,
        input_size: config.image_size,
        input_grad: true,
    });
    layers
}

#[derive(clap::Args, Debug)]
pub struct LayersBench {
    /// Backend to measure.
    #[arg(long, value_enum, default_value = "flex")]
    backend: BackendChoice,
    /// Whose convolution kernels flex runs.
    #[arg(long, value_enum, default_value = "project")]
    kernels: Kernels,
    /// Image side in pixels.
    #[arg(long, default_value_t = 64)]
    size: usize,
    /// Stereo pairs per training batch (each convolution sees twice as many images).
    #[arg(long, default_value_t = 8)]
    batch: usize,
    /// Timed repetitions of each measurement (after one warm-up); the median is kept.
    #[arg(long, default_value_t = 10)]
    runs: usize,
    /// Time only the layers whose name contains this (`encoder1`, `decoder4.first`, `up`).
    #[arg(long)]
    only: Option<String>,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// Milliseconds per pass of one layer.
#[derive(Debug, Serialize)]
struct LayerTimes {
    #[serde(flatten)]
    layer: ConvLayer,
    params: usize,
    forward_ms: f64,
    weight_grad_ms: f64,
    /// `None` where training does not compute it.
    input_grad_ms: Option<f64>,
}

#[derive(Serialize)]
struct LayersResult {
    backend: &'static str,
    kernels: Kernels,
    size: usize,
    batch: usize,
    images_per_convolution: usize,
    threads: usize,
    layers: Vec<LayerTimes>,
    total_forward_ms: f64,
    total_weight_grad_ms: f64,
    total_input_grad_ms: f64,
}

/// Median wall time of `runs` calls of `f` in milliseconds, after one warm-up call.
fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut times: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Which tensor autodiff tracks in a timed backward pass.
#[derive(Clone, Copy, PartialEq)]
enum Tracked {
    Nothing,
    Weight,
    Input,
}

fn time_layer(layer: &ConvLayer, images: usize, runs: usize, device: &Device) -> LayerTimes {
    let [h, w] = layer.input_size.height_width();
    let [oh, ow] = layer.output_size().height_width();
    let (ci, co, k) = (layer.channels_in, layer.channels_out, layer.kernel);
    let random = |shape: [usize; 4]| Tensor::<4>::random(shape, Distribution::Default, device);
    let x = random([images, ci, h, w]);
    // Burn's transposed convolutions store weights as [in, out, k, k].
    let weight = match layer.kind {
        ConvKind::Same => random([co, ci, k, k]),
        ConvKind::TransposedStride2 => random([ci, co, k, k]),
    };
    let bias = Tensor::<1>::random([co], Distribution::Default, device);
    // A fixed upstream gradient: the loss is sum(output * upstream).
    let upstream = random([images, co, oh, ow]);
    let forward = |x: Tensor<4>, weight: Tensor<4>| match layer.kind {
        ConvKind::Same => conv2d(
            x,
            weight,
            Some(bias.clone()),
            ConvOptions::new([1, 1], [k / 2, k / 2], [1, 1], 1),
        ),
        ConvKind::TransposedStride2 => conv_transpose2d(
            x,
            weight,
            Some(bias.clone()),
            ConvTransposeOptions::new([2, 2], [1, 1], [1, 1], [1, 1], 1),
        ),
    };
    let pass = |tracked: Tracked| {
        let (x, weight) = match tracked {
            Tracked::Nothing => (x.clone(), weight.clone()),
            Tracked::Weight => (x.clone(), weight.clone().require_grad()),
            Tracked::Input => (x.clone().require_grad(), weight.clone()),
        };
        let y = forward(x.clone(), weight.clone());
        if tracked == Tracked::Nothing {
            let _ = y.into_data();
            return;
        }
        let grads = (y * upstream.clone()).sum().backward();
        let of = if tracked == Tracked::Weight {
            weight
        } else {
            x
        };
        let _ = of.grad(&grads).expect("tracked").into_data();
    };
    // What the loss itself costs (multiply, sum and their backward), to subtract.
    let loss_only = median_ms(runs, || {
        let y = random([images, co, oh, ow]).require_grad();
        let grads = (y.clone() * upstream.clone()).sum().backward();
        let _ = y.grad(&grads).expect("tracked").into_data();
    }) - median_ms(runs, || {
        let _ = random([images, co, oh, ow]).into_data();
    });
    let forward_ms = median_ms(runs, || pass(Tracked::Nothing));
    let backward = |tracked| (median_ms(runs, || pass(tracked)) - forward_ms - loss_only).max(0.0);
    LayerTimes {
        layer: layer.clone(),
        params: layer.params(),
        forward_ms,
        weight_grad_ms: backward(Tracked::Weight),
        input_grad_ms: layer.input_grad.then(|| backward(Tracked::Input)),
    }
}

pub fn run(args: &LayersBench) -> anyhow::Result<()> {
    let config = HNetConfig::new().with_image_size(ImageSize::square(args.size));
    config.validate()?;
    args.kernels.select();
    let device = args.backend.device()?.autodiff();
    let images = 2 * args.batch;
    let layers: Vec<LayerTimes> = hnet_convolutions(&config)
        .iter()
        .filter(|layer| {
            args.only
                .as_ref()
                .is_none_or(|only| layer.name.contains(only))
        })
        .map(|layer| time_layer(layer, images, args.runs, &device))
        .collect();
    let total = |f: fn(&LayerTimes) -> f64| layers.iter().map(f).sum::<f64>();
    let result = LayersResult {
        backend: args.backend.name(),
        kernels: args.kernels,
        size: args.size,
        batch: args.batch,
        images_per_convolution: images,
        threads: rayon::current_num_threads(),
        total_forward_ms: total(|l| l.forward_ms),
        total_weight_grad_ms: total(|l| l.weight_grad_ms),
        total_input_grad_ms: total(|l| l.input_grad_ms.unwrap_or(0.0)),
        layers,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
        return Ok(());
    }
    println!(
        "{} ({:?} kernels): H-Net convolutions at {}x{}, {} images each (batch of {} pairs), {} threads, median of {} runs (ms)",
        result.backend,
        result.kernels,
        args.size,
        args.size,
        images,
        args.batch,
        result.threads,
        args.runs
    );
    println!(
        "{:<18} {:>9} {:>11} {:>8} {:>12} {:>11}",
        "layer", "in -> out", "input", "forward", "weight grad", "input grad"
    );
    for l in &result.layers {
        println!(
            "{:<18} {:>9} {:>11} {:>8.2} {:>12.2} {:>11}",
            l.layer.name,
            format!("{} -> {}", l.layer.channels_in, l.layer.channels_out),
            l.layer.input_size.to_string(),
            l.forward_ms,
            l.weight_grad_ms,
            l.input_grad_ms
                .map_or_else(|| "-".to_string(), |ms| format!("{ms:.2}"))
        );
    }
    println!(
        "{:<18} {:>9} {:>11} {:>8.1} {:>12.1} {:>11.1}",
        "total",
        "",
        "",
        result.total_forward_ms,
        result.total_weight_grad_ms,
        result.total_input_grad_ms
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::Module;

    /// The listed convolutions are exactly the network's: their parameters add up to H-Net's
    /// minus the force head's dense layers.
    #[test]
    fn the_listed_convolutions_are_the_networks() {
        let config = HNetConfig::new().with_image_size(ImageSize::square(64));
        let layers = hnet_convolutions(&config);
        let net = config.init(&Device::flex()).unwrap();
        let features = 2 * config.pooled_features_per_view();
        let [h1, h2] = config.force_hidden;
        let dense = features * h1 + h1 + h1 * h2 + h2 + h2 * 3 + 3;
        let conv: usize = layers.iter().map(ConvLayer::params).sum();
        assert_eq!(conv + dense, net.num_params());
        assert_eq!(layers.len(), 2 * config.depth + 2 + 3 * config.depth + 1);
        assert_eq!(layers[0].input_size, ImageSize::square(64));
        assert_eq!(layers[2 * config.depth].input_size, ImageSize::square(4));
        assert_eq!(layers.last().unwrap().input_size, ImageSize::square(64));
    }

    #[test]
    fn every_layer_is_timed() {
        let config = HNetConfig::new()
            .with_image_size(ImageSize::square(16))
            .with_filters(4)
            .with_depth(2);
        let device = Device::flex().autodiff();
        for layer in hnet_convolutions(&config) {
            let t = time_layer(&layer, 2, 1, &device);
            assert!(t.forward_ms > 0.0, "{}", layer.name);
            assert!(t.weight_grad_ms >= 0.0);
            assert_eq!(t.input_grad_ms.is_some(), layer.name != "encoder1.first");
            assert_eq!(layer.input_grad, layer.name != "encoder1.first");
        }
    }
}
