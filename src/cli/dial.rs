//! `lidarsim dial [SCENE] (--profiles SET | --ensemble N) [--class C] [--on NAMES] --out DIR`:
//! a scene's retrievals over a profile ensemble with an error budget (`lidarsim::study::dial`).

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

use lidarsim::atmosphere::ProfileSet;
use lidarsim::input::Bounds;
use lidarsim::output::{self, OutputSet, csv_field, csv_number as num};
use lidarsim::scene::Scene;
use lidarsim::shard::{self, ShardSpec};
use lidarsim::study;
use lidarsim::study::dial::{
    self, BudgetSteps, N_SOURCES, ProfileOutcome, ProfileSource, Source, StudyOptions, StudyResult,
    Summary,
};
use lidarsim::study::shard::{self as study_shard, StudyInputs};

/// Arguments of `lidarsim dial`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file (TOML) with `[laser]`/`[receiver]`/`[retrieval]`; without it the embedded
    /// default scene.
    pub scene: Option<PathBuf>,
    /// Profile set (lidarsim format: `profiles generate` or `profiles convert`).
    #[arg(
        long,
        conflicts_with = "ensemble",
        required_unless_present = "ensemble"
    )]
    pub profiles: Option<PathBuf>,
    /// Instead of a set: N members per class drawn around the class's AFGL mean with the
    /// representative NWP forecast-error covariance (as `profiles generate --class C`; class i
    /// of tropical, mid, high takes seed S + i).
    #[arg(long, allow_negative_numbers = true, value_parser = super::count_usize(2, lidarsim::limits::MAX_ENSEMBLE_LEVELS))]
    pub ensemble: Option<usize>,
    /// Seed of a generated ensemble and of the instrument noise (default: the scene's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Latitude class to run: tropical, mid, high or all.
    #[arg(long, default_value = "all", value_parser = super::latitude_class)]
    pub class: String,
    /// On-lines (scene channel names, comma-separated), each paired with the retrieval's
    /// off-line; default the retrieval's own on-line.
    #[arg(long, value_delimiter = ',')]
    pub on: Vec<String>,
    /// Photons per profile; 0 (default for a scene without particle layers) uses the analytic
    /// lidar equation. Default with particle layers: the scene's `simulation.photons`.
    #[arg(long, allow_negative_numbers = true, value_parser = super::count(0, lidarsim::limits::MAX_PHOTONS))]
    pub photons: Option<u64>,
    /// Worker threads, 0 for all cores; at most the cores available.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = super::threads())]
    pub threads: usize,
    /// Budget: temperature knowledge error [K].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(-100.0, 100.0)))]
    pub budget_temperature_k: f64,
    /// Budget: humidity knowledge error [%]: the truth this much wetter than the retrieval
    /// assumes, in [-50, 1000] (the assumed humidity between 1/11 and 2 times the truth's:
    /// positive and finite, and a knowledge error rather than another atmosphere).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(-50.0, 1000.0)))]
    pub budget_humidity_percent: f64,
    /// Budget: surface-pressure knowledge error [hPa].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(-100.0, 100.0)))]
    pub budget_surface_pressure_hpa: f64,
    /// Budget: on-line frequency offset [MHz].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(-1e5, 1e5)))]
    pub budget_frequency_offset_mhz: f64,
    /// Budget: line-width error [%].
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = super::real(Bounds::above(-100.0, 1000.0)))]
    pub budget_linewidth_percent: f64,
    /// Output directory (created if needed).
    #[arg(long, default_value = "dial_study")]
    pub out: PathBuf,
    /// Do not draw the figures.
    #[arg(long)]
    pub no_plots: bool,
    /// Run only shard I of N (0 ≤ I < N) of the profiles and write their records raw to
    /// DIR/shard-I-of-N.lshard; `lidarsim merge` puts the N files together into this study's
    /// outputs.
    #[arg(long, value_name = "I/N", value_parser = clap::value_parser!(ShardSpec))]
    pub shard: Option<ShardSpec>,
    /// Do not write profiles.nc and summary.nc (the CF NetCDF files of profiles.csv and
    /// summary.csv).
    #[arg(long)]
    pub no_netcdf: bool,
}

