//! IPDA and DIAL retrievals of one set of returns, with truth, bias and errors.
//!
//! From the line returns (noise-free: the expected signals) and from noisy realisations of
//! shot-averaged measurements ([`Signals::realise`]):
//!
//! * **IPDA** on the echo of the hard target summed over its window (Ehret et al. 2008):
//!   DAOD = ½ ln(P_off E_on / (P_on E_off)); the dry-air column mixing ratio X = s·X_ref with
//!   D(s) = DAOD (the weighting-function form X = DAOD/IWF for a monochromatic laser;
//!   [`super::reference`]); and the slant column N = (DAOD − D_other)/(σ_on − σ_off) with the
//!   virtual cross-sections σ = −ln T_gas/(2N_ref) of the reference state (the reference study),
//!   D_other the other gases' DAOD in the reference state.
//! * **DIAL** per range cell between gate centres r_a < r_b:
//!   ΔD = ½ ln(P_off(r_b) P_on(r_a) / (P_on(r_b) P_off(r_a))), the cell's gas scaled by s so
//!   that the reference's D(r_b) − D(r_a) equals it; n = s·n_ref and x = s·x_ref. For a
//!   monochromatic laser n = ΔD/(Δσ Δr) (docs/design.md §3, n = dN/dz).
//!
//! Errors, each converted to the product through dD/ds of the reference state:
//! * Monte Carlo: the delta method on the on/off returns with their covariance (shared photon
//!   paths), var ΔD = ¼ Σ_gates [σ²_on/P²_on + σ²_off/P²_off − 2 cov/(P_on P_off)], gates taken
//!   as independent;
//! * random, analytic, per shot pair: var D = ¼ Σ_lines [SNR⁻² + ε_M² + (σ_j S/P)²]
//!   (`docs/design.md` §3 with the energy monitor and the frequency jitter added; the jitter of one shot is common
//!   to both ends of a DIAL cell, so there it enters as σ_j (S_b/P_b − S_a/P_a)); divided by
//!   √N after averaging N shot pairs;
//! * random, simulated: the standard deviation of the retrievals of `realisations` noisy
//!   measurements of 1 and of N shot pairs, and the mean of the N-shot ones (so the bias that
//!   noise itself brings through the logarithm shows). Realisations whose signal is not
//!   positive cannot be retrieved; if more than 10 % of them fail the simulated figures are NaN.
//!
//! A product from Monte Carlo returns with no photon scored in one of its windows (too few
//! photons) has NaN estimates. `retrieval.csv` writes every such NaN as an empty field.

use std::ops::Range;

use super::RetrievalError;
use super::config::RetrievalConfig;
use super::reference::{LayerColumns, PathDepths, ReferenceState};
use crate::instrument::detector::photon_energy_j;
use crate::instrument::laser::{Laser, LineReturns};
use crate::instrument::signals::{Signals, WindowSignal};
use crate::jacobians::{JacobianQuantity, Jacobians};
use crate::returns::{Order, Source};
use crate::rng::{self, Stream};

/// Fewest valid realisations, as a fraction, for a simulated error to be reported.
const MIN_VALID_FRACTION: f64 = 0.9;

/// What was retrieved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    /// Dry-air mixing ratio \[ppm\] (column average for IPDA, cell average for DIAL).
    MixingRatio,
    /// Slant column along the beam [molecules/m²].
    SlantColumn,
    /// Number density, cell average [molecules/m³].
    NumberDensity,
}

impl Quantity {
    /// The `quantity` column value.
    pub fn label(self) -> &'static str {
        match self {
            Quantity::MixingRatio => "mixing_ratio",
            Quantity::SlantColumn => "slant_column",
            Quantity::NumberDensity => "number_density",
        }
    }
    /// The suffix of `retrieval.csv`'s value columns of this quantity (its unit).
    pub fn column_suffix(self) -> &'static str {
        match self {
            Quantity::MixingRatio => "ppm",
            Quantity::SlantColumn => "molecules_per_m2",
            Quantity::NumberDensity => "molecules_per_m3",
        }
    }
    /// All quantities, in the order of `retrieval.csv`'s column groups.
    pub const ALL: [Quantity; 3] = [
        Quantity::MixingRatio,
        Quantity::SlantColumn,
        Quantity::NumberDensity,
    ];
    /// The unit, as text.
    pub fn unit(self) -> &'static str {
        match self {
            Quantity::MixingRatio => "ppm",
            Quantity::SlantColumn => "molecules/m2",
            Quantity::NumberDensity => "molecules/m3",
        }
    }
}

/// The retrieval method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Integrated path to a hard target, mixing ratio by the weighting function.
    Ipda,
    /// Integrated path, column by the virtual cross-sections of the reference state.
    IpdaVirtual,
    /// Range-resolved DIAL.
    Dial,
}

impl Method {
    /// The `method` column value.
    pub fn label(self) -> &'static str {
        match self {
            Method::Ipda => "ipda",
            Method::IpdaVirtual => "ipda_virtual_sigma",
            Method::Dial => "dial",
        }
    }
}

