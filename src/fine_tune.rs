//! What the page's "Fine-tune on my pairs" trains on and what it writes: the labelled pairs as
//! the fine-tuning workers take them (crates/hnet-tune), twin pairs of the weights' own domain
//! (scored for reference, or rehearsed), the kept weights' provenance, and the time left. The
//! workers are driven from `studio/tuning.rs`; the training is [`hnet_model::fine_tune`]'s, the
//! step `hnet train`'s, split between the workers ([`hnet_model::fine_tune::Share`]).

use std::collections::BTreeMap;

use hnet_model::fine_tune::{EpochReport, HeldBackScores};
use hnet_twin::dataset::label_origin::LabelFilter;
use hnet_twin::model_facts::{FineTuneRecord, ForceDomain, fine_tuned_provenance};
use hnet_twin::simulator::carm::{Biplane, CArm};
use hnet_twin::simulator::scene::{Backgrounds, TwinConfig, TwinError, generate};
use hnet_units::ImageSize;

use crate::imaging::WORK_SIZE;
use crate::workspace::LabeledPair;

/// The pairs a fine-tune learns from, packed for the worker's `start`.
#[derive(Debug, Clone, PartialEq)]
pub struct TuningSet {
    /// Each pair in turn: view A and view B (RGB), then mask A and mask B.
    pub images: Vec<u8>,
    /// Each pair's force label `(Fx, Fy, Fz)` in newtons, NaN where it trains its masks only.
    pub forces: Vec<f32>,
    /// Pairs in the set.
    pub pairs: usize,
    /// Of which with a force label the head learns from.
    pub with_force: usize,
    /// Pairs left out because their masks are not labels yet.
    pub left_out: usize,
}

/// Why no fine-tune can start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TuningRefusal {
    /// Fewer than two pairs with labelled masks.
    #[error(
        "fine-tuning needs at least 2 pairs whose masks are labels (painted or kept, each view \
         with a catheter or marked as showing none); {found} found{}",
        if *.left_out > 0 { format!(", {left_out} pair(s) not labelled yet", left_out = .left_out) } else { String::new() }
    )]
    TooFewPairs {
        /// Pairs with labelled masks.
        found: usize,
        /// Pairs without.
        left_out: usize,
    },
    /// The network reads another size than the page's pairs.
    #[error(
        "the loaded network reads {network} images and the page's pairs are {pairs}: load \
         weights trained at {pairs} to fine-tune here"
    )]
    OtherSize {
        /// The network's input size.
        network: ImageSize,
        /// The pairs' size.
        pairs: ImageSize,
    },
}

/// The pairs of `pairs` whose masks are labels, for a network reading `input` images. A force
/// label trains the force head unless it was copied from a model's estimate (as `hnet train`
/// leaves those out by default: a network never learns its own guesses).
pub fn tuning_set(pairs: &[LabeledPair], input: ImageSize) -> Result<TuningSet, TuningRefusal> {
    if input != WORK_SIZE {
        return Err(TuningRefusal::OtherSize {
            network: input,
            pairs: WORK_SIZE,
        });
    }
    let learnt = LabelFilter::not_estimates();
    let labelled: Vec<&LabeledPair> = pairs.iter().filter(|p| p.masks_complete()).collect();
    let left_out = pairs.len() - labelled.len();
    if labelled.len() < 2 {
        return Err(TuningRefusal::TooFewPairs {
            found: labelled.len(),
            left_out,
        });
    }
    let mut set = TuningSet {
        images: Vec::with_capacity(labelled.len() * WORK_SIZE.pixels() * 8),
        forces: Vec::with_capacity(labelled.len() * 3),
        pairs: labelled.len(),
        with_force: 0,
        left_out,
    };
    for pair in labelled {
        for bytes in [&pair.view_a, &pair.view_b, &pair.mask_a, &pair.mask_b] {
            set.images.extend_from_slice(bytes);
        }
        match pair.force_n.filter(|_| learnt.admits(&pair.force_origin)) {
            Some(force) => {
                set.forces.extend_from_slice(&force.newtons());
                set.with_force += 1;
            }
            None => set.forces.extend_from_slice(&[f32::NAN; 3]),
        }
    }
    Ok(set)
}

/// Where a fine-tune's steps run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TuningDevice {
    /// WebGPU, in one worker (the page's WebGPU start-up check passed).
    WebGpu,
    /// The CPU, each step split between this many workers (one per core, at most the batch).
    Cpu {
        /// Workers.
        workers: usize,
    },
}

