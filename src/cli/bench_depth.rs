//! `lidarsim bench --depth DIR`: the figure of merit of C.1's multiple-scattering return at every
//! 10 m gate 50–300 m into the cloud and every field of view 0.5–10 mrad, for lidarsim's
//! estimator (all variance reductions) and the plain local estimate of the same code (no
//! detector-directed sampling, range stratification or cone estimate), timed side by side on
//! the same threads.
//!
//! The plain estimate has rare, huge spikes; its per-photon variance from a short run is far too
//! small. It is therefore taken from a long run (≥ 10⁸ photons) written once with
//! `--write-plain FILE` and read with `--plain FILE`; only its time per photon comes from the
//! side-by-side run. FOM = 1/(rel_err² · t) = mean²/(σ₁² · t₁), σ₁² the variance of one photon's
//! contribution and t₁ the time per photon.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;

use lidarsim::optics::OpticalAtmosphere;
use lidarsim::output::OutputSet;
use lidarsim::returns::Order;
use lidarsim::scene::Scene;
use lidarsim::transport::{self, McResult, TransportOptions};

use super::plot::{FONT, draw_legend, init_font};

/// `print!` that returns a closed stdout (`| head`) as an error instead of panicking.
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($t)*)?;
    }};
}

/// Fields of view of the scan [mrad, full angle].
pub const FOVS_MRAD: [f64; 5] = [0.5, 1.0, 2.0, 5.0, 10.0];
/// Depths into the cloud of the first and last gate starts [m].
const FIRST_DEPTH_M: f64 = 50.0;
const LAST_DEPTH_M: f64 = 290.0;
const CLOUD_BASE_M: f64 = 1000.0;

/// One (FOV, gate) cell: the multiple-scattering mean, the variance of one photon's contribution
/// and the time per photon.
#[derive(Debug, Clone, Copy)]
pub struct Cell {
    pub fov_mrad: f64,
    pub depth_m: f64,
    pub mean_j: f64,
    pub var_per_photon: f64,
    pub s_per_photon: f64,
}

impl Cell {
    /// 1/(rel_err² · t), independent of the number of photons.
    pub fn fom(&self) -> f64 {
        if self.var_per_photon > 0.0 && self.s_per_photon > 0.0 {
            self.mean_j * self.mean_j / (self.var_per_photon * self.s_per_photon)
        } else {
            0.0
        }
    }
}

/// The C.1 scene of the scan: five fields of view, orders 1 and 2+.
pub fn scene() -> anyhow::Result<Scene> {
    let mut s = super::bench::c1_scene()?;
    s.lidar.fov_full_angle_mrad = FOVS_MRAD.to_vec();
    Ok(s)
}

/// Gate indices of the scan in `scene`.
fn gates(scene: &Scene) -> Vec<(usize, f64)> {
    let mut out = Vec::new();
    let mut depth = FIRST_DEPTH_M;
    while depth <= LAST_DEPTH_M + 1e-9 {
        let g = ((CLOUD_BASE_M + depth - scene.gates.start_m) / scene.gates.width_m).round();
        out.push((g as usize, depth));
        depth += scene.gates.width_m;
    }
    out
}

/// The cells of a run.
pub fn cells(scene: &Scene, r: &McResult) -> Vec<Cell> {
    let n = r.photons as f64;
    let mut out = Vec::new();
    for (f, fov) in scene.lidar.fov_full_angle_mrad.iter().enumerate() {
        for (g, depth) in gates(scene) {
            let mean = r.returns.energy(0, f, g, Order::AtLeast(2)).unwrap_or(0.0);
            let se = r.returns.stderr(0, f, g, Order::AtLeast(2)).unwrap_or(0.0);
            out.push(Cell {
                fov_mrad: *fov,
                depth_m: depth,
                mean_j: mean,
                var_per_photon: se * se * n,
                s_per_photon: r.wall_s / n,
            });
        }
    }
    out
}

/// Transport options of the plain local estimate.
pub fn plain(opts: &mut TransportOptions) {
    opts.ddis_epsilon = 0.0;
    opts.range_stratification = 0.0;
    opts.alignment_splitting = 0.0;
    opts.roulette_alignment = 0.0;
    opts.cone_estimate = false;
    opts.crossing_estimate = false;
    opts.ddis_crossing = false;
}

