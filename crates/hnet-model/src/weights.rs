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

use burn::module::Module;
use burn::store::{ModuleRecord, RecordError};
use burn::tensor::{Bytes, Device};
use burn_pack::{Reader, Writer};

use crate::model::{HNet, HNetConfig, HNetConfigError};

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

/// What is wrong with a weights file. Each message says this level only; the cause, where
/// there is one, is the error's [`source`](core::error::Error::source).
#[derive(Debug, thiserror::Error)]
pub enum WeightsProblem {
    /// The network could not be turned into a weights container.
    #[error("the network could not be written as weights")]
    Write(#[source] ContainerProblem),
    /// Not a weights file at all: what the bytes look like instead.
    #[error("not an H-Net weights file (.bpk, written by `hnet train`): this is {0}")]
    NotWeights(&'static str),
    /// A weights container, but damaged or cut short.
    #[error("a weights file, but damaged or cut short (a partial download?)")]
    NotBurnpack(#[source] ContainerProblem),
    /// A burnpack container without H-Net Studio's metadata.
    #[error("a Burn weights file, but not written by H-Net Studio (no `{KEY_FORMAT}` metadata)")]
    NotHNetStudio,
    /// Written by a newer, incompatible version of this format.
    #[error(
        "weights format version {0} is not supported (this build reads version {FORMAT_VERSION})"
    )]
    UnsupportedFormat(String),
    /// Weights of another network.
    #[error("holds `{found}` weights, expected `{expected}`")]
    WrongArchitecture {
        /// What the caller asked for.
        expected: String,
        /// What the file holds.
        found: String,
    },
    /// The configuration in the file cannot be read or describes no valid network.
    #[error("invalid network configuration")]
    BadConfig(#[source] ConfigProblem),
    /// The tensors do not fit the network the configuration describes.
    #[error("weights do not match the network")]
    Mismatch(#[source] ContainerProblem),
}

/// Why a weights container could not be read or written: Burn's own error, kept as it came.
#[derive(Debug, thiserror::Error)]
pub enum ContainerProblem {
    /// From the burnpack container.
    #[error(transparent)]
    Pack(#[from] burn_pack::Error),
    /// From Burn's module record (which is an error value only with `std`, hence its message).
    #[error("{}", record_message(.0))]
    Record(RecordError),
}

/// Why the network settings stored in a weights file are unusable.
#[derive(Debug, thiserror::Error)]
pub enum ConfigProblem {
    /// A metadata entry is missing.
    #[error("missing `{0}` metadata")]
    MissingMetadata(&'static str),
    /// No network of this name exists in this build.
    #[error("unknown architecture `{0}`")]
    UnknownArchitecture(String),
    /// The settings are of another network than the one given with them.
    #[error("settings of `{0}` given for another network")]
    OtherNetwork(&'static str),
    /// The settings' JSON does not parse.
    #[error("unreadable settings")]
    Json(#[source] serde_json::Error),
    /// The settings parse but describe no network that can be built.
    #[error("settings that build no network")]
    Invalid(#[source] HNetConfigError),
    /// A size in the settings is outside what any network of this build has (a damaged or
    /// crafted file: building it would exhaust memory or overflow).
    #[error("`{0}` = {1} is outside {2}")]
    OutOfRange(&'static str, usize, &'static str),
}

/// A weights file that could not be read or written, with the file's name.
#[derive(Debug, thiserror::Error)]
#[error("weights file '{source_name}': {problem}")]
pub struct WeightsError {
    /// The file (or, for in-memory bytes, the name the user knows them by).
    pub source_name: String,
    /// What went wrong; its own causes follow as [`source`](core::error::Error::source).
    #[source]
    pub problem: WeightsProblem,
}

impl WeightsError {
    /// The `problem` of the weights named `source_name`.
    pub fn new(source_name: &str, problem: WeightsProblem) -> Self {
        Self {
            source_name: source_name.to_string(),
            problem,
        }
    }
}

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
    let error = |problem| WeightsError::new(source, problem);
    let write_error = |e: ContainerProblem| error(WeightsProblem::Write(e));
    let record = module
        .into_record()
        .into_bytes()
        .map_err(|e| write_error(ContainerProblem::Record(e)))?;
    let tensors = Reader::from_bytes(record)
        .and_then(Reader::into_tensors)
        .map_err(|e| write_error(e.into()))?;
    let mut writer = Writer::new(tensors)
        .with_metadata(KEY_FORMAT, FORMAT_VERSION)
        .with_metadata(KEY_ARCHITECTURE, architecture)
        .with_metadata(KEY_CONFIG, config_json);
    for (key, value) in provenance {
        writer = writer.with_metadata(&format!("{PROVENANCE_PREFIX}{key}"), value);
    }
    let bytes = writer.into_bytes().map_err(|e| write_error(e.into()))?;
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
    let error = |problem| WeightsError::new(source, problem);
    check_magic(bytes).map_err(error)?;
    let reader = Reader::from_bytes(Bytes::from_bytes_vec(bytes.to_vec()))
        .map_err(|e| error(WeightsProblem::NotBurnpack(e.into())))?;
    let metadata = reader.metadata();
    let format = metadata
        .get(KEY_FORMAT)
        .ok_or_else(|| error(WeightsProblem::NotHNetStudio))?;
    if format != FORMAT_VERSION {
        return Err(error(WeightsProblem::UnsupportedFormat(format.clone())));
    }
    let field = |key: &'static str| {
        metadata.get(key).cloned().ok_or_else(|| {
            error(WeightsProblem::BadConfig(ConfigProblem::MissingMetadata(
                key,
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
    let error = |problem| WeightsError::new(source, problem);
    check_magic(bytes).map_err(error)?;
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(bytes.to_vec()))
        .map_err(|e| error(WeightsProblem::NotBurnpack(ContainerProblem::Record(e))))?;
    module
        .try_load_record(record)
        .map_err(|e| error(WeightsProblem::Mismatch(ContainerProblem::Record(e))))
}

fn record_message(error: &RecordError) -> &str {
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
        return Err(WeightsError::new(
            source,
            WeightsProblem::WrongArchitecture {
                expected: expected.to_string(),
                found: header.architecture,
            },
        ));
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
        let config_json = serde_json::to_string(config).map_err(|e| {
            WeightsError::new(
                "<memory>",
                WeightsProblem::BadConfig(ConfigProblem::Json(e)),
            )
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
        let bad_config = |e| WeightsError::new(source, WeightsProblem::BadConfig(e));
        let config: HNetConfig = serde_json::from_str(&header.config_json)
            .map_err(|e| bad_config(ConfigProblem::Json(e)))?;
        let model = config
            .init(device)
            .map_err(|e| bad_config(ConfigProblem::Invalid(e)))?;
        let model = apply(model, bytes, source)?;
        Ok((model, config, header))
    }
}