/// One retrieved quantity next to its truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Product {
    /// How.
    pub method: Method,
    /// What.
    pub quantity: Quantity,
    /// Returns it was retrieved from.
    pub source: Source,
    /// Scattering order of those returns.
    pub order: Order,
    /// `on/off` line names.
    pub channel_pair: String,
    /// Field of view (full angle) \[mrad\].
    pub fov_full_angle_mrad: f64,
    /// Range interval along the beam \[m\] (IPDA: lidar to target).
    pub range_m: (f64, f64),
    /// Altitude interval \[m\], bottom and top.
    pub altitude_m: (f64, f64),
    /// The scene's own value.
    pub truth: f64,
    /// Retrieved from the expected (noise-free) signals.
    pub retrieved: f64,
    /// Standard error of `retrieved` from the Monte Carlo noise of the returns (0 analytic).
    pub mc_stderr: f64,
    /// What that error would be if the on- and off-line returns were traced independently.
    pub mc_stderr_independent: f64,
    /// Random error of one shot pair, analytic.
    pub random_error_per_shot_pair: f64,
    /// Random error after averaging, analytic.
    pub random_error_averaged: f64,
    /// Standard deviation of simulated single-shot-pair retrievals.
    pub simulated_error_per_shot_pair: f64,
    /// Standard deviation of simulated averaged retrievals.
    pub simulated_error_averaged: f64,
    /// Mean of simulated averaged retrievals.
    pub simulated_mean_averaged: f64,
    /// The first simulated averaged retrieval: one noisy measurement, as an ensemble study
    /// takes one per profile (NaN if its signal was not positive).
    pub simulated_first_averaged: f64,
    /// Shot pairs averaged.
    pub shots_averaged: u64,
}

/// One layer's part of a retrieved product: its weighting function times the layer's gas
/// (`weighting.csv`; [`Retrieval::weighting`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Weighting {
    /// How.
    pub method: Method,
    /// What.
    pub quantity: Quantity,
    /// Scattering order of the returns (1: the single-scatter weighting function; total:
    /// aware of multiple scattering).
    pub order: Order,
    /// `on/off`.
    pub channel_pair: String,
    /// Field of view \[mrad\].
    pub fov_full_angle_mrad: f64,
    /// The product's range interval \[m\].
    pub range_m: (f64, f64),
    /// Layer of the optical atmosphere, and its bottom and top \[m\].
    pub layer: usize,
    /// Bottom and top of the layer \[m\].
    pub layer_m: (f64, f64),
    /// ∂(product)/∂ln n_gas of the layer, in the product's unit.
    pub value: f64,
    /// Its Monte Carlo standard error as if the on- and off-line derivatives and the returns
    /// were independent: they share the photons and are strongly correlated, so this overstates
    /// it (by 50× for the IPDA's sum over layers in the airborne DIAL scene, whose own error is
    /// the product's `mc_stderr`).
    pub stderr: f64,
}

/// Header of `weighting.csv`: as `retrieval.csv` ([`CSV_HEADER`]), one row per (product,
/// layer) with its derivative and error in the two columns of its quantity's unit
/// (`derivative_ppm`, `stderr_independent_ppm` for a mixing ratio, `…_molecules_per_m2`,
/// `…_molecules_per_m3`), the other units' columns empty, so that no column holds two units.
pub const WEIGHTING_HEADER: &str = "method,order,channel_pair,fov_full_angle_mrad,range_start_m,range_end_m,quantity,layer,layer_bottom_m,layer_top_m,derivative_ppm,stderr_independent_ppm,derivative_molecules_per_m2,stderr_independent_molecules_per_m2,derivative_molecules_per_m3,stderr_independent_molecules_per_m3";

/// The value columns of `weighting.csv` of one unit, without the unit's suffix, in order.
pub const WEIGHTING_VALUE_COLUMNS: [&str; 2] = ["derivative", "stderr_independent"];

impl Weighting {
    /// The row of `weighting.csv` (no newline).
    pub fn csv_row(&self) -> String {
        use std::fmt::Write as _;
        let mut row = format!(
            "{},{},{},{},{},{},{},{},{},{}",
            self.method.label(),
            self.order.label(),
            crate::output::csv_field(&self.channel_pair),
            self.fov_full_angle_mrad,
            self.range_m.0,
            self.range_m.1,
            self.quantity.label(),
            self.layer,
            self.layer_m.0,
            self.layer_m.1,
        );
        for q in Quantity::ALL {
            if q == self.quantity {
                let _ = write!(
                    row,
                    ",{:.9e},{:.9e}",
                    crate::output::csv_number(self.value),
                    crate::output::csv_number(self.stderr)
                );
            } else {
                row.push_str(",,");
            }
        }
        row
    }
}

