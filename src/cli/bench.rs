//! `lidarsim bench`: speed and Monte Carlo efficiency of the transport on a fixed workload, or
//! (`--study N`) the speed of the seed paper's clear-sky ensemble study, or (`--scenes FILE…`)
//! what skipping saves on whole scene runs (`lidarsim::pipeline::compare_skip`).
//!
//! The study workload is `scenes/study_co2_ipda.toml` (compiled in) run by `lidarsim dial` over
//! N generated profiles per latitude class (3N in all), every one of its 10 on-lines against the
//! off-line, IPDA and DIAL, with the whole error budget, analytic lidar equation.
//!
//! The workload is the Bissonnette et al. (1995) case C.1 (`scenes/bissonnette_c1.toml`, compiled
//! in) with one 1 mrad field of view. The figure of merit is FOM = 1/(rel_err² · t) of the
//! multiple-scattering return (orders ≥ 2) in the gate starting 100 m into the cloud
//! (1100–1110 m), t the wall-clock time of the transport at the given thread count.

use std::io::Write;

use anyhow::Context;
use std::path::{Path, PathBuf};

use lidarsim::input::Bounds;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::output::write_file;
use lidarsim::returns::Order;
use lidarsim::scene::Scene;
use lidarsim::stats;
use lidarsim::transport::{self, TransportOptions};

const C1_SCENE: &str = include_str!("../../scenes/bissonnette_c1.toml");
const C1_TABLE_FILE: &str = r#"file = "../phase_functions/bissonnette_c1_1064nm.txt""#;
const C1_TABLE_BUILTIN: &str = r#"builtin = "bissonnette_c1_1064nm""#;

/// Arguments of `lidarsim bench`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Photon packets per run.
    #[arg(long, default_value_t = 1_000_000, allow_negative_numbers = true, value_parser = super::count(1, lidarsim::limits::MAX_PHOTONS))]
    pub photons: u64,
    /// Thread counts to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2", allow_negative_numbers = true, value_parser = super::threads())]
    pub threads: Vec<usize>,
    /// Runs per thread count; the fastest is reported (the least disturbed by other load).
    #[arg(long, default_value_t = 3, allow_negative_numbers = true, value_parser = super::count_usize(1, 1000))]
    pub repeat: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Independent batches the photons are split into (the standard errors, and so the figures
    /// of merit, are estimated from the scatter of the batch means: with B batches to about
    /// √(2/B), 14 % at the scenes' 100).
    #[arg(long, default_value_t = 100, allow_negative_numbers = true, value_parser = super::count_usize(2, lidarsim::limits::MAX_BATCHES))]
    pub batches: usize,
    /// Probability of detector-directed importance sampling (0: off).
    #[arg(long, default_value_t = lidarsim::transport::DDIS_EPSILON, allow_negative_numbers = true, value_parser = super::real(Bounds::below(0.0, 1.0)))]
    pub ddis_epsilon: f64,
    /// Probability of drawing the first collision uniformly in range (0: off).
    #[arg(long, default_value_t = lidarsim::transport::RANGE_STRATIFICATION, allow_negative_numbers = true, value_parser = super::real(Bounds::below(0.0, 1.0)))]
    pub range_stratification: f64,
    /// Alignment splitting's reference phase-function value (0: off; `docs/transport.md`).
    #[arg(long, default_value_t = lidarsim::transport::ALIGNMENT_SPLITTING, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 1e6)))]
    pub alignment_splitting: f64,
    /// Russian roulette's alignment importance: its reference phase-function value (0: roulette
    /// on the weight alone; `docs/transport.md` step 7).
    #[arg(long, default_value_t = lidarsim::transport::ROULETTE_ALIGNMENT, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 1e6)))]
    pub roulette_alignment: f64,
    /// Score orders ≥ 2 with the cone estimate (false: ordinary local estimates only).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub cone_estimate: bool,
    /// Score orders ≥ 2 in the wider fields of view with the crossing estimate (false: the
    /// walk's own local estimates there).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub crossing_estimate: bool,
    /// With the crossing estimate, also the DDIS crossing (false: off; `docs/transport.md`).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub ddis_crossing: bool,
    /// Write the figures as JSON here as well.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Instead of the transport: time the clear-sky ensemble study with N profiles per class.
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = super::count_usize(1, lidarsim::limits::MAX_ENSEMBLE_LEVELS))]
    pub study: Option<usize>,
    /// Instead: the figure of merit of C.1's multiple scattering at every gate 50–300 m into the
    /// cloud and FOV 0.5–10 mrad, against the plain local estimate; CSV and PNG into DIR
    /// (photons and the first thread count of `--threads`).
    #[arg(long, value_name = "DIR")]
    pub depth: Option<PathBuf>,
    /// With `--depth`: instead of the FOM, K independent runs of `--photons` and the scatter of
    /// their means against their standard errors (spikes), into DIR/scatter.csv.
    #[arg(long, value_name = "K", requires = "depth")]
    pub seeds: Option<u64>,
    /// With `--depth` and `--plain`: instead of the FOM, the relative error against time of
    /// both estimators at `--photons`/27, /9, /3 and `--photons` (DIR/error_time.{csv,png}).
    #[arg(long, requires = "plain")]
    pub ladder: bool,
    /// With `--depth`: the plain estimator's per-photon variance from a long run (a file written
    /// by `--write-plain`).
    #[arg(long, value_name = "FILE", requires = "depth")]
    pub plain: Option<PathBuf>,
    /// Instead: run the plain local estimate of C.1 with `--photons` (≥ 1e8 to catch its spikes)
    /// on the largest of `--threads` and write its per-photon variance per gate and FOV.
    #[arg(long, value_name = "FILE", conflicts_with = "depth")]
    pub write_plain: Option<PathBuf>,
    /// Instead of the transport: time each scene's whole run as the scene asks for it and with
    /// the Monte Carlo forced on, and the same for the scene without its particle layers.
    #[arg(long, value_name = "SCENE", num_args = 1.., conflicts_with = "study")]
    pub scenes: Vec<PathBuf>,
}

