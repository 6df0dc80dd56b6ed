//! `lidarsim bench`: speed and Monte Carlo efficiency of the transport on a fixed workload, or
//! (`--study N`) the speed of the reference study's clear-sky ensemble study (`--cloudy`: with a
//! cirrus in every profile, by Monte Carlo), or (`--scenes FILE…`)
//! what skipping saves on whole scene runs, or (`--depth DIR`) the figure of merit of C.1's
//! multiple scattering at every gate and field of view. The workloads and measurements are
//! [`lidarsim::benchmark`]'s; this prints them and draws.

use std::path::{Path, PathBuf};

use lidarsim::benchmark::{self, FORCED_PHOTONS, channels, depth};
use lidarsim::input::Bounds;
use lidarsim::output::{OutputSet, write_file};
use lidarsim::scene::{Simulation, VarianceReduction};

/// `print!` that returns a closed stdout (`| head`) as an error instead of panicking.
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($t)*)?;
    }};
}

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
    /// With `--study`: a cirrus (9–10 km, optical depth 0.3, Henyey-Greenstein g 0.75) in
    /// every profile, each truth of a profile by a Monte Carlo of `--study-photons`; the table
    /// adds the time in the transport.
    #[arg(long, requires = "study")]
    pub cloudy: bool,
    /// Photons per truth of `--cloudy`.
    #[arg(long, default_value_t = benchmark::CLOUDY_STUDY_PHOTONS, requires = "cloudy", allow_negative_numbers = true, value_parser = super::count(1, lidarsim::limits::MAX_PHOTONS))]
    pub study_photons: u64,
    /// Instead: the figure of merit of C.1's multiple scattering at every gate 50–300 m into the
    /// cloud and FOV 0.5–10 mrad, against the plain local estimate; CSV and PNG into DIR
    /// (photons and the first thread count of `--threads`).
    #[arg(long, value_name = "DIR")]
    pub depth: Option<PathBuf>,
    /// With `--depth`: instead of the FOM, K independent runs of `--photons` and the scatter of
    /// their means against their standard errors (spikes), into DIR/scatter.csv.
    #[arg(long, value_name = "K", requires = "depth", allow_negative_numbers = true, value_parser = super::count(0, u64::MAX))]
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
    /// Instead: the cost of a scattering event against the channel count, on the first of
    /// `--threads`: C.1's one-channel walk and the default scene at 2, 4 and 16 channels, each
    /// with `--photons`.
    #[arg(long, conflicts_with_all = ["study", "scenes", "depth", "write_plain"])]
    pub channels: bool,
}

/// What skipping saves on whole scene runs ([`lidarsim::pipeline::compare_skip`]).
fn scenes_bench(args: &Args) -> anyhow::Result<()> {
    outln!("{}", benchmark::scenes_header(args.repeat));
    let mut rows = Vec::new();
    for path in &args.scenes {
        for (name, scene) in &benchmark::scene_variants(path)? {
            for &threads in &args.threads {
                let c =
                    lidarsim::pipeline::compare_skip(scene, FORCED_PHOTONS, threads, args.repeat)?;
                let (line, json) = benchmark::scene_row(name, threads, &c);
                outln!("{line}");
                rows.push(json);
            }
        }
    }
    write_json(args, &rows)
}

/// The ensemble study benchmark ([`benchmark::StudyWorkload`]).
fn study_bench(n: usize, args: &Args) -> anyhow::Result<()> {
    let runs = (args.threads.len() as u64).saturating_mul(args.repeat as u64);
    let photons = if args.cloudy { args.study_photons } else { 0 };
    let w = benchmark::StudyWorkload::new(n, args.seed, runs, photons)?;
    outln!("{}", w.header(n));
    let mut rows = Vec::new();
    for &threads in &args.threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?;
        let Some(t) = w.measure(&pool, args.repeat)? else {
            continue;
        };
        let (line, json) = w.row(pool.current_num_threads(), &t);
        outln!("{line}");
        rows.push(json);
    }
    write_json(args, &rows)
}

