//! Step 2 for `[retrieval]`: every check of its values against the rest of the description
//! (the sections it needs, the on- and off-line among the channels, the hard target and the
//! DIAL cells inside the gates, the averaging), with no file read. What needs the resolved
//! atmosphere and lines (the gas's profile and lines, the retrieval's own line file) is
//! checked by resolve.

use std::ops::Range;

use super::description::{LayerDescription, RetrievalDescription, SceneDescription};
use super::ranges::*;
use super::source::KeyPath;
use super::validate_instrument::LaserValues;
use super::validator::Validator;
use super::{Channel, Gates, Lidar, Surface};
use crate::input::{Bounds, InputError};

/// Default number of noisy realisations per retrieval product.
const DEFAULT_REALISATIONS: usize = 1000;

/// The IPDA hard target as validation finds it.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct TargetValues {
    /// The layer hit (its index and name), or `None` for the surface.
    pub layer: Option<(usize, String)>,
    pub range_m: f64,
    pub altitude_m: f64,
    pub gates: Range<usize>,
}

/// The range cells of a DIAL retrieval as validation finds them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct DialValues {
    pub cell_m: f64,
    pub first_gate: usize,
    pub gates_per_cell: usize,
    pub cells: usize,
}

/// The checked values of `[retrieval]`.
#[derive(Debug, Clone)]
pub(super) struct RetrievalValues {
    pub gas: String,
    pub on: usize,
    pub off: usize,
    pub target: Option<TargetValues>,
    pub dial: Option<DialValues>,
    pub averaging_shots: u64,
    pub averaging_label: String,
    pub realisations: usize,
}

/// The names the resolved layers carry: given, or `layer N` (from 1).
pub(super) fn layer_names(layers: &[LayerDescription]) -> Vec<String> {
    layers
        .iter()
        .enumerate()
        .map(|(i, l)| l.name.clone().unwrap_or_else(|| format!("layer {}", i + 1)))
        .collect()
}

/// What the retrieval is checked against: the rest of the checked description.
pub(super) struct Known<'a> {
    pub lines: &'a [Channel],
    pub lidar: &'a Lidar,
    pub laser: &'a LaserValues,
    pub gates: &'a Gates,
    pub surface: Option<&'a Surface>,
}

