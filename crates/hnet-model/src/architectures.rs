//! H-Net and its baselines behind one type, so that one training and evaluation harness (and
//! one weights format) serves them all.
//!
//! Each network is described once, by an [`Architecture`] implementation on its settings type
//! (name, heads, input, size rule, how to build and run it); the `architectures!` list below
//! turns those into [`ModelSpec`] (which network, with its settings) and [`StereoModel`] (the
//! network). Adding a network is one `impl Architecture` and one line in that list.

use alloc::collections::BTreeMap;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::fmt;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::baselines::{Fcn, FcnConfig, HrNet, HrNetConfig, UNet, UNetConfig, YNet, YNetConfig};
use crate::model::{HNet, HNetConfig, HNetConfigError};
use crate::weights::{self, ConfigProblem, WeightsError, WeightsHeader, WeightsProblem};

/// What a network takes as its two inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StereoInput {
    /// The two images `[B, 3, H, W]`.
    Images,
    /// The two catheter masks `[B, 1, H, W]` (Y-Net).
    Masks,
}

/// What a network produced for a batch of `B` pairs.
#[derive(Debug, Clone)]
pub struct StereoOutputs {
    /// Mask logits of view A and view B `[B, 1, H, W]`, for networks that segment.
    pub mask_logits: Option<[Tensor<4>; 2]>,
    /// Tip force `[B, 3]` in newtons, for networks that estimate it.
    pub force: Option<Tensor<2>>,
}

/// Everything the harness needs to know about one network, implemented on its settings type.
pub trait Architecture: Clone + Serialize + DeserializeOwned {
    /// The network these settings build.
    type Network: Module;
    /// The name in weights files, configs and on the command line (`hnet`, `unet`, ...).
    const NAME: &'static str;
    /// Whether it has mask heads.
    const SEGMENTS: bool;
    /// Whether it estimates the tip force.
    const ESTIMATES_FORCE: bool;
    /// What it reads.
    const INPUT: StereoInput;
    /// The architecture's default settings.
    fn defaults() -> Self;
    /// Image sides (pixels) must be multiples of this.
    fn size_multiple(&self) -> usize;
    /// Builds the network with fresh weights.
    fn build(&self, device: &Device) -> Result<Self::Network, HNetConfigError>;
    /// Runs it on `views` (images `[B, 3, H, W]`) or `masks` (`[B, 1, H, W]`), per [`Self::INPUT`].
    fn run(network: &Self::Network, views: [Tensor<4>; 2], masks: [Tensor<4>; 2]) -> StereoOutputs;
}

/// Runs a single-view segmentation network on both views as one batch.
fn both_views(views: [Tensor<4>; 2], net: impl Fn(Tensor<4>) -> Tensor<4>) -> [Tensor<4>; 2] {
    let [a, b] = views;
    let batch = a.dims()[0];
    let logits = net(Tensor::cat(alloc::vec![a, b], 0));
    [
        logits.clone().narrow(0, 0, batch),
        logits.narrow(0, batch, batch),
    ]
}

impl Architecture for HNetConfig {
    type Network = HNet;
    const NAME: &'static str = "hnet";
    const SEGMENTS: bool = true;
    const ESTIMATES_FORCE: bool = true;
    const INPUT: StereoInput = StereoInput::Images;
    fn defaults() -> Self {
        Self::new()
    }
    fn size_multiple(&self) -> usize {
        1 << self.depth.min(16)
    }
    fn build(&self, device: &Device) -> Result<HNet, HNetConfigError> {
        self.init(device)
    }
    fn run(net: &HNet, [a, b]: [Tensor<4>; 2], _masks: [Tensor<4>; 2]) -> StereoOutputs {
        let out = net.forward(a, b);
        StereoOutputs {
            mask_logits: Some([out.mask_logits_a, out.mask_logits_b]),
            force: Some(out.force),
        }
    }
}

/// The [`Architecture`] of a single-view segmentation network (masks only, run on both views as
/// one batch): its settings type, network, name and size rule.
macro_rules! single_view_segmenter {
    ($settings:ty => $network:ty, $name:literal, |$config:ident| $size_multiple:expr) => {
        impl Architecture for $settings {
            type Network = $network;
            const NAME: &'static str = $name;
            const SEGMENTS: bool = true;
            const ESTIMATES_FORCE: bool = false;
            const INPUT: StereoInput = StereoInput::Images;
            fn defaults() -> Self {
                Self::new()
            }
            fn size_multiple(&self) -> usize {
                let $config = self;
                $size_multiple
            }
            fn build(&self, device: &Device) -> Result<$network, HNetConfigError> {
                Ok(self.init(device))
            }
            fn run(net: &$network, views: [Tensor<4>; 2], _: [Tensor<4>; 2]) -> StereoOutputs {
                StereoOutputs {
                    mask_logits: Some(both_views(views, |x| net.forward(x))),
                    force: None,
                }
            }
        }
    };
}

single_view_segmenter!(UNetConfig => UNet, "unet", |c| 1 << c.depth.min(16));
single_view_segmenter!(FcnConfig => Fcn, "fcn", |_c| 32);
single_view_segmenter!(HrNetConfig => HrNet, "hrnet", |_c| 16);

