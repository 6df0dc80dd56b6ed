//! Figures of `lidarsim select-lines`, per group (an AFGL atmosphere or a latitude class):
//! `transmission_<group>.png` (Figure 4 of the reference study) and `errors_<group>.png` (Figure 5).

use std::path::Path;

use plotters::prelude::*;

use lidarsim::output::{OutputError, OutputSet};
use lidarsim::study::select::{Row, StudyConfig, Uncertainties};
use lidarsim::study::select_study::{GroupSummary, SPECTRUM_HALF_GHZ};

use super::{FONT, draw_legend};

/// Half width of the laser's spectral window marked in Figure 4 \[GHz\].
const WINDOW_HALF_GHZ: f64 = 0.5;

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Stage the figures of one group in `files`, for the directory `dir`.
pub fn draw_figures(
    files: &mut OutputSet,
    dir: &Path,
    g: &GroupSummary,
    cfg: &StudyConfig,
    unc: &Uncertainties,
) -> Result<(), OutputError> {
    let (name, rows, stats, members) = (g.name.as_str(), &g.rows, &g.spectra, g.profiles);
    files.write_via(dir.join(format!("transmission_{name}.png")), |p| {
        transmission_figure(p, name, rows, cfg, stats, members)
    })?;
    let labels: Vec<&str> = cfg.spectra.iter().map(|w| w.label.as_str()).collect();
    if rows.iter().any(|r| {
        r.position
            .line
            .as_deref()
            .is_some_and(|l| labels.contains(&l))
    }) {
        files.write_via(dir.join(format!("errors_{name}.png")), |p| {
            errors_figure(p, name, rows, &labels, unc)
        })?;
    } else {
        eprintln!("{name}: no on-line position on {labels:?}: no error figure");
    }
    Ok(())
}

/// The best-ranked position on a line, if any.
fn best_on<'a>(rows: &'a [Row], label: &str) -> Option<&'a Row> {
    rows.iter()
        .filter(|r| r.position.line.as_deref() == Some(label))
        .min_by_key(|r| r.rank)
}

/// Figure 4: the two-way transmission (mean, and its standard deviation over the members of a
/// set) against the offset from each line's centre, the 1 GHz window of the laser marked around
/// the best-ranked on-line position of the line (around the centre if none).
fn transmission_figure(
    path: &Path,
    name: &str,
    rows: &[Row],
    cfg: &StudyConfig,
    stats: &[(Vec<f64>, Vec<f64>)],
    members: usize,
) -> DrawResult {
    let n = cfg.spectra.len().max(1);
    let root = BitMapBackend::new(path, (520 * n as u32, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, n));
    for ((w, (mean, std)), area) in cfg.spectra.iter().zip(stats).zip(&panels) {
        let std_max = std.iter().copied().fold(0.0f64, f64::max);
        let show_std = members > 1 && std_max > 0.0;
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!(
                    "{name}: {} ({members} profile{})",
                    w.label,
                    if members == 1 { "" } else { "s" }
                ),
                (FONT, 17),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .right_y_label_area_size(if show_std { 70 } else { 0 })
            .build_cartesian_2d(-SPECTRUM_HALF_GHZ..SPECTRUM_HALF_GHZ, 0.0..1.0)?
            .set_secondary_coord(
                -SPECTRUM_HALF_GHZ..SPECTRUM_HALF_GHZ,
                0.0..(1.1 * std_max).max(1e-6),
            );
        chart
            .configure_mesh()
            .x_desc(format!(
                "frequency from the line centre {:.3} cm⁻¹ [GHz]",
                w.centre_cm1
            ))
            .y_desc("two-way transmission T² (mean)")
            .label_style((FONT, 13))
            .draw()?;
        let centre = best_on(rows, &w.label).map_or(0.0, |r| r.position.offset_ghz);
        let (a, b) = (centre - WINDOW_HALF_GHZ, centre + WINDOW_HALF_GHZ);
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(a, 0.0), (b, 1.0)],
                BLUE.mix(0.12).filled(),
            )))?
            .label(format!(
                "laser window ±{WINDOW_HALF_GHZ} GHz at {centre:+.1} GHz"
            ))
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], BLUE.mix(0.3).filled()));
        chart
            .draw_series(LineSeries::new(
                w.offsets_ghz.iter().copied().zip(mean.iter().copied()),
                BLACK.stroke_width(2),
            ))?
            .label("T² mean")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        if show_std {
            chart
                .configure_secondary_axes()
                .y_desc("T² standard deviation")
                .label_style((FONT, 13))
                .draw()?;
            chart
                .draw_secondary_series(LineSeries::new(
                    w.offsets_ghz.iter().copied().zip(std.iter().copied()),
                    RED.stroke_width(2),
                ))?
                .label("T² std over profiles (right axis)")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        }
        draw_legend(&mut chart)?;
    }
    root.present()?;
    Ok(())
}