/// Run `scene` `repeat` times with `configure`; the fastest run (least disturbed by other load).
pub fn fastest(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    threads: usize,
    repeat: usize,
    configure: impl Fn(&mut TransportOptions),
) -> anyhow::Result<McResult> {
    let mut best: Option<McResult> = None;
    for _ in 0..repeat.max(1) {
        let mut opts = TransportOptions::from_scene(scene);
        opts.threads = threads;
        configure(&mut opts);
        let r = transport::run(scene, atm, &opts)?;
        if best.as_ref().is_none_or(|b| r.wall_s < b.wall_s) {
            best = Some(r);
        }
    }
    best.context("at least one run")
}

const HEADER: &str =
    "fov_full_angle_mrad,depth_m,ms_energy_j,var_per_photon_j2,s_per_photon,photons";

/// Write the plain estimator's reference cells (from a long run of `photons`).
pub fn write_reference(path: &Path, cells: &[Cell], photons: u64) -> anyhow::Result<()> {
    let mut s = format!(
        "# plain local estimate of C.1, orders >= 2, {photons} photons (lidarsim {})\n{HEADER}\n",
        env!("CARGO_PKG_VERSION")
    );
    for c in cells {
        writeln!(
            s,
            "{},{},{:e},{:e},{:e},{photons}",
            c.fov_mrad, c.depth_m, c.mean_j, c.var_per_photon, c.s_per_photon
        )?;
    }
    let mut files = OutputSet::new();
    files.write(path, s)?;
    files.commit()?;
    Ok(())
}

/// Read a reference written by [`write_reference`]: its cells and photon count. Every refusal
/// names the file, the line and the column.
pub fn read_reference(path: &Path) -> anyhow::Result<(Vec<Cell>, u64)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    let columns: Vec<&str> = HEADER.split(',').collect();
    let mut out = Vec::new();
    let mut photons = 0;
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.starts_with("fov") || line.trim().is_empty() {
            continue;
        }
        let at = format!("{}:{}", path.display(), i + 1);
        let f: Vec<&str> = line.split(',').collect();
        anyhow::ensure!(
            f.len() == columns.len(),
            "{at}: {} fields, expected {} ({HEADER})",
            f.len(),
            columns.len()
        );
        let num = |j: usize| -> anyhow::Result<f64> {
            let v = f[j].trim();
            v.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("{at}: {} `{v}` is not a finite number", columns[j]))
        };
        // Photons ≥ 1 (a whole number), variances and energies ≥ 0, time per photon > 0: else a
        // figure of merit or a standard error would be infinite or NaN.
        let n = num(5)?;
        anyhow::ensure!(
            n >= 1.0 && n.fract() == 0.0 && n <= u64::MAX as f64,
            "{at}: {} = {n} must be a whole number ≥ 1",
            columns[5]
        );
        photons = n as u64;
        let cell = Cell {
            fov_mrad: num(0)?,
            depth_m: num(1)?,
            mean_j: num(2)?,
            var_per_photon: num(3)?,
            s_per_photon: num(4)?,
        };
        for (j, v) in [(2, cell.mean_j), (3, cell.var_per_photon)] {
            anyhow::ensure!(v >= 0.0, "{at}: {} = {v} must be ≥ 0", columns[j]);
        }
        anyhow::ensure!(
            cell.s_per_photon > 0.0,
            "{at}: {} = {} must be > 0",
            columns[4],
            cell.s_per_photon
        );
        out.push(cell);
    }
    anyhow::ensure!(!out.is_empty(), "{}: no cells", path.display());
    Ok((out, photons))
}