/// Every file `dial` may write into its directory.
pub const FILES: [&str; 10] = [
    "profiles.csv",
    dial::PROFILES_NC,
    "summary.csv",
    dial::SUMMARY_NC,
    "budget.csv",
    "failed.csv",
    "ensemble.png",
    "errors.png",
    "budget.png",
    "summary.json",
];

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let out_files = match args.shard {
        Some(spec) => vec![args.out.join(spec.file_name())],
        None => FILES.map(|f| args.out.join(f)).to_vec(),
    };
    // Before the work: a study must not fail at its end on a name it could have refused now.
    output::check_paths(&out_files)?;
    let inputs = study_inputs(&args)?;
    let pool = super::study_pool(args.threads)?;
    if let Some(spec) = args.shard {
        let n = spec.batches(inputs.set.len()).len();
        return super::merge::study_shard(spec, n, "dial shard", &pool, |tick| {
            study_shard::run(&inputs, spec, &args.out, tick)
        });
    }
    let bar = super::progress::Progress::new(inputs.set.len(), "dial", "profiles");
    let result =
        pool.install(|| dial::run(&inputs.scene, &inputs.set, &inputs.options, &|| bar.tick()))?;
    bar.finish();
    write_outputs(&args.out, args.no_plots, !args.no_netcdf, &inputs, &result)
}

/// The scene, profiles and options of a study from the command line (a shard reads the scene
/// and the profile set by their absolute paths, so that shards started anywhere agree).
fn study_inputs(args: &Args) -> anyhow::Result<StudyInputs> {
    let scene = match (&args.scene, args.shard) {
        (Some(p), Some(_)) => shard::read_scene(Some(p))?,
        (Some(p), None) => Scene::read(p)?,
        (None, _) => Scene::default_scene()?,
    };
    let retrieval = scene
        .retrieval
        .as_ref()
        .context("the scene has no [retrieval]: nothing to study")?;
    let seed = args.seed.unwrap_or(scene.simulation.seed);
    let source = match (&args.profiles, args.ensemble) {
        (Some(p), _) if args.shard.is_some() => ProfileSource::Set(
            std::fs::canonicalize(p).with_context(|| format!("cannot read {}", p.display()))?,
        ),
        (Some(p), _) => ProfileSource::Set(p.clone()),
        (None, Some(n)) => ProfileSource::Ensemble(n),
        (None, None) => bail!("give --profiles SET or --ensemble N"),
    };
    let photons = args.photons.unwrap_or(if scene.layers.is_empty() {
        0
    } else {
        scene.simulation.photons
    });
    // The study's size, before its first profile and before an ensemble is drawn (N per class;
    // a set's size is known once read) (README, "Limits").
    let check_size = |profiles: usize| -> anyhow::Result<()> {
        let work = lidarsim::pipeline::study_work(&scene, profiles as u64, photons)?;
        work.check().map_err(anyhow::Error::msg)?;
        work.warnings()
            .iter()
            .for_each(|w| lidarsim::limits::warn(w));
        Ok(())
    };
    if let ProfileSource::Ensemble(n) = source {
        check_size(n.saturating_mul(if args.class == "all" { 3 } else { 1 }))?;
    }
    let set = dial::profile_set(&source, &args.class, seed)?;
    if let ProfileSource::Set(_) = source {
        check_size(set.len())?;
    }
    // Each step was checked by the argument parser (finite, signed where a sign means a
    // direction of the error).
    let steps = BudgetSteps {
        temperature_k: args.budget_temperature_k,
        humidity_fraction: args.budget_humidity_percent / 100.0,
        surface_pressure_hpa: args.budget_surface_pressure_hpa,
        frequency_offset_mhz: args.budget_frequency_offset_mhz,
        linewidth_fraction: args.budget_linewidth_percent / 100.0,
    };
    let line = |name: &str| -> anyhow::Result<usize> {
        scene
            .lines
            .iter()
            .position(|c| c.name == name)
            .with_context(|| {
                let names: Vec<&str> = scene.lines.iter().map(|c| c.name.as_str()).collect();
                format!(
                    "--on {name}: the scene has no line `{name}` (lines: {})",
                    names.join(", ")
                )
            })
    };
    let pairs = if args.on.is_empty() {
        vec![(retrieval.on, retrieval.off)]
    } else {
        let mut p = Vec::new();
        for name in &args.on {
            let on = line(name)?;
            if on == retrieval.off {
                bail!("--on {name} is the retrieval's off-line");
            }
            p.push((on, retrieval.off));
        }
        p
    };
    let options = StudyOptions {
        photons,
        seed,
        pairs,
        steps,
        fov: 0,
    };
    Ok(StudyInputs {
        scene,
        source,
        class: args.class.clone(),
        set,
        options,
    })
}

