//! The products of `lidarsim run` (and of `lidarsim merge` of its shards, whose files must be
//! the same): `returns.csv`, `backscatter.csv`, `depolarisation.csv`, `signals.csv`,
//! `retrieval.csv`, `run.nc` and `summary.json` from a [`RunOutput`], and the report a run
//! prints.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::ProductError;
use crate::backscatter::{self, Backscatter};
use crate::instrument::signals;
use crate::output::{OutputError, OutputSet};
use crate::pipeline::RunOutput;
use crate::retrieval::{self, Method, Product, Quantity};
use crate::returns::{self, Order, Returns, Source};
use crate::scene::Scene;

/// Every file `run` may write into its directory.
pub const FILES: [&str; 13] = [
    "weighting.png",
    "returns.csv",
    "weighting.csv",
    "jacobians.csv",
    "backscatter.csv",
    "depolarisation.csv",
    "depolarisation.png",
    crate::netcdf::RUN_FILE,
    "signals.csv",
    "retrieval.csv",
    "returns.png",
    "dial.png",
    "summary.json",
];

/// Write the files of a run into `out_dir`, all together or none: its tables, `run.nc` when
/// `history` (the NetCDF `history` attribute: the time and the command line) is given, the
/// figures `figures` stages, and `summary.json`. An earlier run's files this one does not
/// rewrite go with the commit. Returns the files written, in order.
pub fn write(
    out_dir: &Path,
    scene: &Scene,
    run: &RunOutput,
    history: Option<&str>,
    figures: impl FnOnce(&mut OutputSet) -> Result<(), OutputError>,
) -> Result<Vec<PathBuf>, ProductError> {
    // Everything is computed; now write all files together or none (`crate::output`), and
    // an earlier run's files this one does not rewrite go with the commit.
    let mut files = OutputSet::new();
    files.replaces(out_dir, &FILES)?;
    let sets = returns_sets(run);
    files.write(out_dir.join("returns.csv"), returns_csv(run))?;
    files.write(out_dir.join("backscatter.csv"), backscatter_csv(scene, run))?;
    // Per line where the run has lines (as `returns.csv`), else per channel.
    if let Some(m) = &run.mc {
        let lines = scene.sampling.lines.len();
        match (&m.jacobians_combined, &m.jacobians) {
            (Some(j), _) => files.write(
                out_dir.join("jacobians.csv"),
                j.first_channels(lines).to_csv(),
            )?,
            (None, Some(j)) => files.write(out_dir.join("jacobians.csv"), j.to_csv())?,
            (None, None) => {}
        }
    }
    if let Some(s) = depolarisation_csv(run) {
        files.write(out_dir.join("depolarisation.csv"), s)?;
    }
    if let Some(s) = signals_csv(run) {
        files.write(out_dir.join("signals.csv"), s)?;
    }
    if !run.weighting.is_empty() {
        let mut s = String::from(crate::retrieval::products::WEIGHTING_HEADER);
        s.push('\n');
        for w in &run.weighting {
            s.push_str(&w.csv_row());
            s.push('\n');
        }
        files.write(out_dir.join("weighting.csv"), s)?;
    }
    if let Some(s) = retrieval_csv(run) {
        files.write(out_dir.join("retrieval.csv"), s)?;
    }
    if let Some(history) = history {
        let nc = netcdf_file(scene, run, &sets, history)?;
        files.write(out_dir.join(crate::netcdf::RUN_FILE), nc)?;
    }
    figures(&mut files)?;
    files.write(out_dir.join("summary.json"), summary_json(scene, run))?;
    Ok(files.commit()?)
}

/// The sets of returns of a run: each line's Monte Carlo mean, then the analytic one.
fn returns_sets(run: &RunOutput) -> Vec<&Returns> {
    run.mc_lines
        .iter()
        .map(|m| &m.mean)
        .chain([&run.analytic_lines.mean])
        .collect()
}

/// `returns.csv`: every set's total, then with polarised light its co and cross rows.
pub fn returns_csv(run: &RunOutput) -> String {
    returns::to_csv(&labelled_sets(run))
}