/// Header of `retrieval.csv`, one row per product: its values in the columns of its
/// quantity's unit (`_ppm` for a mixing ratio, `_molecules_per_m2` for a slant column,
/// `_molecules_per_m3` for a number density), the other units' columns empty, so that no
/// column holds two units.
pub const CSV_HEADER: &str = "method,source,order,channel_pair,fov_full_angle_mrad,range_start_m,range_end_m,altitude_bottom_m,altitude_top_m,quantity,shots_averaged,truth_ppm,retrieved_ppm,bias_ppm,mc_stderr_ppm,random_error_per_shot_pair_ppm,random_error_averaged_ppm,simulated_error_per_shot_pair_ppm,simulated_error_averaged_ppm,simulated_bias_averaged_ppm,truth_molecules_per_m2,retrieved_molecules_per_m2,bias_molecules_per_m2,mc_stderr_molecules_per_m2,random_error_per_shot_pair_molecules_per_m2,random_error_averaged_molecules_per_m2,simulated_error_per_shot_pair_molecules_per_m2,simulated_error_averaged_molecules_per_m2,simulated_bias_averaged_molecules_per_m2,truth_molecules_per_m3,retrieved_molecules_per_m3,bias_molecules_per_m3,mc_stderr_molecules_per_m3,random_error_per_shot_pair_molecules_per_m3,random_error_averaged_molecules_per_m3,simulated_error_per_shot_pair_molecules_per_m3,simulated_error_averaged_molecules_per_m3,simulated_bias_averaged_molecules_per_m3";

/// The value columns of `retrieval.csv` of one unit, without the unit's suffix, in order.
pub const CSV_VALUE_COLUMNS: [&str; 9] = [
    "truth",
    "retrieved",
    "bias",
    "mc_stderr",
    "random_error_per_shot_pair",
    "random_error_averaged",
    "simulated_error_per_shot_pair",
    "simulated_error_averaged",
    "simulated_bias_averaged",
];

impl Product {
    /// Retrieved minus truth.
    pub fn bias(&self) -> f64 {
        self.retrieved - self.truth
    }

    /// The row of `retrieval.csv` (no newline). A value that cannot be computed (NaN or
    /// infinite: Monte Carlo returns with no photon scored in a window, simulated figures when
    /// too many realisations fail) is an empty field, never `NaN` or `inf`.
    pub fn csv_row(&self) -> String {
        let v = |x: f64| -> String {
            if x.is_finite() {
                x.to_string()
            } else {
                String::new()
            }
        };
        let mut row = format!(
            "{},{},{},{},{},{},{},{},{},{},{}",
            self.method.label(),
            self.source.label(),
            self.order.label(),
            crate::output::csv_field(&self.channel_pair),
            v(self.fov_full_angle_mrad),
            v(self.range_m.0),
            v(self.range_m.1),
            v(self.altitude_m.0),
            v(self.altitude_m.1),
            self.quantity.label(),
            self.shots_averaged,
        );
        let values = [
            self.truth,
            self.retrieved,
            self.bias(),
            self.mc_stderr,
            self.random_error_per_shot_pair,
            self.random_error_averaged,
            self.simulated_error_per_shot_pair,
            self.simulated_error_averaged,
            self.simulated_mean_averaged - self.truth,
        ];
        for q in Quantity::ALL {
            for x in values {
                row.push(',');
                if q == self.quantity {
                    row.push_str(&v(x));
                }
            }
        }
        row
    }
}

/// Everything a retrieval of this scene needs that does not depend on the returns.
#[derive(Debug, Clone)]
pub struct Retrieval {
    /// The settings.
    pub config: RetrievalConfig,
    /// The laser (its lines' energies, and the imperfections a measurement has).
    pub laser: Laser,
    /// The reference state the retrieval assumes.
    pub reference: ReferenceState,
    /// The truth: the scene's own profile's columns on the same grid.
    pub truth: LayerColumns,
    /// Lidar altitude \[m\].
    pub lidar_altitude_m: f64,
    /// Cosine of the pointing zenith angle.
    pub mu: f64,
    /// Gate centres \[m\].
    pub range_m: Vec<f64>,
    /// `on/off`.
    pub pair: String,
    /// Random seed of the instrument noise.
    pub seed: u64,
    /// Every measurement the configuration asks for (derived once from the above).
    targets: Vec<Target>,
}

/// What one retrieval of one measurement needs: where, and how to turn D into the product.
#[derive(Debug, Clone)]
struct Target {
    method: Method,
    quantity: Quantity,
    range_m: (f64, f64),
    altitude_m: (f64, f64),
    truth: f64,
    /// Optical depths of the path (DIAL: the cell's part scaled).
    path: PathDepths,
    /// DIAL: the path to the near end of the cell, for `offset`.
    near: Option<PathDepths>,
    /// The reference's slant gas column of the path; read only by the virtual cross-section
    /// method, NaN for the others so that a stray read shows.
    slant_reference: f64,
    /// D of the reference at the near end (DIAL), subtracted before solving.
    offset: f64,
    /// Product per unit s (mixing ratio or density of the reference), or for the virtual
    /// cross-section method 1/(σ_on − σ_off) with `other_daod` removed first.
    per_unit: f64,
    other_daod: f64,
    /// Gates (windows) on which the measurement is made: one window (IPDA) or two (DIAL).
    windows: Vec<Range<usize>>,
}