impl TuningDevice {
    /// Replicas each step is split between ([`hnet_model::fine_tune::FineTuneSettings::replicas`]).
    pub fn replicas(self) -> usize {
        match self {
            Self::WebGpu => 1,
            Self::Cpu { workers } => workers,
        }
    }

    /// `on WebGPU`, `on 2 CPU workers`: what the panel and the provenance say.
    pub fn describe(self) -> String {
        match self {
            Self::WebGpu => "on WebGPU".into(),
            Self::Cpu { workers: 1 } => "on 1 CPU worker".into(),
            Self::Cpu { workers } => {
                format!("on {workers} CPU workers, each step split between them")
            }
        }
    }

    /// The native command's options that repeat the run's steps: `--replicas N` on the CPU,
    /// `--backend wgpu` on WebGPU.
    fn native_options(self) -> String {
        match self {
            Self::WebGpu => "--backend wgpu".into(),
            Self::Cpu { workers } => format!("--replicas {workers}"),
        }
    }
}

/// The kept weights' provenance ([`fine_tuned_provenance`]): where they came from, where each
/// step ran and what share of the starting weights was kept (what `hnet fine-tune --replicas
/// --start-share`, or `--backend wgpu`, repeats), and how they did on the held-back pairs.
pub fn kept_provenance(
    start: &BTreeMap<String, String>,
    (start_name, device, start_share): (&str, TuningDevice, f64),
    set: &TuningSet,
    held_back: usize,
    before: &HeldBackScores,
    best: &EpochReport,
) -> BTreeMap<String, String> {
    let command = format!(
        "H-Net Studio page: Fine-tune on my pairs, from {start_name}, {}, {start_share} of the \
         starting weights kept (natively: hnet fine-tune {} --start-share {start_share})",
        device.describe(),
        device.native_options()
    );
    fine_tuned_provenance(
        start,
        FineTuneRecord {
            command: &command,
            from: start_name,
            on: format!(
                "{} labelled pairs in the page ({} with a force label), {held_back} of them held back",
                set.pairs, set.with_force
            ),
            best_epoch: best.epoch,
            before: before.to_string(),
            after: best.held_back.to_string(),
        },
    )
}

/// Reference pairs scored beside the held-back ones.
pub const REFERENCE_PAIRS: usize = 4;

/// Twin pairs rehearsed beside the user's (trained on, never held back), when the user asks.
pub const REHEARSAL_PAIRS: usize = 8;

/// The reference pairs' seed: the same pairs for every fine-tune.
pub const REFERENCE_SEED: u64 = 0x5EF_E4E4CE;

/// The rehearsed pairs' seed: other pairs than the reference ones, which are never trained on.
pub const REHEARSAL_SEED: u64 = 0x4E4EA45E;

/// `count` twin pairs (seeded `seed`) drawn from the domain the weights' force was trained on (their facts'
/// [`ForceDomain`]: modality, scene ranges, C-arm angles, phantom backgrounds), with the twin's
/// exact masks and true force: what fine-tuning costs there shows on them. `None` when the
/// domain was not the twin's phantom bench (radiograph backgrounds, which the page does not
/// hold, or the paper's bench, whose masks and X-rays are made another way).
pub fn twin_domain_set(
    domain: &ForceDomain,
    count: usize,
    seed: u64,
) -> Option<Result<TuningSet, TwinError>> {
    let sampler = TwinDomainSampler::new(domain)?;
    let mut set = TuningSet::empty();
    for index in 0..count as u64 {
        if let Err(e) = sampler.push(seed, index, &mut set) {
            return Some(Err(e));
        }
    }
    Some(Ok(set))
}

/// Draws twin pairs from a weights' recorded domain one at a time ([`twin_domain_set`]), so
/// that the page can let the browser answer between them.
pub struct TwinDomainSampler {
    config: TwinConfig,
    backgrounds: Backgrounds,
}

impl TwinDomainSampler {
    /// The sampler of `domain`; `None` when it is not the twin's phantom bench.
    pub fn new(domain: &ForceDomain) -> Option<Self> {
        let config = Self::config(domain)?;
        let backgrounds = Backgrounds::phantom(&config.views);
        Some(Self::with_backgrounds(config, backgrounds))
    }

