//! `hnet info`: what a configuration builds.

use std::path::PathBuf;

use anyhow::Context;
use burn::module::Module;
use burn::tensor::Device;
use hnet_model::HNetConfig;
use serde::Serialize;

#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// A model configuration (JSON, as written by `hnet train`); the paper's when omitted.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// What `hnet info --json` prints.
#[derive(Serialize, Debug)]
struct Info {
    architecture: &'static str,
    /// Parameters with the encoder-decoder shared between the views (the paper's design).
    params: usize,
    /// Parameters with a separate encoder-decoder per view.
    params_unshared: usize,
    /// Parameters of the force head alone.
    params_force_head: usize,
    /// One view's input `[channels, height, width]`.
    input: [usize; 3],
    /// Outputs per stereo pair.
    outputs: Outputs,
    config: HNetConfig,
}

#[derive(Serialize, Debug)]
struct Outputs {
    mask_a: [usize; 3],
    mask_b: [usize; 3],
    force_newtons: [usize; 1],
}

pub fn run(args: &InfoArgs) -> anyhow::Result<()> {
    let config = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read config '{}'", path.display()))?;
            serde_json::from_str::<HNetConfig>(&text).with_context(|| {
                format!("config '{}' is not a valid H-Net config", path.display())
            })?
        }
        None => HNetConfig::new(),
    };
    let device = Device::flex();
    let count = |share| -> anyhow::Result<usize> {
        let model = config.clone().with_share_weights(share).init(&device)?;
        Ok(model.num_params())
    };
    let params = count(true)?;
    let params_unshared = count(false)?;
    let [h, w] = config.image_size.height_width();
    let info = Info {
        architecture: "hnet",
        params: if config.share_weights {
            params
        } else {
            params_unshared
        },
        params_unshared,
        params_force_head: force_head_params(&config),
        input: [config.in_channels, h, w],
        outputs: Outputs {
            mask_a: [1, h, w],
            mask_b: [1, h, w],
            force_newtons: [3],
        },
        config,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        println!("H-Net ({} x {} input, {} channels)", h, w, info.input[0]);
        println!("  parameters, encoder-decoder shared by both views: {params}");
        println!("  parameters, one encoder-decoder per view:        {params_unshared}");
        println!(
            "  of which the force head:                          {}",
            info.params_force_head
        );
    }
    Ok(())
}

/// Dense layers of the force head: `2·(depth+1)·filters → h1 → h2 → 3`, with biases.
fn force_head_params(config: &HNetConfig) -> usize {
    let input = 2 * config.pooled_features_per_view();
    let [h1, h2] = config.force_hidden;
    (input + 1) * h1 + (h1 + 1) * h2 + (h2 + 1) * 3
}