/// The scan: lidarsim's estimator and the plain one side by side; writes `fom_depth.csv` and
/// `fom_depth.png` into `out`.
pub fn run(
    out: &Path,
    photons: u64,
    threads: usize,
    repeat: usize,
    seed: u64,
    reference: Option<&PathBuf>,
    method: impl Fn(&mut TransportOptions),
) -> anyhow::Result<()> {
    let mut scene = scene()?;
    scene.simulation.photons = photons;
    scene.simulation.seed = seed;
    // The reference is read, and checked to hold every cell of the scan, before any work.
    let reference = match reference {
        Some(p) => {
            let (cells, photons) = read_reference(p)?;
            for (fov, (_, depth)) in FOVS_MRAD
                .iter()
                .flat_map(|f| gates(&scene).into_iter().map(move |g| (f, g)))
            {
                anyhow::ensure!(
                    cells
                        .iter()
                        .any(|c| c.fov_mrad == *fov && c.depth_m == depth),
                    "plain reference {} has no cell at {fov} mrad, {depth} m (write it with --write-plain)",
                    p.display()
                );
            }
            Some((cells, photons))
        }
        None => None,
    };
    let atm = OpticalAtmosphere::build(&scene)?;
    let ours = fastest(&scene, &atm, threads, repeat, method)?;
    let plain_run = fastest(&scene, &atm, threads, repeat, plain)?;
    let mine = cells(&scene, &ours);
    let short = cells(&scene, &plain_run);
    let (long, long_photons) = reference.unwrap_or_else(|| (short.clone(), plain_run.photons));

    let mut csv = format!(
        "# C.1 multiple scattering (orders >= 2): lidarsim {} photons in {:.2} s and the plain local \
         estimate {} photons in {:.2} s on {} thread(s); plain variance from {} photons\n\
         fov_full_angle_mrad,depth_m,ms_energy_j,rel_err,fom_per_s,plain_ms_energy_j,plain_fom_per_s,fom_ratio,z_vs_plain\n",
        ours.photons, ours.wall_s, plain_run.photons, plain_run.wall_s, ours.threads, long_photons
    );
    let mut rows = Vec::new();
    outln!(
        "C.1, orders ≥ 2: FOM ratio lidarsim / plain local estimate (plain variance from {long_photons} photons)"
    );
    out!("depth_m");
    for f in FOVS_MRAD {
        out!("  {f:>6} mrad");
    }
    outln!();
    // Over the cells where both estimates have a signal (the others print `—`).
    let mut worst = f64::INFINITY;
    let mut z2 = 0.0;
    let mut n_z = 0usize;
    for (i, c) in mine.iter().enumerate() {
        let p = long
            .iter()
            .find(|p| p.fov_mrad == c.fov_mrad && p.depth_m == c.depth_m)
            .with_context(|| {
                format!(
                    "plain reference has no cell at {} mrad, {} m",
                    c.fov_mrad, c.depth_m
                )
            })?;
        // The long run's variance with this run's time per photon.
        let p = Cell {
            s_per_photon: short[i].s_per_photon,
            ..*p
        };
        let ratio = c.fom() / p.fom();
        if ratio.is_finite() {
            worst = worst.min(ratio);
        }
        let rel = (c.var_per_photon / ours.photons as f64).sqrt() / c.mean_j;
        // The two means' difference in combined standard errors (the long run's with its own
        // number of photons): no bias shows as z of order 1.
        let z = (c.mean_j - p.mean_j)
            / (c.var_per_photon / ours.photons as f64 + p.var_per_photon / long_photons as f64)
                .sqrt();
        if z.is_finite() {
            z2 += z * z;
            n_z += 1;
        }
        // A cell without signal has no error, FOM or z: empty fields, never `NaN` or `inf`.
        let n = lidarsim::output::csv_number;
        writeln!(
            csv,
            "{},{},{:e},{:e},{:e},{:e},{:e},{:e},{:.3}",
            c.fov_mrad,
            c.depth_m,
            n(c.mean_j),
            n(rel),
            n(c.fom()),
            n(p.mean_j),
            n(p.fom()),
            n(ratio),
            n(z)
        )?;
        rows.push((*c, p, ratio));
    }
    let n_depth = gates(&scene).len();
    for d in 0..n_depth {
        out!("{:>7}", rows[d].0.depth_m);
        for f in 0..FOVS_MRAD.len() {
            let ratio = rows[f * n_depth + d].2;
            if ratio.is_finite() {
                out!("  {ratio:>11.1}");
            } else {
                out!("  {:>11}", "—");
            }
        }
        outln!();
    }
    let no_signal = rows.iter().filter(|r| !r.2.is_finite()).count();
    if no_signal > 0 {
        outln!("—: no signal in one of the estimates ({no_signal} cells; empty in fom_depth.csv)");
    }
    let least = if worst.is_finite() {
        format!("{worst:.1}")
    } else {
        "— (no cell with a signal in both)".to_string()
    };
    let rms_z = if n_z > 0 {
        format!("{:.2}", (z2 / n_z as f64).sqrt())
    } else {
        "—".to_string()
    };
    outln!(
        "least ratio {least}; means against the plain estimate's: rms z {rms_z} over {n_z} cells"
    );
    let mut files = OutputSet::new();
    files.write(out.join("fom_depth.csv"), csv)?;
    files.write_via(out.join("fom_depth.png"), |path| draw(path, &rows))?;
    files.commit()?;
    outln!("wrote {}", out.join("fom_depth.{csv,png}").display());
    Ok(())
}