/// The sets of `returns.csv` with their `polarisation` labels, in its order.
fn labelled_sets(run: &RunOutput) -> Vec<(&Returns, &'static str)> {
    let sets = returns_sets(run);
    let mut labelled: Vec<(&Returns, &str)> = sets.iter().map(|r| (*r, "total")).collect();
    if let Some(p) = &run.polarised {
        let mc = p.mc.as_ref();
        for (part, label) in [(0, "co"), (1, "cross")] {
            if let Some((co, cross, _)) = mc {
                labelled.push((if part == 0 { co } else { cross }, label));
            }
            labelled.push((
                if part == 0 {
                    &p.analytic.0
                } else {
                    &p.analytic.1
                },
                label,
            ));
        }
    }
    labelled
}

/// The lidar constant C = E₀ η A_tel \[J m²\] of each channel of `returns` (line returns:
/// each line's own pulse energy; [`crate::backscatter`]): NaN for a name that is not one of
/// the scene's laser lines.
pub fn lidar_constants(scene: &Scene, returns: &Returns) -> Vec<f64> {
    let lidar = &scene.lidar;
    returns
        .channels
        .iter()
        .map(|name| {
            scene
                .sampling
                .lines
                .iter()
                .position(|l| l.name == *name)
                .and_then(|l| scene.laser.pulse_energy_j.get(l))
                .map_or(f64::NAN, |e0| {
                    backscatter::lidar_constant_j_m2(
                        *e0,
                        lidar.optical_efficiency,
                        lidar.telescope_area_m2(),
                    )
                })
        })
        .collect()
}

/// The attenuated backscatter and range-corrected signal of one set of line returns.
pub fn backscatter_of(scene: &Scene, returns: &Returns) -> Backscatter {
    Backscatter::of(returns, &scene.gates, &lidar_constants(scene, returns))
}

/// `backscatter.csv`: β′ and the range-corrected signal of every row of `returns.csv`, in
/// its order ([`crate::backscatter`]).
pub fn backscatter_csv(scene: &Scene, run: &RunOutput) -> String {
    let sets: Vec<(Backscatter, &str)> = labelled_sets(run)
        .into_iter()
        .map(|(r, label)| (backscatter_of(scene, r), label))
        .collect();
    let refs: Vec<(&Backscatter, &str)> = sets.iter().map(|(b, l)| (b, *l)).collect();
    backscatter::to_csv(&refs)
}

/// `depolarisation.csv`, with polarised light.
pub fn depolarisation_csv(run: &RunOutput) -> Option<String> {
    let p = run.polarised.as_ref()?;
    let mut s = String::from(returns::DEPOLARISATION_HEADER);
    s.push('\n');
    if let Some((co, cross, cov)) = &p.mc {
        returns::depolarisation_rows(&mut s, co, cross, Some(cov));
    }
    returns::depolarisation_rows(&mut s, &p.analytic.0, &p.analytic.1, None);
    Some(s)
}

/// `signals.csv`, with a receiver.
pub fn signals_csv(run: &RunOutput) -> Option<String> {
    if run.signals.is_empty() {
        return None;
    }
    let mut s = String::from(signals::CSV_HEADER);
    s.push('\n');
    for sig in &run.signals {
        sig.csv_rows(&mut s);
    }
    Some(s)
}

/// `retrieval.csv`, with a retrieval.
pub fn retrieval_csv(run: &RunOutput) -> Option<String> {
    if run.products.is_empty() {
        return None;
    }
    let mut s = String::from(retrieval::products::CSV_HEADER);
    s.push('\n');
    for p in &run.products {
        s.push_str(&p.csv_row());
        s.push('\n');
    }
    Some(s)
}

