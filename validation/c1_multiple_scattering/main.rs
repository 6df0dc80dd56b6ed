//! Bissonnette et al. (1995, Appl. Phys. B 60, 355) case C.1: the multiple-to-single ratio
//! (Monte Carlo total over the analytic single-scatter return) against penetration depth for
//! every field of view of `scenes/bissonnette_c1.toml`, with the run's own standard errors,
//! beside Hogan's fast model (multiscatter, Hogan 2008, J. Atmos. Sci. 65, 3621; `hogan_c1.csv`,
//! made by `hogan_multiscatter.py`) and, when given, the plain-estimator C tracer of
//! `../shared/peers/lidarmc.c` (README.md beside this file).
//!
//! `cargo run --release --example c1_multiple_scattering -- RUN_DIR [LIDARMC_OUTPUT ...]`
//! (RUN_DIR holds the `returns.csv` of `lidarsim run scenes/bissonnette_c1.toml`; run.sh does
//! both). Writes `c1_ratio.csv` and `c1_ratio.png` beside this file and prints the tables.

#[path = "../cloud_common.rs"]
mod cloud_common;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use cloud_common::{COLOURS, FONT, Returns, init_font};
use plotters::prelude::*;

const FOVS: [f64; 6] = [0.1, 0.5, 1.0, 2.0, 5.0, 10.0];
const BASE_M: f64 = 1000.0;
const TOP_M: f64 = 1300.0;

/// One row of the result: gate centre depth, FOV, and the ratios with their errors.
struct Row {
    depth_m: f64,
    fov: usize,
    mc: f64,
    mc_err: f64,
    hogan: f64,
    peer: Option<(f64, f64)>,
}

/// Hogan's ratios by 10 m gate (depth of the centre) and FOV, from `hogan_c1.csv`.
fn read_hogan(path: &Path) -> Result<Vec<(f64, [f64; 6])>> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    let mut out = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let v: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{}: {line}", path.display()))?;
        if v.len() != 7 {
            bail!("{}: expected 7 columns in {line}", path.display());
        }
        out.push((v[0], [v[1], v[2], v[3], v[4], v[5], v[6]]));
    }
    Ok(out)
}

/// Outputs of `lidarmc` (one per seed): rows `r ss_fov tot_fov …` of attenuated backscatter
/// per 10 m gate. Returns, per gate centre range, the mean total per FOV and the standard error
/// of that mean over the seeds (independent runs).
/// Per gate: centre range [m] and (mean, standard error) of the total for each FOV.
type PeerRows = Vec<(f64, [(f64, f64); 6])>;

