//! A simulation split into parts that separate machines make (`hnet simulate --shard K/N`, a
//! Slurm array task or a Kubernetes Indexed Job's completion index each), and the parts joined
//! back into one dataset (`hnet merge`) that is byte for byte the one a single run makes.
//!
//! Every pair of a simulation depends on its index alone (its random stream is
//! `sample_rng(seed, index)`, its split the seeded 80/10/10 draw over all indices), so part `K`
//! of `N` is simply the indices `[K·S/N, (K+1)·S/N)` of the `S` pairs. A part's header is the
//! whole dataset's with its pair count and a `shard` entry (`index`, `count`, `samples`) in its
//! `source`; merging checks that the parts are the `N` parts of one simulation, copies their
//! pairs and writes the whole dataset's header and manifest.

use std::fs;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::dataset::{
    Dataset, DatasetError, DatasetHeader, DatasetWriter, SAMPLE_IMAGES, image_path, record_path,
};

/// The key of a part's `shard` entry in its header's `source`.
pub const SHARD_KEY: &str = "shard";

/// Part `index` of `count` of a simulation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// Which part, from 0 (a scheduler's array index).
    pub index: usize,
    /// How many parts.
    pub count: usize,
}

impl Shard {
    /// The whole simulation as one part.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Parses `K/N` (`K` from 0 to `N - 1`).
    pub fn parse(text: &str) -> Result<Self, String> {
        let bad = || format!("`{text}` is not K/N, part K (from 0) of N parts, e.g. 0/4");
        let (k, n) = text.split_once('/').ok_or_else(bad)?;
        let index: usize = k.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(format!(
                "`{text}`: part {index} of {count} does not exist (parts are numbered 0 to N - 1)"
            ));
        }
        Ok(Self { index, count })
    }

    /// Whether it is the whole simulation.
    pub fn is_whole(&self) -> bool {
        self.count == 1
    }

    /// The pair indices of this part of `samples` pairs.
    pub fn range(&self, samples: usize) -> Range<u64> {
        let bound = |k: usize| (k as u128 * samples as u128 / self.count as u128) as u64;
        bound(self.index)..bound(self.index + 1)
    }

    /// The header of this part of the dataset `whole` describes: its pair count, and the part
    /// recorded in its source. The whole dataset's own header for [`Shard::WHOLE`].
    pub fn header(&self, whole: &DatasetHeader) -> DatasetHeader {
        if self.is_whole() {
            return whole.clone();
        }
        let mut header = whole.clone();
        let range = self.range(whole.samples);
        header.samples = (range.end - range.start) as usize;
        header.source[SHARD_KEY] = serde_json::json!(ShardEntry {
            index: self.index,
            count: self.count,
            samples: whole.samples,
        });
        header
    }
}

/// What a part's header records of the simulation it belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
struct ShardEntry {
    index: usize,
    count: usize,
    /// Pairs of the whole simulation.
    samples: usize,
}

/// What a merge did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MergeReport {
    /// Pairs in the merged dataset.
    pub samples: usize,
    /// Parts joined.
    pub parts: usize,
}

/// Joins the `N` parts of one simulation (each from `hnet simulate --shard K/N`, in any order)
/// into the dataset `out`, byte for byte the one an unsharded run writes. Refused, naming the
/// folder, when a folder is not a finished part, the parts are of different simulations, one is
/// missing or given twice, or `out` holds something else.
pub fn merge_shards(parts: &[PathBuf], out: &Path) -> Result<MergeReport, DatasetError> {
    let Some(first) = parts.first() else {
        return Err(DatasetError::new(out, "no parts to merge"));
    };
    let mut opened = Vec::new();
    for root in parts {
        let dataset = Dataset::open(root)?;
        let entry: ShardEntry = dataset
            .header
            .source
            .get(SHARD_KEY)
            .and_then(|v| serde_json::from_value(v.clone()).ok())
            .ok_or_else(|| {
                DatasetError::new(
                    root,
                    "is not a part of a sharded simulation (no `shard` in its header)",
                )
            })?;
        let rows = dataset.rows.len();
        if rows != dataset.header.samples {
            return Err(DatasetError::new(
                root,
                format!(
                    "holds {rows} of its {} pairs: finish it first (repeat its command)",
                    dataset.header.samples
                ),
            ));
        }
        opened.push((root, dataset, entry));
    }
    let (_, first_set, first_entry) = &opened[0];
    let mut whole = first_set.header.clone();
    if let Some(source) = whole.source.as_object_mut() {
        source.remove(SHARD_KEY);
    }
    whole.samples = first_entry.samples;
    let mut seen = vec![false; first_entry.count];
    for (root, dataset, entry) in &opened {
        let shard = Shard {
            index: entry.index,
            count: entry.count,
        };
        if entry.count != first_entry.count || entry.samples != first_entry.samples {
            return Err(DatasetError::new(
                root,
                format!(
                    "is part {}/{} of {} pairs, but {} is part of {} parts of {} pairs",
                    entry.index,
                    entry.count,
                    entry.samples,
                    first.display(),
                    first_entry.count,
                    first_entry.samples
                ),
            ));
        }
        if shard.index >= seen.len() || std::mem::replace(&mut seen[shard.index], true) {
            return Err(DatasetError::new(
                root,
                format!("is part {}/{}, given twice", shard.index, shard.count),
            ));
        }
        if shard.header(&whole) != dataset.header {
            return Err(DatasetError::new(
                root,
                format!(
                    "was made with other settings than {} (its header differs beyond the part)",
                    first.display()
                ),
            ));
        }
    }
    if let Some(missing) = seen.iter().position(|s| !s) {
        return Err(DatasetError::new(
            out,
            format!("part {missing}/{} is missing", first_entry.count),
        ));
    }
    let writer = DatasetWriter::create_or_resume(out, &whole)?;
    for (root, dataset, _) in &opened {
        for row in &dataset.rows {
            if writer.has_sample(&row.id) {
                continue;
            }
            // The images first, the record last: a copy cut short is made again.
            let mut files = Vec::with_capacity(SAMPLE_IMAGES.len() + 1);
            for path in SAMPLE_IMAGES
                .iter()
                .map(|kind| image_path(&row.id, kind))
                .chain([record_path(&row.id)])
            {
                let from = root.join(&path);
                let bytes = fs::read(&from)
                    .map_err(|e| DatasetError::caused_by(&from, "cannot be read", e))?;
                files.push((path, bytes));
            }
            writer.write_sample(&row.id, &files)?;
        }
    }
    let rows = writer.finish()?;
    Ok(MergeReport {
        samples: rows.len(),
        parts: parts.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_cover_every_index_once() {
        for (samples, count) in [(2000, 4), (7, 3), (2, 5), (0, 2)] {
            let mut next = 0;
            for index in 0..count {
                let range = Shard { index, count }.range(samples);
                assert_eq!(range.start, next);
                next = range.end;
            }
            assert_eq!(next, samples as u64);
        }
        assert_eq!(Shard::parse("1/4"), Ok(Shard { index: 1, count: 4 }));
        assert!(Shard::parse("4/4").unwrap_err().contains("does not exist"));
        assert!(Shard::parse("0/0").is_err());
        assert!(Shard::parse("two").unwrap_err().contains("is not K/N"));
    }
}