    /// The twin settings of `domain`'s pairs; `None` when it is not the twin's phantom bench.
    pub fn config(domain: &ForceDomain) -> Option<TwinConfig> {
        if !domain.phantom_backgrounds || domain.scenes.plate.is_some() {
            return None;
        }
        let mut config = TwinConfig::new(domain.modality, WORK_SIZE);
        config.scene = domain.scenes.clone();
        let view = |deg: [f64; 2]| {
            if domain.modality.is_xray() {
                CArm::cardiac(deg[0], deg[1], WORK_SIZE)
            } else {
                CArm::bench_camera(deg[0], deg[1], WORK_SIZE)
            }
        };
        config.views = Biplane {
            a: view(domain.views_deg[0]),
            b: view(domain.views_deg[1]),
        };
        Some(config)
    }

    /// The sampler of `config`'s pairs on `backgrounds` (its views' phantoms:
    /// [`Backgrounds::phantom`], or [`Backgrounds::phantom_view_in_bands`] for each).
    pub fn with_backgrounds(config: TwinConfig, backgrounds: Backgrounds) -> Self {
        Self {
            config,
            backgrounds,
        }
    }

    /// Adds pair `index` of the run seeded `seed` to `set`, with its masks and true force.
    pub fn push(&self, seed: u64, index: u64, set: &mut TuningSet) -> Result<(), TwinError> {
        let sample = generate(&self.config, &self.backgrounds, seed, index)?;
        let [a, b] = &sample.views;
        set.images.extend(a.pixels.to_rgb());
        set.images.extend(b.pixels.to_rgb());
        set.images.extend_from_slice(&a.mask);
        set.images.extend_from_slice(&b.mask);
        let f = sample.params.tip_force_n;
        set.forces
            .extend([f.x() as f32, f.y() as f32, f.z() as f32]);
        set.pairs += 1;
        set.with_force += 1;
        Ok(())
    }
}

impl TuningSet {
    /// A set of no pairs.
    pub fn empty() -> Self {
        Self {
            images: Vec::new(),
            forces: Vec::new(),
            pairs: 0,
            with_force: 0,
            left_out: 0,
        }
    }
}

