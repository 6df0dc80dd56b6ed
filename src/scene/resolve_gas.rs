//! `[gas_absorption]` resolved: the lines (a HITRAN or CSV file, or the built-in CO2 band)
//! that reach the channels, the cache table's grid, and their checks against the channels and
//! the atmosphere's gases (part of step 3).

use std::sync::Arc;

use super::description::GasAbsorptionDescription;
use super::resolver::Resolver;
use super::source::KeyPath;
use super::{Atmosphere, Channel, GasAbsorption, GasTable, molecular_layer_count};
use crate::input::InputError;
use crate::spectroscopy::{LblOptions, LineFilter, LineList, isotopologues};

impl Resolver<'_> {
    /// The cache table of a `[gas_absorption]` section, if one is asked for.
    fn gas_table(
        &self,
        sec: &KeyPath,
        g: &GasAbsorptionDescription,
        atm: &Atmosphere,
        lo: f64,
        hi: f64,
    ) -> Result<Option<GasTable>, InputError> {
        Ok(match &g.table {
            Some(f) => {
                let start = g.table_start_cm1.unwrap_or(lo - 1.0);
                let end = g.table_end_cm1.unwrap_or(hi + 1.0);
                let step = g.table_step_cm1.unwrap_or(5e-4);
                // The table interpolates with 6 points: 3 grid steps of room beyond each channel.
                if !(start <= lo - 3.0 * step && end >= hi + 3.0 * step) {
                    return Err(self.err(
                        &sec.key("table_start_cm1"),
                        format!("the table grid {start}–{end} cm⁻¹ must contain every channel ({lo}–{hi} cm⁻¹) with 3 steps of room to interpolate"),
                    ));
                }
                // The table holds every grid point of every molecular layer.
                let points = ((end - start) / step).ceil() as u64 + 1;
                let layers = molecular_layer_count(atm);
                crate::limits::check_product(
                    "the gas optical-depth table",
                    &[("grid points", points), ("molecular layers", layers)],
                    crate::limits::MAX_GAS_TABLE_VALUES,
                )
                .map_err(|m| self.err(&sec.key("table_step_cm1"), m))?;
                Some(GasTable {
                    path: self.base_dir.join(f),
                    start_cm1: start,
                    end_cm1: end,
                    step_cm1: step,
                })
            }
            // Grid keys without a table were refused by validation.
            None => None,
        })
    }

    /// Gas absorption: the lines (a file or the built-in CO2 band) that reach the channels
    /// (or the table's grid), checked against the atmosphere's gases.
    pub(super) fn gas(
        &self,
        g: &GasAbsorptionDescription,
        channels: &[Channel],
        atm: &Atmosphere,
    ) -> Result<GasAbsorption, InputError> {
        let sec = KeyPath::table("gas_absorption");
        let mut options = LblOptions::default();
        if let Some(w) = g.wing_cm1 {
            options.wing_cm1 = w;
        }
        if let Some(shape) = &g.line_shape {
            options.line_shape = shape
                .parse()
                .map_err(|m: String| self.err(&sec.key("line_shape"), m))?;
        }
        options.line_mixing = g.line_mixing.unwrap_or(false);
        let lo = channels
            .iter()
            .map(|c| c.wavenumber_cm1)
            .fold(f64::INFINITY, f64::min);
        let hi = channels
            .iter()
            .map(|c| c.wavenumber_cm1)
            .fold(f64::NEG_INFINITY, f64::max);
        let molecules = match &g.molecules {
            Some(names) => {
                let at = sec.key("molecules");
                let mut ids = Vec::new();
                for n in names {
                    ids.push(isotopologues::molecule_id(n).ok_or_else(|| {
                        self.err(
                            &at,
                            format!("`{n}` is not a HITRAN molecule lidarsim knows"),
                        )
                    })?);
                    if atm.profile.gas(n).is_none() {
                        return Err(self.err(&at, format!("the atmosphere has no `{n}` profile")));
                    }
                }
                Some(ids)
            }
            None => None,
        };
        let table = self.gas_table(&sec, g, atm, lo, hi)?;
        // Every line that reaches a channel, or any point of a table's grid (a later run may
        // take channels anywhere inside it).
        let (w_lo, w_hi) = match &table {
            Some(t) => (lo.min(t.start_cm1), hi.max(t.end_cm1)),
            None => (lo, hi),
        };
        let filter = LineFilter {
            molecules,
            isotopologues: None,
            min_cm1: Some(w_lo - options.wing_cm1),
            max_cm1: Some(w_hi + options.wing_cm1),
        };
        let lines = match &g.lines {
            Some(f) => {
                let path = self.base_dir.join(f);
                LineList::read(&path, &filter)
                    .map_err(|e| self.err(&sec.key("lines"), format!("line file: {e}")))?
            }
            // The built-in approximate CO2 band (docs/spectroscopy.md), cut like a file.
            None => LineList::co2_30012_band_model().filtered(&filter),
        };
        self.lines_in_window(g, &lines, (w_lo, w_hi), &options)?;
        options.check_lines(&lines).map_err(|e| {
            let key = if g.line_shape.is_some() {
                "line_shape"
            } else {
                "line_mixing"
            };
            self.err(&sec.key(key), e.to_string())
        })?;
        for id in lines.molecules() {
            let name = isotopologues::molecule_name(id).unwrap_or("?");
            if atm.profile.gas(name).is_none() {
                return Err(self.err(
                    &sec.key("lines"),
                    format!("the lines include {name}, which the atmosphere profile does not carry (restrict `molecules`)"),
                ));
            }
        }
        Ok(GasAbsorption {
            lines: Arc::new(lines),
            options,
            table,
        })
    }

    /// Absorption asked for but no line to give it is a mistake (a file of another molecule,
    /// or of another band), not a transparent atmosphere.
    fn lines_in_window(
        &self,
        g: &GasAbsorptionDescription,
        lines: &LineList,
        (w_lo, w_hi): (f64, f64),
        options: &LblOptions,
    ) -> Result<(), InputError> {
        let sec = KeyPath::table("gas_absorption");
        let window = format!(
            "{:.4}–{:.4} cm⁻¹ (the channels ± the {} cm⁻¹ wing)",
            w_lo - options.wing_cm1,
            w_hi + options.wing_cm1,
            options.wing_cm1
        );
        let source = match &g.lines {
            Some(f) => format!("the line file `{f}`"),
            None => "the built-in CO2 band model".to_string(),
        };
        match &g.molecules {
            Some(names) => {
                let present = lines.molecules();
                for n in names {
                    let id = isotopologues::molecule_id(n).unwrap_or(0);
                    if !present.contains(&id) {
                        return Err(self.err(
                            &sec.key("molecules"),
                            format!("{source} has no {n} line in {window}"),
                        ));
                    }
                }
            }
            None if lines.is_empty() => {
                return Err(self.err(
                    &sec.key(if g.lines.is_some() {
                        "lines"
                    } else {
                        "molecules"
                    }),
                    format!("{source} has no line in {window}"),
                ));
            }
            None => {}
        }
        Ok(())
    }

    /// The checks of [`Self::gas`] against the atmosphere's gases, for gas absorption kept from
    /// a previous scene whose profile this one replaces.
    pub(super) fn gas_in_profile(
        &self,
        g: &GasAbsorptionDescription,
        gas: &GasAbsorption,
        atm: &Atmosphere,
    ) -> Result<(), InputError> {
        let sec = KeyPath::table("gas_absorption");
        for n in g.molecules.iter().flatten() {
            if atm.profile.gas(n).is_none() {
                return Err(self.err(
                    &sec.key("molecules"),
                    format!("the atmosphere has no `{n}` profile"),
                ));
            }
        }
        for id in gas.lines.molecules() {
            let name = isotopologues::molecule_name(id).unwrap_or("?");
            if atm.profile.gas(name).is_none() {
                return Err(self.err(
                    &sec.key("lines"),
                    format!("the lines include {name}, which the atmosphere profile does not carry (restrict `molecules`)"),
                ));
            }
        }
        Ok(())
    }
}