/// The report of a run after its files were `written`: the summary, the gas note and the
/// files' names.
pub fn report(
    out: &mut impl Write,
    scene: &Scene,
    run: &RunOutput,
    written: &[PathBuf],
) -> std::io::Result<()> {
    print_summary(out, scene, run)?;
    if let Some(note) = &run.atmosphere.gas_note {
        writeln!(out, "{note}")?;
    }
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    writeln!(out, "wrote {}", names.join(", "))?;
    Ok(())
}

fn print_summary(out: &mut impl Write, scene: &Scene, run: &RunOutput) -> std::io::Result<()> {
    let name = if scene.description.is_empty() {
        scene.path.display().to_string()
    } else {
        scene.description.clone()
    };
    writeln!(out, "scene: {name}")?;
    if let Some(a) = &scene.atmosphere
        && let Some(ppm) = a.co2_ppm
    {
        writeln!(out, "atmosphere: {}", a.co2_scaling.describe(ppm))?;
    }
    for w in &run.warnings {
        writeln!(out, "warning: {w}")?;
    }
    writeln!(out, "{}", run.monte_carlo.reason)?;
    if scene.lidar.polarisation != crate::scene::Polarisation::None {
        // Once: which layers' scalar phase functions stand in for scattering matrices.
        let stand_ins: Vec<&str> = scene
            .layers
            .iter()
            .filter(|l| l.uses_stand_in())
            .map(|l| l.name.as_str())
            .collect();
        writeln!(
            out,
            "polarisation: {} source, co- and cross-polarised returns in returns.csv and depolarisation.csv{}",
            scene.lidar.polarisation.name(),
            if stand_ins.is_empty() {
                String::new()
            } else {
                format!(
                    "; layers {} scatter through a scalar phase function taken as non-depolarising (F22 = F33 = F44 = F11, F12 = F34 = 0)",
                    stand_ins.join(", ")
                )
            }
        )?;
    }
    let analytic = &run.analytic_lines.mean;
    match (&run.mc, &run.mc_lines) {
        (Some(mc), Some(lines)) => {
            writeln!(
                out,
                "transport: {} photons, {} scattering events in {:.2} s on {} threads ({:.2} M events/s), {} channels for {} lines",
                mc.photons,
                mc.stats.collisions,
                mc.wall_s,
                mc.threads,
                mc.stats.collisions as f64 / mc.wall_s.max(1e-9) * 1e-6,
                scene.channels.len(),
                scene.lines.len()
            )?;
            print_returns(out, &lines.mean, analytic)?;
        }
        _ => {
            for (k, ch) in analytic.channels.iter().enumerate() {
                for (f, fov) in analytic.fov_full_angle_mrad.iter().enumerate() {
                    let an: f64 = (0..analytic.range_m.len())
                        .map(|g| analytic.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0))
                        .sum();
                    writeln!(
                        out,
                        "  channel {ch}, FOV {fov} mrad: all gates {} J",
                        sci(an, 4)
                    )?;
                }
            }
        }
    }
    if let Some(r) = &run.retrieval {
        print_retrieval(out, r, &run.products)?;
    }
    Ok(())
}

fn print_returns(out: &mut impl Write, r: &Returns, analytic: &Returns) -> std::io::Result<()> {
    for (k, ch) in r.channels.iter().enumerate() {
        for (f, fov) in r.fov_full_angle_mrad.iter().enumerate() {
            let (mut total, mut single, mut an) = (0.0, 0.0, 0.0);
            let mut single_err = Vec::with_capacity(r.range_m.len());
            for g in 0..r.range_m.len() {
                total += r.energy(k, f, g, Order::Total).unwrap_or(0.0);
                single += r.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0);
                single_err.push(r.stderr(k, f, g, Order::Exactly(1)).unwrap_or(0.0));
                an += analytic.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0);
            }
            // Gates are not independent; this root sum of variances is only a rough guide.
            let single_se = root_sum_square(&single_err);
            let share = if total > 0.0 {
                100.0 * single / total
            } else {
                0.0
            };
            writeln!(
                out,
                "  channel {ch}, FOV {fov} mrad: all gates {} J, single scattering {} % \
                 (MC {} ± {} J, analytic {} J)",
                sci(total, 4),
                fixed(share, 1),
                sci(single, 4),
                sci(single_se, 1),
                sci(an, 4)
            )?;
        }
    }
    Ok(())
}

