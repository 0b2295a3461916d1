//! Trained weights as one self-describing file.
//!
//! A weights file is a burnpack container (Burn's own record format, written through
//! [`Module::into_record`]) whose metadata also carries the network's configuration as JSON, so
//! that a file is enough to rebuild the network: the browser app can load any file that
//! `hnet train` wrote without being told its sizes. This module reads and writes the bytes;
//! files are the caller's (`hnet` writes them atomically, the page reads the user's).
//!
//! Metadata keys: `hnet.format` ([`FORMAT_VERSION`]), `hnet.architecture` (`"hnet"` or a baseline's
//! name), `hnet.config` (the architecture's configuration as JSON), and free-form provenance
//! under `hnet.provenance.*` (command, seed, data, ...).
//!
//! Loading never panics on a bad file: truncation, a foreign file, another architecture or
//! weights whose shapes do not fit the configuration all come back as a [`WeightsError`] that
//! names the file and the problem.

use alloc::collections::BTreeMap;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::fmt;

use burn::module::Module;
use burn::store::{ModuleRecord, RecordError};
use burn::tensor::{Bytes, Device};
use burn_pack::{Reader, Writer};

use crate::model::{HNet, HNetConfig};

/// Version of the metadata layout written by this crate.
pub const FORMAT_VERSION: &str = "1";
/// File name extension of weights files.
pub const EXTENSION: &str = "bpk";
/// Architecture name of H-Net in `hnet.architecture`.
pub const HNET_ARCHITECTURE: &str = "hnet";

const KEY_FORMAT: &str = "hnet.format";
const KEY_ARCHITECTURE: &str = "hnet.architecture";
const KEY_CONFIG: &str = "hnet.config";
const PROVENANCE_PREFIX: &str = "hnet.provenance.";

/// What is wrong with a weights file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WeightsProblem {
    /// The file could not be read or written.
    Io(String),
    /// Not a weights file at all: what the bytes look like instead.
    NotWeights(&'static str),
    /// A weights container, but damaged or cut short.
    NotBurnpack(String),
    /// A burnpack container without H-Net Studio's metadata.
    NotHNetStudio,
    /// Written by a newer, incompatible version of this format.
    UnsupportedFormat(String),
    /// Weights of another network.
    WrongArchitecture {
        /// What the caller asked for.
        expected: String,
        /// What the file holds.
        found: String,
    },
    /// The configuration in the file cannot be read or describes no valid network.
    BadConfig(String),
    /// The tensors do not fit the network the configuration describes.
    Mismatch(String),
}

impl fmt::Display for WeightsProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "{e}"),
            Self::NotWeights(what) => write!(
                f,
                "not an H-Net weights file (.bpk, written by `hnet train`): this is {what}"
            ),
            Self::NotBurnpack(e) => write!(
                f,
                "a weights file, but damaged or cut short (a partial download?): {e}"
            ),
            Self::NotHNetStudio => write!(
                f,
                "a Burn weights file, but not written by H-Net Studio (no `{KEY_FORMAT}` metadata)"
            ),
            Self::UnsupportedFormat(v) => write!(
                f,
                "weights format version {v} is not supported (this build reads version {FORMAT_VERSION})"
            ),
            Self::WrongArchitecture { expected, found } => {
                write!(f, "holds `{found}` weights, expected `{expected}`")
            }
            Self::BadConfig(e) => write!(f, "invalid network configuration: {e}"),
            Self::Mismatch(e) => write!(f, "weights do not match the network: {e}"),
        }
    }
}

/// A weights file that could not be read or written, with the file's name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WeightsError {
    /// The file (or, for in-memory bytes, the name the user knows them by).
    pub source: String,
    /// What went wrong.
    pub problem: WeightsProblem,
}

impl fmt::Display for WeightsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "weights file '{}': {}", self.source, self.problem)
    }
}

impl core::error::Error for WeightsError {}

/// The metadata of a weights file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WeightsHeader {
    /// Architecture name (`"hnet"`, or a baseline's).
    pub architecture: String,
    /// The architecture's configuration as JSON.
    pub config_json: String,
    /// Provenance entries (command, seed, data, ...) without their key prefix.
    pub provenance: BTreeMap<String, String>,
}

/// Serialises `module` with its header into the bytes of a weights file.
pub fn encode<M: Module>(
    module: M,
    architecture: &str,
    config_json: &str,
    provenance: &BTreeMap<String, String>,
    source: &str,
) -> Result<Vec<u8>, WeightsError> {
    let error = |problem| WeightsError {
        source: source.to_string(),
        problem,
    };
    let record = module
        .into_record()
        .into_bytes()
        .map_err(|e| error(WeightsProblem::Io(e.to_string())))?;
    let tensors = Reader::from_bytes(record)
        .and_then(Reader::into_tensors)
        .map_err(|e| error(WeightsProblem::Io(e.to_string())))?;
    let mut writer = Writer::new(tensors)
        .with_metadata(KEY_FORMAT, FORMAT_VERSION)
        .with_metadata(KEY_ARCHITECTURE, architecture)
        .with_metadata(KEY_CONFIG, config_json);
    for (key, value) in provenance {
        writer = writer.with_metadata(&format!("{PROVENANCE_PREFIX}{key}"), value);
    }
    let bytes = writer
        .into_bytes()
        .map_err(|e| error(WeightsProblem::Io(e.to_string())))?;
    Ok(bytes.to_vec())
}

