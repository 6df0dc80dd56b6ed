//! `lidarsim lbl`: the profile of its layer mode, and its tables: absorption cross-sections on
//! a grid, and layer optical depths along a line of sight.

use std::path::Path;

use super::ProductError;
use crate::atmosphere::{Profile, StandardAtmosphere, parse_afgl};
use crate::spectroscopy::{
    GasOpticalDepthTable, LblOptions, LineFilter, LineList, LineOfSight, WavenumberGrid, WingCentre,
};

/// The cross-section table: a header of comments naming the lines, the line shape and the
/// state (`p_atm`, `t_k`, `self_vmr`: pressure \[atm\], temperature \[K\], self-broadening mole
/// fraction), then `wavenumber_cm1` and one `sigma_<MOLECULE>_cm2` column per entry of
/// `columns` (name, cross-sections on `grid` \[cm²/molecule\]).
pub fn cross_section_csv(
    lines: &LineList,
    grid: &WavenumberGrid,
    opts: &LblOptions,
    (p_atm, t_k, self_vmr): (f64, f64, f64),
    exact: bool,
    columns: &[(String, Vec<f64>)],
) -> String {
    let mut text = String::new();
    text.push_str(&format!(
        "# lidarsim lbl: absorption cross-sections [cm^2/molecule], self-broadening mole fraction {}\n# lines: {}\n\
         # line shape {}{}; pressure_atm = {p_atm}, temperature_k = {t_k}, wing_cm1 = {} around the {} centre, Voigt {}\n",
        self_vmr,
        lines.source,
        opts.line_shape.name(),
        if opts.line_mixing { " with line mixing" } else { "" },
        opts.wing_cm1,
        if opts.wing_centre == WingCentre::Shifted { "shifted" } else { "unshifted" },
        if exact { "exact" } else { "fast (multigrid)" },
    ));
    text.push_str("wavenumber_cm1");
    for (name, _) in columns {
        text.push_str(&format!(",sigma_{name}_cm2"));
    }
    text.push('\n');
    for i in 0..grid.len {
        text.push_str(&format!("{:.6}", grid.at(i)));
        for (_, s) in columns {
            text.push_str(&format!(",{:.12e}", s[i]));
        }
        text.push('\n');
    }
    text
}

/// The layer table: per wavenumber of `grid` and layer of `table` (computed for the profile
/// named `profile` along `los`, `mu` its |cos zenith|) the Curtis-Godson p and T, the vertical
/// and the slant optical depth; and the slant optical depth of the whole path per wavenumber.
pub fn layer_csv(
    table: &GasOpticalDepthTable,
    lines: &LineList,
    profile: &str,
    los: &LineOfSight,
    mu: f64,
    grid: &WavenumberGrid,
    wing_cm1: f64,
) -> (String, Vec<f64>) {
    let mut text = format!(
        "# lidarsim lbl: gas absorption optical depth per layer (vertical, and slant = vertical/|cos zenith|, plane-parallel)\n\
         # lines: {}\n# profile: {}\n# sensor_altitude_m = {}, zenith_deg = {}, surface_altitude_m = {}, wing_cm1 = {}\n\
         wavenumber_cm1,bottom_m,top_m,pressure_pa,temperature_k,tau_vertical,tau_slant\n",
        lines.source,
        profile,
        los.sensor_altitude_m,
        los.zenith_angle_deg,
        los.surface_altitude_m,
        wing_cm1
    );
    let mut column_slant = vec![0.0; grid.len];
    for (i, col) in column_slant.iter_mut().enumerate() {
        for (l, layer) in table.layers.iter().enumerate() {
            let tau = table.tau_at_grid(l, i);
            *col += tau / mu;
            text.push_str(&format!(
                "{:.6},{},{},{:.6e},{:.4},{:.12e},{:.12e}\n",
                grid.at(i),
                layer.bottom_m,
                layer.top_m,
                layer.pressure_pa,
                layer.temperature_k,
                tau,
                tau / mu
            ));
        }
    }
    (text, column_slant)
}

/// The profile of the layer mode: a built-in AFGL atmosphere or an AFGL-format file, with its
/// CO2 scaled so that its surface value is `co2_ppmv` (the shape kept).
pub fn profile(
    atmosphere: Option<StandardAtmosphere>,
    file: Option<&Path>,
    co2_ppmv: Option<f64>,
) -> Result<Profile, ProductError> {
    let mut prof = match (atmosphere, file) {
        (Some(a), None) => a.profile(),
        (None, Some(p)) => {
            let text = std::fs::read_to_string(p).map_err(|e| {
                ProductError::context(&format!("cannot read the profile {}", p.display()), e)
            })?;
            parse_afgl(&p.display().to_string(), &text)?
        }
        _ => {
            return Err(ProductError::Request(
                "give one of --atmosphere or --profile".into(),
            ));
        }
    };
    if let Some(ppmv) = co2_ppmv {
        let g = prof
            .gases
            .iter_mut()
            .find(|g| g.name == "CO2")
            .ok_or_else(|| {
                ProductError::Request("--co2-ppmv: the profile has no CO2 column".into())
            })?;
        let surface = g.vmr.first().copied().unwrap_or(0.0);
        if surface <= 0.0 || surface.is_nan() {
            return Err(ProductError::Request(
                "--co2-ppmv: the profile's surface CO2 is zero, nothing to scale".into(),
            ));
        }
        let f = ppmv * 1e-6 / surface;
        g.vmr.iter_mut().for_each(|v| *v *= f);
    }
    Ok(prof)
}

