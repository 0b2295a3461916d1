//! How the kernels plug into Burn: a backend extension (Burn's `#[backend_extension]`) with the
//! two operations, implemented for flex by the project's kernels and for `Autodiff<Flex>` with a
//! backward pass of its own. Other backends never reach it: [`crate::conv2d`] and
//! [`crate::conv_transpose2d`] send them to Burn's own operations.

use burn::backend::ops::{ActivationOps, ModuleOps};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, ExtensionType, Flex, backend_extension};
use burn::tensor::DType;
use burn::tensor::TensorData;
use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn_flex::FlexTensor;

use crate::geometry::ConvGeometry;
use crate::kernels;
use crate::pooling::{self, PoolShape};

/// A convolution's bias, when it has one.
#[derive(ExtensionType)]
pub enum ConvBias<B: Backend> {
    /// One value per output channel, `[out_channels]`.
    With(FloatTensor<B>),
    /// No bias.
    Without,
}

/// The convolutions the project computes itself. Their results equal Burn's `conv2d` and
/// `conv_transpose2d` (same arguments, same shapes) to float rounding.
#[backend_extension(Flex, Autodiff: cfg(feature = "autodiff"))]
pub trait ProjectConvBackend: Backend {
    /// `conv2d(x, weight, bias, options)`: x `[n, c, h, w]`, weight `[o, c, kh, kw]`; then
    /// `relu` of it when `relu` (fused into the kernels' store, and its backward into the
    /// convolution's).
    fn project_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        #[extension_type] bias: ConvBias<Self>,
        options: ConvOptions<2>,
        relu: bool,
    ) -> FloatTensor<Self>;

    /// `conv_transpose2d(x, weight, bias, options)`: x `[n, c, h, w]`, weight `[c, o, kh, kw]`.
    fn project_conv_transpose2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        #[extension_type] bias: ConvBias<Self>,
        options: ConvTransposeOptions<2>,
    ) -> FloatTensor<Self>;

    /// `max_pool2d(x, [2, 2])` (stride 2, no padding): x `[n, c, h, w]`.
    fn project_max_pool2x2(x: FloatTensor<Self>) -> FloatTensor<Self>;
}

/// Burn's own 2 x 2 max pooling (stride 2, no padding), for what the kernel does not cover.
fn burn_max_pool2x2<B: Backend>(x: FloatTensor<B>) -> FloatTensor<B> {
    B::max_pool2d(x, [2, 2], [2, 2], [0, 0], [1, 1], false)
}

/// The pooling's shape when the kernel covers `x` (f32, four dimensions).
fn pool_shape(x: &FlexTensor) -> Option<PoolShape> {
    (x.dtype() == DType::F32 && x.layout().shape().num_dims() == 4).then(|| PoolShape::of(dims4(x)))
}

/// The kernel's 2 x 2 max pooling of a covered flex tensor.
fn max_pool(shape: &PoolShape, x: &FlexTensor) -> FlexTensor {
    with_values(x, |x| {
        flex_tensor(pooling::max_pool2x2(shape, x), shape.output_dims())
    })
}

impl<B: Backend> ConvBias<B> {
    fn into_option(self) -> Option<FloatTensor<B>> {
        match self {
            ConvBias::With(bias) => Some(bias),
            ConvBias::Without => None,
        }
    }
}

/// A flex tensor's shape as four dimensions.
fn dims4(t: &FlexTensor) -> [usize; 4] {
    let shape = t.layout().shape();
    core::array::from_fn(|i| shape.get(i).copied().unwrap_or(0))
}

/// Runs `read` on a flex tensor's values in row-major order (copying only when its layout is
/// not contiguous).
fn with_values<R>(t: &FlexTensor, read: impl FnOnce(&[f32]) -> R) -> R {
    match t.as_slice::<f32>() {
        Some(values) => read(values),
        None => read(t.to_contiguous().as_slice::<f32>().expect("contiguous f32")),
    }
}

/// A new contiguous flex tensor.
fn flex_tensor(values: Vec<f32>, shape: [usize; 4]) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, shape))
}

/// True when the project's kernels compute these tensors: f32, four and one dimensions.
fn f32_operands(x: &FlexTensor, weight: &FlexTensor, bias: Option<&FlexTensor>) -> bool {
    let f32_rank = |t: &FlexTensor, rank: usize| {
        t.dtype() == DType::F32 && t.layout().shape().num_dims() == rank
    };
    f32_rank(x, 4) && f32_rank(weight, 4) && bias.is_none_or(|b| f32_rank(b, 1))
}

/// What the forward pass of a covered convolution computes, on flex tensors.
#[derive(Debug, Clone, Copy)]
enum Direction {
    /// `conv2d`: the kernels' forward.
    Convolution,
    /// `conv_transpose2d`: the adjoint convolution's input gradient.
    Transposed,
}