impl Target {
    /// The sign of window `k` in D: D of a cell is the far end's minus the near end's; an IPDA
    /// window stands alone.
    fn window_sign(&self, k: usize) -> f64 {
        let ipda = self.windows.len() == 1;
        if k == 0 && !ipda { -1.0 } else { 1.0 }
    }
}

/// Every window any target is measured on, once, and the indices of each target's windows in
/// that list.
fn measurement_windows(targets: &[Target]) -> (Vec<Range<usize>>, Vec<Vec<usize>>) {
    let mut windows: Vec<Range<usize>> = Vec::new();
    let window_ids: Vec<Vec<usize>> = targets
        .iter()
        .map(|t| {
            t.windows
                .iter()
                .map(|w| match windows.iter().position(|x| x == w) {
                    Some(i) => i,
                    None => {
                        windows.push(w.clone());
                        windows.len() - 1
                    }
                })
                .collect()
        })
        .collect();
    (windows, window_ids)
}

/// Where a retrieval looks from: the lidar's altitude, its beam's direction and its gates.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// Altitude of the lidar \[m\].
    pub lidar_altitude_m: f64,
    /// Direction cosine of the beam with the upward vertical.
    pub mu: f64,
    /// Centres of the range gates \[m\].
    pub range_m: Vec<f64>,
}

impl Retrieval {
    /// The expected signal-to-noise ratio per shot of the on-line in the window of each
    /// hard-target (IPDA) measurement, for every field of view of `signals`: (FOV full angle
    /// \[mrad\], SNR). The run warns where it is below 1 ([`crate::scene::warnings`]).
    pub fn ipda_on_line_snr(&self, signals: &Signals) -> Vec<(f64, f64)> {
        let mut out = Vec::new();
        for t in self.targets.iter().filter(|t| t.windows.len() == 1) {
            for (f, fov) in signals.fov_full_angle_mrad.iter().enumerate() {
                let w = signals.window(self.config.on, f, t.windows[0].clone());
                out.push((*fov, w.noise.snr()));
            }
        }
        out
    }

    /// The retrieval of `config` (its line pair named `pair`) seen from `geometry`, against
    /// `reference` and `truth`; `seed` seeds its noise. Checks that the on-line absorbs more
    /// than the off-line over every path it will retrieve.
    pub fn new(
        config: RetrievalConfig,
        laser: Laser,
        (reference, truth): (ReferenceState, LayerColumns),
        geometry: Geometry,
        pair: String,
        seed: u64,
    ) -> Result<Self, RetrievalError> {
        let Geometry {
            lidar_altitude_m,
            mu,
            range_m,
        } = geometry;
        let mut r = Retrieval {
            config,
            laser,
            reference,
            truth,
            lidar_altitude_m,
            mu,
            range_m,
            pair,
            seed,
            targets: Vec::new(),
        };
        r.targets = r.targets();
        r.set_pair(r.config.on, r.config.off, r.pair.clone())?;
        Ok(r)
    }

    /// Retrieve with another on/off pair of the same lines. The paths through the reference
    /// state do not depend on the pair, so a study of many pairs computes them once; only the
    /// pair's own terms (virtual cross-sections, the DIAL near-end D) are redone. Checks that
    /// the new on-line absorbs more than the off-line over every path.
    pub fn set_pair(&mut self, on: usize, off: usize, pair: String) -> Result<(), RetrievalError> {
        let n = self.reference.weights.len();
        if on >= n || off >= n || on == off {
            return Err(RetrievalError::Gas(format!(
                "line pair ({on}, {off}) is not two different lines of {n}"
            )));
        }
        self.config.on = on;
        self.config.off = off;
        self.pair = pair;
        let mut targets = std::mem::take(&mut self.targets);
        for t in &mut targets {
            self.pair_terms(t);
        }
        self.targets = targets;
        let r = &*self;
        for t in &r.targets {
            // dD/ds is the target gas's own differential optical depth over the path.
            let (_, g) = r.reference.daod(&t.path, r.config.on, r.config.off, 1.0);
            if !(g > 0.0) {
                return Err(RetrievalError::NotAbsorbing(format!(
                    "over the ranges {:.0}–{:.0} m the on-line absorbs no more than the off-line (differential optical depth of {} {g:.3e})",
                    t.range_m.0, t.range_m.1, r.config.gas
                )));
            }
        }
        Ok(())
    }