impl Architecture for YNetConfig {
    type Network = YNet;
    const NAME: &'static str = "ynet";
    const SEGMENTS: bool = false;
    const ESTIMATES_FORCE: bool = true;
    const INPUT: StereoInput = StereoInput::Masks;
    fn defaults() -> Self {
        Self::new()
    }
    fn size_multiple(&self) -> usize {
        8
    }
    fn build(&self, device: &Device) -> Result<YNet, HNetConfigError> {
        Ok(self.init(device))
    }
    fn run(net: &YNet, _views: [Tensor<4>; 2], [a, b]: [Tensor<4>; 2]) -> StereoOutputs {
        StereoOutputs {
            mask_logits: None,
            force: Some(net.forward(a, b)),
        }
    }
}

/// Declares [`ModelSpec`] and [`StereoModel`] from the list of architectures and dispatches every
/// method to the variant's [`Architecture`] implementation.
macro_rules! architectures {
    ($($(#[$doc:meta])* $variant:ident($settings:ty),)+) => {
        /// Which network, with its settings. Serialised as `{"architecture": "hnet", ...settings}`.
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(tag = "architecture", rename_all = "lowercase")]
        pub enum ModelSpec {
            $($(#[$doc])* $variant($settings),)+
        }

        /// Any of the networks.
        // One value per training run or page, never in a collection: the size of the largest
        // variant (H-Net's layer records) costs nothing, and Burn's `Module` derive does not see
        // through a `Box`.
        #[allow(clippy::large_enum_variant)]
        #[derive(Module, Debug)]
        pub enum StereoModel {
            $($(#[$doc])* $variant(<$settings as Architecture>::Network),)+
        }

        impl ModelSpec {
            /// Every architecture's name, in the order of the list.
            pub const NAMES: &'static [&'static str] = &[$(<$settings as Architecture>::NAME,)+];

            /// The architecture's name (`hnet`, `unet`, `fcn`, `hrnet`, `ynet`).
            pub fn name(&self) -> &'static str {
                match self {
                    $(Self::$variant(_) => <$settings as Architecture>::NAME,)+
                }
            }

            /// The default settings of an architecture by name.
            pub fn default_for(name: &str) -> Option<Self> {
                $(if name == <$settings as Architecture>::NAME {
                    return Some(Self::$variant(<$settings as Architecture>::defaults()));
                })+
                None
            }

            /// Whether the network segments (has mask heads) and whether it estimates the force.
            pub fn heads(&self) -> (bool, bool) {
                match self {
                    $(Self::$variant(_) => (
                        <$settings as Architecture>::SEGMENTS,
                        <$settings as Architecture>::ESTIMATES_FORCE,
                    ),)+
                }
            }

            /// What the network reads.
            pub fn input(&self) -> StereoInput {
                match self {
                    $(Self::$variant(_) => <$settings as Architecture>::INPUT,)+
                }
            }

            /// Image sides (pixels) must be multiples of this.
            pub fn size_multiple(&self) -> usize {
                match self {
                    $(Self::$variant(s) => s.size_multiple(),)+
                }
            }

            /// Builds the network with fresh weights.
            pub fn init(&self, device: &Device) -> Result<StereoModel, HNetConfigError> {
                Ok(match self {
                    $(Self::$variant(s) => StereoModel::$variant(s.build(device)?),)+
                })
            }

            /// The settings alone as JSON (what a weights file's `hnet.config` holds).
            fn settings_json(&self) -> Result<String, serde_json::Error> {
                match self {
                    $(Self::$variant(s) => serde_json::to_string(s),)+
                }
            }

            /// Settings read from a weights file's `hnet.config`, for the architecture `name`.
            pub fn from_settings_json(name: &str, json: &str) -> Result<Self, ConfigProblem> {
                $(if name == <$settings as Architecture>::NAME {
                    return serde_json::from_str(json)
                        .map(Self::$variant)
                        .map_err(ConfigProblem::Json);
                })+
                Err(ConfigProblem::UnknownArchitecture(name.to_string()))
            }
        }

        impl StereoModel {
            /// Runs the network. `views` are the images `[B, 3, H, W]`; `masks` the catheter
            /// masks `[B, 1, H, W]`, read only by networks whose input is
            /// [`StereoInput::Masks`].
            pub fn forward(&self, views: [Tensor<4>; 2], masks: [Tensor<4>; 2]) -> StereoOutputs {
                match self {
                    $(Self::$variant(net) => <$settings as Architecture>::run(net, views, masks),)+
                }
            }

            /// The bytes of a weights file holding this network with `spec` and `provenance`.
            /// The file stores the architecture's own settings and parameter names, so an H-Net
            /// file written here is the same as one written by [`HNet::to_weights_bytes`].
            pub fn to_weights_bytes(
                &self,
                spec: &ModelSpec,
                provenance: &BTreeMap<String, String>,
            ) -> Result<Vec<u8>, WeightsError> {
                let source = "<memory>";
                let bad_config = |problem| WeightsError::new(source, WeightsProblem::BadConfig(problem));
                let json = spec.settings_json().map_err(|e| bad_config(ConfigProblem::Json(e)))?;
                match (self, spec) {
                    $((Self::$variant(m), ModelSpec::$variant(_)) => {
                        weights::encode(m.clone(), spec.name(), &json, provenance, source)
                    })+
                    #[allow(unreachable_patterns)]
                    _ => Err(bad_config(ConfigProblem::OtherNetwork(spec.name()))),
                }
            }

            /// Rebuilds a network of any architecture from a weights file's bytes.
            pub fn from_weights_bytes(
                bytes: &[u8],
                device: &Device,
                source: &str,
            ) -> Result<(StereoModel, ModelSpec, WeightsHeader), WeightsError> {
                let header = weights::read_header(bytes, source)?;
                let bad_config = |problem| WeightsError::new(source, WeightsProblem::BadConfig(problem));
                let spec = ModelSpec::from_settings_json(&header.architecture, &header.config_json)
                    .and_then(|spec| spec.check_layer_counts().map(|()| spec))
                    .map_err(bad_config)?;
                let model = match spec.init(device).map_err(|e| bad_config(ConfigProblem::Invalid(e)))? {
                    $(Self::$variant(m) => Self::$variant(weights::apply(m, bytes, source)?),)+
                };
                Ok((model, spec, header))
            }
        }
    };
}

architectures! {
    /// H-Net: both masks and the tip force.
    Hnet(HNetConfig),
    /// U-Net on each view: masks only.
    Unet(UNetConfig),
    /// FCN-8s on each view: masks only.
    Fcn(FcnConfig),
    /// Small HRNet on each view: masks only.
    Hrnet(HrNetConfig),
    /// Y-Net: the tip force from both views' masks.
    Ynet(YNetConfig),
}

impl StereoModel {
    /// The network with its encoders frozen for fine-tuning ([`HNet::with_frozen_encoders`]);
    /// a baseline is returned as it is.
    pub fn with_frozen_encoders(self) -> Self {
        match self {
            Self::Hnet(net) => Self::Hnet(net.with_frozen_encoders()),
            other => other,
        }
    }
}

impl fmt::Display for ModelSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl ModelSpec {
    /// Refuses settings whose sizes no real network has before anything is built from them: a
    /// baseline's layers are allocated from its `depth` and filter counts as soon as it is built, so
    /// a file claiming `depth: 2^40` would exhaust memory, and a zero depth or a filter count
    /// shifted past `usize` would panic (found by the property tests, tests/weights.rs). H-Net's own
    /// settings are checked by [`crate::HNetConfig::validate`]; its tensors are allocated lazily and then
    /// compared with the file's.
    pub fn check_layer_counts(&self) -> Result<(), ConfigProblem> {
        const FILTERS: (usize, usize, &str) = (1, 4096, "1..=4096");
        let check =
            |name: &'static str, value: usize, (low, high, range): (usize, usize, &'static str)| {
                if (low..=high).contains(&value) {
                    Ok(())
                } else {
                    Err(ConfigProblem::OutOfRange(name, value, range))
                }
            };
        match self {
            ModelSpec::Hnet(_) => Ok(()),
            ModelSpec::Unet(c) => {
                check("depth", c.depth, (1, 16, "1..=16"))?;
                check("base_filters", c.base_filters, FILTERS)
            }
            ModelSpec::Fcn(c) => check("base_filters", c.base_filters, FILTERS),
            ModelSpec::Hrnet(c) => check("width", c.width, FILTERS),
            ModelSpec::Ynet(c) => {
                check("base_filters", c.base_filters, FILTERS)?;
                check("hidden[0]", c.hidden[0], (1, 1 << 16, "1..=65536"))?;
                check("hidden[1]", c.hidden[1], (1, 1 << 16, "1..=65536"))
            }
        }
    }

    /// Whether weights trained with these settings go on training or run with `goal`'s: the same
    /// settings, or for H-Net the same but for the input size. H-Net's parameters do not depend
    /// on the input size (its force head reads globally averaged features, its position channels
    /// span `[-1, 1]` at any size), so a network trained at 128 px can go on at 224 px.
    pub fn carries_over_to(&self, goal: &ModelSpec) -> bool {
        match (self, goal) {
            (ModelSpec::Hnet(start), ModelSpec::Hnet(goal)) => {
                &HNetConfig {
                    image_size: goal.image_size,
                    ..start.clone()
                } == goal
            }
            _ => self == goal,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The serde tag (the variant's lowercase name) must be the architecture's [`Architecture::NAME`],
    /// or a config file would name a network one way and a weights file another.
    #[test]
    fn every_architecture_is_named_the_same_in_configs_and_weights_files() {
        for name in ModelSpec::NAMES {
            let spec = ModelSpec::default_for(name).expect("listed architectures have defaults");
            assert_eq!(spec.name(), *name);
            let json = serde_json::to_value(&spec).unwrap();
            assert_eq!(json["architecture"], *name);
            let back: ModelSpec = serde_json::from_value(json).unwrap();
            assert_eq!(back, spec);
        }
        assert!(ModelSpec::default_for("resnet").is_none());
    }
}
