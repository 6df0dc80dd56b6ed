//! Figures of a run: on/off returns against range (`returns.png`) and, with a DIAL retrieval,
//! the retrieved mixing-ratio profile with its error bars against the truth (`dial.png`); with
//! polarised light the depolarisation ratio against range per field of view
//! (`depolarisation.png`).

use std::path::Path;

use plotters::prelude::*;

use super::{FONT, init_font};
use lidarsim::output::{OutputError, OutputSet};
use lidarsim::pipeline::RunOutput;
use lidarsim::retrieval::{Method, Product, Quantity, Weighting};
use lidarsim::returns::{Order, Returns, Source};
use lidarsim::scene::Scene;

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Draw every figure the run has data for into `files`, for the directory `dir`: with a
/// retrieval its returns and DIAL profile, with polarised light its depolarisation.
pub fn draw(
    files: &mut OutputSet,
    dir: &Path,
    scene: &Scene,
    run: &RunOutput,
) -> Result<(), OutputError> {
    init_font();
    if scene.retrieval.is_some() {
        draw_retrieval(files, dir, scene, run)?;
    }
    if run.polarised.is_some() {
        files.write_via(dir.join("depolarisation.png"), |p| {
            depolarisation_figure(p, run)
        })?;
    }
    Ok(())
}

/// `returns.png` and, with a DIAL retrieval, `dial.png`.
fn draw_retrieval(
    files: &mut OutputSet,
    dir: &Path,
    scene: &Scene,
    run: &RunOutput,
) -> Result<(), OutputError> {
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
    Ok(())
}