    /// The terms of a target that depend on the on/off pair.
    fn pair_terms(&self, t: &mut Target) {
        let (on, off) = (self.config.on, self.config.off);
        match t.method {
            Method::IpdaVirtual => {
                let slant_ref = t.slant_reference;
                let dsigma = self
                    .reference
                    .virtual_cross_section_m2(&t.path, on, slant_ref)
                    - self
                        .reference
                        .virtual_cross_section_m2(&t.path, off, slant_ref);
                t.per_unit = 1.0 / dsigma;
                t.other_daod = self.reference.daod(&t.path, on, off, 0.0).0;
            }
            Method::Dial => {
                if let Some(near) = &t.near {
                    t.offset = self.reference.daod(near, on, off, 1.0).0;
                }
            }
            Method::Ipda => {}
        }
    }

    fn altitude(&self, range_m: f64) -> f64 {
        self.lidar_altitude_m + self.mu * range_m
    }

    /// Every measurement the configuration asks for, without the pair's own terms
    /// ([`Self::pair_terms`]).
    fn targets(&self) -> Vec<Target> {
        let z0 = self.lidar_altitude_m;
        // Adjacent DIAL cells share an end: each distinct path is computed once.
        let mut paths: Vec<(f64, PathDepths)> = Vec::new();
        let mut path_to = |z: f64| -> PathDepths {
            match paths.iter().find(|(e, _)| e.to_bits() == z.to_bits()) {
                Some((_, p)) => p.clone(),
                None => {
                    let p = self.reference.path(z0, z, self.mu);
                    paths.push((z, p.clone()));
                    p
                }
            }
        };
        let mut out = Vec::new();
        if let Some(t) = &self.config.target {
            let zt = t.altitude_m;
            let path = path_to(zt);
            let (gas_ref, dry_ref) = self.reference.columns.between(z0, zt);
            let (gas, dry) = self.truth.between(z0, zt);
            // The column ends at the top of the atmosphere for a lidar above it.
            let top = self.reference.columns.edges_m.last().copied().unwrap_or(z0);
            let alt = (zt.min(z0.min(top)), zt.max(z0.min(top)));
            let window = vec![t.gates.clone()];
            out.push(Target {
                method: Method::Ipda,
                quantity: Quantity::MixingRatio,
                range_m: (0.0, t.range_m),
                altitude_m: alt,
                truth: gas / dry * 1e6,
                per_unit: gas_ref / dry_ref * 1e6,
                offset: 0.0,
                other_daod: 0.0,
                path: path.clone(),
                near: None,
                slant_reference: f64::NAN,
                windows: window.clone(),
            });
            out.push(Target {
                method: Method::IpdaVirtual,
                quantity: Quantity::SlantColumn,
                range_m: (0.0, t.range_m),
                altitude_m: alt,
                truth: gas / self.mu.abs(),
                per_unit: f64::NAN,
                offset: 0.0,
                other_daod: f64::NAN,
                path,
                near: None,
                slant_reference: gas_ref / self.mu.abs(),
                windows: window,
            });
        }
        if let Some(d) = &self.config.dial {
            for c in 0..d.cells {
                let (a, b) = d.bounds(c);
                let (ra, rb) = (self.range_m[a], self.range_m[b]);
                let (za, zb) = (self.altitude(ra), self.altitude(rb));
                let near = path_to(za);
                let far = path_to(zb);
                let path = PathDepths::cell(&near, &far);
                let (gas_ref, dry_ref) = self.reference.columns.between(za, zb);
                let (gas, dry) = self.truth.between(za, zb);
                let dz = (zb - za).abs();
                let alt = (za.min(zb), za.max(zb));
                for (quantity, truth, per_unit) in [
                    (Quantity::NumberDensity, gas / dz, gas_ref / dz),
                    (
                        Quantity::MixingRatio,
                        gas / dry * 1e6,
                        gas_ref / dry_ref * 1e6,
                    ),
                ] {
                    out.push(Target {
                        method: Method::Dial,
                        quantity,
                        range_m: (ra, rb),
                        altitude_m: alt,
                        truth,
                        per_unit,
                        offset: f64::NAN,
                        other_daod: 0.0,
                        path: path.clone(),
                        near: Some(near.clone()),
                        slant_reference: f64::NAN,
                        windows: vec![a..a + 1, b..b + 1],
                    });
                }
            }
        }
        out
    }

    /// The product from a measured D (IPDA: DAOD; DIAL: ΔD), and its derivative dP/dD.
    fn value(&self, t: &Target, measured: f64) -> (f64, f64) {
        let (on, off) = (self.config.on, self.config.off);
        if t.method == Method::IpdaVirtual {
            return ((measured - t.other_daod) * t.per_unit, t.per_unit);
        }
        let s = self
            .reference
            .solve_scale(&t.path, on, off, measured + t.offset);
        let (_, g) = self.reference.daod(&t.path, on, off, s);
        (s * t.per_unit, t.per_unit / g)
    }

