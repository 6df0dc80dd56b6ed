//! I3RC Phase 3 Case 7 lidar experiments 1–6 (http://i3rc.gsfc.nasa.gov/phase3/lidar/; Hogan &
//! Battaglia 2008, J. Atmos. Sci. 65, 3636): apparent backscatter against apparent depth below
//! the cloud top for the six scenes beside this file, with
//! * Hogan's fast model (`hogan_i3rc.csv`, made by `hogan_multiscatter.sh`),
//! * the analytic single-scatter return, and the Monte Carlo order 1 against it,
//! * the plain-estimator C tracer `../shared/peers/lidarmc.c`, when its outputs are given,
//! * two closed forms: for experiment 1 the late-time diffusion asymptote of a conservative
//!   isotropic half-space, and for experiment 3 its similarity to experiment 2
//!   (β'₃(d) = ϖ β'₂(ϖ d) e^{−2σ(1−ϖ)d}, exact when the field of view sees the whole spot).
//!
//! `cargo run --release --example i3rc_case7 -- RUN_BASE [LIDARMC_DIR]` (RUN_BASE/exp1 …
//! RUN_BASE/exp6 hold the `returns.csv` of `lidarsim run validation/i3rc_case7/expN.toml`;
//! LIDARMC_DIR holds `lmc_eN_S.txt`, lidarmc outputs of experiment N, seed S; run.sh does all).
//! Writes `i3rc_case7.csv` and `i3rc_case7.png` beside this file and prints the tables.

#[path = "../cloud_common.rs"]
mod cloud_common;

use std::path::Path;

use anyhow::{Context, Result, bail};
use cloud_common::{COLOURS, FONT, Returns, attenuated_backscatter, init_font};
use plotters::prelude::*;

const TOP_M: f64 = 1.0e6; // range of the cloud top from the lidar
/// Range of the cloud in the lidarmc runs (run.sh): a multiple of its 15 m bins, which start at 0.
const PEER_TOP_M: f64 = 1.000005e6;
const WIDTH_M: f64 = 15.0;
const FOV_MRAD: f64 = 5.0;
const SIGMA: f64 = 0.04; // extinction of experiments 1-5 [m⁻¹]
/// Slab clouds end 500 m below the top (495 m for experiment 6).
const SLAB_M: f64 = 500.0;

/// One gate of one experiment.
#[derive(Clone, Default)]
struct Row {
    depth_m: f64,
    mc: f64,
    mc_err: f64,
    mc1: f64,
    mc1_err: f64,
    single: f64,
    hogan: Option<f64>,
    peer: Option<(f64, f64)>,
}

fn is_slab(exp: usize) -> bool {
    exp >= 4
}

/// Hogan's apparent backscatter per gate: column of experiment `exp` (for 5 and 6 the run with
/// the C.1 optics lidarsim uses), only inside the cloud for the slabs.
fn read_hogan(path: &Path) -> Result<Vec<(f64, [Option<f64>; 6])>> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    let mut out = Vec::new();
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let v: Vec<Option<f64>> = line.split(',').map(|s| s.trim().parse().ok()).collect();
        if v.len() != 9 {
            bail!("{}: expected 9 columns in {line}", path.display());
        }
        let d = v[0].context("depth")?;
        let cols = [v[1], v[2], v[3], v[4], v[6], v[8]];
        let cols = std::array::from_fn(|k| cols[k].filter(|_| !is_slab(k + 1) || d < SLAB_M));
        out.push((d, cols));
    }
    Ok(out)
}

/// lidarmc outputs `lmc_e{exp}_{seed}.txt` (rows `r ss tot`, β' per 15 m gate): mean of `tot`
/// per gate over the seeds and its standard error. None when there are none.
fn read_peer(dir: &Path, exp: usize) -> Result<Option<Vec<(f64, f64, f64)>>> {
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    for s in 1..=64 {
        let f = dir.join(format!("lmc_e{exp}_{s}.txt"));
        let Ok(text) = std::fs::read_to_string(&f) else {
            continue;
        };
        let mut rows = Vec::new();
        for line in text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        {
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|x| x.parse())
                .collect::<Result<_, _>>()
                .with_context(|| format!("{}: {line}", f.display()))?;
            if v.len() != 3 {
                bail!("{}: expected 3 columns (one FOV)", f.display());
            }
            // lidarmc's cloud starts at PEER_TOP_M (run.sh): depths below it.
            rows.push((v[0] - PEER_TOP_M, v[2]));
        }
        if let Some(first) = runs.first()
            && first.len() != rows.len()
        {
            bail!(
                "{}: {} gates, the first seed has {} (an unfinished run?)",
                f.display(),
                rows.len(),
                first.len()
            );
        }
        runs.push(rows);
    }
    if runs.len() < 2 {
        return Ok(None);
    }
    let n = runs.len() as f64;
    let out = (0..runs[0].len())
        .map(|i| {
            let xs: Vec<f64> = runs.iter().map(|r| r[i].1).collect();
            let m = xs.iter().sum::<f64>() / n;
            let var = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
            (runs[0][i].0, m, (var / n).sqrt())
        })
        .collect();
    Ok(Some(out))
}