/// `v` as `{:.digits$e}`, or `n/a` where it is not a finite number: the summary never prints
/// `NaN` or `inf` (a sum of huge energies can overflow though each is finite).
fn sci(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$e}")
    } else {
        "n/a".into()
    }
}

/// `v` as `{:.digits$}` (with its sign when `signed`), or `n/a` where it is not finite.
fn fixed_with(v: f64, digits: usize, signed: bool) -> String {
    match (v.is_finite(), signed) {
        (false, _) => "n/a".into(),
        (true, true) => format!("{v:+.digits$}"),
        (true, false) => format!("{v:.digits$}"),
    }
}

fn fixed(v: f64, digits: usize) -> String {
    fixed_with(v, digits, false)
}

/// √(Σ xᵢ²), scaled by the largest |xᵢ| so that the squares of finite values cannot overflow;
/// not finite only if some xᵢ is not.
fn root_sum_square(x: &[f64]) -> f64 {
    let m = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if m == 0.0 || !m.is_finite() {
        return if x.iter().all(|v| v.is_finite()) {
            m
        } else {
            f64::NAN
        };
    }
    m * x.iter().map(|v| (v / m).powi(2)).sum::<f64>().sqrt()
}

fn source_label(p: &Product) -> &'static str {
    match (p.source, p.order) {
        (Source::Analytic, _) => "analytic single scattering",
        (Source::MonteCarlo, Order::Exactly(1)) => "MC single scattering",
        _ => "MC all orders",
    }
}

fn print_retrieval(
    out: &mut impl Write,
    r: &retrieval::Retrieval,
    products: &[Product],
) -> std::io::Result<()> {
    let c = &r.config;
    writeln!(
        out,
        "retrieval of {} from {}: reference state = the scene's own profile; averaging {}; {} noisy realisations",
        c.gas, r.pair, c.averaging_label, c.realisations
    )?;
    let ipda: Vec<&Product> = products
        .iter()
        .filter(|p| p.method == Method::Ipda)
        .collect();
    if let (Some(first), Some(t)) = (ipda.first(), &c.target) {
        let what = match &t.kind {
            retrieval::TargetKind::Surface => "the surface".to_string(),
            retrieval::TargetKind::Layer { name, .. } => format!("the top of `{name}`"),
        };
        writeln!(
            out,
            "  IPDA to {what} at {:.0} m: truth X{} = {} ppm (dry-air column {:.0}–{:.0} m)",
            t.range_m,
            c.gas,
            fixed(first.truth, 4),
            first.altitude_m.0,
            first.altitude_m.1
        )?;
        for p in &ipda {
            writeln!(
                out,
                "    FOV {} mrad, {}: retrieved {} ppm, bias {} ppm (MC ± {}, {} if on/off were traced apart); random error {} ppm per shot pair (simulated {}), {} ppm averaged (simulated {})",
                p.fov_full_angle_mrad,
                source_label(p),
                fixed(p.retrieved, 4),
                fixed_with(p.bias(), 4, true),
                sci(p.mc_stderr, 1),
                sci(p.mc_stderr_independent, 1),
                fixed(p.random_error_per_shot_pair, 3),
                fixed(p.simulated_error_per_shot_pair, 3),
                fixed(p.random_error_averaged, 4),
                fixed(p.simulated_error_averaged, 4)
            )?;
        }
    }
    let dial: Vec<&Product> = products
        .iter()
        .filter(|p| p.method == Method::Dial && p.quantity == Quantity::MixingRatio)
        .collect();
    if let Some(d) = &c.dial {
        writeln!(
            out,
            "  DIAL: {} cells of {} m (mixing ratio per cell; all cells in retrieval.csv)",
            d.cells, d.cell_m
        )?;
        let mut keys: Vec<(Source, Order, f64)> = Vec::new();
        for p in &dial {
            if !keys.contains(&(p.source, p.order, p.fov_full_angle_mrad)) {
                keys.push((p.source, p.order, p.fov_full_angle_mrad));
            }
        }
        for (s, o, f) in keys {
            let set: Vec<&&Product> = dial
                .iter()
                .filter(|p| p.source == s && p.order == o && p.fov_full_angle_mrad == f)
                .collect();
            let rms_bias =
                (set.iter().map(|p| p.bias().powi(2)).sum::<f64>() / set.len() as f64).sqrt();
            let mut errs: Vec<f64> = set.iter().map(|p| p.random_error_averaged).collect();
            errs.sort_by(f64::total_cmp);
            writeln!(
                out,
                "    FOV {f} mrad, {}: rms bias {} ppm; random error averaged {}–{} ppm (median {})",
                source_label(set[0]),
                fixed(rms_bias, 4),
                fixed(errs[0], 3),
                fixed(errs[errs.len() - 1], 3),
                fixed(errs[errs.len() / 2], 3)
            )?;
        }
    }
    Ok(())
}

