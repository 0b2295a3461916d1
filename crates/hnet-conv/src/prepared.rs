//! Weights prepared for a kernel (Winograd-transformed, packed for the direct kernel, turned or
//! gathered for an input gradient's classes), kept by each thread for its next call with the
//! same weight.
//!
//! Inference runs the same layers with the same weights call after call, and each call prepared
//! every layer's weight anew: about a tenth of a 64 px pair's time natively (`perf`, 2026-12-07).
//! A prepared weight is kept with a copy of the weight it was prepared from, and it is used again
//! only where the weight given is, bit for bit, that copy. A weight changed in place (a training
//! step) or a freed buffer reused for another weight is prepared again: a kept preparation is
//! never stale, it only saves the work.

use alloc::sync::Arc;
use alloc::vec::Vec;
use core::cell::RefCell;
use std::collections::HashMap;

/// What a preparation is, besides the weight's values: its kind first, then every size it
/// depends on.
pub(crate) type Recipe = Vec<usize>;

/// The kinds of preparation ([`Recipe`]'s first number).
pub(crate) mod kind {
    /// Winograd's weight transform ([`crate::winograd::transform_weight`]).
    pub const WINOGRAD: usize = 1;
    /// Packed for the direct kernel ([`crate::direct::pack_weight`]).
    pub const PACKED: usize = 2;
    /// Kernel rows and columns gathered for an input gradient
    /// ([`crate::geometry::ConvGeometry::gathered_weight`]).
    pub const GATHERED: usize = 3;
}

/// Most values a thread keeps, its sources and preparations together: 16 MiB. H-Net's inference
/// keeps 0.93 Mi (46 preparations, the bundled 224 px weights); a training run's weights change
/// at every step, so its preparations are never used again and pile up (about 0.9 Mi a step)
/// until this bound drops everything kept. The bound is what training pays in memory: in the
/// page's fine-tuning worker, whose WebAssembly memory never shrinks, at most 16 MiB.
const MAX_KEPT_VALUES: usize = 4 << 20;

/// One kept preparation.
struct Kept {
    /// The weight it was prepared from.
    source: Vec<f32>,
    prepared: Arc<[f32]>,
}

#[derive(Default)]
struct KeptPreparations {
    /// Keyed by where the weight lay, its length and the recipe.
    entries: HashMap<(usize, usize, Recipe), Kept>,
    values: usize,
}

std::thread_local! {
    static KEPT: RefCell<KeptPreparations> = RefCell::new(KeptPreparations::default());
}

/// Whether `a` and `b` hold the same bits (so `-0.0` differs from `0.0`, and a NaN equals itself),
/// compared as integers: one `memcmp`.
fn same_bits(a: &[f32], b: &[f32]) -> bool {
    let bits = |values: &[f32]| {
        // SAFETY: `u32` has `f32`'s size and alignment, and every bit pattern is a valid `u32`.
        unsafe { core::slice::from_raw_parts(values.as_ptr().cast::<u32>(), values.len()) }
    };
    bits(a) == bits(b)
}

/// `prepare(weight)`, or this thread's kept result of it where `weight` is bit for bit the
/// weight it was prepared from, at the same place, with the same `recipe`.
pub(crate) fn prepared(
    weight: &[f32],
    recipe: Recipe,
    prepare: impl FnOnce(&[f32]) -> Vec<f32>,
) -> Arc<[f32]> {
    let key = (weight.as_ptr() as usize, weight.len(), recipe);
    let kept = KEPT.with(|kept| {
        let kept = kept.borrow();
        let entry = kept.entries.get(&key)?;
        same_bits(&entry.source, weight).then(|| Arc::clone(&entry.prepared))
    });
    if let Some(prepared) = kept {
        return prepared;
    }
    let prepared: Arc<[f32]> = prepare(weight).into();
    KEPT.with(|kept| {
        let mut kept = kept.borrow_mut();
        let values = weight.len() + prepared.len();
        if kept.values + values > MAX_KEPT_VALUES {
            kept.entries.clear();
            kept.values = 0;
        }
        if values <= MAX_KEPT_VALUES {
            let entry = Kept {
                source: weight.to_vec(),
                prepared: Arc::clone(&prepared),
            };
            if let Some(old) = kept.entries.insert(key, entry) {
                kept.values -= old.source.len() + old.prepared.len();
            }
            kept.values += values;
        }
    });
    prepared
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A kept preparation is used again only for the very bits it was prepared from: a weight
    /// changed in place is prepared again.
    #[test]
    fn a_weight_changed_in_place_is_prepared_again() {
        let mut weight = vec![1.0f32, 2.0, 3.0];
        let calls = core::cell::Cell::new(0);
        let double = |w: &[f32]| {
            calls.set(calls.get() + 1);
            w.iter().map(|v| v * 2.0).collect()
        };
        let recipe = || vec![kind::PACKED, 3];
        assert_eq!(&*prepared(&weight, recipe(), double), &[2.0, 4.0, 6.0]);
        assert_eq!(&*prepared(&weight, recipe(), double), &[2.0, 4.0, 6.0]);
        assert_eq!(calls.get(), 1);
        weight[1] = -0.0;
        assert_eq!(&*prepared(&weight, recipe(), double), &[2.0, -0.0, 6.0]);
        weight[1] = 0.0;
        assert_eq!(
            prepared(&weight, recipe(), double)[1].to_bits(),
            0.0f32.to_bits()
        );
        assert_eq!(calls.get(), 3);
        // Another recipe for the same weight is another preparation.
        prepared(&weight, vec![kind::WINOGRAD, 3], double);
        assert_eq!(calls.get(), 4);
    }
}
