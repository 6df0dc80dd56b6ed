//! Polarised multiple scattering (README.md beside this file): the
//! depolarisation ratio δ and the multiple-scattering fraction against penetration depth of the
//! C.1 cloud at 532 nm for a ground lidar (2, 4, 10 and 20 mrad), and the layer-integrated δ
//! against Hu et al.'s relation η = ((1 − δ)/(1 + δ))² (Hu et al. 2006, Opt. Lett. 31, 1809;
//! 2007, Opt. Express 15, 5327) for those fields of view and a CALIPSO-like space lidar.
//!
//! η is the run's own: the η for which Platt's relation γ = (1 − e^{−2ητ})/(2ηS) gives the
//! layer-integrated attenuated backscatter γ of the run (S = 4π/(ϖ P(180°)) and τ from the
//! scene's optics), as `validation/platt` takes it.
//!
//! `cargo run --release --example polarisation -- RUN_BASE` (RUN_BASE/c1 and RUN_BASE/calipso
//! hold `lidarsim run` outputs of `c1_532.toml` and `calipso.toml`; run.sh does both). Writes
//! `c1_depolarisation.csv`, `hu.csv`, `speed.csv`, `c1_depolarisation.png` and `hu.png`
//! beside this file and prints the tables.

#[path = "../cloud_common.rs"]
mod cloud_common;

use std::path::Path;

use anyhow::{Context, Result};
use cloud_common::{COLOURS, FONT, Returns, attenuated_backscatter, init_font};
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::scene::Scene;
use plotters::prelude::*;

const GROUND_FOVS: [f64; 4] = [2.0, 4.0, 10.0, 20.0];
const CALIPSO_FOV: f64 = 0.13;
/// The δ whose standard error the speed table asks for, and where.
const TARGET_SE: f64 = 0.005;
const SPEED_DEPTH_M: f64 = 105.0;

/// The cloud's optical depth τ, lidar ratio S and the range [m] of its near edge along the
/// beam, from the scene's own optics.
struct Cloud {
    tau: f64,
    s_sr: f64,
    near_m: f64,
}

fn cloud(scene_path: &Path) -> Result<Cloud> {
    let scene = Scene::read(scene_path)?;
    let atm = OpticalAtmosphere::build(&scene)?;
    let l = atm
        .components
        .iter()
        .position(|c| !c.is_empty())
        .context("a cloud layer")?;
    let (z0, z1) = (atm.edges_m[l], atm.edges_m[l + 1]);
    let n = atm.n_channels;
    let (ss, sa) = (atm.sigma_s_per_m[l * n], atm.sigma_a_per_m[l * n]);
    let p180 = atm.phases[atm.components[l][0].phase[0] as usize].backscatter();
    let z_lidar = scene.lidar.altitude_m;
    let (r0, r1) = ((z0 - z_lidar).abs(), (z1 - z_lidar).abs());
    Ok(Cloud {
        tau: (ss + sa) * (z1 - z0),
        s_sr: 4.0 * std::f64::consts::PI * (ss + sa) / (ss * p180),
        near_m: r0.min(r1),
    })
}

/// Platt's γ(η) for optical depth τ and lidar ratio S.
fn platt(eta: f64, c: &Cloud) -> f64 {
    (1.0 - (-2.0 * eta * c.tau).exp()) / (2.0 * eta * c.s_sr)
}