/// The bytes of `run.nc` ([`crate::netcdf`]): the numbers of the CSV files, the scene's text
/// and `history` (the time and the command line).
pub fn netcdf_file(
    scene: &Scene,
    run: &RunOutput,
    returns: &[&Returns],
    history: &str,
) -> Result<Vec<u8>, crate::netcdf::NetcdfError> {
    dataset_of(scene, run, returns, history)?.encode()
}

/// What `run.nc` holds ([`crate::netcdf::run_dataset`]), before it is written: the Python
/// package's `lidarsim.run` returns it as an `xarray.Dataset`. `history` is the CF `history`
/// attribute (when and by what the run was made).
pub fn dataset(
    scene: &Scene,
    run: &RunOutput,
    history: &str,
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    dataset_of(scene, run, &returns_sets(run), history)
}

fn dataset_of(
    scene: &Scene,
    run: &RunOutput,
    returns: &[&Returns],
    history: &str,
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    use crate::netcdf;
    let scene_text = scene.text().to_string();
    let title = if scene.description.is_empty() {
        scene.path.display().to_string()
    } else {
        scene.description.clone()
    };
    let attributes = netcdf::RunAttributes {
        title: format!("lidarsim run: {title}"),
        history: history.to_string(),
        scene_file: scene.path.display().to_string(),
        scene_text,
        seed: scene.simulation.seed,
        photons: run.mc.as_ref().map_or(0, |m| m.photons),
        batches: scene.simulation.batches as u64,
    };
    let mut polarised = Vec::new();
    if let Some(p) = &run.polarised {
        if let Some((co, cross, cov)) = &p.mc {
            polarised.push(netcdf::PolarisedSet {
                co,
                cross,
                cov_j2: Some(cov),
            });
        }
        polarised.push(netcdf::PolarisedSet {
            co: &p.analytic.0,
            cross: &p.analytic.1,
            cov_j2: None,
        });
    }
    // The lines are the channels of every set (one grid, `netcdf::Grid`).
    let constants = returns.first().map(|r| lidar_constants(scene, r));
    netcdf::run_dataset(&netcdf::RunFile {
        returns,
        lidar_constant_j_m2: constants.as_deref(),
        gates: &scene.gates,
        lidar_altitude_m: scene.lidar.altitude_m,
        mu: scene.lidar.zenith_angle_deg.to_radians().cos(),
        lines: &scene.sampling.lines,
        polarised: &polarised,
        signals: &run.signals,
        products: &run.products,
        gas: run.retrieval.as_ref().map(|r| r.config.gas.as_str()),
        // Those of `jacobians.csv` (`write`): per line.
        jacobians: run
            .mc
            .as_ref()
            .and_then(|m| m.jacobians_combined.as_ref().or(m.jacobians.as_ref())),
        attributes: &attributes,
    })
}

