//! Retrievals: the gas from on- and off-line signals, next to the truth.
//!
//! Consumes line returns and signals (the instrument stage), a reference atmospheric state and
//! the scene's own profile (the truth); produces retrieval products (IPDA column mixing ratio
//! and column number density, range-resolved DIAL number density and mixing ratio) with their
//! bias, Monte Carlo error and random error (analytic and simulated).

pub mod config;

pub use config::{AssumedSpectroscopy, DialCells, HardTarget, RetrievalConfig, TargetKind};
pub mod products;
pub mod reference;

pub use products::{Geometry, Method, Product, Quantity, Retrieval, Weighting};
pub use reference::{AssumedInstrument, LayerColumns, PathDepths, ReferenceState};

/// Why a retrieval cannot be done.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RetrievalError {
    /// The line-by-line reference state failed.
    #[error("reference state: {0}")]
    Spectroscopy(#[from] crate::spectroscopy::SpectroscopyError),
    /// The target gas is missing from the profile or the lines.
    #[error("{0}")]
    Gas(String),
    /// The on-line does not absorb more than the off-line over a path.
    #[error("{0}")]
    NotAbsorbing(String),
    /// No signal where a retrieval needs one (SNR ≤ 0).
    #[error("{message}")]
    NoSignal {
        /// In a DIAL cell (else at the hard target).
        dial: bool,
        /// What is wrong.
        message: String,
    },
}

impl RetrievalError {
    /// The scene key (section, key) a user should look at.
    pub fn scene_key(&self) -> (&'static str, &'static str) {
        match self {
            RetrievalError::Spectroscopy(_) | RetrievalError::Gas(_) => ("retrieval", "gas"),
            RetrievalError::NotAbsorbing(_) => ("retrieval", "on"),
            RetrievalError::NoSignal { dial: true, .. } => ("retrieval", "dial_end_m"),
            RetrievalError::NoSignal { dial: false, .. } => ("retrieval", "target"),
        }
    }
}