    /// Retrieve every product from one set of line returns and their signals (same source and
    /// order), for field of view `fov`.
    pub fn retrieve(
        &self,
        returns: &LineReturns,
        signals: &Signals,
        fov: usize,
    ) -> Result<Vec<Product>, RetrievalError> {
        let (on, off) = (self.config.on, self.config.off);
        let mean = &returns.mean;
        let o = mean
            .order_index(signals.order)
            .ok_or_else(|| RetrievalError::Gas("returns without the signals' order".into()))?;
        let e_on = self.laser.pulse_energy_j[on];
        let e_off = self.laser.pulse_energy_j[off];
        let targets = &self.targets;
        let n_avg = self.config.averaging_shots;
        let reals = self.config.realisations;
        let (windows, window_ids) = measurement_windows(targets);
        // The expected echo and noise of every window, for the on- (0) and the off-line (1).
        let expected: [Vec<WindowSignal>; 2] = [on, off].map(|line| {
            windows
                .iter()
                .map(|w| signals.window(line, fov, w.clone()))
                .collect()
        });
        let sims = self.simulate(signals, &expected, reals);
        let mut products = Vec::with_capacity(targets.len());
        for (t, ids) in targets.iter().zip(&window_ids) {
            // Expected signals: D, its Monte Carlo variance (and as if independent).
            let window = |line: usize, w: &Range<usize>| -> (f64, f64) {
                w.clone().fold((0.0, 0.0), |(e, v), g| {
                    let i = mean.index(line, fov, g, o);
                    (e + mean.energy_j[i], v + mean.stderr_j[i].powi(2))
                })
            };
            let cov = |w: &Range<usize>| -> f64 {
                w.clone()
                    .map(|g| mean.covariance_j2(on, off, fov, g, o).unwrap_or(0.0))
                    .sum()
            };
            let ipda = t.windows.len() == 1;
            let sign = |k: usize| t.window_sign(k);
            let (mut d, mut var_mc, mut var_ind) = (0.0, 0.0, 0.0);
            let mut no_signal = None;
            for (k, w) in t.windows.iter().enumerate() {
                let (p_on, v_on) = window(on, w);
                let (p_off, v_off) = window(off, w);
                if !(p_on > 0.0 && p_off > 0.0) {
                    no_signal = Some(w.clone());
                }
                let energy = if ipda { (e_on / e_off).ln() } else { 0.0 };
                d += sign(k) * 0.5 * ((p_off / p_on).ln() + energy);
                let ind = v_on / (p_on * p_on) + v_off / (p_off * p_off);
                var_ind += 0.25 * ind;
                var_mc += 0.25 * (ind - 2.0 * cov(w) / (p_on * p_off));
            }
            let (var_shot, weak) = self.shot_variance(t, ids, &expected);
            let what = if ipda { "hard-target" } else { "atmospheric" };
            let refusal = match (no_signal, weak) {
                (Some(w), _) => Some(format!(
                    "no {what} signal in the gates around {:.0} m: SNR ≤ 0",
                    self.range_m[w.start]
                )),
                (None, Some((w, snr))) => Some(format!(
                    "no usable {what} signal in the gates around {:.0} m: SNR {snr:.1e} is too \
                     small for a random error",
                    self.range_m[w.start]
                )),
                (None, None) => None,
            };
            if let Some(message) = refusal
                && signals.source == Source::Analytic
            {
                return Err(RetrievalError::NoSignal {
                    dial: t.method == Method::Dial,
                    message,
                });
            }
            let (retrieved, slope) = self.value(t, d);
            let sd_shot = 0.5 * var_shot.sqrt() * slope.abs();
            // Simulated: the same retrieval of every noisy measurement, of N and of 1 shot pair.
            let retrieve_sim = |m: &Measurement| -> f64 {
                let mut d_meas = 0.0;
                for (k, id) in ids.iter().enumerate() {
                    d_meas += sign(k) * 0.5 * (m.ln_signal[1][*id] - m.ln_signal[0][*id]);
                }
                if ipda {
                    d_meas -= 0.5 * (m.ln_energy[1] - m.ln_energy[0]);
                }
                if d_meas.is_finite() {
                    self.value(t, d_meas).0
                } else {
                    f64::NAN
                }
            };
            let averaged: Vec<f64> = sims[..reals].iter().map(retrieve_sim).collect();
            let single: Vec<f64> = sims[reals..].iter().map(retrieve_sim).collect();
            let sim_first = averaged.first().copied().unwrap_or(f64::NAN);
            let (sim_mean, sim_sd) = mean_sd(&averaged);
            let (_, sim_single) = mean_sd(&single);
            products.push(Product {
                method: t.method,
                quantity: t.quantity,
                source: signals.source,
                order: signals.order,
                channel_pair: self.pair.clone(),
                fov_full_angle_mrad: mean.fov_full_angle_mrad[fov],
                range_m: t.range_m,
                altitude_m: t.altitude_m,
                truth: t.truth,
                retrieved,
                mc_stderr: var_mc.max(0.0).sqrt() * slope.abs(),
                mc_stderr_independent: var_ind.sqrt() * slope.abs(),
                random_error_per_shot_pair: sd_shot,
                random_error_averaged: sd_shot / (n_avg as f64).sqrt(),
                simulated_error_per_shot_pair: sim_single,
                simulated_error_averaged: sim_sd,
                simulated_mean_averaged: sim_mean,
                simulated_first_averaged: sim_first,
                shots_averaged: n_avg,
            });
        }
        Ok(products)
    }

