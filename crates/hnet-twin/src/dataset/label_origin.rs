//! Where a force label came from: measured by a sensor, typed, imported, simulated, or copied
//! from a model's estimate (and which weights and estimator made it). One vocabulary for the
//! page's labels, the dataset's `manifest.csv` and records, the force tables `hnet import` and
//! the page read, and `hnet train --labels`, which can leave model-made labels out so that a
//! network is never trained on its own guesses.
//!
//! In `manifest.csv` (and any force table) the origin is the column [`ORIGIN_COLUMN`], one word
//! of [`LabelOrigin::word`]; an estimate also names its weights and estimator in
//! [`WEIGHTS_COLUMN`] and [`ESTIMATOR_COLUMN`]. Datasets written before origins were recorded
//! have no such column: their labels read as [`LabelOrigin::Unrecorded`].

use serde::{Deserialize, Serialize};

/// The manifest column holding a label's origin.
pub const ORIGIN_COLUMN: &str = "label_origin";
/// The manifest column naming the weights that made an estimate label (empty otherwise).
pub const WEIGHTS_COLUMN: &str = "label_weights";
/// The manifest column naming the estimator that made an estimate label (empty otherwise).
pub const ESTIMATOR_COLUMN: &str = "label_estimator";

/// Where a force label came from.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(tag = "origin", rename_all = "kebab-case")]
pub enum LabelOrigin {
    /// Read by a force sensor (a bench with a load cell, as the paper had).
    Measured,
    /// Typed by a person.
    Typed,
    /// Read from a file that does not say how it was obtained.
    Imported,
    /// The digital twin's exact force.
    Simulated,
    /// A model's estimate, accepted as the label: not a measurement.
    Estimate {
        /// The weights that made it (their file or bundled name).
        weights: String,
        /// The estimator: `H-Net`, `physics` or `combined`.
        estimator: String,
    },
    /// Labelled before origins were recorded (older exports and datasets).
    #[default]
    Unrecorded,
}

/// The origins' words, in the order of [`LabelOrigin::word`]'s variants.
pub const ORIGIN_WORDS: [&str; 6] = [
    "measured",
    "typed",
    "imported",
    "simulated",
    "estimate",
    "unrecorded",
];

impl LabelOrigin {
    /// Its one-word name, as written in `manifest.csv`.
    pub fn word(&self) -> &'static str {
        match self {
            Self::Measured => ORIGIN_WORDS[0],
            Self::Typed => ORIGIN_WORDS[1],
            Self::Imported => ORIGIN_WORDS[2],
            Self::Simulated => ORIGIN_WORDS[3],
            Self::Estimate { .. } => ORIGIN_WORDS[4],
            Self::Unrecorded => ORIGIN_WORDS[5],
        }
    }

    /// Whether a model made it (a label that must not train the model that made it).
    pub fn is_estimate(&self) -> bool {
        matches!(self, Self::Estimate { .. })
    }

    /// A few words for people: "measured by a sensor", "H-Net's estimate (hnet-cpu.bpk)", ...
    pub fn describe(&self) -> String {
        match self {
            Self::Measured => "measured by a sensor".into(),
            Self::Typed => "typed".into(),
            Self::Imported => "imported from a file".into(),
            Self::Simulated => "the twin's exact force".into(),
            Self::Estimate { weights, estimator } => {
                format!("copied from the {estimator} estimate of {weights}: not measured")
            }
            Self::Unrecorded => "origin not recorded".into(),
        }
    }

    /// The manifest columns [`ORIGIN_COLUMN`], [`WEIGHTS_COLUMN`] and [`ESTIMATOR_COLUMN`].
    pub fn columns(&self) -> [(String, String); 3] {
        let (weights, estimator) = match self {
            Self::Estimate { weights, estimator } => (weights.clone(), estimator.clone()),
            _ => (String::new(), String::new()),
        };
        [
            (ORIGIN_COLUMN.into(), self.word().into()),
            (WEIGHTS_COLUMN.into(), weights),
            (ESTIMATOR_COLUMN.into(), estimator),
        ]
    }

    /// Reads an origin from a table's columns: `column(name)` gives a column's value, `None`
    /// when the table has no such column. No origin column reads as
    /// [`LabelOrigin::Unrecorded`]; an unknown word is an error naming it.
    pub fn from_columns<'a>(
        column: impl Fn(&str) -> Option<&'a str>,
    ) -> Result<Self, UnknownOrigin> {
        let Some(word) = column(ORIGIN_COLUMN).map(str::trim) else {
            return Ok(Self::Unrecorded);
        };
        let text = |name| column(name).unwrap_or_default().trim().to_string();
        Ok(match word.to_ascii_lowercase().as_str() {
            "measured" => Self::Measured,
            "typed" => Self::Typed,
            "imported" => Self::Imported,
            "simulated" => Self::Simulated,
            "estimate" => Self::Estimate {
                weights: text(WEIGHTS_COLUMN),
                estimator: text(ESTIMATOR_COLUMN),
            },
            "unrecorded" | "" => Self::Unrecorded,
            _ => return Err(UnknownOrigin(word.to_string())),
        })
    }
}

