//! Tables of tip forces in CSV, as people write them: a header naming a key column (a pair's id,
//! or an image's name) and the columns `fx`, `fy`, `fz` in newtons, in any order and case, with
//! other columns ignored but `label_origin` ([`crate::dataset::label_origin`]). The one reader behind
//! `hnet import`'s forces file and the page's force labels (the dataset's own `manifest.csv` has
//! its own, stricter reader in [`crate::dataset`]).

use std::sync::Arc;

use hnet_units::TipForce;

use crate::dataset::label_origin::LabelOrigin;

/// The force columns, in the order of the force's components.
pub const FORCE_COLUMNS: [&str; 3] = ["fx", "fy", "fz"];

/// One row of a force table.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceRow {
    /// Its line in the file (the header is line 1).
    pub line: u64,
    /// Its key: the pair's id or the image's name.
    pub key: String,
    /// Tip force `(Fx, Fy, Fz)`, newtons.
    pub force_n: TipForce,
    /// Where it came from, when the table says ([`crate::dataset::label_origin::ORIGIN_COLUMN`]);
    /// [`LabelOrigin::Unrecorded`] otherwise.
    pub origin: LabelOrigin,
}

/// What is wrong with a force table: the line when one line is at fault, and the problem. The
/// caller names the file.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}{problem}", line.map(|l| format!("line {l}: ")).unwrap_or_default())]
pub struct ForceTableError {
    /// The line of the file (the header is line 1).
    pub line: Option<u64>,
    /// What is wrong.
    pub problem: String,
    /// The CSV reader's error, when the text itself could not be read.
    #[source]
    pub cause: Option<Arc<csv::Error>>,
}

impl ForceTableError {
    /// A problem with the table, or with its `line`.
    pub fn new(line: Option<u64>, problem: impl Into<String>) -> Self {
        Self {
            line,
            problem: problem.into(),
            cause: None,
        }
    }
}