/// `summary.json`: the scene, the Monte Carlo's decision and counters, the IPDA products.
pub fn summary_json(scene: &Scene, run: &RunOutput) -> String {
    let mut json = serde_json::json!({
        "scene": scene.path.display().to_string(),
        "description": scene.description,
        "channels": scene.channels.iter().map(|c| serde_json::json!({
            "name": c.name, "wavenumber_cm1": c.wavenumber_cm1,
        })).collect::<Vec<_>>(),
        "photons": run.mc.as_ref().map_or(0, |m| m.photons),
        "monte_carlo": {
            "run": run.monte_carlo.run,
            "multiple_scattering": run.monte_carlo.mode.label(),
            "reason": run.monte_carlo.reason,
        },
    });
    // Only where computed: summary.json holds no nulls.
    if let Some(a) = &scene.atmosphere
        && let Some(ppm) = a.co2_ppm
    {
        json["atmosphere"] = serde_json::json!({
            "co2_ppm": ppm,
            "co2_scaling": a.co2_scaling.name(),
        });
    }
    if !run.warnings.is_empty() {
        json["warnings"] = run.warnings.clone().into();
    }
    if let Some((bound, fov)) = run.monte_carlo.bound {
        json["monte_carlo"]["multiple_scattering_bound"] = bound.into();
        json["monte_carlo"]["multiple_scattering_bound_fov_full_angle_mrad"] = fov.into();
    }
    if let Some(mc) = &run.mc {
        let s = &mc.stats;
        json["batches"] = scene.simulation.batches.into();
        json["seed"] = scene.simulation.seed.into();
        json["threads"] = mc.threads.into();
        json["wall_s"] = mc.wall_s.into();
        json["counters"] = serde_json::json!({
            "collisions": s.collisions,
            "surface_reflections": s.surface_reflections,
            "local_estimates": s.local_estimates,
            "roulette_kills": s.roulette_kills,
            "cut": s.cut,
            "escaped": s.escaped,
            "zero_weight": s.zero_weight,
        });
    }
    if let Some(r) = &run.retrieval {
        json["retrieval"] = serde_json::json!({
            "gas": r.config.gas,
            "channel_pair": r.pair,
            "shots_averaged": r.config.averaging_shots,
            "averaging": r.config.averaging_label,
            "ipda": run.products.iter().filter(|p| p.method == Method::Ipda).map(|p| serde_json::json!({
                "source": p.source.label(),
                "order": p.order.label(),
                "fov_full_angle_mrad": p.fov_full_angle_mrad,
                "truth_ppm": p.truth,
                "retrieved_ppm": p.retrieved,
                "bias_ppm": p.bias(),
                "mc_stderr_ppm": p.mc_stderr,
                "random_error_per_shot_pair_ppm": p.random_error_per_shot_pair,
                "random_error_averaged_ppm": p.random_error_averaged,
            })).collect::<Vec<_>>(),
        });
    }
    serde_json::to_string_pretty(&json).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The summary's numbers: never `NaN` or `inf`; a root sum of squares of finite errors is
    /// finite even where the squares overflow (√2·1e200 from two errors of 1e200, whose squares
    /// do), and exact where they do not (3, 4 → 5).
    #[test]
    fn summary_numbers_are_finite_or_na() {
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(sci(v, 4), "n/a");
            assert_eq!(fixed(v, 1), "n/a");
            assert_eq!(fixed_with(v, 4, true), "n/a");
        }
        assert_eq!(sci(6.0e-2, 4), "6.0000e-2");
        assert_eq!(fixed_with(0.25, 2, true), "+0.25");
        assert_eq!(root_sum_square(&[3.0, 4.0]), 5.0);
        assert_eq!(root_sum_square(&[]), 0.0);
        let r = root_sum_square(&[1e200, 1e200]);
        assert!((r / (2f64.sqrt() * 1e200) - 1.0).abs() < 1e-15, "{r}");
        assert!(root_sum_square(&[1.0, f64::NAN]).is_nan());
        assert_eq!(sci(root_sum_square(&[f64::MAX, f64::MAX]), 1), "n/a");
    }
}