/// FOM against depth, one colour per FOV: lidarsim solid, plain dashed (as points).
fn draw(path: &Path, rows: &[(Cell, Cell, f64)]) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    init_font();
    let root = BitMapBackend::new(path, (1000, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let foms = rows.iter().flat_map(|(a, b, _)| [a.fom(), b.fom()]);
    let (lo, hi) = foms
        .filter(|v| *v > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(l, h), v| (l.min(v), h.max(v)));
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "C.1 multiple scattering: figure of merit against depth (solid lidarsim, dashed plain)",
            (FONT, 20),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(40.0..300.0, (lo / 2.0..hi * 2.0).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("depth into the cloud [m] (gate start)")
        .y_desc("FOM = 1/(rel. error² · s)")
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .draw()?;
    for (i, fov) in FOVS_MRAD.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
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
        chart
            .draw_series(LineSeries::new(
                mine,
                ShapeStyle::from(&colour).stroke_width(2),
            ))?
            .label(format!("{fov} mrad"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
        chart.draw_series(DashedLineSeries::new(
            plain,
            6,
            4,
            ShapeStyle::from(&colour).stroke_width(1),
        ))?;
    }
    draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}

/// Spikes: `seeds` independent runs of `photons`; per (FOV, gate) the scatter of the runs'
/// multiple-scattering means against the standard error each run reports. Without spikes the
/// ratio sd(means)/rms(stderr) is 1 within about 1/√(2(K − 1)); rare large contributions make
/// it large (the batches of one run miss them, other runs catch them). Writes
/// `scatter.csv` into `out`.
pub fn scatter(
    out: &Path,
    photons: u64,
    threads: usize,
    seeds: u64,
    method: impl Fn(&mut TransportOptions),
) -> anyhow::Result<()> {
    anyhow::ensure!(seeds >= 3, "--seeds needs at least 3 runs");
    let mut scene = scene()?;
    scene.simulation.photons = photons;
    let atm = OpticalAtmosphere::build(&scene)?;
    let mut runs = Vec::new();
    for seed in 1..=seeds {
        scene.simulation.seed = 1000 + seed;
        runs.push(cells(&scene, &fastest(&scene, &atm, threads, 1, &method)?));
    }
    let k = seeds as f64;
    let mut csv = format!(
        "# C.1 orders >= 2: {seeds} runs of {photons} photons; ratio = sd of the run means / rms of their standard errors (1 ± {:.2} expected without spikes)\n\
         fov_full_angle_mrad,depth_m,mean_j,sd_of_means_j,rms_stderr_j,ratio\n",
        1.0 / (2.0 * (k - 1.0)).sqrt()
    );
    outln!("scatter of {seeds} runs' means / their standard errors (orders ≥ 2)");
    out!("depth_m");
    for f in FOVS_MRAD {
        out!("  {f:>6} mrad");
    }
    outln!();
    let n_cells = runs[0].len();
    let mut ratios = vec![0.0; n_cells];
    for (i, ratio) in ratios.iter_mut().enumerate() {
        let means: Vec<f64> = runs.iter().map(|r| r[i].mean_j).collect();
        let mean = means.iter().sum::<f64>() / k;
        let sd = (means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
        let rms_se = (runs
            .iter()
            .map(|r| r[i].var_per_photon / photons as f64)
            .sum::<f64>()
            / k)
            .sqrt();
        *ratio = sd / rms_se;
        let c = runs[0][i];
        let n = lidarsim::output::csv_number;
        writeln!(
            csv,
            "{},{},{:e},{:e},{:e},{:.3}",
            c.fov_mrad,
            c.depth_m,
            n(mean),
            n(sd),
            n(rms_se),
            n(*ratio)
        )?;
    }
    let n_depth = n_cells / FOVS_MRAD.len();
    for d in 0..n_depth {
        out!("{:>7}", runs[0][d].depth_m);
        for f in 0..FOVS_MRAD.len() {
            // A cell without signal in any run has no ratio: `—`, never NaN.
            let ratio = ratios[f * n_depth + d];
            if ratio.is_finite() {
                out!("  {ratio:>11.2}");
            } else {
                out!("  {:>11}", "—");
            }
        }
        outln!();
    }
    let mut files = OutputSet::new();
    files.write(out.join("scatter.csv"), csv)?;
    files.commit()?;
    Ok(())
}

/// Error against time: both estimators at `photons`/27, /9, /3 and `photons`; the relative
/// error of orders ≥ 2 at three depths for 1 and 10 mrad against the run's time, with the plain
/// estimator's expected error from the long reference (its short runs miss the spikes).
/// Writes `error_time.csv` and `error_time.png` into `out`.
pub fn ladder(
    out: &Path,
    photons: u64,
    threads: usize,
    reference: &Path,
    method: impl Fn(&mut TransportOptions),
) -> anyhow::Result<()> {
    let (long, _) = read_reference(reference)?;
    let mut scene = scene()?;
    let atm = OpticalAtmosphere::build(&scene)?;
    let picks = [
        (1.0, 100.0),
        (1.0, 200.0),
        (1.0, 290.0),
        (10.0, 100.0),
        (10.0, 200.0),
        (10.0, 290.0),
    ];
    let mut csv = String::from(
        "method,fov_full_angle_mrad,depth_m,photons,seconds,rel_err,plain_expected_rel_err\n",
    );
    // (label, fov, depth) → points (s, rel).
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for (name, plain_method) in [("lidarsim", false), ("plain", true)] {
        let mut pts: Vec<Vec<(f64, f64)>> = vec![Vec::new(); picks.len()];
        for div in [27u64, 9, 3, 1] {
            scene.simulation.photons = (photons / div).max(200);
            scene.simulation.seed = 20 + div;
            let r = fastest(&scene, &atm, threads, 1, |o| {
                if plain_method { plain(o) } else { method(o) }
            })?;
            let cs = cells(&scene, &r);
            for (j, (fov, depth)) in picks.iter().enumerate() {
                let Some(c) = cs
                    .iter()
                    .find(|c| c.fov_mrad == *fov && c.depth_m == *depth)
                else {
                    continue;
                };
                let rel = (c.var_per_photon / r.photons as f64).sqrt() / c.mean_j;
                let expected = long
                    .iter()
                    .find(|p| p.fov_mrad == *fov && p.depth_m == *depth)
                    .map_or(f64::NAN, |p| {
                        (p.var_per_photon / r.photons as f64).sqrt() / p.mean_j
                    });
                let n = lidarsim::output::csv_number;
                writeln!(
                    csv,
                    "{name},{fov},{depth},{},{:.4},{:e},{:e}",
                    r.photons,
                    r.wall_s,
                    n(rel),
                    n(expected)
                )?;
                // The plain estimator is drawn with its expected error (long reference).
                pts[j].push((r.wall_s, if plain_method { expected } else { rel }));
            }
        }
        for (j, (fov, depth)) in picks.iter().enumerate() {
            series.push((format!("{name} {fov} mrad {depth} m"), pts[j].clone()));
        }
    }
    let mut files = OutputSet::new();
    files.write(out.join("error_time.csv"), csv)?;
    files.write_via(out.join("error_time.png"), |path| {
        draw_ladder(path, &series)
    })?;
    files.commit()?;
    outln!("wrote {}", out.join("error_time.{csv,png}").display());
    Ok(())
}

/// Relative error against seconds, log-log: lidarsim solid, plain (expected) dashed.
fn draw_ladder(
    path: &Path,
    series: &[(String, Vec<(f64, f64)>)],
) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    init_font();
    let root = BitMapBackend::new(path, (1000, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let pts = series
        .iter()
        .flat_map(|s| s.1.iter())
        .filter(|(t, e)| *t > 0.0 && *e > 0.0 && e.is_finite());
    let (t0, t1, e0, e1) = pts.fold(
        (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64),
        |a, (t, e)| (a.0.min(*t), a.1.max(*t), a.2.min(*e), a.3.max(*e)),
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "C.1 orders ≥ 2: relative error against time (solid lidarsim, dashed plain, expected)",
            (FONT, 20),
        )
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
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .draw()?;
    let half = series.len() / 2;
    for (i, (label, pts)) in series.iter().enumerate() {
        let colour = Palette99::pick(i % half).to_rgba();
        let pts: Vec<(f64, f64)> = pts.iter().copied().filter(|(_, e)| e.is_finite()).collect();
        if i < half {
            chart
                .draw_series(LineSeries::new(
                    pts,
                    ShapeStyle::from(&colour).stroke_width(2),
                ))?
                .label(label.trim_start_matches("lidarsim ").to_string())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        } else {
            chart.draw_series(DashedLineSeries::new(
                pts,
                6,
                4,
                ShapeStyle::from(&colour).stroke_width(1),
            ))?;
        }
    }
    draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}