/// A `label_origin` that is none of [`ORIGIN_WORDS`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "label_origin `{0}` is not one of measured, typed, imported, simulated, estimate, unrecorded"
)]
pub struct UnknownOrigin(pub String);

/// Which labels may train the force head: a set of origins (`hnet train --labels`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LabelFilter {
    words: Vec<&'static str>,
}

impl LabelFilter {
    /// Every origin but a model's estimates: the default, so that a network never learns its
    /// own guesses unless asked to.
    pub fn not_estimates() -> Self {
        Self {
            words: ORIGIN_WORDS
                .iter()
                .copied()
                .filter(|&w| w != "estimate")
                .collect(),
        }
    }

    /// Every origin, estimates included.
    pub fn all() -> Self {
        Self {
            words: ORIGIN_WORDS.to_vec(),
        }
    }

    /// Parses `all`, or a comma-separated list of [`ORIGIN_WORDS`].
    pub fn parse(text: &str) -> Result<Self, UnknownOrigin> {
        if text.trim() == "all" {
            return Ok(Self::all());
        }
        let mut words = Vec::new();
        for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let word = ORIGIN_WORDS
                .iter()
                .copied()
                .find(|w| w.eq_ignore_ascii_case(part))
                .ok_or_else(|| UnknownOrigin(part.to_string()))?;
            words.push(word);
        }
        if words.is_empty() {
            return Err(UnknownOrigin(text.to_string()));
        }
        Ok(Self { words })
    }

    /// Whether a label of `origin` may train the force head.
    pub fn admits(&self, origin: &LabelOrigin) -> bool {
        self.words.contains(&origin.word())
    }

    /// The admitted origins, comma-separated.
    pub fn words(&self) -> String {
        self.words.join(",")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origins_round_trip_through_their_columns() {
        let origins = [
            LabelOrigin::Measured,
            LabelOrigin::Typed,
            LabelOrigin::Imported,
            LabelOrigin::Simulated,
            LabelOrigin::Estimate {
                weights: "hnet-cpu.bpk".into(),
                estimator: "combined".into(),
            },
            LabelOrigin::Unrecorded,
        ];
        for origin in origins {
            let columns = origin.columns();
            let back = LabelOrigin::from_columns(|name| {
                columns
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, v)| v.as_str())
            })
            .unwrap();
            assert_eq!(back, origin);
        }
        // No column: an older dataset.
        assert_eq!(
            LabelOrigin::from_columns(|_| None),
            Ok(LabelOrigin::Unrecorded)
        );
        let err = LabelOrigin::from_columns(|n| (n == ORIGIN_COLUMN).then_some("guessed"));
        assert_eq!(err, Err(UnknownOrigin("guessed".into())));
    }

    #[test]
    fn the_default_filter_leaves_estimates_out() {
        let estimate = LabelOrigin::Estimate {
            weights: "w".into(),
            estimator: "H-Net".into(),
        };
        let default = LabelFilter::not_estimates();
        assert!(!default.admits(&estimate));
        assert!(default.admits(&LabelOrigin::Unrecorded));
        assert!(LabelFilter::all().admits(&estimate));
        let measured = LabelFilter::parse("measured, Simulated").unwrap();
        assert!(measured.admits(&LabelOrigin::Simulated));
        assert!(!measured.admits(&LabelOrigin::Typed));
        assert_eq!(measured.words(), "measured,simulated");
        assert!(LabelFilter::parse("sensor").is_err());
        assert!(LabelFilter::parse("").is_err());
    }
}
