//! The Platt relation (Platt 1973, J. Atmos. Sci. 30, 1191; Platt 1979, J. Appl. Meteorol. 18,
//! 1130): the integrated attenuated backscatter of a cloud of optical depth τ,
//! γ = ∫β'(r) dr = (1 − e^{−2ητ})/(2ηS) → 1/(2ηS), S the lidar (extinction-to-backscatter) ratio
//! and η the multiple-scattering factor, checked on the C.1 cloud cut to τ = 1, 3, 10 for fields of
//! view 0.1–10 mrad (README.md beside this file).
//!
//! η is taken from the run itself, as a lidar would measure it: the slope of ln β'(r) inside the
//! cloud is −2ησ (plus the slow change of the multiple-scattering enhancement), fitted by least
//! squares over the gates from the base to an optical depth of min(τ, 3) into the cloud, where
//! most of γ comes from. Also given: η_γ, the η for which the relation holds exactly.
//!
//! `cargo run --release --example platt -- RUN_BASE` (RUN_BASE/tau1, tau3, tau10 hold the
//! `returns.csv` of `lidarsim run validation/platt/tauN.toml`; run.sh does both). Writes
//! `platt.csv` and `platt.png` beside this file and prints the table.

#[path = "../cloud_common.rs"]
mod cloud_common;

use std::path::Path;

use anyhow::{Result, bail};
use cloud_common::{COLOURS, FONT, Returns, attenuated_backscatter, init_font};
use plotters::prelude::*;

const FOVS: [f64; 6] = [0.1, 0.5, 1.0, 2.0, 5.0, 10.0];
const TAUS: [f64; 3] = [1.0, 3.0, 10.0];
const SIGMA: f64 = 17.23e-3; // C.1 extinction [m⁻¹]
const BASE_M: f64 = 1000.0;
const WIDTH_M: f64 = 2.0;
/// Lidar ratio of the C.1 droplets at 1064 nm, 4π/(ϖ P(180°)) (`../shared/reference/c1_summary.csv`,
/// the phase-function table's header).
const S_SR: f64 = 19.5896;

struct Row {
    tau: f64,
    fov: f64,
    gamma: f64,
    gamma_err: f64,
    gamma_single: f64,
    eta_slope: f64,
    eta_slope_err: f64,
    eta_gamma: f64,
    beyond_top: f64,
}

/// Platt's relation γ(η) for optical depth τ.
fn platt(eta: f64, tau: f64) -> f64 {
    (1.0 - (-2.0 * eta * tau).exp()) / (2.0 * eta * S_SR)
}

