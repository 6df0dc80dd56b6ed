//! The instrument and retrieval sections of a scene: `[laser]`, `[receiver]`, `[background]`,
//! `[retrieval]`, built from the values validation checked into the instrument's and the
//! retrieval's types (part of step 3, as they build on the instrument and retrieval modules),
//! with the checks that need the resolved atmosphere and lines.

use std::sync::Arc;

use super::description::{RetrievalDescription, SceneDescription};
use super::resolver::Resolver;
use super::source::KeyPath;
use super::validate_instrument::{
    BackgroundValues, FilterWidth, LaserLineShape, LaserValues, ReceiverValues,
};
use super::validate_retrieval::RetrievalValues;
use super::{Atmosphere, Channel, GasAbsorption};
use crate::input::InputError;
use crate::instrument::detector::{self, Detector};
use crate::instrument::laser::{Filter, Laser};
use crate::instrument::line_shape::{LineShape, LineShapeTable, MHZ_PER_CM1};
use crate::instrument::signals::Receiver;
use crate::retrieval::{AssumedSpectroscopy, DialCells, HardTarget, RetrievalConfig, TargetKind};
use crate::spectroscopy::isotopologues;
use crate::spectroscopy::{LineFilter, LineList};

/// Bandwidth stored when no white-noise term needs one \[Hz\] (it then enters no formula).
const UNUSED_BANDWIDTH_HZ: f64 = 1e15;