/// The unit a spectral range of `lbl` is given in (vacuum wavenumber or vacuum wavelength).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpectralUnit {
    /// Wavenumber \[cm⁻¹\].
    Cm1,
    /// Wavelength \[nm\].
    Nm,
    /// Wavelength \[µm\].
    Um,
}

impl SpectralUnit {
    /// The option suffix (`--start-nm`).
    pub fn suffix(self) -> &'static str {
        match self {
            SpectralUnit::Cm1 => "cm1",
            SpectralUnit::Nm => "nm",
            SpectralUnit::Um => "um",
        }
    }

    /// The unit as printed.
    pub fn symbol(self) -> &'static str {
        match self {
            SpectralUnit::Cm1 => "cm⁻¹",
            SpectralUnit::Nm => "nm",
            SpectralUnit::Um => "µm",
        }
    }

    /// `v` in this unit as a vacuum wavenumber \[cm⁻¹\].
    pub fn to_cm1(self, v: f64) -> f64 {
        match self {
            SpectralUnit::Cm1 => v,
            SpectralUnit::Nm => 1e7 / v,
            SpectralUnit::Um => 1e4 / v,
        }
    }

    /// The range of values in this unit a user plausibly means for a lidar or a line list
    /// (0.2–20 µm, 500–50 000 cm⁻¹), for "did you mean".
    fn plausible(self, v: f64) -> bool {
        match self {
            SpectralUnit::Cm1 => (500.0..=50_000.0).contains(&v),
            SpectralUnit::Nm => (200.0..=20_000.0).contains(&v),
            SpectralUnit::Um => (0.2..=20.0).contains(&v),
        }
    }
}

/// The spectral range of `lbl` as the user gave it: both ends in one unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpectralRange {
    /// The unit of `start` and `end`.
    pub unit: SpectralUnit,
    /// First value as given.
    pub start: f64,
    /// Last value as given.
    pub end: f64,
}

impl SpectralRange {
    /// The range from the `--start-*`/`--end-*` options: `(unit, start, end)` for each unit
    /// family given (`None` for an end not given). Exactly one family, with both ends.
    pub fn from_options(
        given: &[(SpectralUnit, Option<f64>, Option<f64>)],
    ) -> Result<SpectralRange, ProductError> {
        let families: Vec<_> = given
            .iter()
            .filter(|(_, a, b)| a.is_some() || b.is_some())
            .collect();
        let all = "--start-cm1/--end-cm1, --start-nm/--end-nm or --start-um/--end-um";
        match families.as_slice() {
            [] => Err(ProductError::Request(format!(
                "give the spectral range: {all}"
            ))),
            [(unit, Some(a), Some(b))] => Ok(SpectralRange {
                unit: *unit,
                start: *a,
                end: *b,
            }),
            [(unit, a, _)] => {
                let (has, lacks) = if a.is_some() {
                    ("start", "end")
                } else {
                    ("end", "start")
                };
                Err(ProductError::Request(format!(
                    "--{has}-{s} needs --{lacks}-{s}",
                    s = unit.suffix()
                )))
            }
            many => Err(ProductError::Request(format!(
                "give the spectral range in one unit ({all}), not in {}",
                many.iter()
                    .map(|(u, _, _)| u.symbol())
                    .collect::<Vec<_>>()
                    .join(" and ")
            ))),
        }
    }

    /// The range as wavenumbers \[cm⁻¹\], low to high (a wavelength range reverses).
    pub fn cm1(&self) -> (f64, f64) {
        let (a, b) = (self.unit.to_cm1(self.start), self.unit.to_cm1(self.end));
        (a.min(b), a.max(b))
    }

    /// The same numbers read in another unit, where they are plausible in it: the ranges a user
    /// who typed the wrong unit meant (`--start-cm1 1570` meaning nm).
    pub fn other_readings(&self) -> Vec<SpectralRange> {
        [SpectralUnit::Cm1, SpectralUnit::Nm, SpectralUnit::Um]
            .into_iter()
            .filter(|u| *u != self.unit && u.plausible(self.start) && u.plausible(self.end))
            .map(|unit| SpectralRange { unit, ..*self })
            .collect()
    }