/// Reads a force table whose key column is named by one of `keys` (the first found, compared
/// without case). A header without the key or a force column fails the whole table; otherwise
/// each row is read on its own, so that a caller may skip bad rows.
pub fn read_force_table(
    bytes: &[u8],
    keys: &[&str],
) -> Result<Vec<Result<ForceRow, ForceTableError>>, ForceTableError> {
    let error = ForceTableError::new;
    let unreadable = |line: Option<u64>, problem: &str, e: csv::Error| ForceTableError {
        cause: Some(Arc::new(e)),
        ..ForceTableError::new(line, problem)
    };
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(bytes);
    let headers = reader
        .headers()
        .map_err(|e| unreadable(Some(1), "cannot read the header", e))?
        .clone();
    let column = |name: &str| headers.iter().position(|h| h.eq_ignore_ascii_case(name));
    let needed = || {
        let key = match keys {
            [one] => format!("`{one}`"),
            _ => format!(
                "one of {}",
                keys.iter()
                    .map(|k| format!("`{k}`"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        };
        format!("the header needs {key} and `fx`, `fy`, `fz` (newtons)")
    };
    let key_column = keys
        .iter()
        .find_map(|k| column(k))
        .ok_or_else(|| error(Some(1), format!("no key column: {}", needed())))?;
    let key_name = headers.get(key_column).unwrap_or_default().to_string();
    let mut force_columns = [0; 3];
    for (axis, slot) in FORCE_COLUMNS.iter().zip(&mut force_columns) {
        *slot = column(axis)
            .ok_or_else(|| error(Some(1), format!("no `{axis}` column: {}", needed())))?;
    }
    let mut rows = Vec::new();
    for record in reader.records() {
        let row = record
            .map_err(|e| unreadable(e.position().map(|p| p.line()), "cannot be read", e))
            .and_then(|record| {
                let line = record.position().map_or(0, |p| p.line());
                let key = record.get(key_column).unwrap_or_default();
                if key.is_empty() {
                    return Err(error(Some(line), format!("the {key_name} is empty")));
                }
                let mut force_n = [0.0; 3];
                for ((axis, &column), value) in
                    FORCE_COLUMNS.iter().zip(&force_columns).zip(&mut force_n)
                {
                    let text = record.get(column).unwrap_or_default();
                    *value = parse_newtons(text).ok_or_else(|| {
                        error(
                            Some(line),
                            format!(
                                "{axis} of `{key}` is `{text}`, not a finite number of newtons"
                            ),
                        )
                    })?;
                }
                let origin = LabelOrigin::from_columns(|name| {
                    column(name).map(|c| record.get(c).unwrap_or_default())
                })
                .map_err(|e| error(Some(line), format!("the label of `{key}`: {e}")))?;
                Ok(ForceRow {
                    line,
                    key: key.to_string(),
                    force_n: TipForce::from_newtons(force_n),
                    origin,
                })
            });
        rows.push(row);
    }
    Ok(rows)
}

/// A force component as people write it: a finite number (`nan` and `inf` are refused), with
/// a point or a comma as the decimal separator (a comma only inside a quoted CSV field).
pub fn parse_newtons(text: &str) -> Option<f32> {
    let text = text.trim();
    let text = if text.contains(',') && !text.contains('.') {
        std::borrow::Cow::Owned(text.replacen(',', ".", 1))
    } else {
        std::borrow::Cow::Borrowed(text)
    };
    text.parse::<f32>().ok().filter(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_read_by_name_in_any_order_and_case() {
        let rows = read_force_table(
            b"FZ,note,Image,fx,fy\n0.3,x,a.png,0.1,-0.2\n",
            &["id", "image"],
        )
        .unwrap();
        let rows: Vec<ForceRow> = rows.into_iter().map(Result::unwrap).collect();
        assert_eq!(
            rows,
            vec![ForceRow {
                line: 2,
                key: "a.png".into(),
                force_n: TipForce::new(0.1, -0.2, 0.3),
                origin: LabelOrigin::Unrecorded,
            }]
        );
        // A table that says where its labels came from (a sensor's log, or an export's manifest).
        let rows =
            read_force_table(b"id,fx,fy,fz,Label_Origin\np1,0.1,0,0,measured\n", &["id"]).unwrap();
        assert_eq!(rows[0].as_ref().unwrap().origin, LabelOrigin::Measured);
        let rows =
            read_force_table(b"id,fx,fy,fz,label_origin\np1,0.1,0,0,guess\n", &["id"]).unwrap();
        assert!(
            rows[0]
                .as_ref()
                .unwrap_err()
                .to_string()
                .starts_with("line 2: the label of `p1`: label_origin `guess` is not one of"),
            "{rows:?}"
        );
    }

    #[test]
    fn bad_rows_are_named_and_the_others_kept() {
        let rows = read_force_table(
            b"id,fx,fy,fz\np1,0,0,0\np2,0,NaN,0\n,0,0,0\np4,0,0\n",
            &["id"],
        )
        .unwrap();
        assert!(rows[0].is_ok());
        assert_eq!(
            rows[1].as_ref().unwrap_err().to_string(),
            "line 3: fy of `p2` is `NaN`, not a finite number of newtons"
        );
        assert_eq!(
            rows[2].as_ref().unwrap_err().to_string(),
            "line 4: the id is empty"
        );
        assert_eq!(
            rows[3].as_ref().unwrap_err().to_string(),
            "line 5: fz of `p4` is ``, not a finite number of newtons"
        );
        let err = read_force_table(b"name,fx,fy,fz\n", &["id"]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "line 1: no key column: the header needs `id` and `fx`, `fy`, `fz` (newtons)"
        );
        assert_eq!(parse_newtons(" -0,05 "), Some(-0.05));
        assert_eq!(parse_newtons("1,000.5"), None);
        let err = read_force_table(b"image,fx,fz\n", &["image", "file"]).unwrap_err();
        assert!(
            err.problem
                .starts_with("no `fy` column: the header needs one of `image`, `file`")
        );
    }
}
