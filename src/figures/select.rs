//! Figures of `lidarsim select-lines`, per group (an AFGL atmosphere or a latitude class):
//! `transmission_<group>.png` (Figure 4 of the reference study) and `errors_<group>.png` (Figure 5).
//! Their numbers are the study's: the rows of `sensitivities.csv` and the spectra of each
//! group's mean profile ([`GroupSummary::spectra`]); nothing is computed here.

use std::path::Path;

use plotters::prelude::*;

use lidarsim::output::{OutputError, OutputSet};
use lidarsim::study::select::{GHZ_PER_CM1, Row, StudyConfig, Uncertainties};
use lidarsim::study::select_study::{GroupSummary, SPECTRUM_HALF_GHZ};

use super::DrawResult;
use super::style::{self, Axis, Entry, Mark, colour};

/// Half width of the laser's spectral window marked in Figure 4 \[GHz\].
const WINDOW_HALF_GHZ: f64 = 0.5;

/// Stage the figures of one group in `files`, for the directory `dir`.
pub fn draw_figures(
    files: &mut OutputSet,
    dir: &Path,
    g: &GroupSummary,
    cfg: &StudyConfig,
    unc: &Uncertainties,
) -> Result<(), OutputError> {
    let (name, rows, members) = (g.name.as_str(), &g.rows, g.profiles);
    match &g.spectra {
        Ok(spectra) if spectra.len() == cfg.spectra.len() => {
            files.write_via(dir.join(format!("transmission_{name}.png")), |p| {
                transmission_figure(p, name, rows, cfg, spectra, members)
            })?;
        }
        Ok(_) => eprintln!("{name}: no spectra of its mean profile: no transmission figure"),
        Err(e) => eprintln!("{name}: the spectra of its mean profile: {e}: no transmission figure"),
    }
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

/// Figure 4: the two-way transmission against the offset from each line's centre, one panel
/// per line: the spectrum of the group's mean profile ([`GroupSummary::spectra`]), and at the
/// candidate on-lines of the study in the panel the mean and standard deviation over the
/// profiles of their transmission (the rows' `t2_on_mean`, `t2_on_std`), the 1 GHz window of
/// the laser marked around the best-ranked on-line position of the line (around the centre if
/// none).
fn transmission_figure(
    path: &Path,
    name: &str,
    rows: &[Row],
    cfg: &StudyConfig,
    spectra: &[Vec<f64>],
    members: usize,
) -> DrawResult {
    let n = cfg.spectra.len().max(1);
    let (plots, key) = style::canvas(
        path,
        (560 * n as u32 + style::LEGEND_W, 600),
        &format!(
            "Two-way column transmission around the figure lines, {name} ({members} profile{})",
            if members == 1 { "" } else { "s" }
        ),
        true,
    )?;
    let panels = plots.split_evenly((1, n));
    // Each panel's candidate on-lines: (offset from its centre [GHz], T² mean, T² std).
    let candidates: Vec<Vec<(f64, f64, f64)>> = cfg
        .spectra
        .iter()
        .map(|w| {
            let mut c: Vec<(f64, f64, f64)> = rows
                .iter()
                .map(|r| {
                    let x = (r.position.nu_cm1 - w.centre_cm1) * GHZ_PER_CM1;
                    (x, r.t2_on_mean, r.t2_on_std)
                })
                .filter(|(x, m, s)| x.abs() <= SPECTRUM_HALF_GHZ && m.is_finite() && s.is_finite())
                .collect();
            c.sort_by(|a, b| a.0.total_cmp(&b.0));
            c
        })
        .collect();
    let show_std = members > 1 && candidates.iter().flatten().any(|c| c.2 > 0.0);
    let (window_c, mean_c, std_c) = (colour(7), style::INK, colour(6));
    for (((w, spectrum), cands), area) in cfg
        .spectra
        .iter()
        .zip(spectra)
        .zip(&candidates)
        .zip(&panels)
    {
        let std_max = cands.iter().map(|c| c.2).fold(0.0f64, f64::max);
        let mut b = ChartBuilder::on(area);
        b.margin(10)
            .x_label_area_size(50)
            .y_label_area_size(75)
            .right_y_label_area_size(if show_std { 80 } else { 0 })
            .caption(
                format!("{} (centre {} cm⁻¹)", w.label, style::tick(w.centre_cm1)),
                (style::FONT, style::CAPTION),
            );
        let mut chart = b
            .build_cartesian_2d(-SPECTRUM_HALF_GHZ..SPECTRUM_HALF_GHZ, 0.0..1.0)?
            .set_secondary_coord(
                -SPECTRUM_HALF_GHZ..SPECTRUM_HALF_GHZ,
                0.0..(1.1 * std_max).max(1e-6),
            );
        style::mesh(
            &mut chart,
            Axis::Linear("frequency from the line centre [GHz]"),
            Axis::Linear("two-way transmission T²"),
        )?;
        let centre = best_on(rows, &w.label).map_or(0.0, |r| r.position.offset_ghz);
        let (a, b) = (centre - WINDOW_HALF_GHZ, centre + WINDOW_HALF_GHZ);
        chart.draw_series(std::iter::once(Rectangle::new(
            [(a, 0.0), (b, 1.0)],
            window_c.mix(0.25).filled(),
        )))?;
        // Spectra of many points draw as their per-pixel envelope ([`style::decimate`]).
        let pts: Vec<(f64, f64)> = w
            .offsets_ghz
            .iter()
            .copied()
            .zip(spectrum.iter().copied())
            .collect();
        style::line(&mut chart, style::decimate(&pts, 600), mean_c, 2, false)?;
        chart.draw_series(
            cands
                .iter()
                .map(|c| Circle::new((c.0, c.1), 4, mean_c.stroke_width(2))),
        )?;
        if show_std {
            let fy = |v: &f64| style::tick(*v);
            chart
                .configure_secondary_axes()
                .y_desc("T² standard deviation over profiles")
                .y_label_formatter(&fy)
                .label_style((style::FONT, style::TICK))
                .axis_desc_style((style::FONT, style::AXIS))
                .draw()?;
            let pts: Vec<(f64, f64)> = cands.iter().map(|c| (c.0, c.2)).collect();
            chart.draw_secondary_series(LineSeries::new(pts.clone(), std_c.stroke_width(1)))?;
            chart.draw_secondary_series(
                pts.into_iter().map(|p| Circle::new(p, 4, std_c.filled())),
            )?;
        }
    }
    let profile = if members == 1 {
        "T² of the profile".to_string()
    } else {
        format!("T² of the mean of the {members} profiles")
    };
    let mut entries = vec![
        Entry::new(profile, mean_c, Mark::Line(2, false)),
        Entry::new(
            if members == 1 {
                "T² at the candidate on-lines"
            } else {
                "T² mean over profiles at the candidate on-lines"
            },
            mean_c,
            Mark::Point(false),
        ),
    ];
    if show_std {
        entries.push(Entry::new(
            "T² standard deviation over profiles at the candidate on-lines (right axis)",
            std_c,
            Mark::Point(true),
        ));
    }
    entries.push(Entry::new(
        format!("laser window ±{WINDOW_HALF_GHZ} GHz around the best-ranked on-line"),
        window_c,
        Mark::Box,
    ));
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}

/// Figure 5: the XCO2 error contributions (sensitivity × uncertainty, signed), the random error
/// and the total against the on-line's offset from each chosen line's centre, one panel per
/// line, on one y range so the lines compare.
fn errors_figure(
    path: &Path,
    name: &str,
    rows: &[Row],
    labels: &[&str],
    unc: &Uncertainties,
) -> DrawResult {
    let n = labels.len().max(1);
    let (plots, key) = style::canvas(
        path,
        (560 * n as u32 + style::LEGEND_W, 600),
        &format!("XCO2 error contributions against the on-line position, {name}"),
        true,
    )?;
    let panels = plots.split_evenly((1, n));
    let names = [
        format!("temperature ± {} K", style::tick(unc.temperature_k)),
        format!("frequency ± {} MHz", style::tick(unc.frequency_mhz)),
        format!(
            "surface pressure ± {} hPa",
            style::tick(unc.surface_pressure_hpa)
        ),
        format!("H2O ± {} %", style::tick(unc.h2o_percent)),
        "random (1σ)".to_string(),
        "total (root sum of squares)".to_string(),
    ];
    let colours = [
        colour(0),
        colour(2),
        colour(4),
        colour(7),
        colour(6),
        style::INK,
    ];
    // Per line: the six series, and the x range of its positions.
    type Series = Vec<Vec<(f64, f64)>>;
    let per_label: Vec<(Series, (f64, f64))> = labels
        .iter()
        .map(|label| {
            let mut pts: Vec<&Row> = rows
                .iter()
                .filter(|r| r.position.line.as_deref() == Some(*label))
                .collect();
            pts.sort_by(|a, b| a.position.offset_ghz.total_cmp(&b.position.offset_ghz));
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
            let x = match (pts.first(), pts.last()) {
                (Some(a), Some(b)) => (a.position.offset_ghz, b.position.offset_ghz),
                _ => (0.0, 0.0),
            };
            (series, x)
        })
        .collect();
    // One y range for every panel: the 2nd–98th percentiles of all values, with zero.
    let all: Vec<f64> = per_label
        .iter()
        .flat_map(|(s, _)| s.iter().flatten().map(|p| p.1))
        .collect();
    let y = style::robust_range(&all, &[0.0]);
    for ((label, (series, (x0, x1))), area) in labels.iter().zip(per_label).zip(&panels) {
        if series.iter().all(Vec::is_empty) {
            continue;
        }
        let x = style::padded(x0, x1);
        let mut chart = style::chart(area, &format!("on-line on {label}"), x, y.clone())?;
        style::mesh(
            &mut chart,
            Axis::Linear("on-line offset from the line centre [GHz]"),
            Axis::Linear("XCO2 error [ppm]"),
        )?;
        for (s, c) in series.into_iter().zip(colours) {
            let width = if c == style::INK { 3 } else { 2 };
            let markers = s.len() <= 60;
            let inside: Vec<(f64, f64)> = s.into_iter().filter(|p| y.contains(&p.1)).collect();
            if markers {
                chart.draw_series(inside.iter().map(|p| Circle::new(*p, 3, c.filled())))?;
            }
            style::line(&mut chart, inside, c, width, false)?;
        }
    }
    let entries: Vec<Entry> = names
        .into_iter()
        .zip(colours)
        .map(|(n, c)| Entry::new(n, c, Mark::Line(if c == style::INK { 3 } else { 2 }, false)))
        .collect();
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}