    /// The weighting functions of every product retrieved from `returns` (line returns of
    /// `order`, field of view `fov`): per layer L of the optical atmosphere, the product's
    /// change per relative change of the gases in L, ∂P/∂ln n_L = dP/dD · ∂D/∂ln n_L, with
    ///   ∂D/∂ln n_L = Σ_windows ± ½ (G_off/P_off − G_on/P_on),
    /// G a line's `gas_amount` Jacobian summed over the window (the Monte Carlo's, from the
    /// same photons as its returns). Their sum over the layers is the product itself for an
    /// exact retrieval; in order 1 it is the single-scatter weighting function, with all
    /// orders the multiple-scattering-aware one, and the difference of the two sums is the
    /// bias multiple scattering brings (to first order in it). Standard errors from those of G
    /// alone, as if independent ([`Weighting::stderr`]). Empty without the lines' Jacobians.
    pub fn weighting(
        &self,
        returns: &LineReturns,
        jac: &Jacobians,
        order: Order,
        fov: usize,
    ) -> Vec<Weighting> {
        let (on, off) = (self.config.on, self.config.off);
        let mean = &returns.mean;
        let (Some(o), Some(jo)) = (
            mean.order_index(order),
            jac.orders.iter().position(|x| *x == order),
        ) else {
            return Vec::new();
        };
        let find = |line: usize| jac.channels.iter().position(|c| *c == mean.channels[line]);
        let (Some(j_on), Some(j_off)) = (find(on), find(off)) else {
            return Vec::new();
        };
        let q = JacobianQuantity::ALL
            .iter()
            .position(|x| *x == JacobianQuantity::GasAmount)
            .expect("gas amount is a quantity");
        let e_on = self.laser.pulse_energy_j[on];
        let e_off = self.laser.pulse_energy_j[off];
        let n_layers = jac.layer_bottom_m.len();
        let mut out = Vec::new();
        for t in &self.targets {
            let ipda = t.windows.len() == 1;
            let p = |line: usize, w: &Range<usize>| -> f64 {
                w.clone()
                    .map(|g| mean.energy_j[mean.index(line, fov, g, o)])
                    .sum()
            };
            let mut d = 0.0;
            for (k, w) in t.windows.iter().enumerate() {
                let energy = if ipda { (e_on / e_off).ln() } else { 0.0 };
                d += t.window_sign(k) * 0.5 * ((p(off, w) / p(on, w)).ln() + energy);
            }
            let (_, slope) = self.value(t, d);
            if !slope.is_finite() {
                continue;
            }
            // Each window's on- and off-line returns, once for all the layers.
            let windows: Vec<(&Range<usize>, f64, f64)> =
                t.windows.iter().map(|w| (w, p(on, w), p(off, w))).collect();
            for l in 0..n_layers {
                if !(jac.is_defined(j_on, l, q) && jac.is_defined(j_off, l, q)) {
                    continue;
                }
                let (mut dd, mut var) = (0.0, 0.0);
                for (k, &(w, p_on, p_off)) in windows.iter().enumerate() {
                    let g = |j: usize| -> (f64, f64) {
                        w.clone().fold((0.0, 0.0), |(v, e2), gate| {
                            let i = jac.index(j, fov, gate, jo, l, q);
                            (v + jac.value[i], e2 + jac.stderr[i].powi(2))
                        })
                    };
                    let ((g_on, v_on), (g_off, v_off)) = (g(j_on), g(j_off));
                    dd += t.window_sign(k) * 0.5 * (g_off / p_off - g_on / p_on);
                    var += 0.25 * (v_off / (p_off * p_off) + v_on / (p_on * p_on));
                }
                let value = slope * dd;
                if value == 0.0 || !value.is_finite() {
                    continue;
                }
                out.push(Weighting {
                    method: t.method,
                    quantity: t.quantity,
                    order,
                    channel_pair: self.pair.clone(),
                    fov_full_angle_mrad: mean.fov_full_angle_mrad[fov],
                    range_m: t.range_m,
                    // The optical atmosphere's index, as in `jacobians.csv`.
                    layer: jac.first_layer + l,
                    layer_m: (jac.layer_bottom_m[l], jac.layer_top_m[l]),
                    value,
                    stderr: slope.abs() * var.sqrt(),
                });
            }
        }
        out
    }

