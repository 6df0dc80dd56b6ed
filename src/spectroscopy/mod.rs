//! Gas absorption line by line from HITRAN line lists.
//!
//! Consumes line lists (HITRAN 160-character `.par` records, or the built-in CO2 30012←00001
//! band model) and atmospheric [`Profile`](crate::atmosphere::Profile)s; produces monochromatic
//! cross-sections and layer optical depths per channel, in a table that can be saved and loaded.
//!
//! | step | module | entry point |
//! |---|---|---|
//! | isotopologue masses, abundances | [`isotopologues`] | [`isotopologues::Isotopologue::get`] |
//! | partition sums (TIPS-2021) | [`tips`] | [`tips::partition_sum`] |
//! | lines and line lists | [`lines`] | [`Line`], [`LineList`], [`LineFilter`] |
//! | line lists | [`hitran`] | [`LineList::read_par`], [`LineList::co2_30012_band_model`] |
//! | Voigt profile | [`voigt`] | [`voigt::re_w`], [`voigt::re_w_exact`] |
//! | cross-sections | [`xsec`] | [`cross_section`], [`cross_section_at`] |
//! | Curtis-Godson layers | [`layers`] | [`layers::curtis_godson_layers`] |
//! | layer optical depths, direct | [`optical_depth`] | [`layer_optical_depths_at`] |
//! | optical-depth table | [`table`] | [`GasOpticalDepthTable`] |
//! | CO2 band model | [`band_model`] | [`band_model::Co2BandModel`] |
//!
//! Conventions: wavenumbers in cm⁻¹ (vacuum), cross-sections in cm²/molecule of the gas (HITRAN
//! intensities include the natural isotopic abundance, so a list with all isotopologues of a
//! molecule gives σ per molecule of that gas), line strengths in cm/molecule at 296 K. The method
//! and every default are described in `docs/spectroscopy.md`.

pub mod band_model;
pub mod csv_lines;
pub mod hitran;
pub mod htp;
pub mod isotopologues;
pub mod layers;
pub mod lines;
pub mod optical_depth;
pub mod table;
pub mod tips;
pub mod voigt;
pub mod xsec;

pub use layers::{CgLayer, LineOfSight};
pub use lines::{Broadener, Line, LineFilter, LineList, ShapeColumns, ShapeParameters};
pub use optical_depth::{
    LayerDepthMemo, LayerGasCounts, layer_gas_counts, layer_optical_depths_at,
};
pub use table::GasOpticalDepthTable;
pub use xsec::{
    Conventions, GasState, LblOptions, LineShapeModel, VoigtMethod, WavenumberGrid, WingCentre,
    cross_section, cross_section_at,
};

use crate::input::InputError;

/// Everything that can go wrong in the spectroscopy stage.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SpectroscopyError {
    /// A bad input file (line list, profile, table), with file, line and field.
    #[error(transparent)]
    Input(#[from] InputError),
    /// No partition sum for an isotopologue at a temperature (outside the embedded table or an
    /// isotopologue lidarsim does not know).
    #[error(
        "no TIPS-2021 partition sum for molecule {molecule_id} isotopologue {iso_id} at {temperature_k} K: {reason}"
    )]
    PartitionSum {
        /// HITRAN molecule number.
        molecule_id: u8,
        /// HITRAN local isotopologue number.
        iso_id: u8,
        /// Requested temperature \[K\].
        temperature_k: f64,
        /// Why.
        reason: String,
    },
    /// A line profile asks for parameters the line list does not have.
    #[error("{lines}: {parameters}")]
    MissingParameters {
        /// The line list (its file).
        lines: String,
        /// Which parameters, and for what.
        parameters: String,
    },
    /// An argument outside its valid range (names the argument and the value).
    #[error("invalid {name} = {value}: {reason}")]
    InvalidArgument {
        /// Argument name, with its unit.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The constraint it breaks.
        reason: String,
    },
    /// A wavenumber outside the grid of a table.
    #[error(
        "wavenumber {wavenumber_cm1} cm-1 is outside the table's grid [{start_cm1}, {end_cm1}] cm-1 (interpolation needs two grid points on each side)"
    )]
    OutsideGrid {
        /// Requested wavenumber [cm⁻¹].
        wavenumber_cm1: f64,
        /// First usable grid point [cm⁻¹].
        start_cm1: f64,
        /// Last usable grid point [cm⁻¹].
        end_cm1: f64,
    },
    /// An altitude outside the profile.
    #[error("altitude {altitude_m} m is outside the profile `{profile}` ({bottom_m} to {top_m} m)")]
    OutsideProfile {
        /// Requested altitude \[m\].
        altitude_m: f64,
        /// Profile name.
        profile: String,
        /// Lowest level \[m\].
        bottom_m: f64,
        /// Highest level \[m\].
        top_m: f64,
    },
    /// A cross-section or optical depth below zero: where, which line, and why.
    #[error("{location}: {message}")]
    NegativeAbsorption {
        /// The line list (file and line, and the column, where one line is to blame) or table.
        location: String,
        /// What is negative, where, and the cause.
        message: String,
    },
    /// A saved table that does not match what it is asked for.
    #[error("the optical-depth table does not match: {0}")]
    TableMismatch(String),
    /// A gas in the line list that the profile does not carry (or the reverse).
    #[error("gas {0}")]
    Gas(String),
    /// Writing a file failed.
    #[error(transparent)]
    Write(#[from] crate::output::OutputError),
}
