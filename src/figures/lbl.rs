//! The figure of `lidarsim lbl --plot`: cross-sections or optical depths against wavenumber.

use std::path::Path;

use anyhow::bail;
use plotters::prelude::*;

use lidarsim::output::OutputSet;

use super::{FONT, init_font};

/// Line plot with a logarithmic y axis (positive values only), staged in `files` as `path`.
pub fn plot(
    files: &mut OutputSet,
    path: &Path,
    title: &str,
    y_label: &str,
    x: &[f64],
    series: &[(String, Vec<f64>)],
) -> anyhow::Result<()> {
    init_font();
    let (x0, x1) = (x[0], x[x.len() - 1].max(x[0] + 1e-9));
    let pos = series
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .filter(|v| *v > 0.0);
    let (lo, hi) = pos.fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    if hi.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        bail!("nothing to plot: every value is zero");
    }
    let lo = lo.max(hi * 1e-8);
    let draw = |tmp: &Path| -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(tmp, (1000, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 18))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(80)
            // log10 on a linear axis: plotters' log axis draws no labels for values ~1e-25.
            .build_cartesian_2d(x0..x1, (lo.log10() - 0.1)..(hi.log10() + 0.1))?;
        chart
            .configure_mesh()
            .x_desc("wavenumber [cm⁻¹]")
            .y_desc(y_label)
            .label_style((FONT, 13))
            .y_label_formatter(&|v| format!("{:.1e}", 10f64.powf(*v)))
            .draw()?;
        let colours = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
        for (k, (name, v)) in series.iter().enumerate() {
            let c = colours[k % colours.len()];
            chart
                .draw_series(LineSeries::new(
                    x.iter().zip(v).map(|(a, b)| (*a, b.max(lo).log10())),
                    c.stroke_width(1),
                ))?
                .label(name.as_str())
                .legend(move |(px, py)| PathElement::new(vec![(px, py), (px + 20, py)], c));
        }
        super::draw_legend(&mut chart)?;
        root.present()?;
        Ok(())
    };
    Ok(files.write_via(path, draw)?)
}