    /// `--start-nm 1570 --end-nm 1580 (6329.1–6369.4 cm⁻¹)`.
    pub fn describe(&self) -> String {
        let (lo, hi) = self.cm1();
        let s = self.unit.suffix();
        if self.unit == SpectralUnit::Cm1 {
            format!("--start-{s} {} --end-{s} {}", self.start, self.end)
        } else {
            format!(
                "--start-{s} {} --end-{s} {} ({lo:.1}–{hi:.1} cm⁻¹)",
                self.start, self.end
            )
        }
    }
}

/// The lines of `lbl`: every file of `paths` read with `filter` and merged (sorted by
/// wavenumber), or the whole built-in CO2 band model without files. An error names the file.
pub fn read_lines(
    paths: &[std::path::PathBuf],
    filter: &LineFilter,
) -> Result<LineList, ProductError> {
    if paths.is_empty() {
        return Ok(LineList::co2_30012_band_model());
    }
    let mut out = LineList {
        source: String::new(),
        lines: Vec::new(),
    };
    let mut sources = Vec::new();
    for p in paths {
        let l = LineList::read(p, filter)
            .map_err(|e| ProductError::context(&format!("--lines {}", p.display()), e))?;
        sources.push(l.source);
        out.lines.extend(l.lines);
    }
    out.lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
    out.source = sources.join(" + ");
    Ok(out)
}

/// The error of a range no line reaches: what was asked and, where the same numbers in
/// another unit reach lines of the same files, the range the user probably meant.
pub fn no_lines_error(
    paths: &[std::path::PathBuf],
    range: &SpectralRange,
    wing_cm1: f64,
    source: &str,
) -> ProductError {
    let (lo, hi) = range.cm1();
    let mut message =
        format!("no lines of {source} reach {lo}–{hi} cm⁻¹ (with the {wing_cm1} cm⁻¹ wing)");
    for other in range.other_readings() {
        let (a, b) = other.cm1();
        let window = LineFilter::window(a - wing_cm1, b + wing_cm1);
        let reach = read_lines(paths, &window).is_ok_and(|l| !l.filtered(&window).is_empty());
        if reach {
            message.push_str(&format!(" — did you mean {}?", other.describe()));
            break;
        }
    }
    ProductError::Request(message)
}

#[cfg(test)]
mod tests {
    use super::*;
    use SpectralUnit::{Cm1, Nm, Um};

    #[test]
    fn a_range_is_given_in_exactly_one_unit_with_both_ends() {
        let r = SpectralRange::from_options(&[
            (Cm1, None, None),
            (Nm, Some(1570.0), Some(1580.0)),
            (Um, None, None),
        ])
        .unwrap();
        assert_eq!((r.unit, r.start, r.end), (Nm, 1570.0, 1580.0));
        // 1e7/1580 … 1e7/1570 cm⁻¹, low to high.
        assert_eq!(r.cm1(), (1e7 / 1580.0, 1e7 / 1570.0));
        let um = SpectralRange {
            unit: Um,
            start: 1.58,
            end: 1.57,
        };
        assert_eq!(um.cm1(), (1e4 / 1.58, 1e4 / 1.57));
        let err = |given: &[(SpectralUnit, Option<f64>, Option<f64>)]| {
            SpectralRange::from_options(given).unwrap_err().to_string()
        };
        assert!(err(&[(Cm1, None, None)]).starts_with("give the spectral range"));
        assert_eq!(err(&[(Nm, None, Some(1.0))]), "--end-nm needs --start-nm");
        assert!(
            err(&[(Cm1, Some(1.0), Some(2.0)), (Um, Some(1.0), None)])
                .ends_with("not in cm⁻¹ and µm")
        );
    }

    #[test]
    fn the_other_readings_of_a_range_are_the_plausible_ones() {
        let r = SpectralRange {
            unit: Cm1,
            start: 1570.0,
            end: 1580.0,
        };
        // 1570 is a plausible wavenumber (CO2 has no band there, but H2O does) and wavelength,
        // not a plausible µm.
        let others: Vec<SpectralUnit> = r.other_readings().iter().map(|o| o.unit).collect();
        assert_eq!(others, [Nm]);
        assert_eq!(
            r.other_readings()[0].describe(),
            "--start-nm 1570 --end-nm 1580 (6329.1–6369.4 cm⁻¹)"
        );
        let r = SpectralRange {
            unit: Nm,
            start: 6360.0,
            end: 6361.0,
        };
        let others: Vec<SpectralUnit> = r.other_readings().iter().map(|o| o.unit).collect();
        assert_eq!(others, [Cm1]);
        assert_eq!(
            r.other_readings()[0].describe(),
            "--start-cm1 6360 --end-cm1 6361"
        );
    }
}