impl Validator<'_> {
    /// The `[retrieval]` section.
    pub(super) fn retrieval(
        &self,
        raw: &SceneDescription,
        known: &Known,
    ) -> Result<Option<RetrievalValues>, InputError> {
        let Known {
            lines,
            lidar,
            laser,
            gates,
            surface,
        } = *known;
        let Some(r) = &raw.retrieval else {
            return Ok(None);
        };
        let sec = KeyPath::table("retrieval");
        let gas_name = r.gas.clone().unwrap_or_else(|| "CO2".into());
        if raw.atmosphere.is_none() || raw.gas_absorption.is_none() {
            return Err(self.err(
                &sec,
                "needs an [atmosphere] with gas profiles and [gas_absorption]",
            ));
        }
        if raw.receiver.is_none() {
            return Err(self.err(&sec, "needs a [receiver] (detector and noise)"));
        }
        let line = |key: &str, v: &Option<String>, default: &str| -> Result<usize, InputError> {
            let name = v.as_deref().unwrap_or(default);
            lines.iter().position(|c| c.name == name).ok_or_else(|| {
                let names: Vec<&str> = lines.iter().map(|c| c.name.as_str()).collect();
                self.err(
                    &sec.key(key),
                    format!("no channel named `{name}` (channels: {})", names.join(", ")),
                )
            })
        };
        let on = line("on", &r.on, "on")?;
        let off = line("off", &r.off, "off")?;
        if on == off {
            return Err(self.err(&sec.key("off"), "must differ from the on-line"));
        }
        let target = self.target(r, lidar, gates, surface, &raw.layer)?;
        let dial = self.dial_cells(r, lidar, gates, surface)?;
        if target.is_none() && dial.is_none() {
            return Err(self.err(
                &sec.key("target"),
                "nothing to retrieve: no hard target in range (IPDA) and no `dial_cell_m` (DIAL)",
            ));
        }
        let (averaging_shots, averaging_label) = self.averaging(r, laser.repetition_rate_hz())?;
        let realisations = r.realisations.unwrap_or(DEFAULT_REALISATIONS);
        if !(10..=1_000_000).contains(&realisations) {
            return Err(self.err(
                &sec.key("realisations"),
                format!("{realisations} must lie in 10..=1000000"),
            ));
        }
        if let Some(shape) = &r.line_shape {
            crate::input::names::gas_line_shape(shape)
                .map_err(|m| self.err(&sec.key("line_shape"), m))?;
        }
        Ok(Some(RetrievalValues {
            gas: gas_name,
            on,
            off,
            target,
            dial,
            averaging_shots,
            averaging_label,
            realisations,
        }))
    }

    /// The shot pairs averaged per product, and how the scene gave them.
    fn averaging(
        &self,
        r: &RetrievalDescription,
        repetition_rate_hz: f64,
    ) -> Result<(u64, String), InputError> {
        let sec = KeyPath::table("retrieval");
        Ok(
            match (
                r.averaging_shots,
                r.averaging_length_km,
                r.platform_speed_m_per_s,
            ) {
                (Some(n), None, None) => {
                    if n == 0 || n > 1_000_000_000 {
                        return Err(self.err(
                            &sec.key("averaging_shots"),
                            format!("{n} must lie in 1..=1e9"),
                        ));
                    }
                    (n, format!("{n} shot pairs"))
                }
                (None, Some(len), Some(v)) => {
                    let len =
                        self.range(&sec.key("averaging_length_km"), len, AVERAGING_LENGTH_KM)?;
                    let v = self.range(&sec.key("platform_speed_m_per_s"), v, SPEED_M_PER_S)?;
                    if !repetition_rate_hz.is_finite() {
                        return Err(self.err(
                            &sec.key("averaging_length_km"),
                            "an averaging length needs the laser's `repetition_rate_hz` ([laser])",
                        ));
                    }
                    let n = (len * 1e3 / v * repetition_rate_hz).round();
                    if !(1.0..=1e9).contains(&n) {
                        return Err(self.err(
                            &sec.key("averaging_length_km"),
                            format!("makes {n} shot pairs; must be 1 to 1e9"),
                        ));
                    }
                    (n as u64, format!("{len} km along track ({n} shot pairs)"))
                }
                (None, None, None) => {
                    return Err(self.err(
                        &sec,
                        "needs `averaging_shots`, or `averaging_length_km` with `platform_speed_m_per_s`",
                    ));
                }
                _ => {
                    return Err(self.err(
                        &sec.key("averaging_shots"),
                        "give `averaging_shots` or `averaging_length_km` with `platform_speed_m_per_s`, not both",
                    ));
                }
            },
        )
    }

    /// The IPDA hard target: given, or the surface when it is in range.
    fn target(
        &self,
        r: &RetrievalDescription,
        lidar: &Lidar,
        gates: &Gates,
        surface: Option<&Surface>,
        layers: &[LayerDescription],
    ) -> Result<Option<TargetValues>, InputError> {
        let at = KeyPath::table("retrieval").key("target");
        let mu = lidar.axis().z;
        let z0 = lidar.altitude_m;
        let gate_of = |range: f64| -> Option<usize> {
            let x = (range - gates.start_m) / gates.width_m;
            (x >= 0.0 && x < gates.count as f64).then_some(x as usize)
        };
        let (layer, range_m, altitude_m, window_m) = match r.target.as_deref() {
            None | Some("surface") => {
                let explicit = r.target.is_some();
                let in_range = surface
                    .filter(|_| mu < -1e-12)
                    .map(|s| (s, (z0 - s.altitude_m) / -mu))
                    .filter(|(_, range)| gate_of(*range).is_some());
                match in_range {
                    Some((s, range)) => (None, range, s.altitude_m, 0.0),
                    None if !explicit => return Ok(None),
                    None => {
                        let why = match surface {
                            None => "the scene has no [surface]".to_string(),
                            Some(_) if mu >= -1e-12 => {
                                "the lidar does not look down at the surface".into()
                            }
                            Some(s) => format!(
                                "the surface is {:.1} m away, outside the gates {}–{} m",
                                (z0 - s.altitude_m) / -mu,
                                gates.start_m,
                                gates.end_m()
                            ),
                        };
                        return Err(self.err(&at, format!("no hard target in range: {why}")));
                    }
                }
            }
            Some(name) => {
                let names = layer_names(layers);
                let (index, layer) = layers
                    .iter()
                    .enumerate()
                    .find(|(i, _)| names[*i] == name)
                    .ok_or_else(|| {
                        self.err(
                            &at,
                            format!(
                                "`{name}` is neither `surface` nor a layer name (layers: {})",
                                names.join(", ")
                            ),
                        )
                    })?;
                if mu.abs() < 1e-12 {
                    return Err(self.err(&at, "a horizontal beam has no layer top to hit"));
                }
                // The near side of the layer: its top seen from above, its base from below.
                let near = if mu < 0.0 { layer.top_m } else { layer.base_m };
                let range = (near - z0) / mu;
                if !(range > 0.0) || gate_of(range).is_none() {
                    return Err(self.err(
                        &at,
                        format!(
                            "no hard target in range: layer `{name}` begins {range:.1} m along the beam, outside the gates {}–{} m",
                            gates.start_m,
                            gates.end_m()
                        ),
                    ));
                }
                let thickness = (layer.top_m - layer.base_m) / mu.abs();
                (Some((index, name.to_string())), range, near, thickness)
            }
        };
        let w_at = KeyPath::table("retrieval").key("target_window_m");
        let window_m = match r.target_window_m {
            Some(w) => self.range(&w_at, w, PATH_LENGTH_M)?,
            None => window_m,
        };
        let first = gate_of(range_m).unwrap_or(0);
        // The last gate the echo reaches (a window ending on a gate edge stays in that gate).
        let last = ((range_m + window_m - gates.start_m) / gates.width_m).ceil() as usize;
        let last = last.max(first + 1);
        if last > gates.count {
            return Err(self.err(
                &w_at,
                format!(
                    "the echo window {range_m:.1}–{:.1} m reaches beyond the last gate ({} m)",
                    range_m + window_m,
                    gates.end_m()
                ),
            ));
        }
        Ok(Some(TargetValues {
            layer,
            range_m,
            altitude_m,
            gates: first..last,
        }))
    }

    /// Range cells of a range-resolved DIAL retrieval, if `dial_cell_m` is given.
    fn dial_cells(
        &self,
        r: &RetrievalDescription,
        lidar: &Lidar,
        gates: &Gates,
        surface: Option<&Surface>,
    ) -> Result<Option<DialValues>, InputError> {
        let sec = KeyPath::table("retrieval");
        let Some(cell) = r.dial_cell_m else {
            for (k, given) in [
                ("dial_start_m", r.dial_start_m.is_some()),
                ("dial_end_m", r.dial_end_m.is_some()),
            ] {
                if given {
                    return Err(self.err(&sec.key(k), "goes with `dial_cell_m`"));
                }
            }
            return Ok(None);
        };
        let at = sec.key("dial_cell_m");
        let cell = self.range(&at, cell, Bounds::positive(PATH_LENGTH_M.hi))?;
        if cell < gates.width_m * (1.0 - 1e-9) {
            return Err(self.err(
                &at,
                format!(
                    "a range cell of {cell} m is shorter than a gate ({} m)",
                    gates.width_m
                ),
            ));
        }
        let k = (cell / gates.width_m).round();
        if (cell / gates.width_m - k).abs() > 1e-6 * k {
            return Err(self.err(
                &at,
                format!(
                    "{cell} m is not a whole number of {} m gates",
                    gates.width_m
                ),
            ));
        }
        let k = k as usize;
        let centre = |g: usize| gates.centre_m(g);
        // The last usable gate: inside the gates, and wholly before the surface if the beam
        // hits one (the surface echo would swamp the atmospheric return of its gate).
        let mut last = gates.count - 1;
        let mu = lidar.axis().z;
        if let Some(s) = surface.filter(|_| mu < -1e-12) {
            let rs = (lidar.altitude_m - s.altitude_m) / -mu;
            let x = ((rs - gates.start_m) / gates.width_m).floor();
            if x < 1.0 {
                return Err(self.err(&at, "no gate lies wholly before the surface"));
            }
            last = last.min(x as usize - 1);
        }
        let first = match r.dial_start_m {
            Some(s) => {
                let s_at = sec.key("dial_start_m");
                let g = ((s - gates.start_m) / gates.width_m - 0.5).ceil().max(0.0);
                if !(s.is_finite()) || g as usize > last {
                    return Err(self.err(
                        &s_at,
                        format!(
                            "{s} m is beyond the last usable gate centre ({} m)",
                            centre(last)
                        ),
                    ));
                }
                g as usize
            }
            None => 0,
        };
        let end_gate = match r.dial_end_m {
            Some(e) => {
                let e_at = sec.key("dial_end_m");
                let g = ((e - gates.start_m) / gates.width_m - 0.5).floor();
                if !(e.is_finite()) || g < first as f64 {
                    return Err(self.err(
                        &e_at,
                        format!(
                            "{e} m is before the first cell starts ({} m)",
                            centre(first)
                        ),
                    ));
                }
                (g as usize).min(last)
            }
            None => last,
        };
        let cells = (end_gate - first) / k;
        if cells == 0 {
            return Err(self.err(
                &at,
                format!(
                    "no whole {cell} m cell fits between the gate centres {} and {} m",
                    centre(first),
                    centre(end_gate)
                ),
            ));
        }
        Ok(Some(DialValues {
            cell_m: cell,
            first_gate: first,
            gates_per_cell: k,
            cells,
        }))
    }
}