    /// The analytic variance of D per shot pair of target `t`, measured on the windows `ids` of
    /// `expected`, and the first window too weak for it (then the variance is infinite).
    fn shot_variance(
        &self,
        t: &Target,
        ids: &[usize],
        expected: &[Vec<WindowSignal>; 2],
    ) -> (f64, Option<(Range<usize>, f64)>) {
        let ipda = t.windows.len() == 1;
        let sign = |k: usize| t.window_sign(k);
        // Analytic random error per shot pair.
        let mut var_shot = 0.0;
        // A window whose SNR is so small (a signal of 1e-300 photo-electrons) that 1/SNR²
        // overflows carries no more usable signal than one with none.
        let mut weak = None;
        for line_windows in expected {
            let mut jitter = 0.0;
            for (k, id) in ids.iter().enumerate() {
                let w = &line_windows[*id];
                let snr = w.noise.snr();
                let inv = 1.0 / (snr * snr);
                if inv.is_finite() {
                    var_shot += inv;
                } else {
                    var_shot = f64::INFINITY;
                    weak.get_or_insert((t.windows[k].clone(), snr));
                }
                jitter += sign(k) * w.jitter_relative(self.laser.frequency_jitter_rms_mhz);
            }
            var_shot += jitter * jitter;
            if ipda {
                var_shot += self.laser.energy_monitor_error_fraction.powi(2);
            }
        }
        (var_shot, weak)
    }

    /// Noisy measurements: `reals` of N shot pairs, then `reals` of one shot pair. Each draws the
    /// shots of the on- and the off-line once and measures every window with them, as the
    /// instrument does. Streams are tied to the realisation (common random numbers: every
    /// source, order and field of view sees the same draws).
    fn simulate(
        &self,
        signals: &Signals,
        expected: &[Vec<WindowSignal>; 2],
        reals: usize,
    ) -> Vec<Measurement> {
        let streams = rng::streams(self.seed, Stream::Instrument, 2 * reals);
        let lines = [self.config.on, self.config.off];
        // Realisation r draws from stream r: N shot pairs for the first `reals`, one after.
        let shots = std::iter::repeat_n(self.config.averaging_shots, reals)
            .chain(std::iter::repeat_n(1, reals));
        streams
            .into_iter()
            .zip(shots)
            .map(|(mut rng, shots)| {
                let mut m = Measurement {
                    ln_signal: [Vec::new(), Vec::new()],
                    ln_energy: [0.0; 2],
                };
                for (i, line) in lines.iter().enumerate() {
                    let (counts, monitored) =
                        signals.realise(&self.laser, &expected[i], shots, &mut rng);
                    // Photo-electrons back to energy: the lines' photon energies differ by 1e-4.
                    let j_per_pe = photon_energy_j(signals.lines[*line].wavenumber_cm1)
                        / signals.detector.quantum_efficiency;
                    m.ln_signal[i] = counts
                        .iter()
                        .map(|c| {
                            if *c > 0.0 {
                                (c * j_per_pe).ln()
                            } else {
                                f64::NAN
                            }
                        })
                        .collect();
                    m.ln_energy[i] = (monitored * self.laser.pulse_energy_j[*line]).ln();
                }
                m
            })
            .collect()
    }
}

/// One noisy measurement: ln of the summed signal energy in each window and ln of the monitored
/// emitted energy, for the on- (index 0) and the off-line (1).
struct Measurement {
    ln_signal: [Vec<f64>; 2],
    ln_energy: [f64; 2],
}

/// Mean and standard deviation of the finite values, NaN if fewer than
/// [`MIN_VALID_FRACTION`] of them are finite.
fn mean_sd(v: &[f64]) -> (f64, f64) {
    let ok: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if ok.len() < 2 || (ok.len() as f64) < MIN_VALID_FRACTION * v.len() as f64 {
        return (f64::NAN, f64::NAN);
    }
    let n = ok.len() as f64;
    let m = ok.iter().sum::<f64>() / n;
    let var = ok.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, var.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook sample (2, 4, 4, 4, 5, 5, 7, 9): mean 5, Σ(x − x̄)² = 32, so the sample
    /// standard deviation with Bessel's correction is √(32/7); NaNs are left out.
    #[test]
    fn mean_sd_is_the_sample_mean_and_standard_deviation_of_the_finite_values() {
        let x = [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0];
        let (m, sd) = mean_sd(&x);
        assert_eq!(m, 5.0);
        assert!((sd - (32.0f64 / 7.0).sqrt()).abs() < 1e-15, "{sd}");
        // Nine finite values of ten are enough; eight of ten are not.
        let mut v: Vec<f64> = x.iter().copied().chain([5.0]).collect();
        assert_eq!(v.len(), 9);
        v.push(f64::NAN);
        let (m, sd) = mean_sd(&v);
        assert_eq!(m, 5.0);
        assert!((sd - (32.0f64 / 8.0).sqrt()).abs() < 1e-15, "{sd}");
        v[0] = f64::INFINITY;
        assert!(mean_sd(&v).0.is_nan() && mean_sd(&v).1.is_nan());
        // One value has no spread to give.
        assert!(mean_sd(&[1.0]).1.is_nan());
    }
}
