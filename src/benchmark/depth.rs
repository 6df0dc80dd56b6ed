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
use std::path::Path;

use super::{BenchError, ensure, fastest};
use crate::optics::OpticalAtmosphere;
use crate::output::{OutputSet, csv_number};
use crate::returns::Order;
use crate::scene::Scene;
use crate::scene::{Simulation, VarianceReduction};
use crate::transport::{McResult, Progress};

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
    /// Field of view \[mrad, full angle\].
    pub fov_mrad: f64,
    /// Depth of the gate's start into the cloud \[m\].
    pub depth_m: f64,
    /// Multiple-scattering energy \[J\].
    pub mean_j: f64,
    /// Variance of one photon's contribution \[J²\].
    pub var_per_photon: f64,
    /// Time per photon \[s\].
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
pub fn scene() -> Result<Scene, BenchError> {
    let mut s = super::c1_scene()?;
    s.lidar.fov_full_angle_mrad = FOVS_MRAD.to_vec();
    Ok(s)
}

/// Gate indices of the scan in `scene`.
pub fn gates(scene: &Scene) -> Vec<(usize, f64)> {
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

/// The settings of the plain local estimate: no variance reduction.
pub fn plain(sim: &mut Simulation) {
    sim.variance_reduction = VarianceReduction::none();
}

const HEADER: &str =
    "fov_full_angle_mrad,depth_m,ms_energy_j,var_per_photon_j2,s_per_photon,photons";

/// Write the plain estimator's reference cells (from a long run of `photons`).
pub fn write_reference(path: &Path, cells: &[Cell], photons: u64) -> Result<(), BenchError> {
    let mut s = format!(
        "# plain local estimate of C.1, orders >= 2, {photons} photons (lidarsim {})\n{HEADER}\n",
        env!("CARGO_PKG_VERSION")
    );
    for c in cells {
        let _ = writeln!(
            s,
            "{},{},{:e},{:e},{:e},{photons}",
            c.fov_mrad, c.depth_m, c.mean_j, c.var_per_photon, c.s_per_photon
        );
    }
    let mut files = OutputSet::new();
    files.write(path, s)?;
    files.commit()?;
    Ok(())
}

/// Read a reference written by [`write_reference`]: its cells and photon count. Every refusal
/// names the file, the line and the column.
pub fn read_reference(path: &Path) -> Result<(Vec<Cell>, u64), BenchError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| BenchError::Invalid(format!("{}: {e}", path.display())))?;
    let columns: Vec<&str> = HEADER.split(',').collect();
    let mut out = Vec::new();
    let mut photons = 0;
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.starts_with("fov") || line.trim().is_empty() {
            continue;
        }
        let at = format!("{}:{}", path.display(), i + 1);
        let f: Vec<&str> = line.split(',').collect();
        ensure!(
            f.len() == columns.len(),
            "{at}: {} fields, expected {} ({HEADER})",
            f.len(),
            columns.len()
        );
        let num = |j: usize| -> Result<f64, BenchError> {
            let v = f[j].trim();
            v.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    BenchError::Invalid(format!(
                        "{at}: {} `{v}` is not a finite number",
                        columns[j]
                    ))
                })
        };
        // Photons ≥ 1 (a whole number), variances and energies ≥ 0, time per photon > 0: else a
        // figure of merit or a standard error would be infinite or NaN.
        let n = num(5)?;
        ensure!(
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
            ensure!(v >= 0.0, "{at}: {} = {v} must be ≥ 0", columns[j]);
        }
        ensure!(
            cell.s_per_photon > 0.0,
            "{at}: {} = {} must be > 0",
            columns[4],
            cell.s_per_photon
        );
        out.push(cell);
    }
    ensure!(!out.is_empty(), "{}: no cells", path.display());
    Ok((out, photons))
}

/// The scan's result: every cell of lidarsim's estimator with the plain one's and their FOM
/// ratio, in FOV-major order, and `fom_depth.csv`.
pub struct Scan {
    /// (lidarsim's cell, the plain one's, FOM ratio) per FOV and depth.
    pub rows: Vec<(Cell, Cell, f64)>,
    /// Depths per FOV.
    pub n_depth: usize,
    /// Photons of the plain variance (the long reference's, or the side-by-side run's).
    pub long_photons: u64,
    /// The least finite FOM ratio (infinite if none).
    pub worst: f64,
    /// Root mean square of the finite z of the means against the plain estimate's, and their
    /// number.
    pub rms_z: Option<(f64, usize)>,
    /// `fom_depth.csv`.
    pub csv: String,
}