/// β' of a conservative isotropic half-space of extinction σ at late times (diffusion
/// asymptote, exact to leading order in d^{-1/2}): a pulse normally incident reflects at the rate
/// R(t) → (z₀+z_b)(4πDct)^{-1/2}/t per unit time (image solution with extrapolated boundary,
/// Patterson et al. 1989, Appl. Opt. 28, 2331), with D = 1/(3σ); for the exact transport
/// solution z₀+z_b = H(1)/(√3 σ) (the escape function of the Milne problem, van de Hulst 1980,
/// Multiple Light Scattering, ch. 11) and the emergent radiance per unit flux at nadir is
/// K(1)/π = √3 H(1)/(4π), H(1) = 2.9078 (Chandrasekhar 1960, Radiative Transfer, table XIII).
/// With d = ct/2 the apparent depth: β'(d) = K(1)/π · (z₀+z_b)/√(8πD) · d^{-3/2}.
fn diffusion_asymptote(d: f64) -> f64 {
    let h1 = 2.9078;
    let mfp = 1.0 / SIGMA;
    let z = h1 / 3f64.sqrt() * mfp;
    let diff = mfp / 3.0;
    let k1_over_pi = 3f64.sqrt() * h1 / (4.0 * std::f64::consts::PI);
    k1_over_pi * z / (8.0 * std::f64::consts::PI * diff).sqrt() * d.powf(-1.5)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(base) = args.first() else {
        bail!("usage: i3rc_case7 RUN_BASE [LIDARMC_DIR]");
    };
    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/i3rc_case7");
    let hogan = read_hogan(&here.join("hogan_i3rc.csv"))?;

    let mut all: Vec<Vec<Row>> = Vec::new();
    for exp in 1..=6 {
        let ret = Returns::read(&Path::new(base).join(format!("exp{exp}")))?;
        let tot = ret.get("mc", FOV_MRAD, "total")?;
        let o1 = ret.get("mc", FOV_MRAD, "1")?;
        let an = ret.get("analytic", FOV_MRAD, "1")?;
        let peer = match args.get(1) {
            Some(d) => read_peer(Path::new(d), exp)?,
            None => None,
        };
        let mut rows = Vec::new();
        for ((t, g1), a) in tot.iter().zip(o1).zip(an) {
            let depth = t.range_m - TOP_M;
            let (mc, mc_err) = attenuated_backscatter(t, WIDTH_M);
            let (mc1, mc1_err) = attenuated_backscatter(g1, WIDTH_M);
            let single = attenuated_backscatter(a, WIDTH_M).0;
            let h = hogan
                .iter()
                .find(|(d, _)| (d - depth).abs() < 0.5)
                .and_then(|(_, c)| c[exp - 1]);
            let p = peer.as_ref().and_then(|p| {
                p.iter()
                    .find(|(d, _, _)| (d - depth).abs() < 0.5)
                    .map(|&(_, m, e)| (m, e))
            });
            rows.push(Row {
                depth_m: depth,
                mc,
                mc_err,
                mc1,
                mc1_err,
                single,
                hogan: h,
                peer: p,
            });
        }
        all.push(rows);
    }

    let mut csv = String::from(
        "experiment,apparent_depth_m,beta_lidarsim_per_m_sr,stderr_lidarsim,beta_lidarsim_order1,stderr_order1,beta_analytic_single,beta_hogan_multiscatter,beta_lidarmc,stderr_lidarmc\n",
    );
    let opt = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.5e}"));
    for (e, rows) in all.iter().enumerate() {
        for r in rows {
            csv.push_str(&format!(
                "{},{},{:.5e},{:.3e},{:.5e},{:.3e},{:.5e},{},{},{}\n",
                e + 1,
                r.depth_m,
                r.mc,
                r.mc_err,
                r.mc1,
                r.mc1_err,
                r.single,
                opt(r.hogan),
                opt(r.peer.map(|p| p.0)),
                opt(r.peer.map(|p| p.1))
            ));
        }
    }
    std::fs::write(here.join("i3rc_case7.csv"), csv)?;

    report(&all);
    draw(&here.join("i3rc_case7.png"), &all).map_err(|e| anyhow::anyhow!("i3rc_case7.png: {e}"))?;
    println!(
        "\nwrote {}/i3rc_case7.csv and i3rc_case7.png",
        here.display()
    );
    Ok(())
}

