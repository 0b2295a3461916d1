//! H-Net and its baselines behind one type, so that one training and evaluation harness (and
//! one weights format) serves them all.

use alloc::collections::BTreeMap;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::fmt;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::baselines::{Fcn, FcnConfig, HrNet, HrNetConfig, UNet, UNetConfig, YNet, YNetConfig};
use crate::model::{HNet, HNetConfig};
use crate::weights::{self, WeightsError, WeightsHeader, WeightsProblem};

/// Which network, with its settings. Serialised as `{"architecture": "hnet", ...settings}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "architecture", rename_all = "lowercase")]
pub enum ModelSpec {
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

/// What a network takes as its two inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StereoInput {
    /// The two images `[B, 3, H, W]`.
    Images,
    /// The two catheter masks `[B, 1, H, W]` (Y-Net).
    Masks,
}

impl ModelSpec {
    /// The architecture's name (`hnet`, `unet`, `fcn`, `hrnet`, `ynet`).
    pub fn name(&self) -> &'static str {
        match self {
            ModelSpec::Hnet(_) => "hnet",
            ModelSpec::Unet(_) => "unet",
            ModelSpec::Fcn(_) => "fcn",
            ModelSpec::Hrnet(_) => "hrnet",
            ModelSpec::Ynet(_) => "ynet",
        }
    }

    /// The default settings of an architecture by name.
    pub fn default_for(name: &str) -> Option<Self> {
        Some(match name {
            "hnet" => ModelSpec::Hnet(HNetConfig::new()),
            "unet" => ModelSpec::Unet(UNetConfig::new()),
            "fcn" => ModelSpec::Fcn(FcnConfig::new()),
            "hrnet" => ModelSpec::Hrnet(HrNetConfig::new()),
            "ynet" => ModelSpec::Ynet(YNetConfig::new()),
            _ => return None,
        })
    }

    /// Whether the network segments (has mask heads) and whether it estimates the force.
    pub fn heads(&self) -> (bool, bool) {
        match self {
            ModelSpec::Hnet(_) => (true, true),
            ModelSpec::Ynet(_) => (false, true),
            _ => (true, false),
        }
    }

    /// What the network reads.
    pub fn input(&self) -> StereoInput {
        match self {
            ModelSpec::Ynet(_) => StereoInput::Masks,
            _ => StereoInput::Images,
        }
    }

    /// Image sides must be multiples of this.
    pub fn size_multiple(&self) -> usize {
        match self {
            ModelSpec::Hnet(c) => 1 << c.depth.min(16),
            ModelSpec::Unet(c) => 1 << c.depth.min(16),
            ModelSpec::Fcn(_) => 32,
            ModelSpec::Hrnet(_) => 16,
            ModelSpec::Ynet(_) => 8,
        }
    }

    /// Builds the network with fresh weights.
    pub fn init(&self, device: &Device) -> Result<StereoModel, String> {
        Ok(match self {
            ModelSpec::Hnet(c) => StereoModel::Hnet(c.init(device).map_err(|e| e.to_string())?),
            ModelSpec::Unet(c) => StereoModel::Unet(c.init(device)),
            ModelSpec::Fcn(c) => StereoModel::Fcn(c.init(device)),
            ModelSpec::Hrnet(c) => StereoModel::Hrnet(c.init(device)),
            ModelSpec::Ynet(c) => StereoModel::Ynet(c.init(device)),
        })
    }
}

impl fmt::Display for ModelSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Any of the networks.
// One value per training run or page, never in a collection: the size of the largest variant
// (H-Net's layer records) costs nothing, and Burn's `Module` derive does not see through a `Box`.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum StereoModel {
    /// H-Net.
    Hnet(HNet),
    /// U-Net.
    Unet(UNet),
    /// FCN-8s.
    Fcn(Fcn),
    /// Small HRNet.
    Hrnet(HrNet),
    /// Y-Net.
    Ynet(YNet),
}