/// Refuses bytes that are not a weights file at all (they do not begin with Burn's burnpack
/// magic number), saying what they look like instead.
fn check_magic(bytes: &[u8]) -> Result<(), WeightsProblem> {
    if bytes.starts_with(&burn_pack::MAGIC_NUMBER.to_le_bytes()) {
        return Ok(());
    }
    let what = if bytes.is_empty() {
        "an empty file"
    } else if bytes.starts_with(b"\x89PNG") {
        "a PNG image"
    } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
        "a JPEG image"
    } else if bytes.starts_with(b"PK\x03\x04") {
        "a zip archive"
    } else if bytes.starts_with(b"DICM") || bytes.get(128..132) == Some(&b"DICM"[..]) {
        "a DICOM file"
    } else if bytes.starts_with(b"\x80") || bytes.starts_with(b"PK") {
        "another program's model or archive"
    } else if looks_like_text(&bytes[..bytes.len().min(512)]) {
        "a text file"
    } else {
        "another kind of file"
    };
    Err(WeightsProblem::NotWeights(what))
}

/// Whether a file's first bytes are UTF-8 text (a character cut at the end is allowed).
fn looks_like_text(head: &[u8]) -> bool {
    match core::str::from_utf8(head) {
        Ok(_) => true,
        Err(e) => e.error_len().is_none(),
    }
}

/// Reads the header of a weights file's bytes.
pub fn read_header(bytes: &[u8], source: &str) -> Result<WeightsHeader, WeightsError> {
    let error = |problem| WeightsError {
        source: source.to_string(),
        problem,
    };
    check_magic(bytes).map_err(error)?;
    let reader = Reader::from_bytes(Bytes::from_bytes_vec(bytes.to_vec()))
        .map_err(|e| error(WeightsProblem::NotBurnpack(e.to_string())))?;
    let metadata = reader.metadata();
    let format = metadata
        .get(KEY_FORMAT)
        .ok_or_else(|| error(WeightsProblem::NotHNetStudio))?;
    if format != FORMAT_VERSION {
        return Err(error(WeightsProblem::UnsupportedFormat(format.clone())));
    }
    let field = |key: &str| {
        metadata.get(key).cloned().ok_or_else(|| {
            error(WeightsProblem::BadConfig(format!(
                "missing `{key}` metadata"
            )))
        })
    };
    Ok(WeightsHeader {
        architecture: field(KEY_ARCHITECTURE)?,
        config_json: field(KEY_CONFIG)?,
        provenance: metadata
            .iter()
            .filter_map(|(k, v)| {
                k.strip_prefix(PROVENANCE_PREFIX)
                    .map(|k| (k.to_string(), v.clone()))
            })
            .collect(),
    })
}

/// Loads the tensors of a weights file into `module`, which must have the same structure.
pub fn apply<M: Module>(module: M, bytes: &[u8], source: &str) -> Result<M, WeightsError> {
    let error = |problem| WeightsError {
        source: source.to_string(),
        problem,
    };
    check_magic(bytes).map_err(error)?;
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(bytes.to_vec()))
        .map_err(|e| error(WeightsProblem::NotBurnpack(record_message(e))))?;
    module
        .try_load_record(record)
        .map_err(|e| error(WeightsProblem::Mismatch(record_message(e))))
}

fn record_message(error: RecordError) -> String {
    match error {
        RecordError::Io(m) | RecordError::Validation(m) => m,
    }
}

/// Checks the header of `bytes` names `expected` and returns it.
pub fn expect_architecture(
    bytes: &[u8],
    expected: &str,
    source: &str,
) -> Result<WeightsHeader, WeightsError> {
    let header = read_header(bytes, source)?;
    if header.architecture != expected {
        return Err(WeightsError {
            source: source.to_string(),
            problem: WeightsProblem::WrongArchitecture {
                expected: expected.to_string(),
                found: header.architecture,
            },
        });
    }
    Ok(header)
}

impl HNet {
    /// The bytes of a weights file holding this network, its `config` and `provenance`.
    pub fn to_weights_bytes(
        &self,
        config: &HNetConfig,
        provenance: &BTreeMap<String, String>,
    ) -> Result<Vec<u8>, WeightsError> {
        let config_json = serde_json::to_string(config).map_err(|e| WeightsError {
            source: "<memory>".to_string(),
            problem: WeightsProblem::BadConfig(e.to_string()),
        })?;
        encode(
            self.clone(),
            HNET_ARCHITECTURE,
            &config_json,
            provenance,
            "<memory>",
        )
    }

    /// Rebuilds a network from the bytes of a weights file on `device`. `source` names the
    /// bytes in error messages (a file name).
    pub fn from_weights_bytes(
        bytes: &[u8],
        device: &Device,
        source: &str,
    ) -> Result<(HNet, HNetConfig, WeightsHeader), WeightsError> {
        let header = expect_architecture(bytes, HNET_ARCHITECTURE, source)?;
        let bad_config = |e: String| WeightsError {
            source: source.to_string(),
            problem: WeightsProblem::BadConfig(e),
        };
        let config: HNetConfig =
            serde_json::from_str(&header.config_json).map_err(|e| bad_config(e.to_string()))?;
        let model = config.init(device).map_err(|e| bad_config(e.to_string()))?;
        let model = apply(model, bytes, source)?;
        Ok((model, config, header))
    }
}