/// Seconds left, from `elapsed_s` for `done` of `total` steps (`None` before the first).
pub fn seconds_left(elapsed_s: f64, done: usize, total: usize) -> Option<f64> {
    (done > 0).then(|| elapsed_s / done as f64 * total.saturating_sub(done) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workspace::{PairSource, View};
    use hnet_twin::dataset::label_origin::LabelOrigin;
    use hnet_twin::model_facts::FACTS_KEY;
    use hnet_units::TipForce;

    fn pair(id: &str, painted: bool, force: Option<(TipForce, LabelOrigin)>) -> LabeledPair {
        let rgb = vec![40u8; WORK_SIZE.pixels() * 3];
        let mut p = LabeledPair::new(
            id.into(),
            PairSource::Upload {
                view_a: "a.png".into(),
                view_b: "b.png".into(),
                views: None,
            },
            rgb.clone(),
            rgb,
        );
        if painted {
            p.mask_a[5] = 255;
            p.mask_b[9] = 255;
            p.masks_labeled = true;
        }
        if let Some((f, origin)) = force {
            p.force_n = Some(f);
            p.force_origin = origin;
        }
        p
    }

    #[test]
    fn only_labelled_masks_train_and_estimates_never_teach_the_force() {
        let estimate = LabelOrigin::Estimate {
            weights: "bundled".into(),
            estimator: "H-Net".into(),
        };
        let pairs = vec![
            pair(
                "p1",
                true,
                Some((TipForce::new(0.1, 0.2, 0.3), LabelOrigin::Measured)),
            ),
            pair("p2", true, Some((TipForce::new(0.5, 0.5, 0.5), estimate))),
            // Masks not labelled yet: left out whatever its force.
            pair(
                "p3",
                false,
                Some((TipForce::new(0.1, 0.1, 0.1), LabelOrigin::Typed)),
            ),
            pair("p4", true, None),
        ];
        let set = tuning_set(&pairs, WORK_SIZE).unwrap();
        assert_eq!((set.pairs, set.with_force, set.left_out), (3, 1, 1));
        let per_pair = WORK_SIZE.pixels() * 8;
        assert_eq!(set.images.len(), 3 * per_pair);
        assert_eq!(&set.forces[..3], &[0.1, 0.2, 0.3]);
        assert!(set.forces[3..].iter().all(|f| f.is_nan()));
        // Pair p1's mask A is right after its two views.
        assert_eq!(set.images[2 * WORK_SIZE.pixels() * 3 + 5], 255);
        assert_eq!(pairs[0].labeled_pixels(View::A), 1);
    }

    #[test]
    fn too_few_pairs_or_another_size_are_refused_with_why() {
        let one = vec![pair("p1", true, None), pair("p2", false, None)];
        let refusal = tuning_set(&one, WORK_SIZE).unwrap_err();
        assert_eq!(
            refusal,
            TuningRefusal::TooFewPairs {
                found: 1,
                left_out: 1
            }
        );
        assert!(refusal.to_string().contains("1 pair(s) not labelled yet"));
        let two = vec![pair("p1", true, None), pair("p2", true, None)];
        let refusal = tuning_set(&two, ImageSize::square(64)).unwrap_err();
        assert!(
            refusal.to_string().contains("reads 64×64 images"),
            "{refusal}"
        );
    }

    #[test]
    fn reference_pairs_come_from_the_weights_own_twin_domain() {
        let domain = ForceDomain {
            data: "bench".into(),
            modality: hnet_twin::simulator::scene::Modality::Xray2,
            scenes: hnet_twin::simulator::scene::SceneSampling::bench(),
            views_deg: [[0.0, 0.0], [90.0, 0.0]],
            phantom_backgrounds: true,
        };
        let set = twin_domain_set(&domain, 2, REFERENCE_SEED)
            .unwrap()
            .unwrap();
        let rehearsed = twin_domain_set(&domain, 1, REHEARSAL_SEED)
            .unwrap()
            .unwrap();
        assert_ne!(&rehearsed.images[..], &set.images[..rehearsed.images.len()]);
        assert_eq!(set.images.len(), 2 * WORK_SIZE.pixels() * 8);
        assert!(set.forces.iter().all(|f| f.is_finite()));
        // A mask holds the catheter.
        let mask_a = &set.images[2 * WORK_SIZE.pixels() * 3..][..WORK_SIZE.pixels()];
        let catheter = mask_a
            .iter()
            .filter(|&&m| hnet_units::mask::is_catheter_label(m));
        assert!(catheter.count() > 50);
    }

    #[test]
    fn kept_weights_drop_the_measured_errors_and_say_where_they_came_from() {
        let start = BTreeMap::from([
            ("command".to_string(), "hnet train …".to_string()),
            (FACTS_KEY.to_string(), "{}".to_string()),
            ("seed".to_string(), "42".to_string()),
        ]);
        let set = tuning_set(&[pair("p1", true, None), pair("p2", true, None)], WORK_SIZE).unwrap();
        let scores = |iou| HeldBackScores {
            pairs: 1,
            loss: 0.1,
            catheter_iou: iou,
            force_mae_n: None,
            force_pairs: 0,
        };
        let best = EpochReport {
            epoch: 3,
            train_loss: 0.1,
            held_back: scores(0.9),
            reference: None,
            best: true,
            finished: true,
            finished_because: None,
        };
        let on_webgpu = kept_provenance(
            &start,
            ("hnet-cpu.bpk", TuningDevice::WebGpu, 0.15),
            &set,
            1,
            &scores(0.2),
            &best,
        );
        assert!(
            on_webgpu["command"].ends_with(
                "on WebGPU, 0.15 of the starting weights kept (natively: hnet fine-tune \
                 --backend wgpu --start-share 0.15)"
            ),
            "{}",
            on_webgpu["command"]
        );
        let kept = kept_provenance(
            &start,
            ("hnet-cpu.bpk", TuningDevice::Cpu { workers: 2 }, 0.15),
            &set,
            1,
            &scores(0.2),
            &best,
        );
        assert!(!kept.contains_key(FACTS_KEY));
        assert_eq!(kept["seed"], "42");
        assert_eq!(kept["held_back_before"], "catheter IoU 0.200");
        assert_eq!(kept["held_back_after"], "catheter IoU 0.900");
        assert!(kept["command"].contains("from hnet-cpu.bpk"));
        assert!(
            kept["command"].ends_with("(natively: hnet fine-tune --replicas 2 --start-share 0.15)")
        );
        assert_eq!(seconds_left(10.0, 2, 6), Some(20.0));
        assert_eq!(seconds_left(0.0, 0, 6), None);
    }
}