fn bias_matches(g: &ConvGeometry, direction: Direction, bias: Option<&FlexTensor>) -> bool {
    let channels = match direction {
        Direction::Convolution => g.out_channels,
        Direction::Transposed => g.in_channels,
    };
    bias.is_none_or(|b| b.layout().shape()[0] == channels)
}

/// The forward pass on flex, for a geometry the kernels cover; a convolution's followed by a
/// ReLU when `relu`.
fn forward(
    g: &ConvGeometry,
    direction: Direction,
    x: &FlexTensor,
    weight: &FlexTensor,
    bias: Option<&FlexTensor>,
    relu: bool,
) -> FlexTensor {
    with_values(x, |x| {
        with_values(weight, |w| {
            let run = |bias: Option<&[f32]>| match direction {
                Direction::Convolution => {
                    flex_tensor(kernels::forward(g, x, w, bias, relu), g.output_shape())
                }
                Direction::Transposed => {
                    debug_assert!(!relu, "no fused ReLU for transposed convolutions");
                    flex_tensor(kernels::input_gradient(g, w, x, bias), g.input_shape())
                }
            };
            match bias {
                Some(bias) => with_values(bias, |b| run(Some(b))),
                None => run(None),
            }
        })
    })
}

/// The gradients of a covered convolution's input, weight and bias, on flex.
#[cfg(feature = "autodiff")]
struct Gradients {
    x: Option<FlexTensor>,
    weight: Option<FlexTensor>,
    bias: Option<FlexTensor>,
}

/// Which gradients to compute.
#[cfg(feature = "autodiff")]
#[derive(Debug, Clone, Copy)]
struct Wanted {
    x: bool,
    weight: bool,
    bias: bool,
}

#[cfg(feature = "autodiff")]
fn gradients(
    g: &ConvGeometry,
    direction: Direction,
    x: &FlexTensor,
    weight: &FlexTensor,
    dy: &FlexTensor,
    wanted: Wanted,
) -> Gradients {
    let weight_shape = g.weight_shape();
    with_values(x, |x_values| {
        with_values(weight, |w| {
            with_values(dy, |dy| match direction {
                // y = conv(x): dx = raise(Wᵀ dy), dW = dy lower(x)ᵀ.
                Direction::Convolution => Gradients {
                    x: wanted.x.then(|| {
                        flex_tensor(kernels::input_gradient(g, w, dy, None), g.input_shape())
                    }),
                    weight: wanted.weight.then(|| {
                        flex_tensor(kernels::weight_gradient(g, x_values, dy), weight_shape)
                    }),
                    bias: wanted.bias.then(|| {
                        let db = kernels::channel_sums(dy, g.out_channels, g.output_plane());
                        FlexTensor::from_data(TensorData::new(db, [g.out_channels]))
                    }),
                },
                // y = raise(Wᵀ x), the adjoint's input gradient: dx = conv(dy), dW = x lower(dy)ᵀ.
                Direction::Transposed => Gradients {
                    x: wanted.x.then(|| {
                        flex_tensor(kernels::forward(g, dy, w, None, false), g.output_shape())
                    }),
                    weight: wanted.weight.then(|| {
                        flex_tensor(kernels::weight_gradient(g, dy, x_values), weight_shape)
                    }),
                    bias: wanted.bias.then(|| {
                        let db = kernels::channel_sums(dy, g.in_channels, g.input_plane());
                        FlexTensor::from_data(TensorData::new(db, [g.in_channels]))
                    }),
                },
            })
        })
    })
}

fn conv2d_geometry(
    x: &FlexTensor,
    weight: &FlexTensor,
    bias: Option<&FlexTensor>,
    options: &ConvOptions<2>,
) -> Option<ConvGeometry> {
    if !f32_operands(x, weight, bias) {
        return None;
    }
    ConvGeometry::of_conv2d(dims4(x), dims4(weight), options)
        .filter(|g| bias_matches(g, Direction::Convolution, bias))
}

fn conv_transpose2d_geometry(
    x: &FlexTensor,
    weight: &FlexTensor,
    bias: Option<&FlexTensor>,
    options: &ConvTransposeOptions<2>,
) -> Option<ConvGeometry> {
    if !f32_operands(x, weight, bias) {
        return None;
    }
    ConvGeometry::of_conv_transpose2d(dims4(x), dims4(weight), options)
        .filter(|g| bias_matches(g, Direction::Transposed, bias))
}