/// Photons of a forced Monte Carlo for a scene that asks for none (the default scene's count).
const FORCED_PHOTONS: u64 = 200_000;

/// What skipping saves on whole scene runs (module docs).
fn scenes_bench(args: &Args) -> anyhow::Result<()> {
    use lidarsim::pipeline::compare_skip;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "whole runs (`lidarsim run`, no figures), fastest of {}; forced = multiple_scattering \"always\" ({FORCED_PHOTONS} photons if the scene asks for none)",
        args.repeat
    )?;
    writeln!(
        out,
        "| scene | threads | Monte Carlo (auto) | optics s | auto s | forced s | forced transport s | saved s | why |"
    )?;
    writeln!(out, "|---|---|---|---|---|---|---|---|---|")?;
    let mut rows = Vec::new();
    for path in &args.scenes {
        let scene = Scene::read(path)?;
        let mut variants = vec![(path.display().to_string(), scene.clone())];
        if !scene.layers.is_empty() {
            let mut clear = scene.clone();
            clear.layers.clear();
            variants.push((format!("{} without its layers", path.display()), clear));
        }
        for (name, scene) in &variants {
            for &threads in &args.threads {
                let c = compare_skip(scene, FORCED_PHOTONS, threads, args.repeat)?;
                let saved = c.forced_s - c.auto_s;
                // Both run the Monte Carlo: their difference is only the noise of the machine.
                let saved_text = if c.decision.run {
                    "— (both run it)".to_string()
                } else {
                    format!("{saved:.3}")
                };
                writeln!(
                    out,
                    "| {name} | {threads} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {saved_text} | {} |",
                    if c.decision.run { "run" } else { "skipped" },
                    c.optics_s,
                    c.auto_s,
                    c.forced_s,
                    c.forced_transport_s,
                    c.decision.reason
                )?;
                rows.push(serde_json::json!({
                    "scene": name, "threads": threads, "monte_carlo_run": c.decision.run,
                    "reason": c.decision.reason, "optics_s": c.optics_s, "auto_s": c.auto_s,
                    "forced_s": c.forced_s, "forced_photons": c.forced_photons,
                    "forced_transport_s": c.forced_transport_s, "saved_s": saved,
                }));
            }
        }
    }
    if let Some(path) = &args.json {
        write_file(path, serde_json::to_string_pretty(&rows)?.as_bytes())?;
    }
    Ok(())
}

const STUDY_SCENE: &str = include_str!("../../scenes/study_co2_ipda.toml");

