//! Force labels typed or read from a file: one component in newtons as typed, the
//! plausibility rule, and a CSV of labels (`id,fx,fy,fz[,label_origin]`, a dataset's
//! `manifest.csv` included) with where each came from.

use hnet_twin::dataset::force_table::{ForceTableError, read_force_table};
pub use hnet_twin::dataset::implausible_tip_force;
use hnet_twin::dataset::label_origin::LabelOrigin;
use hnet_units::TipForce;

/// Why a force-label file cannot be used: the file, and what is wrong in it (with the line,
/// when it is one line's fault).
#[derive(Debug, Clone, thiserror::Error)]
#[error("{file}, {table}")]
pub struct ForceLabelError {
    /// The file's name.
    pub file: String,
    /// What is wrong in it.
    pub table: ForceTableError,
}

/// A typed force component that is not a number of newtons.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TypedForceError {
    /// Nothing was typed.
    #[error("{axis} is empty: enter a number of newtons")]
    Empty {
        /// The component (`Fx`, `Fy` or `Fz`).
        axis: String,
    },
    /// What was typed is not a finite number (of f32's range).
    #[error("{axis} is `{text}`, not a number of newtons")]
    NotNewtons {
        /// The component (`Fx`, `Fy` or `Fz`).
        axis: String,
        /// What was typed, trimmed.
        text: String,
    },
}

/// Reads one typed force component in newtons (`axis` names it in the message), by the rule of
/// [`hnet_twin::dataset::force_table::parse_newtons`].
pub fn parse_newtons(axis: &str, text: &str) -> Result<f32, TypedForceError> {
    let trimmed = text.trim();
    if trimmed.is_empty() {
        return Err(TypedForceError::Empty {
            axis: axis.to_string(),
        });
    }
    hnet_twin::dataset::force_table::parse_newtons(trimmed).ok_or_else(|| {
        TypedForceError::NotNewtons {
            axis: axis.to_string(),
            text: trimmed.to_string(),
        }
    })
}

/// A force label read from a file: the pair's id, the force in newtons, and where it came from.
pub type ForceLabelRow = (String, TipForce, LabelOrigin);

/// Reads force labels from a CSV file with a header naming the columns `id`, `fx`, `fy` and `fz`
/// (newtons; other columns are ignored, so a dataset's `manifest.csv` works too). Every value must
/// be a finite number of newtons and the label plausible (see [`implausible_tip_force`]); the first
/// bad line is reported and nothing is applied. A `label_origin` column says where each label
/// came from (a sensor's log writes `measured`); without one, they are `imported`.
pub fn parse_force_labels(file: &str, bytes: &[u8]) -> Result<Vec<ForceLabelRow>, ForceLabelError> {
    let error = |table: ForceTableError| ForceLabelError {
        file: file.to_string(),
        table,
    };
    let mut labels = Vec::new();
    for row in read_force_table(bytes, &["id"]).map_err(error)? {
        let row = row.map_err(error)?;
        let force = row.force_n;
        if let Some(why) = implausible_tip_force(force) {
            return Err(error(ForceTableError::new(
                Some(row.line),
                format!("the force of `{}` is refused: {why}", row.key),
            )));
        }
        let origin = match row.origin {
            LabelOrigin::Unrecorded => LabelOrigin::Imported,
            origin => origin,
        };
        labels.push((row.key, force, origin));
    }
    if labels.is_empty() {
        return Err(error(ForceTableError::new(None, "holds no force labels")));
    }
    Ok(labels)
}

/// Regression (found by `typed_forces_are_finite_or_an_error`): a typed force beyond f32's
/// range was read as an infinite label.
#[cfg(all(test, not(target_arch = "wasm32")))]
#[test]
fn typed_forces_beyond_f32_are_refused() {
    let err = parse_newtons("Fx", "6445156245511322000000000000000000000000").unwrap_err();
    assert!(err.to_string().contains("not a number of newtons"), "{err}");
    assert!(parse_newtons("Fx", "1e39").is_err());
    assert_eq!(parse_newtons("Fx", "0.25"), Ok(0.25));
}