impl ProjectConvBackend for Flex {
    fn project_conv2d(
        x: FlexTensor,
        weight: FlexTensor,
        bias: ConvBias<Self>,
        options: ConvOptions<2>,
        relu: bool,
    ) -> FlexTensor {
        let bias = bias.into_option();
        match conv2d_geometry(&x, &weight, bias.as_ref(), &options) {
            Some(g) => forward(&g, Direction::Convolution, &x, &weight, bias.as_ref(), relu),
            None => {
                let y = <Flex as ModuleOps<Flex>>::conv2d(x, weight, bias, options);
                if relu {
                    <Flex as ActivationOps<Flex>>::relu(y)
                } else {
                    y
                }
            }
        }
    }

    fn project_conv_transpose2d(
        x: FlexTensor,
        weight: FlexTensor,
        bias: ConvBias<Self>,
        options: ConvTransposeOptions<2>,
    ) -> FlexTensor {
        let bias = bias.into_option();
        match conv_transpose2d_geometry(&x, &weight, bias.as_ref(), &options) {
            Some(g) => forward(&g, Direction::Transposed, &x, &weight, bias.as_ref(), false),
            None => <Flex as ModuleOps<Flex>>::conv_transpose2d(x, weight, bias, options),
        }
    }

    fn project_max_pool2x2(x: FlexTensor) -> FlexTensor {
        match pool_shape(&x) {
            Some(shape) => max_pool(&shape, &x),
            None => burn_max_pool2x2::<Flex>(x),
        }
    }
}

#[cfg(feature = "autodiff")]
mod autodiff {
    use burn::backend::Autodiff;
    use burn::backend::Flex;
    use burn::backend::autodiff::checkpoint::base::Checkpointer;
    use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
    use burn::backend::autodiff::grads::Gradients as GradientStore;
    use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
    use burn::backend::ops::{ActivationOps, ModuleOps};
    use burn::backend::tensor::FloatTensor;
    use burn::tensor::TensorData;
    use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
    use burn_flex::FlexTensor;

    use super::{
        ConvBias, Direction, ProjectConvBackend, Wanted, burn_max_pool2x2,
        conv_transpose2d_geometry, conv2d_geometry, flex_tensor, forward, gradients, max_pool,
        pool_shape, with_values,
    };
    use crate::geometry::ConvGeometry;
    use crate::pooling::{self, PoolShape};

    /// The backward step of a covered max pooling: its input, kept from the forward pass, where
    /// each window's winner is found again.
    #[derive(Debug)]
    struct MaxPoolBackward;

    impl Backward<Flex, 1> for MaxPoolBackward {
        type State = (PoolShape, FlexTensor);

        fn backward(
            self,
            ops: Ops<Self::State, 1>,
            grads: &mut GradientStore,
            _checkpointer: &mut Checkpointer,
        ) {
            let dy = grads.consume::<Flex>(&ops.node);
            let (shape, x) = &ops.state;
            if let [Some(node)] = &ops.parents {
                let dx = with_values(x, |x| {
                    with_values(&dy, |dy| pooling::max_pool2x2_backward(shape, x, dy))
                });
                grads.register::<Flex>(node.id, flex_tensor(dx, shape.input_dims()));
            }
        }
    }

    /// The backward step of a covered convolution: its inputs, kept from the forward pass.
    #[derive(Debug)]
    struct ConvBackward;

    #[derive(Debug, Clone)]
    struct ConvState {
        geometry: ConvGeometry,
        direction: Direction,
        x: FlexTensor,
        weight: FlexTensor,
        /// The result, when a ReLU was fused into the convolution: its backward passes the
        /// output gradient only where the result is positive.
        relu_output: Option<FlexTensor>,
    }

    impl<const N: usize> Backward<Flex, N> for ConvBackward {
        type State = ConvState;

        fn backward(
            self,
            ops: Ops<Self::State, N>,
            grads: &mut GradientStore,
            _checkpointer: &mut Checkpointer,
        ) {
            let dy = grads.consume::<Flex>(&ops.node);
            let dy = match &ops.state.relu_output {
                Some(y) => relu_backward(&dy, y),
                None => dy,
            };
            let parent = |i: usize| ops.parents.get(i).cloned().flatten();
            let (x_node, weight_node, bias_node) = (parent(0), parent(1), parent(2));
            let s = ops.state;
            let wanted = Wanted {
                x: x_node.is_some(),
                weight: weight_node.is_some(),
                bias: bias_node.is_some(),
            };
            let computed = gradients(&s.geometry, s.direction, &s.x, &s.weight, &dy, wanted);
            for (node, gradient) in [
                (x_node, computed.x),
                (weight_node, computed.weight),
                (bias_node, computed.bias),
            ] {
                if let (Some(node), Some(gradient)) = (node, gradient) {
                    grads.register::<Flex>(node.id, gradient);
                }
            }
        }
    }