/// The scan: lidarsim's estimator (`method`) and the plain one side by side, `photons` on
/// `threads`, fastest of `repeat`; the plain variance from `reference` if given.
pub fn scan(
    photons: u64,
    threads: usize,
    repeat: usize,
    seed: u64,
    reference: Option<&Path>,
    method: impl Fn(&mut Simulation),
) -> Result<Scan, BenchError> {
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
                ensure!(
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
    // Over the cells where both estimates have a signal.
    let mut worst = f64::INFINITY;
    let mut z2 = 0.0;
    let mut n_z = 0usize;
    for (i, c) in mine.iter().enumerate() {
        let p = long
            .iter()
            .find(|p| p.fov_mrad == c.fov_mrad && p.depth_m == c.depth_m)
            .ok_or_else(|| {
                BenchError::Invalid(format!(
                    "plain reference has no cell at {} mrad, {} m",
                    c.fov_mrad, c.depth_m
                ))
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
        let n = csv_number;
        let _ = writeln!(
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
        );
        rows.push((*c, p, ratio));
    }
    Ok(Scan {
        rows,
        n_depth: gates(&scene).len(),
        long_photons,
        worst,
        rms_z: (n_z > 0).then(|| ((z2 / n_z as f64).sqrt(), n_z)),
        csv,
    })
}

/// The spikes' result: per (FOV, depth) cell, in FOV-major order, the ratio of the scatter of
/// the runs' means to their standard errors, and `scatter.csv`.
pub struct Scatter {
    /// The cells' depths (of the first FOV) \[m\].
    pub depths_m: Vec<f64>,
    /// The ratio per cell.
    pub ratios: Vec<f64>,
    /// `scatter.csv`.
    pub csv: String,
}

/// Spikes: `seeds` independent runs of `photons`; per (FOV, gate) the scatter of the runs'
/// multiple-scattering means against the standard error each run reports. Without spikes the
/// ratio sd(means)/rms(stderr) is 1 within about 1/√(2(K − 1)); rare large contributions make
/// it large (the batches of one run miss them, other runs catch them).
pub fn scatter(
    photons: u64,
    threads: usize,
    seeds: u64,
    method: impl Fn(&mut Simulation),
) -> Result<Scatter, BenchError> {
    ensure!(seeds >= 3, "--seeds needs at least 3 runs");
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
        let n = csv_number;
        let _ = writeln!(
            csv,
            "{},{},{:e},{:e},{:e},{:.3}",
            c.fov_mrad,
            c.depth_m,
            n(mean),
            n(sd),
            n(rms_se),
            n(*ratio)
        );
    }
    let n_depth = n_cells / FOVS_MRAD.len();
    Ok(Scatter {
        depths_m: runs[0][..n_depth].iter().map(|c| c.depth_m).collect(),
        ratios,
        csv,
    })
}

/// Error against time: both estimators at `photons`/27, /9, /3 and `photons`; the relative
/// error of orders ≥ 2 at three depths for 1 and 10 mrad against the run's time, with the plain
/// estimator's expected error from the long reference (its short runs miss the spikes).
/// Returns `error_time.csv` and the series (label, points (s, relative error)): lidarsim's
/// first, then the plain estimator's (drawn with its expected error).
#[allow(clippy::type_complexity)]
pub fn ladder(
    photons: u64,
    threads: usize,
    reference: &Path,
    method: impl Fn(&mut Simulation),
) -> Result<(String, Vec<(String, Vec<(f64, f64)>)>), BenchError> {
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
                let n = csv_number;
                let _ = writeln!(
                    csv,
                    "{name},{fov},{depth},{},{:.4},{:e},{:e}",
                    r.photons,
                    r.wall_s,
                    n(rel),
                    n(expected)
                );
                // The plain estimator is drawn with its expected error (long reference).
                pts[j].push((r.wall_s, if plain_method { expected } else { rel }));
            }
        }
        for (j, (fov, depth)) in picks.iter().enumerate() {
            series.push((format!("{name} {fov} mrad {depth} m"), pts[j].clone()));
        }
    }
    Ok((csv, series))
}

/// `--write-plain`: the plain local estimate of C.1 with `photons` on `threads` threads, in
/// `batches`, reporting its batches to `progress`; its cells written to `path` as the reference
/// of the scan.
pub fn write_plain(
    path: &Path,
    photons: u64,
    seed: u64,
    threads: usize,
    batches: usize,
    progress: Progress,
) -> Result<McResult, BenchError> {
    let mut scene = scene()?;
    scene.simulation.photons = photons;
    scene.simulation.seed = seed;
    let atm = OpticalAtmosphere::build(&scene)?;
    let r = super::fastest_with(
        &scene,
        &atm,
        threads,
        1,
        |o| {
            plain(o);
            o.batches = batches;
        },
        progress,
    )?;
    write_reference(path, &cells(&scene, &r), r.photons)?;
    Ok(r)
}
