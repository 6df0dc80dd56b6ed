//! `lidarsim lbl`: the profile of its layer mode, and its tables: absorption cross-sections on
//! a grid, and layer optical depths along a line of sight.

use std::path::Path;

use super::ProductError;
use crate::atmosphere::{Profile, StandardAtmosphere, parse_afgl};
use crate::spectroscopy::{
    GasOpticalDepthTable, LblOptions, LineList, LineOfSight, WavenumberGrid, WingCentre,
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
