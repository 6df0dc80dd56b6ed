//! The figure of `lidarsim lbl --plot`: cross-sections or optical depths against wavenumber.

use std::path::Path;

use anyhow::bail;

use lidarsim::output::OutputSet;

use super::style::{self, Axis, Entry, Mark, colour, dashed};

/// Line plot with a logarithmic y axis (positive values only), staged in `files` as `path`;
/// `title` says what is drawn (a quantity and its conditions, not a file).
pub fn plot(
    files: &mut OutputSet,
    path: &Path,
    title: &str,
    y_label: &str,
    x: &[f64],
    series: &[(String, Vec<f64>)],
) -> anyhow::Result<()> {
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
    let draw = |tmp: &Path| -> super::DrawResult {
        let (plots, key) = style::canvas(tmp, (1000 + style::LEGEND_W, 600), title, true)?;
        // log10 on a linear axis: plotters' log axis draws no labels for values ~1e-25.
        let mut chart = style::chart(&plots, "", x0..x1, (lo.log10() - 0.1)..(hi.log10() + 0.1))?;
        style::mesh(
            &mut chart,
            Axis::Linear("wavenumber [cm⁻¹]"),
            Axis::Log10(y_label),
        )?;
        let mut entries = Vec::new();
        for (k, (name, v)) in series.iter().enumerate() {
            // At most ~2000 points per series at the figure's width (min/max per bucket).
            let pts: Vec<(f64, f64)> = x
                .iter()
                .zip(v)
                .map(|(a, b)| (*a, b.max(lo).log10()))
                .collect();
            style::line(
                &mut chart,
                style::decimate(&pts, 1000),
                colour(k),
                1,
                dashed(k),
            )?;
            entries.push(Entry::new(
                name.clone(),
                colour(k),
                Mark::Line(2, dashed(k)),
            ));
        }
        style::legend(&key.expect("legend column"), &entries)?;
        Ok(())
    };
    Ok(files.write_via(path, draw)?)
}
