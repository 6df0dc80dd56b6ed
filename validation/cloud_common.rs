//! Shared by the cloud validation examples (`validation/c1_multiple_scattering`,
//! `validation/i3rc_case7`, `validation/platt`): reading the `returns.csv` of a `lidarsim run`
//! (the contract of DESIGN §4, so the examples do not depend on the transport's internals), the
//! attenuated backscatter, and the embedded font for the figures.

#![allow(dead_code)] // each example uses a different part

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, bail};

/// One gate of one series: centre range [m], energy [J], standard error [J].
#[derive(Debug, Clone, Copy)]
pub struct Gate {
    pub range_m: f64,
    pub energy_j: f64,
    pub stderr_j: f64,
}

/// Key of a series: (source, FOV full angle in µrad, order, polarisation), the FOV as an
/// integer so that it can be ordered and looked up exactly.
type Key = (String, u64, String, String);

/// The returns of one run, by source, field of view and order, each a list of gates in range
/// order.
pub struct Returns {
    series: BTreeMap<Key, Vec<Gate>>,
}

fn fov_key(fov_mrad: f64) -> u64 {
    (fov_mrad * 1000.0).round() as u64
}

impl Returns {
    /// Read `dir/returns.csv`.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join("returns.csv");
        let mut rd = csv::Reader::from_path(&path).with_context(|| {
            format!(
                "{}: cannot open (run the case's run.sh first)",
                path.display()
            )
        })?;
        let mut series: BTreeMap<Key, Vec<Gate>> = BTreeMap::new();
        for (i, rec) in rd.records().enumerate() {
            let rec = rec.with_context(|| format!("{} line {}", path.display(), i + 2))?;
            let num = |j: usize| -> Result<f64> {
                rec[j]
                    .parse::<f64>()
                    .with_context(|| format!("{} line {} column {}", path.display(), i + 2, j + 1))
            };
            // `polarisation` (the eighth column): `total`, or `co`/`cross` in a polarised run.
            let pol = rec.get(7).unwrap_or("total").to_string();
            let key = (
                rec[0].to_string(),
                fov_key(num(2)?),
                rec[4].to_string(),
                pol,
            );
            series.entry(key).or_default().push(Gate {
                range_m: num(3)?,
                energy_j: num(5)?,
                stderr_j: num(6)?,
            });
        }
        if series.is_empty() {
            bail!("{}: no returns", path.display());
        }
        Ok(Self { series })
    }

    /// The gates of `source` (`mc` or `analytic`), field of view and order (`total`, `1`, …).
    pub fn get(&self, source: &str, fov_mrad: f64, order: &str) -> Result<&[Gate]> {
        self.get_polarised(source, fov_mrad, order, "total")
    }

    /// As [`Self::get`], for the `polarisation` part `total`, `co` or `cross`.
    pub fn get_polarised(
        &self,
        source: &str,
        fov_mrad: f64,
        order: &str,
        polarisation: &str,
    ) -> Result<&[Gate]> {
        self.series
            .get(&(
                source.to_string(),
                fov_key(fov_mrad),
                order.to_string(),
                polarisation.to_string(),
            ))
            .map(|v| v.as_slice())
            .with_context(|| {
                format!(
                    "no {source} {polarisation} returns of order {order} at FOV {fov_mrad} mrad"
                )
            })
    }
}

/// Attenuated (apparent) backscatter β' [m⁻¹ sr⁻¹] of a gate: the energy per pulse E over
/// E₀ A Δr / r² (the single-scatter lidar equation of DESIGN §3 solved for β e^{−2τ}), for a
/// pulse energy E₀ = 1 J, efficiency 1 and a telescope of 1 m diameter, as the validation scenes
/// have. Returns (β', its standard error).
pub fn attenuated_backscatter(g: &Gate, width_m: f64) -> (f64, f64) {
    let area = std::f64::consts::PI * 0.25;
    let f = g.range_m * g.range_m / (area * width_m);
    (g.energy_j * f, g.stderr_j * f)
}

/// The family name under which the embedded font is registered.
pub const FONT: &str = "sans-serif";

/// Register the embedded DejaVu Sans (as `src/figures/mod.rs` does) so the PNGs render anywhere.
pub fn init_font() {
    static REGISTER: std::sync::Once = std::sync::Once::new();
    REGISTER.call_once(|| {
        plotters::style::register_font(
            FONT,
            plotters::style::FontStyle::Normal,
            include_bytes!("../assets/DejaVuSans.ttf"),
        )
        .map_err(|_| "embedded font")
        .expect("assets/DejaVuSans.ttf is a valid TTF font");
    });
}

/// Colours for up to eight series, distinguishable in print.
pub const COLOURS: [plotters::style::RGBColor; 8] = [
    plotters::style::RGBColor(0, 0, 0),
    plotters::style::RGBColor(31, 119, 180),
    plotters::style::RGBColor(255, 127, 14),
    plotters::style::RGBColor(44, 160, 44),
    plotters::style::RGBColor(214, 39, 40),
    plotters::style::RGBColor(148, 103, 189),
    plotters::style::RGBColor(140, 86, 75),
    plotters::style::RGBColor(227, 119, 194),
];