/// Write a study's files into `dir` (all or none) and print its report: `lidarsim dial`, and
/// `lidarsim merge` of dial shards. With `netcdf`, profiles.nc and summary.nc too (each when
/// its CSV has rows).
pub fn write_outputs(
    dir: &Path,
    no_plots: bool,
    netcdf: bool,
    inputs: &StudyInputs,
    result: &StudyResult,
) -> anyhow::Result<()> {
    let (scene, set, options) = (&inputs.scene, &inputs.set, &inputs.options);
    let failures = failure_groups(&result.outcomes);
    if !result.outcomes.is_empty() && result.outcomes.iter().all(|o| o.records.is_err()) {
        // Nothing to report: no file is written as if the study had succeeded.
        // The profiles and the scene they ran through: either may be the cause.
        let of = match &inputs.source {
            ProfileSource::Set(p) => p.display().to_string(),
            ProfileSource::Ensemble(_) => format!("the ensemble ({})", set.name),
        };
        let of = format!("{of} through the scene {}", scene.path.display());
        bail!("{}", study::all_failed_message(&of, &failures));
    }
    let summaries = dial::summarise(&result.outcomes);
    // An earlier study's files this one does not rewrite (figures, a NetCDF file) go with the
    // commit.
    let mut files = OutputSet::new();
    files.replaces(dir, &FILES)?;
    files.write(dir.join("profiles.csv"), profiles_csv(result))?;
    files.write(dir.join("summary.csv"), summary_csv(&summaries))?;
    if netcdf {
        let history = super::netcdf_history();
        // Not the scene's path: a merge has it absolute (summary.json holds it).
        let title = format!("lidarsim dial: retrievals over {}", set.name);
        if result
            .outcomes
            .iter()
            .any(|o| o.records.as_ref().is_ok_and(|r| !r.is_empty()))
        {
            let nc = dial::profiles_netcdf(&result.outcomes, &title, &history)?;
            files.write(dir.join(dial::PROFILES_NC), nc)?;
        }
        if !summaries.is_empty() {
            let nc = dial::summary_netcdf(&summaries, &title, &history)?;
            files.write(dir.join(dial::SUMMARY_NC), nc)?;
        }
    }
    files.write(
        dir.join("budget.csv"),
        budget_csv(&summaries, &options.steps, scene),
    )?;
    files.write(dir.join("failed.csv"), failed_csv(&result.outcomes))?;
    if !no_plots {
        super::study_figures::draw(&mut files, dir, set, result, &summaries)?;
    }
    files.write(
        dir.join("summary.json"),
        summary_json(scene, set, options, result),
    )?;
    let written = files.commit()?;

    let mut out = std::io::stdout().lock();
    print_report(
        &mut out,
        set,
        result,
        &summaries,
        &failures,
        options.photons,
    )?;
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    writeln!(out, "wrote {}", names.join(", "))?;
    Ok(())
}

/// Header of `profiles.csv`, one row per profile, line pair and retrieved quantity.
pub const PROFILES_HEADER: &str = "profile_id,class,pair,method,altitude_bottom_m,altitude_top_m,truth_ppm,retrieved_ppm,error_ppm,retrieved_noisy_ppm,error_noisy_ppm,retrieved_own_profile_ppm";