    /// `dy` where `y > 0` (or is NaN), else 0: a ReLU's backward, from its output `y`, as Burn's
    /// flex computes it (on every rayon worker with `rayon`).
    fn relu_backward(dy: &FlexTensor, y: &FlexTensor) -> FlexTensor {
        let shape = dy.layout().shape().clone();
        let pass = |&d: &f32, &y: &f32| if y.is_nan() || y > 0.0 { d } else { 0.0 };
        with_values(dy, |dy| {
            with_values(y, |y| {
                #[cfg(feature = "rayon")]
                let masked: Vec<f32> = {
                    use rayon::prelude::*;
                    dy.par_iter().zip(y).map(|(d, y)| pass(d, y)).collect()
                };
                #[cfg(not(feature = "rayon"))]
                let masked: Vec<f32> = dy.iter().zip(y).map(|(d, y)| pass(d, y)).collect();
                FlexTensor::from_data(TensorData::new(masked, shape))
            })
        })
    }

    /// Records a covered convolution (with its fused ReLU when `relu`) on the autodiff graph
    /// (when any operand is tracked) and computes its forward pass.
    fn tracked<C: CheckpointStrategy>(
        geometry: ConvGeometry,
        direction: Direction,
        x: FloatTensor<Autodiff<Flex, C>>,
        weight: FloatTensor<Autodiff<Flex, C>>,
        bias: Option<FloatTensor<Autodiff<Flex, C>>>,
        relu: bool,
    ) -> FloatTensor<Autodiff<Flex, C>> {
        let run = |bias: Option<&FlexTensor>| {
            forward(
                &geometry,
                direction,
                x.primitive(),
                weight.primitive(),
                bias,
                relu,
            )
        };
        let state = |y: &FlexTensor| ConvState {
            geometry,
            direction,
            x: x.primitive().clone(),
            weight: weight.primitive().clone(),
            relu_output: relu.then(|| y.clone()),
        };
        match &bias {
            Some(b) => match ConvBackward
                .prepare::<C>([x.node(), weight.node(), b.node()])
                .compute_bound()
                .stateful()
            {
                OpsKind::Tracked(prep) => {
                    let y = run(Some(b.primitive()));
                    prep.finish(state(&y), y)
                }
                OpsKind::UnTracked(prep) => prep.finish(run(Some(b.primitive()))),
            },
            None => match ConvBackward
                .prepare::<C>([x.node(), weight.node()])
                .compute_bound()
                .stateful()
            {
                OpsKind::Tracked(prep) => {
                    let y = run(None);
                    prep.finish(state(&y), y)
                }
                OpsKind::UnTracked(prep) => prep.finish(run(None)),
            },
        }
    }

    impl<C: CheckpointStrategy> ProjectConvBackend for Autodiff<Flex, C> {
        fn project_conv2d(
            x: FloatTensor<Self>,
            weight: FloatTensor<Self>,
            bias: ConvBias<Self>,
            options: ConvOptions<2>,
            relu: bool,
        ) -> FloatTensor<Self> {
            let bias = bias.into_option();
            let geometry = conv2d_geometry(
                x.primitive(),
                weight.primitive(),
                bias.as_ref().map(|b| b.primitive()),
                &options,
            );
            match geometry {
                Some(g) => tracked::<C>(g, Direction::Convolution, x, weight, bias, relu),
                None => {
                    let y = <Self as ModuleOps<Self>>::conv2d(x, weight, bias, options);
                    if relu {
                        <Self as ActivationOps<Self>>::relu(y)
                    } else {
                        y
                    }
                }
            }
        }

        fn project_conv_transpose2d(
            x: FloatTensor<Self>,
            weight: FloatTensor<Self>,
            bias: ConvBias<Self>,
            options: ConvTransposeOptions<2>,
        ) -> FloatTensor<Self> {
            let bias = bias.into_option();
            let geometry = conv_transpose2d_geometry(
                x.primitive(),
                weight.primitive(),
                bias.as_ref().map(|b| b.primitive()),
                &options,
            );
            match geometry {
                Some(g) => tracked::<C>(g, Direction::Transposed, x, weight, bias, false),
                None => <Self as ModuleOps<Self>>::conv_transpose2d(x, weight, bias, options),
            }
        }

        fn project_max_pool2x2(x: FloatTensor<Self>) -> FloatTensor<Self> {
            let Some(shape) = pool_shape(x.primitive()) else {
                return burn_max_pool2x2::<Self>(x);
            };
            match MaxPoolBackward
                .prepare::<C>([x.node()])
                .compute_bound()
                .stateful()
            {
                OpsKind::Tracked(prep) => {
                    let y = max_pool(&shape, x.primitive());
                    prep.finish((shape, x.primitive().clone()), y)
                }
                OpsKind::UnTracked(prep) => prep.finish(max_pool(&shape, x.primitive())),
            }
        }
    }
}
