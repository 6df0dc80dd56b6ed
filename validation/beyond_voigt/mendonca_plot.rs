//! The figure of the `mendonca_30012` example: measurement, both models and both residuals over
//! the window (left) and around R(16)e (right).

use std::path::Path;

use anyhow::{Result, anyhow};
use plotters::prelude::*;

use super::fit::{FitResult, Measurement};

const FONT: &str = "sans-serif";

/// Register the embedded font, as `src/figures/mod.rs` does (DejaVu Sans, `assets/`).
fn init_font() {
    static REGISTER: std::sync::Once = std::sync::Once::new();
    REGISTER.call_once(|| {
        plotters::style::register_font(
            FONT,
            plotters::style::FontStyle::Normal,
            include_bytes!("../../assets/DejaVuSans.ttf"),
        )
        .map_err(|_| "embedded font")
        .expect("assets/DejaVuSans.ttf is a valid TTF font");
    });
}

type Series<'a> = (&'a str, Vec<(f64, f64)>, RGBColor);

fn panel(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    title: &str,
    y_desc: &str,
    x: (f64, f64),
    series: &[Series],
) -> Result<(), Box<dyn std::error::Error>> {
    let (lo, hi) = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let pad = 0.05 * (hi - lo).max(1e-6);
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 17))
        .margin(10)
        .x_label_area_size(42)
        .y_label_area_size(75)
        .build_cartesian_2d(x.0..x.1, (lo - pad)..(hi + pad))?;
    chart
        .configure_mesh()
        .x_desc("wavenumber [cm⁻¹]")
        .y_desc(y_desc)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .draw()?;
    for (name, pts, c) in series {
        let c = *c;
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(1)))?
            .label(*name)
            .legend(move |(px, py)| PathElement::new(vec![(px, py), (px + 20, py)], c));
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// Draw the figure to `path`, whole or not at all (`lidarsim::output::OutputSet`).
pub fn figure(
    path: &Path,
    meas: &Measurement,
    voigt: &FitResult,
    beyond: &FitResult,
    r16_cm1: f64,
) -> Result<()> {
    init_font();
    let all =
        |v: &[f64]| -> Vec<(f64, f64)> { meas.nu.iter().copied().zip(v.iter().copied()).collect() };
    let near = |v: &[f64]| -> Vec<(f64, f64)> {
        meas.nu
            .iter()
            .copied()
            .zip(v.iter().copied())
            .filter(|(n, _)| (n - r16_cm1).abs() <= 0.6)
            .collect()
    };
    let (nu0, nu1) = (meas.nu[0], meas.nu[meas.nu.len() - 1]);
    let zoom = (r16_cm1 - 0.6, r16_cm1 + 0.6);
    let black = RGBColor(0, 0, 0);
    let blue = RGBColor(30, 90, 220);
    let red = RGBColor(220, 30, 30);
    let mut files = lidarsim::output::OutputSet::new();
    files.write_via(path, |tmp: &Path| -> Result<()> {
        let root = BitMapBackend::new(tmp, (1800, 1200)).into_drawing_area();
        let draw = || -> Result<(), Box<dyn std::error::Error>> {
            root.fill(&WHITE)?;
            let p = root.split_evenly((2, 2));
            panel(
                &p[0],
                "NIST FTS, 9.03 % CO2, 742.08 Torr, 295.30 K, 3254 cm: transmission",
                "transmission",
                (nu0, nu1),
                &[
                    ("measurement", all(&meas.t), black),
                    ("Voigt, HITRAN2016", all(&voigt.model), blue),
                    ("SDNGP + line mixing, NIST", all(&beyond.model), red),
                ],
            )?;
            panel(
                &p[1],
                "R(16)e (±0.6 cm⁻¹): transmission",
                "transmission",
                zoom,
                &[
                    ("measurement", near(&meas.t), black),
                    ("Voigt, HITRAN2016", near(&voigt.model), blue),
                    ("SDNGP + line mixing, NIST", near(&beyond.model), red),
                ],
            )?;
            panel(
                &p[2],
                &format!(
                    "residual measurement − model (rms: Voigt {:.2e}, beyond-Voigt {:.2e})",
                    voigt.rms, beyond.rms
                ),
                "residual [transmission]",
                (nu0, nu1),
                &[
                    ("Voigt, HITRAN2016", all(&voigt.residual), blue),
                    ("SDNGP + line mixing, NIST", all(&beyond.residual), red),
                ],
            )?;
            panel(
                &p[3],
                "R(16)e: residual measurement − model",
                "residual [transmission]",
                zoom,
                &[
                    ("Voigt, HITRAN2016", near(&voigt.residual), blue),
                    ("SDNGP + line mixing, NIST", near(&beyond.residual), red),
                ],
            )?;
            root.present()?;
            Ok(())
        };
        draw().map_err(|e| anyhow!("cannot draw: {e}"))
    })?;
    files.commit()?;
    Ok(())
}