/// Figure 5: the XCO2 error contributions (sensitivity × uncertainty, signed), the random error
/// and the total against the on-line's offset from each chosen line's centre.
fn errors_figure(
    path: &Path,
    name: &str,
    rows: &[Row],
    labels: &[&str],
    unc: &Uncertainties,
) -> DrawResult {
    let n = labels.len().max(1);
    let root = BitMapBackend::new(path, (520 * n as u32, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, n));
    for (label, area) in labels.iter().zip(&panels) {
        let mut pts: Vec<&Row> = rows
            .iter()
            .filter(|r| r.position.line.as_deref() == Some(*label))
            .collect();
        pts.sort_by(|a, b| a.position.offset_ghz.total_cmp(&b.position.offset_ghz));
        if pts.is_empty() {
            continue;
        }
        let names = [
            format!("T ± {} K", unc.temperature_k),
            format!("frequency ± {} MHz", unc.frequency_mhz),
            format!("surface pressure ± {} hPa", unc.surface_pressure_hpa),
            format!("H2O ± {} %", unc.h2o_percent),
            "random".to_string(),
            "total".to_string(),
        ];
        let series: Vec<Vec<(f64, f64)>> = (0..6)
            .map(|k| {
                pts.iter()
                    .map(|r| {
                        let c = unc.contributions_ppm(r);
                        let v = match k {
                            0..=3 => c[k],
                            4 => r.random_error_ppm,
                            _ => r.total_error_ppm,
                        };
                        (r.position.offset_ghz, v)
                    })
                    .filter(|p| p.1.is_finite())
                    .collect()
            })
            .collect();
        let (lo, hi) = series
            .iter()
            .flatten()
            .fold((0.0f64, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
        let pad = 0.05 * (hi - lo).max(1e-3);
        let (x0, x1) = (
            pts[0].position.offset_ghz,
            pts[pts.len() - 1].position.offset_ghz,
        );
        let (x0, x1) = if x1 > x0 {
            (x0, x1)
        } else {
            (x0 - 1.0, x1 + 1.0)
        };
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("{name}: XCO2 errors, on-line on {label}"),
                (FONT, 17),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, (lo - pad)..(hi + pad))?;
        chart
            .configure_mesh()
            .x_desc("on-line offset from the line centre [GHz]")
            .y_desc("XCO2 error [ppm]")
            .label_style((FONT, 13))
            .draw()?;
        let colours = [RED, BLUE, GREEN, CYAN, MAGENTA, BLACK];
        for ((s, c), label) in series.into_iter().zip(colours).zip(names) {
            let width = if label == "total" { 3 } else { 2 };
            chart
                .draw_series(LineSeries::new(s.clone(), c.stroke_width(width)))?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
            chart.draw_series(s.into_iter().map(|p| Circle::new(p, 3, c.filled())))?;
        }
        draw_legend(&mut chart)?;
    }
    root.present()?;
    Ok(())
}