/// The IPDA's weighting functions, per km of layer against altitude: left the single-scatter
/// one (order 1), right its change by multiple scattering (all orders − order 1, whose sum
/// over the layers, in the legend, is the bias multiple scattering brings), one colour per
/// field of view.
fn weighting_figure(path: &Path, rows: &[&Weighting]) -> DrawResult {
    let root = BitMapBackend::new(path, (1100, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let pair = rows[0].channel_pair.clone();
    let root = root.titled(
        &format!("IPDA weighting functions ({pair}): single scattering and the change by multiple scattering"),
        (FONT, 18),
    )?;
    let (left, right) = root.split_horizontally(500);
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
        let pad = 0.05 * (hi - lo).max(1e-30);
        (lo - pad)..(hi + pad)
    };
    let colour = |i: usize| super::palette(i);
    let mut chart = ChartBuilder::on(&left)
        .caption("single scattering", (FONT, 15))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(range(&|x| x.1), 0.0..z_hi)?;
    chart
        .configure_mesh()
        .x_desc("∂XCO2/∂ln n(gas) per km of layer [ppm/km]")
        .y_desc("altitude [km]")
        .label_style((FONT, 13))
        .draw()?;
    for (i, (fov, (p, _))) in fovs.iter().zip(&profiles).enumerate() {
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(
                p.iter().map(|x| (x.1, x.0)),
                c.stroke_width(2),
            ))?
            .label(format!("{fov} mrad"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    super::draw_legend(&mut chart)?;
    let mut chart = ChartBuilder::on(&right)
        .caption("all orders − single scattering", (FONT, 15))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(range(&|x| x.2), 0.0..z_hi)?;
    chart
        .configure_mesh()
        .x_desc("[ppm/km]")
        .y_desc("altitude [km]")
        .label_style((FONT, 13))
        .draw()?;
    for (i, (fov, (p, sum))) in fovs.iter().zip(&profiles).enumerate() {
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(
                p.iter().map(|x| (x.2, x.0)),
                c.stroke_width(2),
            ))?
            .label(format!("{fov} mrad: bias {sum:.2e} ppm"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    super::draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}

/// The depolarisation ratio δ = cross/co of the first line against range, one colour per field
/// of view: Monte Carlo (all orders) as points with ±1 standard error, analytic single
/// scattering as a line.
fn depolarisation_figure(path: &Path, run: &RunOutput) -> DrawResult {
    let Some(pol) = &run.polarised else {
        return Err("not a polarised run".into());
    };
    let root = BitMapBackend::new(path, (1000, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let (aco, across) = &pol.analytic;
    let fovs = &aco.fov_full_angle_mrad;
    let ratio = |co: &Returns, cross: &Returns, f: usize, g: usize, order: Order| {
        let (c, x) = (co.energy(0, f, g, order)?, cross.energy(0, f, g, order)?);
        (c > 0.0).then(|| x / c)
    };
    // Monte Carlo δ and its error per FOV (first-order propagation, as depolarisation.csv).
    let mc: Vec<Vec<(f64, f64, f64)>> = match &pol.mc {
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
                        Some((co.range_m[g], d, d * rel.max(0.0).sqrt()))
                    })
                    .collect()
            })
            .collect(),
        None => vec![Vec::new(); fovs.len()],
    };
    let hi = mc
        .iter()
        .flatten()
        .map(|p| p.1 + p.2)
        .chain((0..fovs.len()).flat_map(|f| {
            (0..aco.range_m.len()).filter_map(move |g| ratio(aco, across, f, g, Order::Exactly(1)))
        }))
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-3);
    let (x0, x1) = (
        aco.range_m.first().copied().unwrap_or(0.0),
        aco.range_m.last().copied().unwrap_or(1.0),
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("depolarisation ratio δ = cross/co, {}", aco.channels[0]),
            (FONT, 18),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1.max(x0 + 1.0), 0.0..(1.1 * hi).min(2.0))?;
    chart
        .configure_mesh()
        .x_desc("range [m]")
        .y_desc("δ")
        .label_style((FONT, 13))
        .draw()?;
    let colours = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    for (f, fov) in fovs.iter().enumerate() {
        let c = colours[f % colours.len()];
        chart
            .draw_series(
                mc[f]
                    .iter()
                    .map(|&(r, d, e)| ErrorBar::new_vertical(r, d - e, d, d + e, c.filled(), 4)),
            )?
            .label(format!("{fov} mrad, Monte Carlo (all orders)"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
        chart.draw_series(LineSeries::new(
            (0..aco.range_m.len()).filter_map(|g| {
                ratio(aco, across, f, g, Order::Exactly(1)).map(|d| (aco.range_m[g], d))
            }),
            c.stroke_width(1),
        ))?;
    }
    super::draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}

/// log10 of the returns of the first field of view: analytic order 1 as lines, Monte Carlo
/// (all orders) as points, every line.
fn returns_figure(
    path: &Path,
    scene: &Scene,
    analytic: &Returns,
    mc: Option<&Returns>,
) -> DrawResult {
    let root = BitMapBackend::new(path, (1000, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let series = |r: &Returns, k: usize, order: Order| -> Vec<(f64, f64)> {
        (0..r.range_m.len())
            .filter_map(|g| {
                let e = r.energy(k, 0, g, order)?;
                (e > 0.0).then(|| (r.range_m[g], e.log10()))
            })
            .collect()
    };
    let mut all: Vec<(f64, f64)> = Vec::new();
    for k in 0..analytic.channels.len() {
        all.extend(series(analytic, k, Order::Exactly(1)));
        if let Some(m) = mc {
            all.extend(series(m, k, Order::Total));
        }
    }
    if all.is_empty() {
        return Err("no positive return to draw".into());
    }
    let (x0, x1) = (scene.gates.start_m, scene.gates.end_m());
    let (lo, hi) = all
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.1), b.max(p.1))
        });
    // Atmospheric returns span decades below a hard target; keep 8 of them.
    let lo = lo.max(hi - 8.0);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "returns per pulse, FOV {} mrad",
                analytic.fov_full_angle_mrad[0]
            ),
            (FONT, 18),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, (lo - 0.2)..(hi + 0.2))?;
    chart
        .configure_mesh()
        .x_desc("range [m]")
        .y_desc("energy per gate [J]")
        .label_style((FONT, 13))
        .y_label_formatter(&|v| format!("{:.0e}", 10f64.powf(*v)))
        .draw()?;
    let colours = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    for k in 0..analytic.channels.len() {
        let c = colours[k % colours.len()];
        let name = &analytic.channels[k];
        chart
            .draw_series(LineSeries::new(
                series(analytic, k, Order::Exactly(1))
                    .into_iter()
                    .filter(|p| p.1 >= lo),
                c.stroke_width(1),
            ))?
            .label(format!("{name}, analytic single scattering"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        if let Some(m) = mc {
            chart
                .draw_series(
                    series(m, k, Order::Total)
                        .into_iter()
                        .filter(|p| p.1 >= lo)
                        .map(|p| Circle::new(p, 2, c.filled())),
                )?
                .label(format!("{name}, Monte Carlo, all orders"))
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
        }
    }
    super::draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}

/// Retrieved mixing ratio per DIAL cell against altitude, with the averaged random error
/// (analytic) as error bars, next to the truth, for each set of returns of the first FOV.
fn dial_figure(path: &Path, products: &[&Product]) -> DrawResult {
    let root = BitMapBackend::new(path, (800, 800)).into_drawing_area();
    root.fill(&WHITE)?;
    let fov = products[0].fov_full_angle_mrad;
    let set: Vec<&&Product> = products
        .iter()
        .filter(|p| p.fov_full_angle_mrad == fov)
        .collect();
    let z = |p: &Product| 0.5 * (p.altitude_m.0 + p.altitude_m.1);
    let mut x_lo = f64::INFINITY;
    let mut x_hi = f64::NEG_INFINITY;
    for p in &set {
        for v in [
            p.truth,
            p.retrieved - p.random_error_averaged,
            p.retrieved + p.random_error_averaged,
        ] {
            if v.is_finite() {
                x_lo = x_lo.min(v);
                x_hi = x_hi.max(v);
            }
        }
    }
    if x_hi.partial_cmp(&x_lo) != Some(std::cmp::Ordering::Greater) {
        x_lo -= 1.0;
        x_hi += 1.0;
    }
    let pad = 0.05 * (x_hi - x_lo);
    let (z_lo, z_hi) = set
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.altitude_m.0), b.max(p.altitude_m.1))
        });
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "DIAL {}, FOV {fov} mrad, {} shot pairs",
                set[0].channel_pair, set[0].shots_averaged
            ),
            (FONT, 18),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((x_lo - pad)..(x_hi + pad), z_lo..z_hi)?;
    chart
        .configure_mesh()
        .x_desc("dry-air mixing ratio [ppm]")
        .y_desc("altitude [m]")
        .label_style((FONT, 13))
        .draw()?;
    let truth: Vec<(f64, f64)> = set
        .iter()
        .filter(|p| p.source == Source::Analytic)
        .flat_map(|p| [(p.truth, p.altitude_m.0), (p.truth, p.altitude_m.1)])
        .collect();
    chart
        .draw_series(LineSeries::new(truth, BLACK.stroke_width(2)))?
        .label("truth (cell averages)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    let kinds = [
        (
            Source::Analytic,
            Order::Exactly(1),
            BLUE,
            "analytic single scattering",
        ),
        (
            Source::MonteCarlo,
            Order::Total,
            RED,
            "Monte Carlo, all orders",
        ),
    ];
    for (src, order, c, name) in kinds {
        let pts: Vec<&&&Product> = set
            .iter()
            .filter(|p| p.source == src && p.order == order && p.retrieved.is_finite())
            .collect();
        if pts.is_empty() {
            continue;
        }
        chart.draw_series(pts.iter().map(|p| {
            let e = if p.random_error_averaged.is_finite() {
                p.random_error_averaged
            } else {
                0.0
            };
            PathElement::new(
                vec![(p.retrieved - e, z(p)), (p.retrieved + e, z(p))],
                c.stroke_width(1),
            )
        }))?;
        chart
            .draw_series(
                pts.iter()
                    .map(|p| Circle::new((p.retrieved, z(p)), 3, c.filled())),
            )?
            .label(format!("{name} ± random error"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
    }
    super::draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}
