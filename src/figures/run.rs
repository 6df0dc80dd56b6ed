//! Figures of a run, for every scene: the returns of every channel and field of view against
//! range (`returns.png`); with a DIAL retrieval the retrieved mixing-ratio profiles and their
//! bias per line pair (`dial.png`); with IPDA Jacobians the weighting functions
//! (`weighting.png`); with polarised light the depolarisation ratio (`depolarisation.png`).

use std::path::Path;

use plotters::prelude::*;

use super::style::{self, Axis, Entry, Mark, colour, dashed, length_unit};
use super::{DrawResult, init_font};
use lidarsim::output::{OutputError, OutputSet};
use lidarsim::pipeline::RunOutput;
use lidarsim::retrieval::{Method, Product, Quantity, Weighting};
use lidarsim::returns::{Order, Returns, Source};
use lidarsim::scene::Scene;

/// Draw every figure the run has data for into `files`, for the directory `dir`: always its
/// returns (every channel and field of view), with a DIAL retrieval its mixing-ratio profiles,
/// with IPDA Jacobians their weighting functions, with polarised light its depolarisation.
pub fn draw(
    files: &mut OutputSet,
    dir: &Path,
    scene: &Scene,
    run: &RunOutput,
) -> Result<(), OutputError> {
    init_font();
    let mc = run.mc_lines.as_ref().map(|m| &m.mean);
    files.write_via(dir.join("returns.png"), |p| {
        returns_figure(p, scene, &run.analytic_lines.mean, mc)
    })?;
    let dial: Vec<&Product> = run
        .products
        .iter()
        .filter(|p| p.method == Method::Dial && p.quantity == Quantity::MixingRatio)
        .collect();
    if !dial.is_empty() {
        files.write_via(dir.join("dial.png"), |p| dial_figure(p, &dial))?;
    }
    let ipda: Vec<&Weighting> = run
        .weighting
        .iter()
        .filter(|w| w.method == Method::Ipda)
        .collect();
    if !ipda.is_empty() {
        files.write_via(dir.join("weighting.png"), |p| weighting_figure(p, &ipda))?;
    }
    if run.polarised.is_some() {
        files.write_via(dir.join("depolarisation.png"), |p| {
            depolarisation_figure(p, run)
        })?;
    }
    Ok(())
}

/// Panels per row for `n` small multiples.
fn columns(n: usize) -> usize {
    if n <= 1 {
        1
    } else if n <= 4 {
        2
    } else {
        3
    }
}