fn profiles_csv(result: &StudyResult) -> String {
    let mut s = String::from(PROFILES_HEADER);
    for src in Source::ALL {
        let _ = write!(s, ",{}", src.column());
    }
    s.push('\n');
    for o in &result.outcomes {
        let Ok(records) = &o.records else { continue };
        for r in records {
            let _ = write!(
                s,
                "{},{},{},{},{},{},{},{},{},{},{},{}",
                csv_field(&o.id),
                o.class,
                csv_field(&r.pair),
                r.method.label(),
                num(r.altitude_m.0),
                num(r.altitude_m.1),
                num(r.truth_ppm),
                num(r.retrieved_ppm),
                num(r.error_ppm()),
                num(r.retrieved_noisy_ppm),
                num(r.error_noisy_ppm()),
                num(r.retrieved_own_ppm)
            );
            for v in &r.budget_ppm {
                let _ = write!(s, ",{}", num(*v));
            }
            s.push('\n');
        }
    }
    s
}

/// Header of `summary.csv`, one row per class (and `all`), pair and retrieved quantity.
pub const SUMMARY_HEADER: &str = "class,pair,method,altitude_bottom_m,altitude_top_m,profiles,retrieved_profiles,noisy_profiles,truth_mean_ppm,bias_ppm,sd_ppm,noisy_bias_ppm,noisy_sd_ppm,random_error_rms_ppm,noise_ratio,total_budget_ppm";

fn summary_csv(summaries: &[Summary]) -> String {
    let mut s = String::from(SUMMARY_HEADER);
    s.push('\n');
    for m in summaries {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            csv_field(&m.class),
            csv_field(&m.pair),
            m.method.label(),
            num(m.altitude_m.0),
            num(m.altitude_m.1),
            m.profiles,
            m.retrieved_profiles,
            m.noisy_profiles,
            num(m.truth_mean_ppm),
            num(m.bias_ppm),
            num(m.sd_ppm),
            num(m.noisy_bias_ppm),
            num(m.noisy_sd_ppm),
            num(m.sources[0].rms_ppm),
            num(m.noise_ratio),
            num(m.total_ppm)
        );
    }
    s
}

/// Header of `budget.csv`, one row per class, pair, quantity and error source.
pub const BUDGET_HEADER: &str = "class,pair,method,altitude_bottom_m,altitude_top_m,source,perturbation,bias_ppm,sd_ppm,rms_ppm,share";

fn budget_csv(summaries: &[Summary], steps: &BudgetSteps, scene: &Scene) -> String {
    let mut s = String::from(BUDGET_HEADER);
    s.push('\n');
    for m in summaries {
        for (j, src) in Source::ALL.iter().enumerate() {
            let st = &m.sources[j];
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{},{},{},{}",
                csv_field(&m.class),
                csv_field(&m.pair),
                m.method.label(),
                num(m.altitude_m.0),
                num(m.altitude_m.1),
                src.label(),
                csv_field(&src.describe(steps, &scene.laser)),
                num(st.bias_ppm),
                num(st.sd_ppm),
                num(st.rms_ppm),
                num(st.share)
            );
        }
    }
    s
}

fn failed_csv(outcomes: &[ProfileOutcome]) -> String {
    let mut s = String::from("profile_id,class,reason\n");
    for o in outcomes {
        if let Err(e) = &o.records {
            let _ = writeln!(s, "{},{},{}", csv_field(&o.id), o.class, csv_field(e));
        }
    }
    s
}

