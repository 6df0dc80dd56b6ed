//! What a retrieval is asked to do: the gas, the line pair, the hard target, the DIAL cells and
//! the averaging. Built from a scene's `[retrieval]` section (validated there) or by hand.

use std::ops::Range;
use std::sync::Arc;

use crate::spectroscopy::{LblOptions, LineList};

/// The spectroscopy a retrieval assumes for its reference state: lines and line shape, which
/// may differ from the truth's (to study imperfect spectroscopy).
#[derive(Debug, Clone, PartialEq)]
pub struct AssumedSpectroscopy {
    /// The lines.
    pub lines: Arc<LineList>,
    /// Line-by-line options (line shape, line mixing, wing…).
    pub options: LblOptions,
}

/// The hard target of an integrated-path (IPDA) retrieval.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetKind {
    /// The scene's Lambertian surface.
    Surface,
    /// The top of a particle layer (a cloud), by its index in the scene's layers.
    Layer {
        /// Index of the layer.
        index: usize,
        /// Its name, for messages and output.
        name: String,
    },
}

/// A hard target and the gates its echo is summed over.
#[derive(Debug, Clone, PartialEq)]
pub struct HardTarget {
    /// What the target is.
    pub kind: TargetKind,
    /// Range from the lidar to the target (surface or layer top) along the axis \[m\].
    pub range_m: f64,
    /// Altitude of the target \[m\].
    pub altitude_m: f64,
    /// Gates whose energies make the echo.
    pub gates: Range<usize>,
}

/// Range cells of a range-resolved DIAL retrieval: cell c spans the centres of gates
/// `first_gate + c·gates_per_cell` and `first_gate + (c + 1)·gates_per_cell`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DialCells {
    /// Cell length along the axis \[m\].
    pub cell_m: f64,
    /// Gate whose centre starts the first cell.
    pub first_gate: usize,
    /// Gates per cell.
    pub gates_per_cell: usize,
    /// Number of cells.
    pub cells: usize,
}

impl DialCells {
    /// The two gates bounding cell c.
    pub fn bounds(&self, c: usize) -> (usize, usize) {
        let a = self.first_gate + c * self.gates_per_cell;
        (a, a + self.gates_per_cell)
    }
}

impl RetrievalConfig {
    /// The lines and options of the reference state: the retrieval's own spectroscopy, or the
    /// truth's (`truth_lines`, `truth_options`) when it has none.
    pub fn assumed<'a>(
        &'a self,
        truth_lines: &'a LineList,
        truth_options: &LblOptions,
    ) -> (&'a LineList, LblOptions) {
        match &self.spectroscopy {
            Some(s) => (&s.lines, s.options),
            None => (truth_lines, *truth_options),
        }
    }
}

/// The retrieval settings.
#[derive(Debug, Clone, PartialEq)]
pub struct RetrievalConfig {
    /// Target gas (a profile gas with lines, e.g. `CO2`).
    pub gas: String,
    /// Index of the on-line among the laser lines.
    pub on: usize,
    /// Index of the off-line.
    pub off: usize,
    /// IPDA on this hard target, if any.
    pub target: Option<HardTarget>,
    /// Range-resolved DIAL on these cells, if any.
    pub dial: Option<DialCells>,
    /// Shot pairs averaged into one measurement.
    pub averaging_shots: u64,
    /// What `averaging_shots` stands for, for output (e.g. `50 km along track`).
    pub averaging_label: String,
    /// Noisy realisations simulated per product.
    pub realisations: usize,
    /// The spectroscopy of the reference state; `None`: the truth's (`[gas_absorption]`).
    pub spectroscopy: Option<AssumedSpectroscopy>,
}