fn read_peer(files: &[PathBuf]) -> Result<PeerRows> {
    let mut runs: Vec<Vec<(f64, [f64; 6])>> = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(f).with_context(|| f.display().to_string())?;
        let mut rows = Vec::new();
        for line in text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        {
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|s| s.parse())
                .collect::<Result<_, _>>()
                .with_context(|| format!("{}: {line}", f.display()))?;
            if v.len() != 13 {
                bail!("{}: expected 13 columns (6 FOVs)", f.display());
            }
            rows.push((v[0], std::array::from_fn(|k| v[2 + 2 * k])));
        }
        runs.push(rows);
    }
    let n = runs.len() as f64;
    let mut out = Vec::new();
    for (i, (r, _)) in runs[0].iter().enumerate() {
        let cols = std::array::from_fn(|k| {
            let xs: Vec<f64> = runs.iter().map(|run| run[i].1[k]).collect();
            let m = xs.iter().sum::<f64>() / n;
            let var = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
            (m, (var / n).sqrt())
        });
        out.push((*r, cols));
    }
    Ok(out)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(run_dir) = args.first() else {
        bail!("usage: c1_multiple_scattering RUN_DIR [LIDARMC_OUTPUT ...]");
    };
    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/c1_multiple_scattering");
    let ret = Returns::read(Path::new(run_dir))?;
    let hogan = read_hogan(&here.join("hogan_c1.csv"))?;
    let peer_files: Vec<PathBuf> = args[1..].iter().map(PathBuf::from).collect();
    let peer = if peer_files.is_empty() {
        None
    } else {
        Some(read_peer(&peer_files)?)
    };

    let mut rows = Vec::new();
    for (f, &fov) in FOVS.iter().enumerate() {
        let tot = ret.get("mc", fov, "total")?;
        let single = ret.get("analytic", fov, "1")?;
        for (t, a) in tot.iter().zip(single) {
            if t.range_m < BASE_M || t.range_m > TOP_M {
                continue;
            }
            let depth = t.range_m - BASE_M;
            let h = hogan
                .iter()
                .find(|(d, _)| (d - depth).abs() < 0.5)
                .with_context(|| format!("hogan_c1.csv has no gate at {depth} m"))?
                .1[f];
            // The peer prints apparent backscatter β' = E r²/(E₀ A Δr), the analytic return the
            // energy: both over the analytic β' of the same gate.
            let beta_ss = a.energy_j * a.range_m * a.range_m / (std::f64::consts::PI * 0.25 * 10.0);
            let p = peer.as_ref().and_then(|p| {
                p.iter()
                    .find(|(r, _)| (r - t.range_m).abs() < 0.5)
                    .map(|(_, c)| (c[f].0 / beta_ss, c[f].1 / beta_ss))
            });
            rows.push(Row {
                depth_m: depth,
                fov: f,
                mc: t.energy_j / a.energy_j,
                mc_err: t.stderr_j / a.energy_j,
                hogan: h,
                peer: p,
            });
        }
    }

    // CSV of every gate and FOV.
    let mut csv = String::from(
        "depth_m,fov_full_angle_mrad,ratio_lidarsim,stderr_lidarsim,ratio_hogan_multiscatter,ratio_lidarmc,stderr_lidarmc\n",
    );
    for r in &rows {
        let (p, pe) = r.peer.map_or((String::new(), String::new()), |(a, b)| {
            (format!("{a:.5}"), format!("{b:.5}"))
        });
        csv.push_str(&format!(
            "{},{},{:.5},{:.5},{:.5},{p},{pe}\n",
            r.depth_m, FOVS[r.fov], r.mc, r.mc_err, r.hogan
        ));
    }
    std::fs::write(here.join("c1_ratio.csv"), csv)?;

    // Tables for the README: the ratio every 30 m, and the agreement summaries.
    println!(
        "| depth [m] |{}",
        FOVS.map(|f| format!(" {f} mrad |")).concat()
    );
    println!("|---|{}", "---|".repeat(FOVS.len()));
    for d in (0..30)
        .map(|i| 5.0 + 10.0 * i as f64)
        .filter(|d| (((d - 5.0) / 10.0) as usize).is_multiple_of(3) || *d == 295.0)
    {
        print!("| {d} |");
        for f in 0..FOVS.len() {
            let r = rows.iter().find(|r| r.fov == f && r.depth_m == d).unwrap();
            print!(" {:.3} ± {:.3} (H {:.3}) |", r.mc, r.mc_err, r.hogan);
        }
        println!();
    }
    println!("\nlidarsim / Hogan multiscatter, by FOV: mean and range over the 30 gates");
    for (f, fov) in FOVS.iter().enumerate() {
        let q: Vec<f64> = rows
            .iter()
            .filter(|r| r.fov == f)
            .map(|r| r.mc / r.hogan)
            .collect();
        let (lo, hi) = q
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(*x), b.max(*x)));
        // The multiple-scattering part alone (ratio − 1): where models differ most.
        let m: Vec<f64> = rows
            .iter()
            .filter(|r| r.fov == f)
            .map(|r| (r.mc - 1.0) / (r.hogan - 1.0))
            .collect();
        println!(
            "  {fov:>4} mrad: total {:.3} [{lo:.3}, {hi:.3}]; multiple-scattering part (ratio − 1) {:.2} (median)",
            q.iter().sum::<f64>() / q.len() as f64,
            median(&m)
        );
    }
    if peer.is_some() {
        let (mut n, mut z2, mut zmax) = (0usize, 0.0, 0.0f64);
        for r in &rows {
            if let Some((p, pe)) = r.peer {
                let z = (r.mc - p) / (r.mc_err.powi(2) + pe.powi(2)).sqrt();
                if z.is_finite() {
                    n += 1;
                    z2 += z * z;
                    zmax = zmax.max(z.abs());
                }
            }
        }
        println!(
            "\nlidarsim − lidarmc over {n} gates × FOVs: rms z {:.2}, max |z| {zmax:.2} (errors of both added)",
            (z2 / n as f64).sqrt()
        );
    }
    draw(&here.join("c1_ratio.png"), &rows).map_err(|e| anyhow::anyhow!("c1_ratio.png: {e}"))?;
    println!("wrote {}/c1_ratio.csv and c1_ratio.png", here.display());
    Ok(())
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

fn draw(path: &Path, rows: &[Row]) -> Result<(), Box<dyn std::error::Error>> {
    init_font();
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Bissonnette et al. (1995) C.1, 1064 nm: total / single scattering",
            (FONT, 20),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..300.0, (0.95f64..40.0).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("penetration depth into the cloud [m]")
        .y_desc("multiple-to-single ratio")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v}"))
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .draw()?;
    for (f, fov) in FOVS.iter().enumerate() {
        let c = COLOURS[f + 1];
        let pts: Vec<&Row> = rows.iter().filter(|r| r.fov == f).collect();
        chart
            .draw_series(pts.iter().map(|r| {
                ErrorBar::new_vertical(
                    r.depth_m,
                    (r.mc - 2.0 * r.mc_err).max(0.96),
                    r.mc,
                    r.mc + 2.0 * r.mc_err,
                    c.filled(),
                    6,
                )
            }))?
            .label(format!("{fov} mrad lidarsim (±2σ)"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
        chart.draw_series(
            pts.iter()
                .map(|r| Circle::new((r.depth_m, r.mc), 3, c.filled())),
        )?;
        chart.draw_series(LineSeries::new(
            pts.iter().map(|r| (r.depth_m, r.hogan)),
            c.stroke_width(2),
        ))?;
        let peer: Vec<(f64, f64)> = pts
            .iter()
            .filter_map(|r| r.peer.map(|(p, _)| (r.depth_m + 2.0, p)))
            .filter(|p| p.1 > 0.95)
            .collect();
        chart.draw_series(
            peer.iter()
                .map(|&(x, y)| Cross::new((x, y), 4, c.stroke_width(1))),
        )?;
    }
    chart
        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
        .label("lines: Hogan multiscatter 1.2 (PVC + TDTS), r = 6 µm")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    chart
        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
        .label("crosses: lidarmc.c plain local estimate (peer tracer)")
        .legend(|(x, y)| Cross::new((x + 10, y), 4, BLACK.stroke_width(1)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