/// The IPDA's weighting functions, per km of layer against altitude: left the single-scatter
/// one (order 1), right its change by multiple scattering (all orders − order 1, whose sum
/// over the layers, in the legend, is the bias multiple scattering brings), one colour per
/// field of view.
fn weighting_figure(path: &Path, rows: &[&Weighting]) -> DrawResult {
    let pair = rows[0].channel_pair.clone();
    let (plots, key) = style::canvas(
        path,
        (1400, 700),
        &format!(
            "IPDA weighting functions ({pair}): single scattering and its change by multiple scattering"
        ),
        true,
    )?;
    let (left, right) = plots.split_horizontally(plots.dim_in_pixel().0 / 2);
    let mut fovs: Vec<f64> = rows.iter().map(|w| w.fov_full_angle_mrad).collect();
    fovs.sort_by(f64::total_cmp);
    fovs.dedup();
    // Per FOV: (altitude [km], order-1 per km, (total − order 1) per km), and the sum.
    let profile = |fov: f64| -> (Vec<(f64, f64, f64)>, f64) {
        let mut by_layer: std::collections::BTreeMap<usize, (f64, f64, f64, f64)> =
            Default::default();
        for w in rows.iter().filter(|w| w.fov_full_angle_mrad == fov) {
            let e = by_layer.entry(w.layer).or_insert((
                0.5e-3 * (w.layer_m.0 + w.layer_m.1),
                1e-3 * (w.layer_m.1 - w.layer_m.0),
                0.0,
                0.0,
            ));
            match w.order {
                Order::Exactly(1) => e.2 = w.value,
                _ => e.3 = w.value,
            }
        }
        let sum = by_layer.values().map(|(_, _, a, b)| b - a).sum();
        (
            by_layer
                .values()
                .map(|(z, dz, a, b)| (*z, a / dz, (b - a) / dz))
                .collect(),
            sum,
        )
    };
    let profiles: Vec<_> = fovs.iter().map(|f| profile(*f)).collect();
    let z_hi = profiles
        .iter()
        .flat_map(|(p, _)| p.iter().map(|x| x.0))
        .fold(0.0f64, f64::max)
        .max(1e-3);
    let range = |f: &dyn Fn(&(f64, f64, f64)) -> f64| {
        let (lo, hi) = profiles
            .iter()
            .flat_map(|(p, _)| p.iter().map(f))
            .fold((0.0f64, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
        style::padded(lo, hi)
    };
    let mut entries = vec![Entry::heading("field of view (full angle)")];
    for (panel, pick, x_desc, caption) in [
        (
            &left,
            1usize,
            "∂XCO2/∂ln n(gas) per km of layer [ppm/km]",
            "single scattering",
        ),
        (
            &right,
            2,
            "change by multiple scattering [ppm/km]",
            "all orders − single scattering",
        ),
    ] {
        let f = move |x: &(f64, f64, f64)| if pick == 1 { x.1 } else { x.2 };
        let mut chart = style::chart(panel, caption, range(&f), 0.0..z_hi * 1.02)?;
        style::mesh(
            &mut chart,
            Axis::Linear(x_desc),
            Axis::Linear("altitude [km]"),
        )?;
        for (i, (p, _)) in profiles.iter().enumerate() {
            let pts = p.iter().map(|x| (f(x), x.0)).collect();
            style::line(&mut chart, pts, colour(i), 2, dashed(i))?;
        }
    }
    for (i, (fov, (_, sum))) in fovs.iter().zip(&profiles).enumerate() {
        entries.push(Entry::new(
            format!(
                "{} mrad: multiple-scattering bias {sum:.2e} ppm",
                style::tick(*fov)
            ),
            colour(i),
            Mark::Line(2, dashed(i)),
        ));
    }
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}

/// The depolarisation ratio δ = cross/co of the first line against range, one colour per field
/// of view: Monte Carlo (all orders) as points with ±1 standard error, analytic single
/// scattering as a line.
fn depolarisation_figure(path: &Path, run: &RunOutput) -> DrawResult {
    let Some(pol) = &run.polarised else {
        return Err("not a polarised run".into());
    };
    let (aco, across) = &pol.analytic;
    let (plots, key) = style::canvas(
        path,
        (1300, 650),
        &format!(
            "Depolarisation ratio δ = cross/co against range, {}",
            aco.channels[0]
        ),
        true,
    )?;
    let fovs = &aco.fov_full_angle_mrad;
    let ratio = |co: &Returns, cross: &Returns, f: usize, g: usize, order: Order| {
        let (c, x) = (co.energy(0, f, g, order)?, cross.energy(0, f, g, order)?);
        (c > 0.0).then(|| x / c)
    };
    let (scale, unit) = length_unit(aco.range_m.last().copied().unwrap_or(0.0));
    // Monte Carlo δ and its error per FOV (first-order propagation, as depolarisation.csv).
    let mc: Vec<Vec<(f64, f64, f64, f64)>> = match &pol.mc {
        Some((co, cross, cov)) => (0..fovs.len())
            .map(|f| {
                (0..co.range_m.len())
                    .filter_map(|g| {
                        let o = co.order_index(Order::Total)?;
                        let i = co.index(0, f, g, o);
                        let (c, x) = (co.energy_j[i], cross.energy_j[i]);
                        if !(c > 0.0 && x > 0.0) {
                            return None;
                        }
                        let rel = (co.stderr_j[i] / c).powi(2) + (cross.stderr_j[i] / x).powi(2)
                            - 2.0 * cov[i] / (c * x);
                        let d = x / c;
                        let e = d * rel.max(0.0).sqrt();
                        Some((co.range_m[g] * scale, d, d - e, d + e))
                    })
                    .collect()
            })
            .collect(),
        None => vec![Vec::new(); fovs.len()],
    };
    let values: Vec<f64> = mc
        .iter()
        .flatten()
        .map(|p| p.1)
        .chain((0..fovs.len()).flat_map(|f| {
            (0..aco.range_m.len()).filter_map(move |g| ratio(aco, across, f, g, Order::Exactly(1)))
        }))
        .collect();
    // δ is a ratio of two returns: every value is shown (up to 2, beyond which a ratio of
    // near-zero co-polarised returns says nothing).
    let hi = values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    let y = style::padded(0.0, hi.clamp(1e-3, 2.0));
    let (x0, x1) = (
        aco.range_m.first().copied().unwrap_or(0.0) * scale,
        aco.range_m.last().copied().unwrap_or(1.0) * scale,
    );
    let mut chart = style::chart(&plots, "", x0..x1.max(x0 + scale), y)?;
    style::mesh(
        &mut chart,
        Axis::Linear(&format!("range [{unit}]")),
        Axis::Linear("δ"),
    )?;
    let mut entries = vec![Entry::heading("field of view (full angle)")];
    for (f, fov) in fovs.iter().enumerate() {
        let c = colour(f);
        style::points_with_errors(&mut chart, &mc[f], c, !dashed(f))?;
        let pts = (0..aco.range_m.len())
            .filter_map(|g| {
                ratio(aco, across, f, g, Order::Exactly(1)).map(|d| (aco.range_m[g] * scale, d))
            })
            .collect();
        style::line(&mut chart, pts, c, 2, dashed(f))?;
        entries.push(Entry::new(
            format!("{} mrad", style::tick(*fov)),
            c,
            Mark::Line(2, dashed(f)),
        ));
    }
    entries.push(Entry::heading("source"));
    entries.push(Entry::new(
        "analytic, single scattering",
        style::INK,
        Mark::Line(2, false),
    ));
    if pol.mc.is_some() {
        entries.push(Entry::new(
            "Monte Carlo, all orders, ±1 standard error",
            style::INK,
            Mark::Point(true),
        ));
    }
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}

/// The returns of every channel (colour; dashed in the palette's second round) in one panel per
/// field of view, on a log axis: analytic single scattering as lines, Monte Carlo (all orders)
/// as points with ±1 standard error. The y range is shared by the panels and keeps eight
/// decades below the largest return (a hard target's echo dwarfs the atmosphere's).
fn returns_figure(
    path: &Path,
    scene: &Scene,
    analytic: &Returns,
    mc: Option<&Returns>,
) -> DrawResult {
    let (scale, unit) = length_unit(scene.gates.end_m());
    let series = |r: &Returns, k: usize, f: usize, order: Order| -> Vec<(f64, f64, f64, f64)> {
        (0..r.range_m.len())
            .filter_map(|g| {
                let e = r.energy(k, f, g, order)?;
                let s = r.stderr(k, f, g, order).unwrap_or(0.0);
                (e > 0.0).then(|| {
                    let lo = if e - s > 0.0 {
                        (e - s).log10()
                    } else {
                        f64::NEG_INFINITY
                    };
                    (r.range_m[g] * scale, e.log10(), lo, (e + s).log10())
                })
            })
            .collect()
    };
    let (nk, nf) = (analytic.channels.len(), analytic.fov_full_angle_mrad.len());
    let mut hi = f64::NEG_INFINITY;
    let mut lo = f64::INFINITY;
    for k in 0..nk {
        for f in 0..nf {
            let mut s = series(analytic, k, f, Order::Exactly(1));
            if let Some(m) = mc {
                s.extend(series(m, k, f, Order::Total));
            }
            for p in s {
                hi = hi.max(p.1);
                lo = lo.min(p.1);
            }
        }
    }
    if !hi.is_finite() {
        lo = -20.0;
        hi = -10.0;
    }
    let lo = lo.max(hi - 8.0).floor();
    let hi = hi.ceil().max(lo + 1.0);
    let cols = columns(nf);
    let rows = nf.div_ceil(cols);
    let name = scene
        .path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let (plots, key) = style::canvas(
        path,
        (560 * cols as u32 + style::LEGEND_W, 430 * rows as u32 + 50),
        &format!("Received energy per pulse and gate against range, scene {name}"),
        true,
    )?;
    let panels = plots.split_evenly((rows, cols));
    let (x0, x1) = (scene.gates.start_m * scale, scene.gates.end_m() * scale);
    for (f, panel) in panels.iter().enumerate().take(nf) {
        let mut chart = style::chart(
            panel,
            &format!(
                "field of view {} mrad (full angle)",
                style::tick(analytic.fov_full_angle_mrad[f])
            ),
            x0..x1.max(x0 + scale),
            lo..hi,
        )?;
        style::mesh(
            &mut chart,
            Axis::Linear(&format!("range [{unit}]")),
            Axis::Log10("energy per gate [J]"),
        )?;
        for k in 0..nk {
            let c = colour(k);
            let pts: Vec<(f64, f64)> = series(analytic, k, f, Order::Exactly(1))
                .into_iter()
                .filter(|p| p.1 >= lo)
                .map(|p| (p.0, p.1))
                .collect();
            // The Monte Carlo first, so that the analytic line stays on top.
            if let Some(m) = mc {
                let pts = series(m, k, f, Order::Total);
                style::points_with_errors(&mut chart, &pts, c, !dashed(k))?;
            }
            style::line(&mut chart, pts, c, 2, dashed(k))?;
        }
        if !hi.is_finite() || nk == 0 {
            panel.draw(&Text::new(
                "no positive return",
                (60, 60),
                (style::FONT, style::AXIS),
            ))?;
        }
    }
    let mut entries = vec![Entry::heading("channel")];
    for (k, ch) in analytic.channels.iter().enumerate() {
        entries.push(Entry::new(ch.clone(), colour(k), Mark::Line(2, dashed(k))));
    }
    entries.push(Entry::heading("source"));
    entries.push(Entry::new(
        "analytic, single scattering",
        style::INK,
        Mark::Line(2, false),
    ));
    if mc.is_some() {
        entries.push(Entry::new(
            "Monte Carlo, all orders, ±1 standard error",
            style::INK,
            Mark::Point(true),
        ));
    }
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}

/// Retrieved mixing ratio per DIAL cell against altitude, one row of panels per line pair:
/// left the retrieval with its averaged random error (analytic) against the truth, right its
/// bias (retrieved − truth). Colour is the field of view; filled points are the Monte Carlo
/// (all orders), hollow the analytic single scattering. Axis limits come from the 2nd–98th
/// percentiles (and the truth, and zero bias), so a cell with no signal does not flatten the
/// rest; its error bar is cut at the panel's edge.
fn dial_figure(path: &Path, products: &[&Product]) -> DrawResult {
    let mut pairs: Vec<&str> = Vec::new();
    let mut fovs: Vec<f64> = Vec::new();
    for p in products {
        if !pairs.contains(&p.channel_pair.as_str()) {
            pairs.push(&p.channel_pair);
        }
        if !fovs.contains(&p.fov_full_angle_mrad) {
            fovs.push(p.fov_full_angle_mrad);
        }
    }
    let z_max = products.iter().map(|p| p.altitude_m.1).fold(0.0, f64::max);
    let (scale, unit) = length_unit(z_max);
    let z = |p: &Product| 0.5 * (p.altitude_m.0 + p.altitude_m.1) * scale;
    let (z_lo, z_hi) = products
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.altitude_m.0 * scale), b.max(p.altitude_m.1 * scale))
        });
    let shots = products[0].shots_averaged;
    let (plots, key) = style::canvas(
        path,
        (1100 + style::LEGEND_W, 520 * pairs.len() as u32 + 50),
        &format!("DIAL mixing-ratio profiles per line pair ({shots} shot pairs averaged)"),
        true,
    )?;
    let rows = plots.split_evenly((pairs.len(), 2));
    let kinds = [
        (Source::MonteCarlo, Order::Total, true),
        (Source::Analytic, Order::Exactly(1), false),
    ];
    for (i, pair) in pairs.iter().enumerate() {
        let set: Vec<&Product> = products
            .iter()
            .copied()
            .filter(|p| p.channel_pair == *pair && p.retrieved.is_finite())
            .collect();
        let err = |p: &Product| {
            if p.random_error_averaged.is_finite() {
                p.random_error_averaged
            } else {
                0.0
            }
        };
        let truth: Vec<f64> = set.iter().map(|p| p.truth).collect();
        let retrieved: Vec<f64> = set.iter().map(|p| p.retrieved).collect();
        let bias: Vec<f64> = set.iter().map(|p| p.retrieved - p.truth).collect();
        for (j, panel) in [&rows[2 * i], &rows[2 * i + 1]].into_iter().enumerate() {
            let (x, desc, caption) = match j {
                0 => (
                    style::robust_range(&retrieved, &truth),
                    "dry-air mixing ratio [ppm]",
                    format!("{pair}: retrieved ± random error, and truth"),
                ),
                _ => (
                    style::robust_range(&bias, &[0.0]),
                    "retrieved − truth [ppm]",
                    format!("{pair}: bias"),
                ),
            };
            let mut chart = style::chart(panel, &caption, x, z_lo..z_hi)?;
            style::mesh(
                &mut chart,
                Axis::Linear(desc),
                Axis::Linear(&format!("altitude [{unit}]")),
            )?;
            // The truth (left) or zero bias (right) as a black reference.
            let reference: Vec<(f64, f64)> = if j == 0 {
                let mut cells: Vec<&Product> = set
                    .iter()
                    .copied()
                    .filter(|p| {
                        p.fov_full_angle_mrad == fovs[0]
                            && p.source == set[0].source
                            && p.order == set[0].order
                    })
                    .collect();
                cells.sort_by(|a, b| a.altitude_m.0.total_cmp(&b.altitude_m.0));
                cells
                    .iter()
                    .flat_map(|p| {
                        [
                            (p.truth, p.altitude_m.0 * scale),
                            (p.truth, p.altitude_m.1 * scale),
                        ]
                    })
                    .collect()
            } else {
                vec![(0.0, z_lo), (0.0, z_hi)]
            };
            style::line(&mut chart, reference, style::INK, 2, false)?;
            for (f, fov) in fovs.iter().enumerate() {
                for (src, order, filled) in kinds {
                    let pts: Vec<(f64, f64, f64, f64)> = set
                        .iter()
                        .filter(|p| {
                            p.fov_full_angle_mrad == *fov && p.source == src && p.order == order
                        })
                        .map(|p| {
                            let v = if j == 0 {
                                p.retrieved
                            } else {
                                p.retrieved - p.truth
                            };
                            (v, z(p), v - err(p), v + err(p))
                        })
                        .collect();
                    style::points_with_x_errors(&mut chart, &pts, colour(f), filled)?;
                }
            }
        }
    }
    let mut entries = vec![Entry::heading("field of view (full angle)")];
    for (f, fov) in fovs.iter().enumerate() {
        entries.push(Entry::new(
            format!("{} mrad", style::tick(*fov)),
            colour(f),
            Mark::Box,
        ));
    }
    entries.push(Entry::heading("source"));
    entries.push(Entry::new(
        "Monte Carlo, all orders",
        style::INK,
        Mark::Point(true),
    ));
    entries.push(Entry::new(
        "analytic, single scattering",
        style::INK,
        Mark::Point(false),
    ));
    entries.push(Entry::new(
        "truth (cell averages); zero bias",
        style::INK,
        Mark::Line(2, false),
    ));
    entries.push(Entry::heading(
        "error bars: averaged random error (1σ); points beyond the axes are left out",
    ));
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}
