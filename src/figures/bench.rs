//! Figures of `lidarsim bench --depth`: `fom_depth.png` and `error_time.png`.

use std::path::Path;

use lidarsim::benchmark::depth::{self, Cell};

use super::FONT;
use super::style::{self, Entry, Mark, colour};

/// FOM against depth, one colour per FOV: lidarsim solid, plain dashed (as points).
pub fn fom_depth(
    path: &Path,
    rows: &[(Cell, Cell, f64)],
) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    let (root, key) = style::canvas(
        path,
        (1000 + style::LEGEND_W, 650),
        "C.1 multiple scattering: figure of merit against depth into the cloud",
        true,
    )?;
    let mut entries = vec![Entry::heading("field of view (full angle)")];
    let foms = rows.iter().flat_map(|(a, b, _)| [a.fom(), b.fom()]);
    let (lo, hi) = foms
        .filter(|v| *v > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    let mut chart = ChartBuilder::on(&root)
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(40.0..300.0, (lo / 2.0..hi * 2.0).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("depth into the cloud [m] (gate start)")
        .y_desc("FOM = 1/(rel. error² · s)")
        .x_label_formatter(&|v| style::tick(*v))
        .y_label_formatter(&|v| style::tick(*v))
        .label_style((FONT, style::TICK))
        .axis_desc_style((FONT, style::AXIS))
        .draw()?;
    for (i, fov) in depth::FOVS_MRAD.iter().enumerate() {
        let colour = colour(i);
        let mine: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.0.fov_mrad == *fov && r.0.fom() > 0.0)
            .map(|r| (r.0.depth_m + 5.0, r.0.fom()))
            .collect();
        let plain: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.1.fov_mrad == *fov && r.1.fom() > 0.0)
            .map(|r| (r.1.depth_m + 5.0, r.1.fom()))
            .collect();
        chart.draw_series(LineSeries::new(mine, colour.stroke_width(2)))?;
        chart.draw_series(DashedLineSeries::new(plain, 6, 4, colour.stroke_width(1)))?;
        entries.push(Entry::new(
            format!("{} mrad", style::tick(*fov)),
            colour,
            Mark::Line(2, false),
        ));
    }
    entries.push(Entry::heading("solid: lidarsim; dashed: plain Monte Carlo"));
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}

/// Relative error against seconds, log-log: lidarsim solid, plain (expected) dashed.
pub fn error_time(
    path: &Path,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    let (root, key) = style::canvas(
        path,
        (1000 + style::LEGEND_W, 650),
        "C.1 orders ≥ 2: relative standard error against time",
        true,
    )?;
    let mut entries = Vec::new();
    let pts = series
        .iter()
        .flat_map(|s| s.1.iter())
        .filter(|(t, e)| *t > 0.0 && *e > 0.0 && e.is_finite());
    let (t0, t1, e0, e1) = pts.fold(
        (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64),
        |a, (t, e)| (a.0.min(*t), a.1.max(*t), a.2.min(*e), a.3.max(*e)),
    );
    let mut chart = ChartBuilder::on(&root)
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (t0 / 1.5..t1 * 1.5).log_scale(),
            (e0 / 1.5..e1 * 1.5).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("wall-clock seconds, 1 thread")
        .y_desc("relative standard error")
        .x_label_formatter(&|v| style::tick(*v))
        .y_label_formatter(&|v| style::tick(*v))
        .label_style((FONT, style::TICK))
        .axis_desc_style((FONT, style::AXIS))
        .draw()?;
    let half = series.len() / 2;
    for (i, (label, pts)) in series.iter().enumerate() {
        let colour = colour(i % half.max(1));
        let pts: Vec<(f64, f64)> = pts.iter().copied().filter(|(_, e)| e.is_finite()).collect();
        if i < half {
            chart.draw_series(LineSeries::new(pts, colour.stroke_width(2)))?;
            entries.push(Entry::new(
                label.trim_start_matches("lidarsim ").to_string(),
                colour,
                Mark::Line(2, false),
            ));
        } else {
            chart.draw_series(DashedLineSeries::new(pts, 6, 4, colour.stroke_width(1)))?;
        }
    }
    entries.push(Entry::heading(
        "solid: lidarsim; dashed: plain Monte Carlo (expected)",
    ));
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}
