
// A/B of Burn 0.23.0-pre.1's own flex convolutions, timed exactly as `hnet bench layers`
// (crates/hnet-cli/src/bench/layers.rs, whose time_layer is copied here) at 64 x 64, batch 8.
use std::time::Instant;
use burn::tensor::module::{conv_transpose2d, conv2d};
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Device, Distribution, Tensor};

#[derive(Clone, Copy, PartialEq)]
enum ConvKind { Same, TransposedStride2 }
#[derive(Clone)]
struct ConvLayer { name: String, kind: ConvKind, channels_in: usize, channels_out: usize, kernel: usize, input_size: Size, input_grad: bool }
#[derive(Clone, Copy)]
struct Size { width: usize, height: usize }
impl Size { fn height_width(&self) -> [usize; 2] { [self.height, self.width] } }
impl ConvLayer {
    fn params(&self) -> usize { self.channels_in * self.channels_out * self.kernel * self.kernel + self.channels_out }
    fn output_size(&self) -> Size { match self.kind { ConvKind::Same => self.input_size, ConvKind::TransposedStride2 => Size { width: 2 * self.input_size.width, height: 2 * self.input_size.height } } }
}
#[allow(dead_code)]
struct LayerTimes { layer: ConvLayer, params: usize, forward_ms: f64, weight_grad_ms: f64, input_grad_ms: Option<f64> }

fn layers(size: usize) -> Vec<ConvLayer> {
    let f = 32; let depth = 4;
    let at = |l: usize| Size { width: size >> l, height: size >> l };
    let same = |name: String, ci: usize, s: Size| ConvLayer { name, kind: ConvKind::Same, channels_in: ci, channels_out: f, kernel: 3, input_size: s, input_grad: true };
    let mut v = Vec::new();
    for l in 0..depth {
        let b = format!("encoder{}", l + 1);
        if l == 0 { v.push(ConvLayer { input_grad: false, ..same(format!("{b}.first"), 3, at(0)) }); } else { v.push(same(format!("{b}.first"), f, at(l))); }
        v.push(same(format!("{b}.second"), f, at(l)));
    }
    v.push(same("bottleneck.first".into(), f, at(depth)));
    v.push(same("bottleneck.second".into(), f, at(depth)));
    for b in 0..depth {
        let name = format!("decoder{}", b + 1);
        v.push(ConvLayer { name: format!("{name}.up"), kind: ConvKind::TransposedStride2, channels_in: f, channels_out: f, kernel: 3, input_size: at(depth - b), input_grad: true });
        v.push(same(format!("{name}.first"), 2 * f, at(depth - b - 1)));
        v.push(same(format!("{name}.second"), f, at(depth - b - 1)));
    }
    v.push(ConvLayer { name: "head".into(), kind: ConvKind::Same, channels_in: f, channels_out: 1, kernel: 1, input_size: at(0), input_grad: true });
    v
}

fn main() {
    let size: usize = std::env::args().nth(1).map_or(64, |s| s.parse().unwrap());
    let runs: usize = std::env::args().nth(2).map_or(9, |s| s.parse().unwrap());
    let device = Device::flex().autodiff();
    let (mut f, mut w, mut i) = (0.0, 0.0, 0.0);
    for layer in layers(size) {
        let t = time_layer(&layer, 16, runs, &device);
        println!("{:<18} {:>8.2} {:>8.2} {:>8}", layer.name, t.forward_ms, t.weight_grad_ms, t.input_grad_ms.map_or("-".into(), |v| format!("{v:.2}")));
        f += t.forward_ms; w += t.weight_grad_ms; i += t.input_grad_ms.unwrap_or(0.0);
    }
    println!("total forward {f:.1} weight grad {w:.1} input grad {i:.1} (burn 0.23.0-pre.1 flex, {size}x{size}, 16 images, median of {runs})");
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