/// The rows as JSON into `--json`, if given.
fn write_json(args: &Args, rows: &[serde_json::Value]) -> anyhow::Result<()> {
    if let Some(path) = &args.json {
        write_file(path, serde_json::to_string_pretty(rows)?.as_bytes())?;
    }
    Ok(())
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    // Before the work, which takes minutes.
    lidarsim::output::check_paths(&args.json.iter().collect::<Vec<_>>())?;
    if let Some(n) = args.study {
        return study_bench(n, &args);
    }
    let first_threads = args.threads.first().copied().unwrap_or(1);
    let method = |o: &mut Simulation| {
        o.batches = args.batches;
        o.variance_reduction = VarianceReduction {
            ddis_epsilon: args.ddis_epsilon,
            range_stratification: args.range_stratification,
            alignment_splitting: args.alignment_splitting,
            roulette_alignment: args.roulette_alignment,
            cone_estimate: args.cone_estimate,
            crossing_estimate: args.crossing_estimate,
            ddis_crossing: args.ddis_crossing,
        };
    };
    if let (Some(dir), Some(k)) = (&args.depth, args.seeds) {
        return scatter(dir, args.photons, first_threads, k, method);
    }
    if let (Some(dir), Some(plain), true) = (&args.depth, &args.plain, args.ladder) {
        let (csv, series) = depth::ladder(args.photons, first_threads, plain, method)?;
        let mut files = OutputSet::new();
        files.write(dir.join("error_time.csv"), csv)?;
        files.write_via(dir.join("error_time.png"), |path| {
            crate::figures::bench::error_time(path, &series)
        })?;
        files.commit()?;
        outln!("wrote {}", dir.join("error_time.{csv,png}").display());
        return Ok(());
    }
    if let Some(dir) = &args.depth {
        return depth_scan(dir, &args, first_threads, method);
    }
    if let Some(path) = &args.write_plain {
        let threads = args.threads.iter().copied().max().unwrap_or(0);
        let bar = super::progress::Progress::new(0, "transport", "batches");
        let r = depth::write_plain(
            path,
            args.photons,
            args.seed,
            threads,
            args.batches,
            &|done, total| bar.reach(done, total),
        )?;
        bar.finish();
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
    if args.channels {
        let w = channels::workloads(args.photons, args.seed)?;
        let rows = channels::measure(&w, first_threads, args.repeat, method)?;
        outln!("{}", channels::table(&rows, first_threads));
        return write_json(&args, &[channels::json(&rows, first_threads)]);
    }
    let w = benchmark::TransportWorkload::new(args.photons, args.seed)?;
    outln!("{}", w.header());
    let mut rows = Vec::new();
    for &threads in &args.threads {
        let r = w.measure(threads, args.repeat, method)?;
        outln!("{}", r.line());
        rows.push(r.json());
    }
    write_json(&args, &rows)
}

/// The depth scan ([`depth::scan`]): its table of FOM ratios, `fom_depth.csv` and
/// `fom_depth.png` into `dir`.
fn depth_scan(
    dir: &Path,
    args: &Args,
    threads: usize,
    method: impl Fn(&mut Simulation),
) -> anyhow::Result<()> {
    let s = depth::scan(
        args.photons,
        threads,
        args.repeat,
        args.seed,
        args.plain.as_deref(),
        method,
    )?;
    outln!(
        "C.1, orders ≥ 2: FOM ratio lidarsim / plain local estimate (plain variance from {} photons)",
        s.long_photons
    );
    let depths: Vec<f64> = s.rows[..s.n_depth].iter().map(|r| r.0.depth_m).collect();
    let ratios: Vec<f64> = s.rows.iter().map(|r| r.2).collect();
    print_table(&depths, &ratios, 1)?;
    let no_signal = s.rows.iter().filter(|r| !r.2.is_finite()).count();
    if no_signal > 0 {
        outln!("—: no signal in one of the estimates ({no_signal} cells; empty in fom_depth.csv)");
    }
    let least = if s.worst.is_finite() {
        format!("{:.1}", s.worst)
    } else {
        "— (no cell with a signal in both)".to_string()
    };
    let (rms_z, n_z) = match s.rms_z {
        Some((z, n)) => (format!("{z:.2}"), n),
        None => ("—".to_string(), 0),
    };
    outln!(
        "least ratio {least}; means against the plain estimate's: rms z {rms_z} over {n_z} cells"
    );
    let mut files = OutputSet::new();
    files.write(dir.join("fom_depth.csv"), s.csv)?;
    files.write_via(dir.join("fom_depth.png"), |path| {
        crate::figures::bench::fom_depth(path, &s.rows)
    })?;
    files.commit()?;
    outln!("wrote {}", dir.join("fom_depth.{csv,png}").display());
    Ok(())
}

/// The spikes ([`depth::scatter`]): their table and `scatter.csv` into `dir`.
fn scatter(
    dir: &Path,
    photons: u64,
    threads: usize,
    seeds: u64,
    method: impl Fn(&mut Simulation),
) -> anyhow::Result<()> {
    let s = depth::scatter(photons, threads, seeds, method)?;
    outln!("scatter of {seeds} runs' means / their standard errors (orders ≥ 2)");
    print_table(&s.depths_m, &s.ratios, 2)?;
    let mut files = OutputSet::new();
    files.write(dir.join("scatter.csv"), s.csv)?;
    files.commit()?;
    Ok(())
}

/// A table of `values` (FOV-major) by depth and FOV with `digits` decimals; `—` where a value
/// is not finite (a cell without signal), never NaN.
fn print_table(depths_m: &[f64], values: &[f64], digits: usize) -> anyhow::Result<()> {
    out!("depth_m");
    for f in depth::FOVS_MRAD {
        out!("  {f:>6} mrad");
    }
    outln!();
    let n_depth = depths_m.len();
    for (d, depth_m) in depths_m.iter().enumerate() {
        out!("{:>7}", depth_m);
        for f in 0..depth::FOVS_MRAD.len() {
            let v = values[f * n_depth + d];
            if v.is_finite() {
                out!("  {v:>11.digits$}");
            } else {
                out!("  {:>11}", "—");
            }
        }
        outln!();
    }
    Ok(())
}
