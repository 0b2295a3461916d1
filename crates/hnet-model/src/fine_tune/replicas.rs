//! A training step split between replicas: the page's tuning workers, one per core. Each replica
//! holds the same network and computes the gradients of its share of the step's batch
//! ([`super::FineTune::share`]); every replica then applies the same average of all shares
//! ([`super::FineTune::apply`]), so that all keep the same weights, bit for bit, with no weights
//! sent between them. This is data-parallel training with an all-reduce of the gradients, done
//! by the page relaying each share to every worker; natively the shares run one after another,
//! so `hnet fine-tune --replicas N` computes what N workers in the page do.
//!
//! A share travels as plain numbers: each trainable parameter's gradient, in the network's
//! visiting order, row-major (zeros where the step left a parameter without a gradient).

use alloc::vec::Vec;

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData, Transaction};

use super::FineTuneError;
use crate::architectures::StereoModel;

/// One replica's part of a training step.
#[derive(Debug, Clone, PartialEq)]
pub struct Share {
    /// Pairs in the share (0 where the step's batch has fewer pairs than there are replicas).
    pub pairs: usize,
    /// The mean loss over the share's pairs (0 without pairs).
    pub loss: f64,
    /// The gradient of that loss for each trainable parameter, flattened (empty without pairs).
    pub gradients: Vec<f32>,
}

impl Share {
    /// The share as the page's tuning workers pass it on: the pairs and the gradients' length
    /// (each a `u32` in an `f32`'s bits), the loss (an `f32`'s value, as the loss tensor holds
    /// it), then the gradients.
    pub fn to_message(&self) -> Vec<f32> {
        let mut message = Vec::with_capacity(3 + self.gradients.len());
        message.push(f32::from_bits(self.pairs as u32));
        message.push(f32::from_bits(self.gradients.len() as u32));
        message.push(self.loss as f32);
        message.extend_from_slice(&self.gradients);
        message
    }

    /// The shares in `messages`, one after another as [`Self::to_message`] wrote them.
    pub fn from_messages(mut messages: &[f32]) -> Result<Vec<Share>, FineTuneError> {
        let mut shares = Vec::new();
        while !messages.is_empty() {
            let unreadable = || {
                FineTuneError::Readback(alloc::format!(
                    "share {} of a step is cut short ({} values left)",
                    shares.len(),
                    messages.len()
                ))
            };
            let [pairs, len, loss, rest @ ..] = messages else {
                return Err(unreadable());
            };
            let len = len.to_bits() as usize;
            if rest.len() < len {
                return Err(unreadable());
            }
            let (gradients, rest) = rest.split_at(len);
            shares.push(Share {
                pairs: pairs.to_bits() as usize,
                loss: f64::from(*loss),
                gradients: gradients.to_vec(),
            });
            messages = rest;
        }
        Ok(shares)
    }
}

/// The positions `start..end` in a batch of `len` pairs that replica `replica` of `replicas`
/// trains on: contiguous, in replica order, sizes differing by at most one.
pub fn share_range(len: usize, replica: usize, replicas: usize) -> core::ops::Range<usize> {
    let replicas = replicas.max(1);
    (len * replica / replicas)..(len * (replica + 1) / replicas)
}

/// The gradients of `grads` for `net`'s trainable parameters as a share's values, read back in
/// one transaction (asynchronously: WebGPU in the browser reads no other way).
pub(super) async fn flatten(
    net: &StereoModel,
    grads: &GradientsParams,
) -> Result<Vec<f32>, FineTuneError> {
    /// Each trainable parameter's gradient, or its length where the step left it none.
    enum Slot {
        Read,
        Zeros(usize),
    }
    struct Collect<'a> {
        grads: &'a GradientsParams,
        slots: Vec<Slot>,
        transaction: Transaction,
    }
    impl ModuleVisitor for Collect<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if !param.is_require_grad() {
                return;
            }
            match self.grads.get::<D>(param.id) {
                Some(grad) => {
                    let transaction = core::mem::take(&mut self.transaction);
                    self.transaction = transaction.register(grad);
                    self.slots.push(Slot::Read);
                }
                None => self.slots.push(Slot::Zeros(param.shape().num_elements())),
            }
        }
    }
    let mut collect = Collect {
        grads,
        slots: Vec::new(),
        transaction: Transaction::default(),
    };
    net.visit(&mut collect);
    let mut read = read_back(collect.transaction).await?.into_iter();
    let mut values = Vec::new();
    for slot in collect.slots {
        match slot {
            Slot::Read => {
                let data = read.next().ok_or_else(|| {
                    FineTuneError::Readback("the device returned fewer gradients than asked".into())
                })?;
                values.extend(self::values(data)?);
            }
            Slot::Zeros(len) => values.resize(values.len() + len, 0.0),
        }
    }
    Ok(values)
}