/// The ensemble study benchmark (module docs).
fn study_bench(n: usize, args: &Args) -> anyhow::Result<()> {
    use lidarsim::atmosphere::{LatitudeClass, ProfileSet, class_ensemble};
    use lidarsim::study::dial::{self, StudyOptions};
    use std::time::Instant;
    let scene = Scene::from_toml(
        Path::new("<embedded scenes/study_co2_ipda.toml>"),
        STUDY_SCENE,
    )?;
    let retrieval = scene
        .retrieval
        .as_ref()
        .context("study scene has a retrieval")?;
    let pairs: Vec<(usize, usize)> = (0..scene.lines.len())
        .filter(|&k| k != retrieval.off)
        .map(|k| (k, retrieval.off))
        .collect();
    // Every thread count runs the study `repeat` times: its size before the ensemble is drawn
    // (README, "Limits").
    let runs = (3 * n as u64)
        .saturating_mul(args.threads.len() as u64)
        .saturating_mul(args.repeat as u64);
    let work = lidarsim::pipeline::study_work(&scene, runs, 0)?;
    work.check()
        .map_err(|m| anyhow::anyhow!("--study {n} (× --threads, × --repeat): {m}"))?;
    work.warnings()
        .iter()
        .for_each(|w| lidarsim::limits::warn(w));
    let t = Instant::now();
    let mut set = ProfileSet::default();
    for (i, c) in LatitudeClass::ALL.iter().enumerate() {
        set.members.extend(
            class_ensemble(*c, n, args.seed.wrapping_add(i as u64))?
                .0
                .members,
        );
    }
    let generate_s = t.elapsed().as_secs_f64();
    let options = StudyOptions {
        pairs,
        seed: args.seed,
        ..StudyOptions::from_scene(&scene).context("study scene has a retrieval")?
    };
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "ensemble study: {} profiles (3 classes × {n}), {} on-lines × IPDA and {} DIAL cells, error budget of {} rows; ensemble generated in {generate_s:.2} s",
        set.len(),
        options.pairs.len(),
        retrieval.dial.map_or(0, |d| d.cells),
        lidarsim::study::dial::N_SOURCES
    )?;
    writeln!(
        out,
        "threads  wall_s  profiles/s  truth_optics_s  returns_s  references_s  retrievals_s  (thread-summed)"
    )?;
    let mut rows = Vec::new();
    for &threads in &args.threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?;
        let mut best: Option<dial::Timing> = None;
        for _ in 0..args.repeat {
            let r = pool.install(|| dial::run(&scene, &set, &options, &|| {}))?;
            let failed = r.outcomes.iter().filter(|o| o.records.is_err()).count();
            anyhow::ensure!(failed == 0, "{failed} profiles failed");
            if best.is_none_or(|b| r.timing.wall_s < b.wall_s) {
                best = Some(r.timing);
            }
        }
        let Some(t) = best else { continue };
        writeln!(
            out,
            "{:>7} {:>7.2} {:>11.1} {:>15.2} {:>10.2} {:>13.2} {:>13.2}",
            pool.current_num_threads(),
            t.wall_s,
            set.len() as f64 / t.wall_s,
            t.truth_optics_s,
            t.returns_s,
            t.references_s + t.mean_references_s,
            t.retrievals_s
        )?;
        rows.push(serde_json::json!({
            "threads": pool.current_num_threads(), "profiles": set.len(), "wall_s": t.wall_s,
            "generate_s": generate_s, "truth_optics_s": t.truth_optics_s, "returns_s": t.returns_s,
            "references_s": t.references_s + t.mean_references_s, "retrievals_s": t.retrievals_s,
        }));
    }
    if let Some(path) = &args.json {
        write_file(path, serde_json::to_string_pretty(&rows)?.as_bytes())?;
    }
    Ok(())
}