/// Depth after the peak where β' first falls below peak/`factor` (log-linear between gates).
fn fall_depth(d: &[f64], b: &[f64], factor: f64) -> Option<f64> {
    let (ip, &peak) = b.iter().enumerate().max_by(|x, y| x.1.total_cmp(y.1))?;
    let target = peak / factor;
    (ip + 1..b.len()).find(|&i| b[i] < target).map(|i| {
        let (l0, l1) = (b[i - 1].ln(), b[i].ln());
        d[i - 1] + (d[i] - d[i - 1]) * (l0 - target.ln()) / (l0 - l1)
    })
}

/// β'-weighted mean apparent depth over the gates given.
fn mean_depth(d: &[f64], b: &[f64]) -> f64 {
    d.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() / b.iter().sum::<f64>()
}

fn report(all: &[Vec<Row>]) {
    println!("## lidarsim / Hogan multiscatter, apparent backscatter at chosen apparent depths\n");
    let depths = [7.5, 22.5, 52.5, 97.5, 202.5, 487.5, 997.5, 1492.5];
    println!("| exp |{}", depths.map(|d| format!(" {d} m |")).concat());
    println!("|---|{}", "---|".repeat(depths.len()));
    for (e, rows) in all.iter().enumerate() {
        print!("| {} |", e + 1);
        for d in depths {
            let r = rows.iter().find(|r| r.depth_m == d).unwrap();
            match r.hogan {
                Some(h) => print!(" {:.3} ± {:.3} |", r.mc / h, r.mc_err / h),
                None => print!(" – |"),
            }
        }
        println!();
    }

    println!("\n## Pulse stretching (window 0–1500 m; slabs: Hogan only inside the cloud)\n");
    println!(
        "| exp | peak at, lidarsim [m] | Hogan [m] | mean apparent depth lidarsim [m] | Hogan [m] | peak/10 lidarsim [m] | Hogan [m] | peak/100 lidarsim [m] | Hogan [m] | rms of lidarsim/Hogan − 1 in the cloud |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (e, rows) in all.iter().enumerate() {
        let d: Vec<f64> = rows.iter().map(|r| r.depth_m).collect();
        let b: Vec<f64> = rows.iter().map(|r| r.mc).collect();
        let hd: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| r.hogan.map(|h| (r.depth_m, h)))
            .collect();
        let (hx, hy): (Vec<f64>, Vec<f64>) = hd.iter().copied().unzip();
        let full = hx.len() == d.len();
        let f = |x: Option<f64>| x.map_or("> window".to_string(), |v| format!("{v:.0}"));
        // Hogan's slab returns stop at the cloud base: a fall not reached there is unknown.
        let hf = |x: Option<f64>| {
            if full || x.is_some() {
                f(x)
            } else {
                "–".to_string()
            }
        };
        let in_cloud: Vec<f64> = rows
            .iter()
            .filter_map(|r| r.hogan.map(|h| (r.mc / h - 1.0).powi(2)))
            .collect();
        let peak_at = |x: &[f64], y: &[f64]| {
            let i = (0..y.len())
                .max_by(|&i, &j| y[i].total_cmp(&y[j]))
                .unwrap_or(0);
            x[i]
        };
        println!(
            "| {} | {} | {} | {:.0} | {} | {} | {} | {} | {} | {:.3} |",
            e + 1,
            peak_at(&d, &b),
            peak_at(&hx, &hy),
            mean_depth(&d, &b),
            if full {
                format!("{:.0}", mean_depth(&hx, &hy))
            } else {
                "–".into()
            },
            f(fall_depth(&d, &b, 10.0)),
            hf(fall_depth(&hx, &hy, 10.0)),
            f(fall_depth(&d, &b, 100.0)),
            hf(fall_depth(&hx, &hy, 100.0)),
            (in_cloud.iter().sum::<f64>() / in_cloud.len() as f64).sqrt()
        );
    }

    println!("\n## Monte Carlo order 1 against the analytic single-scatter return");
    for (e, rows) in all.iter().enumerate() {
        let z: Vec<f64> = rows
            .iter()
            .filter(|r| r.single > 0.0 && r.mc1_err < 0.1 * r.mc1)
            .map(|r| (r.mc1 - r.single) / r.mc1_err)
            .collect();
        let rms = (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt();
        let first = &rows[0];
        println!(
            "  exp {}: {} gates, rms z {rms:.2}, max |z| {:.2}; first gate MC/analytic {:.4}",
            e + 1,
            z.len(),
            z.iter().fold(0.0f64, |a, x| a.max(x.abs())),
            first.mc1 / first.single
        );
    }

    // Experiment 3 from experiment 2 by similarity: with ϖ < 1 the scattering coefficient is ϖσ
    // (a conservative medium stretched by 1/ϖ, whose β' scales as ϖ β'(ϖ d) when the FOV sees
    // the whole spot, 2.5 km wide against a spread of a few hundred metres) times the
    // absorption e^{−σ(1−ϖ)ℓ} over the in-cloud path ℓ = 2d (to x²/2R ≤ 3 m).
    let w = 0.98;
    let (e2, e3) = (&all[1], &all[2]);
    let interp = |x: f64| -> (f64, f64) {
        let i = e2
            .iter()
            .position(|r| r.depth_m >= x)
            .unwrap_or(e2.len() - 1)
            .max(1);
        let (a, b) = (&e2[i - 1], &e2[i]);
        let t = (x - a.depth_m) / (b.depth_m - a.depth_m);
        let v = (a.mc.ln() * (1.0 - t) + b.mc.ln() * t).exp();
        (v, v * (a.mc_err / a.mc * (1.0 - t) + b.mc_err / b.mc * t))
    };
    let mut z2 = Vec::new();
    for r in e3.iter() {
        let (b2, s2) = interp(w * r.depth_m);
        let att = w * (-2.0 * SIGMA * (1.0 - w) * r.depth_m).exp();
        let z = (r.mc - att * b2) / (r.mc_err.powi(2) + (att * s2).powi(2)).sqrt();
        z2.push(z);
    }
    println!(
        "\n## Experiment 3 against ϖ β'₂(ϖ d) e^(−2σ(1−ϖ)d) from experiment 2: {} gates, rms z {:.2}, max |z| {:.2}",
        z2.len(),
        (z2.iter().map(|z| z * z).sum::<f64>() / z2.len() as f64).sqrt(),
        z2.iter().fold(0.0f64, |a, x| a.max(x.abs()))
    );

    println!(
        "\n## Experiment 1 against the diffusion asymptote (conservative isotropic half-space)"
    );
    for d in [202.5, 502.5, 997.5, 1492.5] {
        let r = all[0].iter().find(|r| r.depth_m == d).unwrap();
        let h = r.hogan.unwrap_or(f64::NAN);
        let a = diffusion_asymptote(d);
        println!(
            "  d = {d} m: asymptote {a:.4e}; lidarsim/asymptote {:.3} ± {:.3}; Hogan/asymptote {:.3}",
            r.mc / a,
            r.mc_err / a,
            h / a
        );
    }
    let pts: Vec<(f64, f64)> = all[0]
        .iter()
        .filter(|r| r.depth_m > 750.0)
        .map(|r| (r.depth_m.ln(), r.mc.ln()))
        .collect();
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
        / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
    println!("  log-log slope of lidarsim's β' over 750–1500 m: {slope:.3} (asymptote −1.5)");

    println!("\n## lidarsim against the plain-estimator C tracer (lidarmc.c)");
    for (e, rows) in all.iter().enumerate() {
        let z: Vec<f64> = rows
            .iter()
            .filter_map(|r| {
                r.peer
                    .filter(|p| p.1 > 0.0)
                    .map(|(p, pe)| (r.mc - p) / (r.mc_err.powi(2) + pe * pe).sqrt())
            })
            .collect();
        if z.is_empty() {
            continue;
        }
        let ratio: Vec<f64> = rows
            .iter()
            .filter_map(|r| r.peer.map(|p| r.mc / p.0))
            .collect();
        println!(
            "  exp {}: {} gates, rms z {:.2}, max |z| {:.2}, mean lidarsim/lidarmc {:.4}",
            e + 1,
            z.len(),
            (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt(),
            z.iter().fold(0.0f64, |a, x| a.max(x.abs())),
            ratio.iter().sum::<f64>() / ratio.len() as f64
        );
    }
}

fn draw(path: &Path, all: &[Vec<Row>]) -> Result<(), Box<dyn std::error::Error>> {
    init_font();
    let root = BitMapBackend::new(path, (1500, 950)).into_drawing_area();
    root.fill(&WHITE)?;
    let (title, body) = root.split_vertically(40);
    title.draw_text(
        "I3RC Phase 3 Case 7 lidar experiments: 532 nm, 1000 km, pencil beam, FOV 5 mrad full angle",
        &(FONT, 20).into_text_style(&title),
        (20, 10),
    )?;
    let names = [
        "1: semi-infinite, isotropic",
        "2: semi-infinite, HG g=0.85",
        "3: semi-infinite, HG 0.85, ϖ=0.98",
        "4: 500 m slab, HG 0.85",
        "5: 500 m slab, droplet (C.1 532 nm)",
        "6: 495 m, 78.8→2 km⁻¹, droplet",
    ];
    for (e, area) in body.split_evenly((2, 3)).iter().enumerate() {
        let rows = &all[e];
        let mut chart = ChartBuilder::on(area)
            .caption(names[e], (FONT, 16))
            .margin(8)
            .x_label_area_size(38)
            .y_label_area_size(62)
            .build_cartesian_2d(0.0..1500.0, (1e-7f64..5e-3).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("apparent depth c t/2 below the cloud top [m]")
            .y_desc("apparent backscatter [m⁻¹ sr⁻¹]")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style((FONT, 12))
            .axis_desc_style((FONT, 13))
            .draw()?;
        let c = COLOURS[1];
        chart
            .draw_series(rows.iter().filter(|r| r.mc > 0.0).map(|r| {
                ErrorBar::new_vertical(
                    r.depth_m,
                    (r.mc - 2.0 * r.mc_err).max(1e-8),
                    r.mc,
                    r.mc + 2.0 * r.mc_err,
                    c.filled(),
                    4,
                )
            }))?
            .label("lidarsim, all orders (±2σ)")
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
        chart.draw_series(
            rows.iter()
                .filter(|r| r.mc > 0.0)
                .map(|r| Circle::new((r.depth_m, r.mc), 2, c.filled())),
        )?;
        let s = COLOURS[6];
        chart
            .draw_series(LineSeries::new(
                rows.iter()
                    .filter(|r| r.single > 1e-8)
                    .map(|r| (r.depth_m, r.single)),
                s.stroke_width(1),
            ))?
            .label("analytic single scattering")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], s));
        let h = COLOURS[4];
        chart
            .draw_series(LineSeries::new(
                rows.iter().filter_map(|r| r.hogan.map(|v| (r.depth_m, v))),
                h.stroke_width(2),
            ))?
            .label("Hogan multiscatter (PVC + TDTS)")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], h.stroke_width(2)));
        let p = COLOURS[3];
        let peer: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| r.peer.map(|q| (r.depth_m, q.0)))
            .filter(|q| q.1 > 0.0)
            .collect();
        if !peer.is_empty() {
            chart
                .draw_series(
                    peer.iter()
                        .step_by(2)
                        .map(|&q| Cross::new(q, 4, p.stroke_width(1))),
                )?
                .label("lidarmc.c (plain local estimate)")
                .legend(move |(x, y)| Cross::new((x + 10, y), 4, p.stroke_width(1)));
        }
        if e == 0 {
            let k = COLOURS[0];
            chart
                .draw_series(DashedLineSeries::new(
                    (10..=150).map(|i| (10.0 * i as f64, diffusion_asymptote(10.0 * i as f64))),
                    6,
                    4,
                    k.stroke_width(1),
                ))?
                .label("diffusion asymptote ∝ d^(−3/2)")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], k));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 11))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