/// Values read back, as `f32`s.
pub(super) fn values(data: TensorData) -> Result<Vec<f32>, FineTuneError> {
    data.try_into_vec_as::<f32>()
        .map_err(|e| FineTuneError::Readback(alloc::format!("{e:?}")))
}

/// What `transaction` registered, read back from the device without blocking (the one read-back
/// of a fine-tune: WebGPU in the browser must not block).
pub(super) async fn read_back(transaction: Transaction) -> Result<Vec<TensorData>, FineTuneError> {
    transaction
        .execute_async()
        .await
        .map_err(|e| FineTuneError::Readback(alloc::format!("{e:?}")))
}

/// The average of `shares`, each weighted by its pairs, as `net`'s gradients on `device`.
/// Every replica computes it in the same order, so every replica gets the same numbers.
pub(super) fn average(
    net: &StereoModel,
    shares: &[Share],
    device: &Device,
) -> Result<GradientsParams, FineTuneError> {
    let pairs: usize = shares.iter().map(|s| s.pairs).sum();
    let with_pairs: Vec<&Share> = shares.iter().filter(|s| s.pairs > 0).collect();
    let len = with_pairs.first().map_or(0, |s| s.gradients.len());
    if pairs == 0 || with_pairs.iter().any(|s| s.gradients.len() != len) {
        return Err(FineTuneError::Shares {
            pairs,
            lengths: shares.iter().map(|s| s.gradients.len()).collect(),
        });
    }
    let mut sum = alloc::vec![0f32; len];
    for share in &with_pairs {
        let weight = share.pairs as f32;
        for (total, g) in sum.iter_mut().zip(&share.gradients) {
            *total += weight * g;
        }
    }
    let total = pairs as f32;
    for value in &mut sum {
        *value /= total;
    }
    struct Unflatten<'a> {
        values: &'a [f32],
        device: &'a Device,
        grads: GradientsParams,
        short: bool,
    }
    impl ModuleVisitor for Unflatten<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if !param.is_require_grad() {
                return;
            }
            let shape = param.shape();
            let n = shape.num_elements();
            if self.values.len() < n {
                self.short = true;
                return;
            }
            let (mine, rest) = self.values.split_at(n);
            self.values = rest;
            let grad = Tensor::<D>::from_data(TensorData::new(mine.to_vec(), shape), self.device);
            self.grads.register::<D>(param.id, grad);
        }
    }
    let mut unflatten = Unflatten {
        values: &sum,
        device,
        grads: GradientsParams::new(),
        short: false,
    };
    net.visit(&mut unflatten);
    if unflatten.short || !unflatten.values.is_empty() {
        return Err(FineTuneError::Shares {
            pairs,
            lengths: shares.iter().map(|s| s.gradients.len()).collect(),
        });
    }
    Ok(unflatten.grads)
}

#[cfg(test)]
mod tests {
    use super::{Share, share_range};

    #[test]
    fn shares_read_back_as_they_were_written() {
        let shares = [
            Share {
                pairs: 1,
                loss: 0.25,
                gradients: vec![1.0, -2.5, f32::MIN_POSITIVE],
            },
            Share {
                pairs: 0,
                loss: 0.0,
                gradients: vec![],
            },
        ];
        let messages: Vec<f32> = shares.iter().flat_map(Share::to_message).collect();
        assert_eq!(Share::from_messages(&messages).unwrap(), shares);
        assert!(Share::from_messages(&messages[..4]).is_err());
    }

    #[test]
    fn shares_cover_the_batch_once_in_order() {
        for len in 0..7 {
            for replicas in 1..5 {
                let ranges: Vec<_> = (0..replicas)
                    .map(|r| share_range(len, r, replicas))
                    .collect();
                assert_eq!(ranges[0].start, 0);
                assert_eq!(ranges[replicas - 1].end, len);
                for pair in ranges.windows(2) {
                    assert_eq!(pair[0].end, pair[1].start);
                }
                let sizes: Vec<usize> = ranges.iter().map(|r| r.len()).collect();
                let (min, max) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
                assert!(max - min <= 1, "{len} over {replicas}: {sizes:?}");
            }
        }
    }
}