/// The C.1 scene with a single 1 mrad field of view, orders split into 1 and 2+.
pub fn c1_scene() -> anyhow::Result<Scene> {
    anyhow::ensure!(
        C1_SCENE.contains(C1_TABLE_FILE),
        "the C.1 scene no longer names its table"
    );
    let text = C1_SCENE.replace(C1_TABLE_FILE, C1_TABLE_BUILTIN);
    let mut scene = Scene::from_toml(Path::new("<embedded scenes/bissonnette_c1.toml>"), &text)?;
    scene.lidar.fov_full_angle_mrad = vec![1.0];
    scene.simulation.max_order = 1;
    Ok(scene)
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    // Before the work, which takes minutes.
    lidarsim::output::check_paths(&args.json.iter().collect::<Vec<_>>())?;
    if let Some(n) = args.study {
        return study_bench(n, &args);
    }
    let first_threads = args.threads.first().copied().unwrap_or(1);
    let method = |o: &mut TransportOptions| {
        o.batches = args.batches;
        o.ddis_epsilon = args.ddis_epsilon;
        o.range_stratification = args.range_stratification;
        o.alignment_splitting = args.alignment_splitting;
        o.roulette_alignment = args.roulette_alignment;
        o.cone_estimate = args.cone_estimate;
        o.crossing_estimate = args.crossing_estimate;
        o.ddis_crossing = args.ddis_crossing;
    };
    if let (Some(dir), Some(k)) = (&args.depth, args.seeds) {
        return super::bench_depth::scatter(dir, args.photons, first_threads, k, method);
    }
    if let (Some(dir), Some(plain), true) = (&args.depth, &args.plain, args.ladder) {
        return super::bench_depth::ladder(dir, args.photons, first_threads, plain, method);
    }
    if let Some(dir) = &args.depth {
        return super::bench_depth::run(
            dir,
            args.photons,
            first_threads,
            args.repeat,
            args.seed,
            args.plain.as_ref(),
            method,
        );
    }
    if let Some(path) = &args.write_plain {
        use super::bench_depth as d;
        let mut scene = d::scene()?;
        scene.simulation.photons = args.photons;
        scene.simulation.seed = args.seed;
        let atm = OpticalAtmosphere::build(&scene)?;
        let threads = args.threads.iter().copied().max().unwrap_or(0);
        let r = d::fastest(&scene, &atm, threads, 1, |o| {
            d::plain(o);
            o.batches = args.batches;
            o.progress = true;
        })?;
        d::write_reference(path, &d::cells(&scene, &r), r.photons)?;
        outln!(
            "plain local estimate, {} photons in {:.1} s on {} threads: wrote {}",
            r.photons,
            r.wall_s,
            r.threads,
            path.display()
        );
        return Ok(());
    }
    if !args.scenes.is_empty() {
        return scenes_bench(&args);
    }
    let mut scene = c1_scene()?;
    scene.simulation.photons = args.photons;
    scene.simulation.seed = args.seed;
    let atm = OpticalAtmosphere::build(&scene)?;
    let gate = scene
        .gates
        .count
        .min(((1100.0 - scene.gates.start_m) / scene.gates.width_m).round() as usize);

    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "Bissonnette C.1, 1064 nm, FOV 1 mrad, {} photons; FOM of the multiple-scattering return at {}–{} m",
        args.photons,
        scene.gates.start_m + gate as f64 * scene.gates.width_m,
        scene.gates.start_m + (gate + 1) as f64 * scene.gates.width_m
    )?;
    writeln!(
        out,
        "threads  wall_s   photons/s   events/s  events/s/thread   E_ms [J]      rel_err     FOM [1/s]"
    )?;
    let mut rows = Vec::new();
    for &threads in &args.threads {
        let mut best: Option<transport::McResult> = None;
        for _ in 0..args.repeat {
            let mut opts = TransportOptions::from_scene(&scene);
            opts.threads = threads;
            method(&mut opts);
            let r = transport::run(&scene, &atm, &opts)?;
            if best.as_ref().is_none_or(|b| r.wall_s < b.wall_s) {
                best = Some(r);
            }
        }
        let Some(r) = best else { continue };
        let ms = Order::AtLeast(2);
        let e = r.returns.energy(0, 0, gate, ms).unwrap_or(0.0);
        let se = r.returns.stderr(0, 0, gate, ms).unwrap_or(f64::NAN);
        let rel = stats::rel_err(e, se);
        let fom = stats::figure_of_merit(rel, r.wall_s);
        let pps = r.photons as f64 / r.wall_s;
        let eps = r.stats.collisions as f64 / r.wall_s;
        writeln!(
            out,
            "{:>7} {:>7.2} {:>11.3e} {:>10.3e} {:>16.3e} {:>10.4e} {:>11.3e} {:>11.3e}",
            r.threads,
            r.wall_s,
            pps,
            eps,
            eps / r.threads as f64,
            e,
            rel,
            fom
        )?;
        rows.push(serde_json::json!({
            "threads": r.threads, "wall_s": r.wall_s, "photons": r.photons,
            "photons_per_s": pps, "events_per_s": eps, "events_per_s_per_thread": eps / r.threads as f64,
            "multiple_scattering_j": e, "rel_err": rel, "fom_per_s": fom,
        }));
    }
    if let Some(path) = &args.json {
        write_file(path, serde_json::to_string_pretty(&rows)?.as_bytes())?;
    }
    Ok(())
}