/// The η for which `platt(η, τ) = γ` (γ(η) falls monotonically in η), by bisection.
fn eta_from_gamma(gamma: f64, tau: f64) -> f64 {
    let (mut lo, mut hi) = (1e-3, 2.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if platt(mid, tau) > gamma {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

fn main() -> Result<()> {
    let Some(base) = std::env::args().nth(1) else {
        bail!("usage: platt RUN_BASE");
    };
    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/platt");
    let mut rows = Vec::new();
    for tau in TAUS {
        let ret = Returns::read(&Path::new(&base).join(format!("tau{tau}")))?;
        let top = BASE_M + tau / SIGMA;
        let fit_end = BASE_M + tau.min(3.0) / SIGMA;
        for fov in FOVS {
            let tot = ret.get("mc", fov, "total")?;
            let an = ret.get("analytic", fov, "1")?;
            let b: Vec<(f64, f64, f64)> = tot
                .iter()
                .map(|g| {
                    let (v, e) = attenuated_backscatter(g, WIDTH_M);
                    (g.range_m, v, e)
                })
                .collect();
            let gamma: f64 = b.iter().map(|x| x.1 * WIDTH_M).sum();
            // Gates share photons, so their errors are correlated: the plain sum of the errors
            // bounds the error of γ from above (the returns file has no covariances).
            let gamma_err: f64 = b.iter().map(|x| x.2 * WIDTH_M).sum();
            let gamma_single: f64 = an
                .iter()
                .map(|g| attenuated_backscatter(g, WIDTH_M).0 * WIDTH_M)
                .sum();
            let beyond: f64 = b.iter().filter(|x| x.0 > top).map(|x| x.1 * WIDTH_M).sum();
            // Unweighted least squares of ln β' against range inside the fit window; its
            // standard error from the residuals.
            let pts: Vec<(f64, f64)> = b
                .iter()
                .filter(|x| x.0 < fit_end && x.1 > 0.0)
                .map(|x| (x.0 - BASE_M, x.1.ln()))
                .collect();
            let n = pts.len() as f64;
            let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
            let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
            let sxx = pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
            let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx;
            let res = pts
                .iter()
                .map(|p| (p.1 - my - slope * (p.0 - mx)).powi(2))
                .sum::<f64>()
                / (n - 2.0);
            rows.push(Row {
                tau,
                fov,
                gamma,
                gamma_err,
                gamma_single,
                eta_slope: -slope / (2.0 * SIGMA),
                eta_slope_err: (res / sxx).sqrt() / (2.0 * SIGMA),
                eta_gamma: eta_from_gamma(gamma, tau),
                beyond_top: beyond / gamma,
            });
        }
    }

    let mut csv = String::from(
        "optical_depth,fov_full_angle_mrad,gamma_lidarsim_per_sr,gamma_stderr_bound,gamma_single_analytic,gamma_single_closed_form,eta_slope,eta_slope_stderr,gamma_platt_eta_slope,ratio_lidarsim_to_platt,eta_exact,fraction_beyond_cloud_top\n",
    );
    println!(
        "| τ | FOV [mrad] | γ lidarsim [sr⁻¹] | 2Sγ | γ single (analytic) / closed form | η slope | Platt γ(η slope) | lidarsim / Platt | η for exact Platt | beyond top |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        let closed = platt(1.0, r.tau);
        let p = platt(r.eta_slope, r.tau);
        csv.push_str(&format!(
            "{},{},{:.6},{:.6},{:.6},{:.6},{:.4},{:.4},{:.6},{:.4},{:.4},{:.5}\n",
            r.tau,
            r.fov,
            r.gamma,
            r.gamma_err,
            r.gamma_single,
            closed,
            r.eta_slope,
            r.eta_slope_err,
            p,
            r.gamma / p,
            r.eta_gamma,
            r.beyond_top
        ));
        println!(
            "| {} | {} | {:.5} ± {:.5} | {:.3} | {:.5} / {:.5} | {:.3} ± {:.3} | {:.5} | {:.3} | {:.3} | {:.1e} |",
            r.tau,
            r.fov,
            r.gamma,
            r.gamma_err,
            2.0 * S_SR * r.gamma,
            r.gamma_single,
            closed,
            r.eta_slope,
            r.eta_slope_err,
            p,
            r.gamma / p,
            r.eta_gamma,
            r.beyond_top
        );
    }
    std::fs::write(here.join("platt.csv"), csv)?;
    draw(&here.join("platt.png"), &rows).map_err(|e| anyhow::anyhow!("platt.png: {e}"))?;
    println!("\nwrote {}/platt.csv and platt.png", here.display());
    Ok(())
}

fn draw(path: &Path, rows: &[Row]) -> Result<(), Box<dyn std::error::Error>> {
    init_font();
    let root = BitMapBackend::new(path, (1400, 620)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(700);
    let x = (0.07f64..14.0).log_scale();

    let mut a = ChartBuilder::on(&left)
        .caption(
            "integrated attenuated backscatter, C.1 cloud, 1064 nm",
            (FONT, 17),
        )
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(55)
        .build_cartesian_2d(x.clone(), 0.8f64..1.8)?;
    a.configure_mesh()
        .x_desc("field of view, full angle [mrad]")
        .y_desc("2 S γ  (single scattering: 1 − e^(−2τ))")
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .draw()?;
    for (i, tau) in TAUS.iter().enumerate() {
        let c = COLOURS[i + 1];
        let pts: Vec<&Row> = rows.iter().filter(|r| r.tau == *tau).collect();
        a.draw_series(pts.iter().map(|r| {
            let k = 2.0 * S_SR;
            ErrorBar::new_vertical(
                r.fov,
                k * (r.gamma - r.gamma_err),
                k * r.gamma,
                k * (r.gamma + r.gamma_err),
                c.filled(),
                6,
            )
        }))?
        .label(format!("τ = {tau}: lidarsim"))
        .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.filled()));
        a.draw_series(
            pts.iter()
                .map(|r| Circle::new((r.fov, 2.0 * S_SR * r.gamma), 4, c.filled())),
        )?;
        a.draw_series(LineSeries::new(
            pts.iter()
                .map(|r| (r.fov, 2.0 * S_SR * platt(r.eta_slope, r.tau))),
            c.stroke_width(2),
        ))?
        .label(format!("τ = {tau}: Platt, η from the slope"))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        let ss = 1.0 - (-2.0 * tau).exp();
        a.draw_series(DashedLineSeries::new(
            [(0.07, ss), (14.0, ss)],
            5,
            4,
            c.stroke_width(1),
        ))?;
    }
    a.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, 12))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;

    let mut b = ChartBuilder::on(&right)
        .caption("multiple-scattering factor η", (FONT, 17))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(55)
        .build_cartesian_2d(x, 0.4f64..1.1)?;
    b.configure_mesh()
        .x_desc("field of view, full angle [mrad]")
        .y_desc("η")
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .draw()?;
    for (i, tau) in TAUS.iter().enumerate() {
        let c = COLOURS[i + 1];
        let pts: Vec<&Row> = rows.iter().filter(|r| r.tau == *tau).collect();
        b.draw_series(LineSeries::new(
            pts.iter().map(|r| (r.fov, r.eta_slope)),
            c.stroke_width(2),
        ))?
        .label(format!(
            "τ = {tau}: slope of ln β' (base to τ = {})",
            tau.min(3.0)
        ))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        b.draw_series(
            pts.iter()
                .map(|r| Circle::new((r.fov, r.eta_slope), 3, c.filled())),
        )?;
        b.draw_series(DashedLineSeries::new(
            pts.iter().map(|r| (r.fov, r.eta_gamma)),
            5,
            4,
            c.stroke_width(2),
        ))?
        .label(format!("τ = {tau}: η making Platt exact"))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], c.stroke_width(2)));
    }
    b.configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .label_font((FONT, 12))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