/// What a network produced for a batch of `B` pairs.
#[derive(Debug, Clone)]
pub struct StereoOutputs {
    /// Mask logits of view A and view B `[B, 1, H, W]`, for networks that segment.
    pub mask_logits: Option<[Tensor<4>; 2]>,
    /// Tip force `[B, 3]` in newtons, for networks that estimate it.
    pub force: Option<Tensor<2>>,
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

impl StereoModel {
    /// Runs the network. `views` are the images `[B, 3, H, W]`; `masks` the catheter masks
    /// `[B, 1, H, W]`, read only by networks whose input is [`StereoInput::Masks`].
    pub fn forward(&self, views: [Tensor<4>; 2], masks: [Tensor<4>; 2]) -> StereoOutputs {
        match self {
            StereoModel::Hnet(net) => {
                let [a, b] = views;
                let out = net.forward(a, b);
                StereoOutputs {
                    mask_logits: Some([out.mask_logits_a, out.mask_logits_b]),
                    force: Some(out.force),
                }
            }
            StereoModel::Unet(net) => StereoOutputs {
                mask_logits: Some(both_views(views, |x| net.forward(x))),
                force: None,
            },
            StereoModel::Fcn(net) => StereoOutputs {
                mask_logits: Some(both_views(views, |x| net.forward(x))),
                force: None,
            },
            StereoModel::Hrnet(net) => StereoOutputs {
                mask_logits: Some(both_views(views, |x| net.forward(x))),
                force: None,
            },
            StereoModel::Ynet(net) => {
                let [a, b] = masks;
                StereoOutputs {
                    mask_logits: None,
                    force: Some(net.forward(a, b)),
                }
            }
        }
    }

    /// The bytes of a weights file holding this network with `spec` and `provenance`. The
    /// file stores the architecture's own settings and parameter names, so an H-Net file written
    /// here is the same as one written by [`HNet::to_weights_bytes`].
    pub fn to_weights_bytes(
        &self,
        spec: &ModelSpec,
        provenance: &BTreeMap<String, String>,
    ) -> Result<Vec<u8>, WeightsError> {
        let source = "<memory>";
        let json = |r: Result<String, serde_json::Error>| {
            r.map_err(|e| WeightsError {
                source: source.to_string(),
                problem: WeightsProblem::BadConfig(e.to_string()),
            })
        };
        let name = spec.name();
        match (self, spec) {
            (StereoModel::Hnet(m), ModelSpec::Hnet(c)) => weights::encode(
                m.clone(),
                name,
                &json(serde_json::to_string(c))?,
                provenance,
                source,
            ),
            (StereoModel::Unet(m), ModelSpec::Unet(c)) => weights::encode(
                m.clone(),
                name,
                &json(serde_json::to_string(c))?,
                provenance,
                source,
            ),
            (StereoModel::Fcn(m), ModelSpec::Fcn(c)) => weights::encode(
                m.clone(),
                name,
                &json(serde_json::to_string(c))?,
                provenance,
                source,
            ),
            (StereoModel::Hrnet(m), ModelSpec::Hrnet(c)) => weights::encode(
                m.clone(),
                name,
                &json(serde_json::to_string(c))?,
                provenance,
                source,
            ),
            (StereoModel::Ynet(m), ModelSpec::Ynet(c)) => weights::encode(
                m.clone(),
                name,
                &json(serde_json::to_string(c))?,
                provenance,
                source,
            ),
            _ => Err(WeightsError {
                source: source.to_string(),
                problem: WeightsProblem::BadConfig(alloc::format!(
                    "settings of `{name}` given for another network"
                )),
            }),
        }
    }

    /// Rebuilds a network of any architecture from a weights file's bytes.
    pub fn from_weights_bytes(
        bytes: &[u8],
        device: &Device,
        source: &str,
    ) -> Result<(StereoModel, ModelSpec, WeightsHeader), WeightsError> {
        let header = weights::read_header(bytes, source)?;
        let bad_config = |e: String| WeightsError {
            source: source.to_string(),
            problem: WeightsProblem::BadConfig(e),
        };
        fn parse<T: serde::de::DeserializeOwned>(json: &str) -> Result<T, String> {
            serde_json::from_str(json).map_err(|e| e.to_string())
        }
        let json = header.config_json.as_str();
        let spec = match header.architecture.as_str() {
            "hnet" => ModelSpec::Hnet(parse(json).map_err(bad_config)?),
            "unet" => ModelSpec::Unet(parse(json).map_err(bad_config)?),
            "fcn" => ModelSpec::Fcn(parse(json).map_err(bad_config)?),
            "hrnet" => ModelSpec::Hrnet(parse(json).map_err(bad_config)?),
            "ynet" => ModelSpec::Ynet(parse(json).map_err(bad_config)?),
            other => {
                return Err(bad_config(alloc::format!("unknown architecture `{other}`")));
            }
        };
        let model = match spec.init(device).map_err(bad_config)? {
            StereoModel::Hnet(m) => StereoModel::Hnet(weights::apply(m, bytes, source)?),
            StereoModel::Unet(m) => StereoModel::Unet(weights::apply(m, bytes, source)?),
            StereoModel::Fcn(m) => StereoModel::Fcn(weights::apply(m, bytes, source)?),
            StereoModel::Hrnet(m) => StereoModel::Hrnet(weights::apply(m, bytes, source)?),
            StereoModel::Ynet(m) => StereoModel::Ynet(weights::apply(m, bytes, source)?),
        };
        Ok((model, spec, header))
    }
}