fn summary_json(
    scene: &Scene,
    set: &ProfileSet,
    options: &StudyOptions,
    result: &StudyResult,
) -> String {
    let t = &result.timing;
    let failed = result
        .outcomes
        .iter()
        .filter(|o| o.records.is_err())
        .count();
    let v = serde_json::json!({
        "scene": scene.path.display().to_string(),
        "profile_set": set.name,
        "profiles": set.len(),
        "failed": failed,
        "photons_per_profile": options.photons,
        "seed": options.seed,
        "pairs": options.pairs.iter().map(|(a, b)| format!("{}/{}", scene.lines[*a].name, scene.lines[*b].name)).collect::<Vec<_>>(),
        "budget_steps": {
            "temperature_k": options.steps.temperature_k,
            "humidity_fraction": options.steps.humidity_fraction,
            "surface_pressure_hpa": options.steps.surface_pressure_hpa,
            "frequency_offset_mhz": options.steps.frequency_offset_mhz,
            "linewidth_fraction": options.steps.linewidth_fraction,
        },
        "timing_s": {
            "wall": t.wall_s,
            "mean_references": t.mean_references_s,
            "truth_optics_thread_sum": t.truth_optics_s,
            "returns_thread_sum": t.returns_s,
            "references_thread_sum": t.references_s,
            "retrievals_thread_sum": t.retrievals_s,
        },
        "lidarsim_version": env!("CARGO_PKG_VERSION"),
    });
    format!("{v:#}\n")
}

/// `x` with three decimals, `-` where it cannot be computed (a standard deviation of one
/// profile).
fn fixed(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.3}")
    } else {
        "-".into()
    }
}

/// The failed profiles of `outcomes` grouped by reason ([`study::group_failures`]).
fn failure_groups(outcomes: &[ProfileOutcome]) -> Vec<study::FailureGroup> {
    study::group_failures(outcomes.iter().filter_map(|o| match &o.records {
        Err(e) => Some((o.id.as_str(), e.as_str())),
        Ok(_) => None,
    }))
}

fn print_report(
    out: &mut impl Write,
    set: &ProfileSet,
    result: &StudyResult,
    summaries: &[Summary],
    failures: &[study::FailureGroup],
    photons: u64,
) -> std::io::Result<()> {
    let failed: usize = failures.iter().map(|g| g.count).sum();
    writeln!(
        out,
        "{} profiles of {} ({}), {failed} failed and left out of the statistics{}",
        set.len(),
        set.name,
        if photons > 0 {
            format!("Monte Carlo, {photons} photons per profile")
        } else {
            "analytic lidar equation".into()
        },
        if failed > 0 { " (failed.csv):" } else { "" }
    )?;
    // Each reason once, with its count and first profile: not a line per profile.
    for g in failures {
        writeln!(out, "  failed: {g}")?;
    }
    writeln!(
        out,
        "XCO2 (IPDA; class-mean virtual σ, own dry-air column), errors in ppm:"
    )?;
    writeln!(
        out,
        "  {:<9} {:<20} {:>5} {:>8} {:>8} {:>9} {:>9} {:>8} {:>7}  largest budget rows",
        "class", "pair", "n", "bias", "sd", "noisy sd", "random", "total", "ratio"
    )?;
    for m in summaries
        .iter()
        .filter(|m| m.method == lidarsim::retrieval::Method::Ipda)
    {
        let mut rows: Vec<(usize, f64)> = (0..N_SOURCES).map(|j| (j, m.sources[j].share)).collect();
        rows.sort_by(|a, b| b.1.total_cmp(&a.1));
        let top: Vec<String> = rows
            .iter()
            .take(3)
            .map(|(j, s)| format!("{} {:.0} %", Source::ALL[*j].label(), 100.0 * s))
            .collect();
        writeln!(
            out,
            "  {:<9} {:<20} {:>5} {:>8} {:>8} {:>9} {:>9} {:>8} {:>7}  {}",
            m.class,
            m.pair,
            m.profiles,
            fixed(m.bias_ppm),
            fixed(m.sd_ppm),
            fixed(m.noisy_sd_ppm),
            fixed(m.sources[0].rms_ppm),
            fixed(m.total_ppm),
            fixed(m.noise_ratio),
            top.join(", ")
        )?;
    }
    let t = &result.timing;
    writeln!(
        out,
        "time: {:.2} s wall; thread-summed: truth optics {:.2} s, returns {:.2} s, reference states {:.2} s (+{:.2} s class means), retrievals {:.2} s",
        t.wall_s,
        t.truth_optics_s,
        t.returns_s,
        t.references_s,
        t.mean_references_s,
        t.retrievals_s
    )?;
    Ok(())
}