impl Resolver<'_> {
    /// The laser of checked values; a line-shape table is read here.
    pub(super) fn laser(&self, v: &LaserValues, n_lines: usize) -> Result<Laser, InputError> {
        let l = match v {
            LaserValues::Ideal { pulse_energy_j } => {
                return Ok(Laser::ideal(*pulse_energy_j, n_lines));
            }
            LaserValues::Given(l) => l,
        };
        let sec = KeyPath::table("laser");
        let width_at = sec.key("linewidth_fwhm_mhz");
        let line_shape = match &l.line_shape {
            LaserLineShape::Monochromatic => LineShape::Monochromatic,
            LaserLineShape::Gaussian(w) => {
                LineShape::gaussian(*w).map_err(|m| self.err(&width_at, m))?
            }
            LaserLineShape::Lorentzian(w) => {
                LineShape::lorentzian(*w).map_err(|m| self.err(&width_at, m))?
            }
            LaserLineShape::TableValues(t) => {
                let table = LineShapeTable {
                    source: t.name.as_deref().unwrap_or(super::DESCRIPTION_NAME).into(),
                    offset_mhz: t.offset_mhz.clone(),
                    relative_intensity: t.relative_intensity.clone(),
                };
                table.validate().map_err(|m| {
                    self.err(
                        &sec.key("line_shape_table"),
                        format!("line-shape table: {m}"),
                    )
                })?;
                LineShape::Table(table)
            }
            LaserLineShape::TableFile(f) => {
                let p = self.base_dir.join(f);
                LineShape::Table(LineShapeTable::read(&p).map_err(|e| {
                    self.err(
                        &sec.key("line_shape_file"),
                        format!("line-shape table: {e}"),
                    )
                })?)
            }
        };
        Ok(Laser {
            line_shape,
            nodes: l.nodes,
            frequency_offset_mhz: l.frequency_offset_mhz.clone(),
            frequency_jitter_rms_mhz: l.frequency_jitter_rms_mhz,
            spectral_purity: l.spectral_purity,
            impurity_wavenumber_cm1: l.impurity_wavenumber_cm1.clone(),
            pulse_energy_j: l.pulse_energy_j.clone(),
            repetition_rate_hz: l.repetition_rate_hz,
            pulse_energy_jitter_fraction: l.pulse_energy_jitter_fraction,
            energy_monitor_error_fraction: l.energy_monitor_error_fraction,
        })
    }

    /// The receiver of checked values: the filter's width at the lines' mean wavenumber, the
    /// detector and the background radiance.
    pub(super) fn receiver(
        &self,
        v: Option<&ReceiverValues>,
        lines: &[Channel],
    ) -> Result<Option<Receiver>, InputError> {
        let Some(r) = v else {
            return Ok(None);
        };
        let sec = KeyPath::table("receiver");
        // Filter width as a wavenumber interval at the lines' mean wavenumber.
        let nu = lines.iter().map(|c| c.wavenumber_cm1).sum::<f64>() / lines.len() as f64;
        let bandwidth_cm1 = match r.filter_width {
            FilterWidth::None => f64::INFINITY,
            FilterWidth::Nm(nm) => nm * nu * nu * 1e-7,
            // Δλ = λ² Δν: GHz → cm⁻¹ → nm at the mean wavenumber.
            FilterWidth::Ghz(ghz) => {
                let nm = ghz * (1e3 / MHZ_PER_CM1 * 1e7 / (nu * nu));
                nm * nu * nu * 1e-7
            }
        };
        let excess_noise_factor = if r.from_ionization_ratio {
            detector::excess_noise_factor(r.gain, r.excess_noise)
        } else {
            r.excess_noise
        };
        let detector = Detector {
            quantum_efficiency: r.quantum_efficiency,
            gain: r.gain,
            excess_noise_factor,
            dark_current_a: r.dark_current_a,
            nep_w_per_sqrt_hz: r.nep_w_per_sqrt_hz,
            amplifier_noise_a_per_sqrt_hz: r.amplifier_noise_a_per_sqrt_hz,
            readout_noise_electrons: r.readout_noise_electrons,
            bandwidth_hz: r.bandwidth_hz.unwrap_or(UNUSED_BANDWIDTH_HZ),
        };
        // The ranges of validation hold; this is the detector's own statement of them.
        detector.validate().map_err(|m| self.err(&sec, m))?;
        // Sunlight: L = ρ E_sun cos θ_sun / π from a Lambertian scene (no atmospheric
        // attenuation of the sunlight).
        let background_radiance_w_per_m2_sr_um = match r.background {
            BackgroundValues::None => 0.0,
            BackgroundValues::Radiance(l) => l,
            BackgroundValues::Sunlight {
                irradiance_w_per_m2_um: e,
                zenith_deg: z,
                reflectance: rho,
            } => rho * e * z.to_radians().cos() / std::f64::consts::PI,
        };
        Ok(Some(Receiver {
            filter: Filter {
                bandwidth_cm1,
                transmission: r.filter_transmission,
            },
            detector,
            background_radiance_w_per_m2_sr_um,
        }))
    }

    /// The `[retrieval]` section: its checked values, the checks against the resolved
    /// atmosphere and lines, and its own spectroscopy.
    pub(super) fn retrieval(
        &self,
        raw: &SceneDescription,
        v: Option<&RetrievalValues>,
        atmosphere: Option<&Atmosphere>,
        gas: Option<&GasAbsorption>,
        kept_spectroscopy: Option<Option<AssumedSpectroscopy>>,
    ) -> Result<Option<RetrievalConfig>, InputError> {
        let (Some(r), Some(v)) = (&raw.retrieval, v) else {
            return Ok(None);
        };
        let sec = KeyPath::table("retrieval");
        let gas_at = sec.key("gas");
        let gas_name = v.gas.clone();
        let (Some(atm), Some(g)) = (atmosphere, gas) else {
            return Err(self.err(
                &sec,
                "needs an [atmosphere] with gas profiles and [gas_absorption]",
            ));
        };
        // The molecules lidarsim knows are the embedded isotopologue table's (a data file,
        // read by the spectroscopy module), so the name is checked here.
        let id = isotopologues::molecule_id(&gas_name).ok_or_else(|| {
            self.err(
                &gas_at,
                format!("`{gas_name}` is not a HITRAN molecule lidarsim knows"),
            )
        })?;
        if atm.profile.gas(&gas_name).is_none() {
            return Err(self.err(
                &gas_at,
                format!("the atmosphere has no `{gas_name}` profile"),
            ));
        }
        if !g.lines.molecules().contains(&id) {
            return Err(self.err(
                &gas_at,
                format!("the gas absorption has no {gas_name} lines near the channels"),
            ));
        }
        let target = v.target.as_ref().map(|t| HardTarget {
            kind: match &t.layer {
                None => TargetKind::Surface,
                Some((index, name)) => TargetKind::Layer {
                    index: *index,
                    name: name.clone(),
                },
            },
            range_m: t.range_m,
            altitude_m: t.altitude_m,
            gates: t.gates.clone(),
        });
        let dial = v.dial.map(|d| DialCells {
            cell_m: d.cell_m,
            first_gate: d.first_gate,
            gates_per_cell: d.gates_per_cell,
            cells: d.cells,
        });
        let spectroscopy = match kept_spectroscopy {
            Some(kept) => kept,
            None => self.assumed_spectroscopy(r, g)?,
        };
        Ok(Some(RetrievalConfig {
            gas: gas_name,
            on: v.on,
            off: v.off,
            target,
            dial,
            averaging_shots: v.averaging_shots,
            averaging_label: v.averaging_label.clone(),
            realisations: v.realisations,
            spectroscopy,
        }))
    }

    /// `[retrieval]`'s own spectroscopy (`lines`, `line_shape`, `line_mixing`), if it differs
    /// from the truth's: lines cut like the truth's, the truth's options otherwise.
    fn assumed_spectroscopy(
        &self,
        r: &RetrievalDescription,
        g: &GasAbsorption,
    ) -> Result<Option<AssumedSpectroscopy>, InputError> {
        if r.lines.is_none() && r.line_shape.is_none() && r.line_mixing.is_none() {
            return Ok(None);
        }
        let sec = KeyPath::table("retrieval");
        let mut options = g.options;
        if let Some(shape) = &r.line_shape {
            options.line_shape = shape
                .parse()
                .map_err(|m: String| self.err(&sec.key("line_shape"), m))?;
        }
        if let Some(m) = r.line_mixing {
            options.line_mixing = m;
        }
        let lines = match &r.lines {
            Some(f) => {
                let path = self.base_dir.join(f);
                let (lo, hi) = g
                    .lines
                    .lines
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), l| {
                        (a.min(l.nu_cm1), b.max(l.nu_cm1))
                    });
                let molecules = Some(g.lines.molecules());
                let filter = LineFilter {
                    molecules,
                    isotopologues: None,
                    min_cm1: Some(lo - 1.0),
                    max_cm1: Some(hi + 1.0),
                };
                Arc::new(
                    LineList::read(&path, &filter)
                        .map_err(|e| self.err(&sec.key("lines"), format!("line file: {e}")))?,
                )
            }
            None => g.lines.clone(),
        };
        options.check_lines(&lines).map_err(|e| {
            let key = if r.line_shape.is_some() {
                "line_shape"
            } else if r.line_mixing.is_some() {
                "line_mixing"
            } else {
                "lines"
            };
            self.err(&sec.key(key), e.to_string())
        })?;
        Ok(Some(AssumedSpectroscopy { lines, options }))
    }
}