/// The η for which Platt's relation gives γ (γ(η) falls monotonically), by bisection.
fn eta_from_gamma(gamma: f64, c: &Cloud) -> f64 {
    let (mut lo, mut hi) = (1e-3, 2.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if platt(mid, c) > gamma {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Hu's relation solved for δ: δ = (1 − √η)/(1 + √η).
fn hu_delta(eta: f64) -> f64 {
    (1.0 - eta.sqrt()) / (1.0 + eta.sqrt())
}

/// One row of `depolarisation.csv`: δ and its error by (source, FOV, range, order).
struct Delta {
    source: String,
    fov: f64,
    range_m: f64,
    order: String,
    delta: f64,
    se: f64,
}

fn read_delta(dir: &Path) -> Result<Vec<Delta>> {
    let path = dir.join("depolarisation.csv");
    let mut rd = csv::Reader::from_path(&path)
        .with_context(|| format!("{}: run run.sh first", path.display()))?;
    let mut out = Vec::new();
    for rec in rd.records() {
        let rec = rec?;
        out.push(Delta {
            source: rec[0].to_string(),
            fov: rec[2].parse()?,
            range_m: rec[3].parse()?,
            order: rec[4].to_string(),
            delta: rec[5].parse()?,
            se: rec[6].parse()?,
        });
    }
    Ok(out)
}

/// The transport's photons and wall time from `summary.json`.
fn run_cost(dir: &Path) -> Result<(f64, f64, u64)> {
    let text = std::fs::read_to_string(dir.join("summary.json"))?;
    let v: serde_json::Value = serde_json::from_str(&text)?;
    let get = |k: &str| {
        v.get(k)
            .and_then(|x| x.as_f64())
            .with_context(|| format!("{k} in summary.json"))
    };
    Ok((get("photons")?, get("wall_s")?, get("threads")? as u64))
}

/// Layer-integrated quantities of one field of view: γ = Σ β' Δr and δ = Σ cross / Σ co over
/// every gate, each with an error bound (the sum of the gates' errors).
fn layer(r: &Returns, fov: f64, width_m: f64) -> Result<(f64, f64, f64, f64)> {
    let total = r.get("mc", fov, "total")?;
    let co = r.get_polarised("mc", fov, "total", "co")?;
    let cross = r.get_polarised("mc", fov, "total", "cross")?;
    let (mut g, mut ge) = (0.0, 0.0);
    for gate in total {
        let (b, be) = attenuated_backscatter(gate, width_m);
        g += b * width_m;
        ge += be * width_m;
    }
    let (c, ce): (f64, f64) = co
        .iter()
        .fold((0.0, 0.0), |a, x| (a.0 + x.energy_j, a.1 + x.stderr_j));
    let (x, xe): (f64, f64) = cross
        .iter()
        .fold((0.0, 0.0), |a, x| (a.0 + x.energy_j, a.1 + x.stderr_j));
    let d = x / c;
    Ok((g, ge, d, d * (ce / c + xe / x)))
}

fn main() -> Result<()> {
    let base = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "target/validation/polarisation".into());
    let base = Path::new(&base);
    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("validation/polarisation");
    let (c1_dir, cal_dir) = (base.join("c1"), base.join("calipso"));
    let c1 = cloud(&here.join("c1_532.toml"))?;
    let cal = cloud(&here.join("calipso.toml"))?;
    println!(
        "C.1 at 532 nm: cloud optical depth {:.3}, lidar ratio {:.3} sr (ground); CALIPSO case τ {:.3}",
        c1.tau, c1.s_sr, cal.tau
    );

    // δ and the multiple-scattering fraction against depth.
    let returns = Returns::read(&c1_dir)?;
    let deltas = read_delta(&c1_dir)?;
    let mut csv = String::from(
        "fov_full_angle_mrad,depth_m,delta,delta_stderr,ms_fraction,ms_fraction_stderr\n",
    );
    let mut series = Vec::new();
    for fov in GROUND_FOVS {
        let total = returns.get("mc", fov, "total")?;
        let single = returns.get("analytic", fov, "1")?;
        let mut pts = Vec::new();
        for (t, a) in total.iter().zip(single) {
            let depth = t.range_m - c1.near_m;
            if !(0.0..=300.0).contains(&depth) || t.energy_j <= 0.0 {
                continue;
            }
            let d = deltas
                .iter()
                .find(|d| {
                    d.source == "mc" && d.fov == fov && d.order == "total" && d.range_m == t.range_m
                })
                .context("δ of a gate")?;
            let ms = 1.0 - a.energy_j / t.energy_j;
            let ms_se = a.energy_j / (t.energy_j * t.energy_j) * t.stderr_j;
            csv.push_str(&format!(
                "{fov},{depth},{:.6e},{:.3e},{ms:.6e},{ms_se:.3e}\n",
                d.delta, d.se
            ));
            pts.push((depth, d.delta, d.se, ms, ms_se));
        }
        series.push((fov, pts));
    }
    std::fs::write(here.join("c1_depolarisation.csv"), csv)?;
    println!("\nδ (all orders) and multiple-scattering fraction, every 50 m of depth");
    for (fov, pts) in &series {
        let cells: Vec<String> = pts
            .iter()
            .filter(|p| ((p.0 - 5.0) % 50.0).abs() < 1e-6)
            .map(|p| format!("{:.0} m {:.3}±{:.3} ({:.2})", p.0, p.1, p.2, p.3))
            .collect();
        println!("  {fov:>4} mrad: {}", cells.join(", "));
    }

    // Speed: photons and seconds for a standard error of 0.005 in δ at 105 m.
    let (photons, wall_s, threads) = run_cost(&c1_dir)?;
    let mut speed = String::from(
        "fov_full_angle_mrad,depth_m,delta,delta_stderr,photons_run,seconds_run,threads,photons_for_0.005,seconds_for_0.005\n",
    );
    println!(
        "\nfor δ ± {TARGET_SE} at {SPEED_DEPTH_M} m (from {photons:.0} photons in {wall_s:.1} s on {threads} threads):"
    );
    for (fov, pts) in &series {
        let p = pts
            .iter()
            .find(|p| (p.0 - SPEED_DEPTH_M).abs() < 1e-6)
            .context("the gate at 105 m")?;
        let f = (p.2 / TARGET_SE).powi(2);
        speed.push_str(&format!(
            "{fov},{SPEED_DEPTH_M},{:.6e},{:.3e},{photons},{wall_s},{threads},{:.3e},{:.3e}\n",
            p.1,
            p.2,
            photons * f,
            wall_s * f
        ));
        println!(
            "  {fov:>4} mrad: δ {:.4} ± {:.4}: {:.2e} photons, {:.2} s",
            p.1,
            p.2,
            photons * f,
            wall_s * f
        );
    }
    std::fs::write(here.join("speed.csv"), speed)?;

    // Layer-integrated δ against Hu's relation.
    let cal_returns = Returns::read(&cal_dir)?;
    let mut hu = String::from(
        "case,fov_full_angle_mrad,gamma_per_sr,gamma_bound,eta,delta_layer,delta_bound,delta_hu,hu_over_run\n",
    );
    let mut points = Vec::new();
    println!("\nlayer-integrated δ against Hu's relation δ = (1 − √η)/(1 + √η)");
    let cases: Vec<(&str, f64, &Returns, &Cloud, f64)> = GROUND_FOVS
        .iter()
        .map(|f| ("ground", *f, &returns, &c1, 10.0))
        .chain([("calipso", CALIPSO_FOV, &cal_returns, &cal, 15.0)])
        .collect();
    for (case, fov, r, c, width) in cases {
        let (g, ge, d, de) = layer(r, fov, width)?;
        let eta = eta_from_gamma(g, c);
        let dh = hu_delta(eta);
        hu.push_str(&format!(
            "{case},{fov},{g:.6e},{ge:.2e},{eta:.5},{d:.5},{de:.2e},{dh:.5},{:.4}\n",
            dh / d
        ));
        println!(
            "  {case:>7} {fov:>5} mrad: γ {g:.4e} sr⁻¹, η {eta:.3}, δ {d:.4} ± {de:.4}, Hu {dh:.4} ({:.2}×)",
            dh / d
        );
        points.push((case, fov, eta, d, de));
    }
    std::fs::write(here.join("hu.csv"), hu)?;

    init_font();
    draw_depth(&here.join("c1_depolarisation.png"), &series)?;
    draw_hu(&here.join("hu.png"), &points)?;
    println!("\nwrote c1_depolarisation.csv, hu.csv, speed.csv, c1_depolarisation.png, hu.png");
    Ok(())
}

type Series = Vec<(f64, Vec<(f64, f64, f64, f64, f64)>)>;

fn draw_depth(path: &Path, series: &Series) -> Result<()> {
    let root = BitMapBackend::new(path, (1300, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(650);
    for (panel, area) in [(0, left), (1, right)] {
        let (title, y_hi, y_desc) = if panel == 0 {
            ("δ = cross/co (all orders)", 0.8, "δ")
        } else {
            ("multiple-scattering fraction 1 − E₁/E", 1.0, "fraction")
        };
        let mut chart = ChartBuilder::on(&area)
            .caption(format!("C.1 at 532 nm, ground lidar: {title}"), (FONT, 16))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(0.0..305.0, 0.0..y_hi)?;
        chart
            .configure_mesh()
            .x_desc("penetration depth [m]")
            .y_desc(y_desc)
            .label_style((FONT, 12))
            .draw()?;
        for (i, (fov, pts)) in series.iter().enumerate() {
            let c = COLOURS[(i + 1) % COLOURS.len()];
            chart
                .draw_series(pts.iter().map(|p| {
                    let (v, e) = if panel == 0 { (p.1, p.2) } else { (p.3, p.4) };
                    ErrorBar::new_vertical(
                        p.0,
                        (v - e).max(0.0),
                        v,
                        (v + e).min(y_hi),
                        c.filled(),
                        3,
                    )
                }))?
                .label(format!("{fov} mrad"))
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 12))
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

fn draw_hu(path: &Path, points: &[(&str, f64, f64, f64, f64)]) -> Result<()> {
    let root = BitMapBackend::new(path, (800, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "layer-integrated δ against η: Hu et al.'s relation and the runs",
            (FONT, 16),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..1.05, 0.0..0.8)?;
    chart
        .configure_mesh()
        .x_desc("multiple-scattering factor η (from Platt's relation and the run's γ)")
        .y_desc("δ")
        .label_style((FONT, 12))
        .draw()?;
    chart
        .draw_series(LineSeries::new(
            (5..=105).map(|i| {
                let eta = i as f64 / 100.0;
                (eta, hu_delta(eta))
            }),
            BLACK.stroke_width(2),
        ))?
        .label("Hu et al.: η = ((1 − δ)/(1 + δ))²")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    for (i, (case, fov, eta, d, de)) in points.iter().enumerate() {
        let c = COLOURS[(i + 1) % COLOURS.len()];
        chart
            .draw_series([ErrorBar::new_vertical(
                *eta,
                d - de,
                *d,
                d + de,
                c.filled(),
                4,
            )])?
            .label(format!("{case}, {fov} mrad"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.filled()));
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 12))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
