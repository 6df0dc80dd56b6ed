//! The products of `lidarsim dial` (and of `lidarsim merge` of its shards): `profiles.csv`,
//! `summary.csv`, `budget.csv`, `failed.csv`, `profiles.nc`, `summary.nc` and `summary.json`
//! from a study's results, and the report it prints.

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::ProductError;
use crate::atmosphere::ProfileSet;
use crate::output::{OutputError, OutputSet, csv_field, csv_number as num};
use crate::scene::Scene;
use crate::study::dial::{
    self, BudgetSteps, N_SOURCES, ProfileOutcome, ProfileSource, Source, StudyOptions, StudyResult,
    Summary,
};
use crate::study::shard::StudyInputs;
use crate::study::{self, FailurePolicy, FailureReport};

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

/// What a `dial` command asks for, before anything is read: the scene (or the embedded
/// default), the profiles (a set or a generated ensemble), the lines, the photons and the
/// budget's steps. [`Self::resolve`] makes the study's inputs.
#[derive(Debug, Clone)]
pub struct DialRequest {
    /// Scene file (`-`: standard input); the embedded default scene without one.
    pub scene: Option<PathBuf>,
    /// `--set KEY=VALUE` overrides of the scene's values.
    pub overrides: Vec<crate::scene::SceneOverride>,
    /// A profile set.
    pub profiles: Option<PathBuf>,
    /// Instead of a set: N generated members per class.
    pub ensemble: Option<usize>,
    /// Seed of the ensemble and the noise; the scene's without one.
    pub seed: Option<u64>,
    /// Latitude class: tropical, mid, high or all.
    pub class: String,
    /// On-lines by name, each paired with the retrieval's off-line; the retrieval's own
    /// on-line if empty.
    pub on: Vec<String>,
    /// Photons per profile; without: 0 (the analytic lidar equation) for a scene without
    /// particle layers, else the scene's.
    pub photons: Option<u64>,
    /// The budget's steps.
    pub steps: BudgetSteps,
    /// For a shard: the scene and the set are read by their absolute paths.
    pub shard: bool,
}

impl DialRequest {
    /// The scene, profiles and options of the study (a shard reads the scene and the profile
    /// set by their absolute paths, so that shards started anywhere agree). Refused before
    /// any work: a study beyond the limits (README, "Limits"), an unknown on-line.
    pub fn resolve(&self) -> Result<StudyInputs, ProductError> {
        let args = self;
        let scene = super::read_scene(args.scene.as_deref(), &args.overrides, args.shard)?;
        let source = match (&args.profiles, args.ensemble) {
            (Some(p), _) if args.shard => {
                ProfileSource::Set(std::fs::canonicalize(p).map_err(|e| {
                    ProductError::Request(format!("cannot read {}: {e}", p.display()))
                })?)
            }
            (Some(p), _) => ProfileSource::Set(p.clone()),
            (None, Some(n)) => ProfileSource::Ensemble(n),
            (None, None) => {
                return Err(ProductError::Request(
                    "give --profiles SET or --ensemble N".into(),
                ));
            }
        };
        self.resolve_with(scene, source)
    }

    /// [`Self::resolve`] with the scene and the profiles given (the Python package's; `scene`
    /// and `profiles` of the request are not read).
    pub fn resolve_with(
        &self,
        scene: Scene,
        source: ProfileSource,
    ) -> Result<StudyInputs, ProductError> {
        let args = self;
        args.steps.check().map_err(ProductError::Request)?;
        let retrieval = scene.retrieval.as_ref().ok_or_else(|| {
            ProductError::Request("the scene has no [retrieval]: nothing to study".into())
        })?;
        let seed = args.seed.unwrap_or(scene.simulation.seed);
        let photons = args.photons.unwrap_or(if scene.layers.is_empty() {
            0
        } else {
            scene.simulation.photons
        });
        // The study's size, before its first profile and before an ensemble is drawn (N per class;
        // a set's size is known once read) (README, "Limits").
        let check_size = |profiles: usize| -> Result<(), ProductError> {
            let work = crate::pipeline::study_work(&scene, profiles as u64, photons)?;
            work.check().map_err(ProductError::Request)?;
            work.warnings().iter().for_each(|w| crate::limits::warn(w));
            Ok(())
        };
        if let ProfileSource::Ensemble(n) = source {
            check_size(n.saturating_mul(if args.class == "all" { 3 } else { 1 }))?;
        }
        let set = dial::profile_set(&source, &args.class, seed)?;
        if !matches!(source, ProfileSource::Ensemble(_)) {
            check_size(set.len())?;
        }
        // Each step was checked by the argument parser (finite, signed where a sign means a
        // direction of the error).
        let steps = args.steps;
        let line = |name: &str| -> Result<usize, ProductError> {
            scene
                .lines
                .iter()
                .position(|c| c.name == name)
                .ok_or_else(|| {
                    let names: Vec<&str> = scene.lines.iter().map(|c| c.name.as_str()).collect();
                    ProductError::Request(format!(
                        "--on {name}: the scene has no line `{name}` (lines: {})",
                        names.join(", ")
                    ))
                })
        };
        let pairs = if args.on.is_empty() {
            vec![(retrieval.on, retrieval.off)]
        } else {
            let mut p = Vec::new();
            for name in &args.on {
                let on = line(name)?;
                if on == retrieval.off {
                    return Err(ProductError::Request(format!(
                        "--on {name} is the retrieval's off-line"
                    )));
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
}

/// The profiles of a study and the scene they run through, as its failures name them: either
/// may be the cause.
fn profiles_of(inputs: &StudyInputs) -> String {
    let of = match &inputs.source {
        ProfileSource::Set(p) => p.display().to_string(),
        ProfileSource::Ensemble(_) => format!("the ensemble ({})", inputs.set.name),
        ProfileSource::Given(given) => format!("the profiles given ({})", given.name),
    };
    format!("{of} through the scene {}", inputs.scene.path.display())
}

/// Before a study runs: under [`FailurePolicy::Strict`] refuse it when any profile cannot be
/// run at all ([`dial::unusable`], [`FailureReport::verdict_before_run`]), instead of after
/// the work of the others; nothing to check otherwise.
pub fn check_before_run(inputs: &StudyInputs, policy: FailurePolicy) -> Result<(), ProductError> {
    if policy == FailurePolicy::Tolerate {
        return Ok(());
    }
    dial::unusable(&inputs.scene, &inputs.set)
        .verdict_before_run(&profiles_of(inputs), policy)
        .map_err(ProductError::ProfilesFailed)
}

/// A study's results ready to be written and reported: its inputs, its results, the
/// statistics of its classes and its failures grouped by reason.
pub struct DialProducts<'a> {
    /// The scene, profiles and options the study ran with.
    pub inputs: &'a StudyInputs,
    /// Its outcome per profile and its timing.
    pub result: &'a StudyResult,
    /// Its statistics per class, pair and quantity ([`dial::summarise`]).
    pub summaries: Vec<Summary>,
    /// Its failed profiles grouped by reason.
    pub failures: Vec<study::FailureGroup>,
}

impl<'a> DialProducts<'a> {
    /// The products of a study; an error when every profile failed (nothing is written as if
    /// the study had succeeded).
    pub fn new(inputs: &'a StudyInputs, result: &'a StudyResult) -> Result<Self, ProductError> {
        Self::with_policy(inputs, result, FailurePolicy::Tolerate)
    }

    /// [`Self::new`] under `policy`: with [`FailurePolicy::Strict`] an error when any profile
    /// failed ([`study::FailureReport::verdict`]).
    pub fn with_policy(
        inputs: &'a StudyInputs,
        result: &'a StudyResult,
        policy: FailurePolicy,
    ) -> Result<Self, ProductError> {
        let report = FailureReport::new(
            result.outcomes.len(),
            result.outcomes.iter().filter_map(|o| match &o.records {
                Err(e) => Some((o.id.as_str(), e.as_str())),
                Ok(_) => None,
            }),
        );
        if report.failed() > 0 {
            report
                .verdict(&profiles_of(inputs), policy)
                .map_err(ProductError::ProfilesFailed)?;
        }
        Ok(DialProducts {
            inputs,
            result,
            summaries: dial::summarise(&result.outcomes),
            failures: report.groups,
        })
    }

    /// Write the study's files into `dir`, all or none: its tables, with `history` (the NetCDF
    /// `history` attribute) profiles.nc and summary.nc too (each when its CSV has rows), the
    /// figures `figures` stages, and summary.json. Returns the files written, in order.
    pub fn write(
        &self,
        dir: &Path,
        history: Option<&str>,
        figures: impl FnOnce(&mut OutputSet) -> Result<(), OutputError>,
    ) -> Result<Vec<PathBuf>, ProductError> {
        let (scene, set, options) = (&self.inputs.scene, &self.inputs.set, &self.inputs.options);
        let (result, summaries) = (self.result, &self.summaries);
        // An earlier study's files this one does not rewrite (figures, a NetCDF file) go with
        // the commit.
        let mut files = OutputSet::new();
        files.replaces(dir, &FILES)?;
        files.write(dir.join("profiles.csv"), profiles_csv(result))?;
        files.write(dir.join("summary.csv"), summary_csv(summaries))?;
        if let Some(history) = history {
            // Not the scene's path: a merge has it absolute (summary.json holds it).
            let title = format!("lidarsim dial: retrievals over {}", set.name);
            if result
                .outcomes
                .iter()
                .any(|o| o.records.as_ref().is_ok_and(|r| !r.is_empty()))
            {
                let nc = profiles_nc(&result.outcomes, &title, history, scene, set, options.seed)?;
                files.write(dir.join(dial::PROFILES_NC), nc.encode()?)?;
            }
            if !summaries.is_empty() {
                let nc = summary_nc(summaries, &title, history, scene, set, options.seed)?;
                files.write(dir.join(dial::SUMMARY_NC), nc.encode()?)?;
            }
        }
        files.write(
            dir.join("budget.csv"),
            budget_csv(summaries, &options.steps, scene),
        )?;
        files.write(dir.join("failed.csv"), failed_csv(&result.outcomes))?;
        figures(&mut files)?;
        files.write(
            dir.join("summary.json"),
            summary_json(scene, set, options, result),
        )?;
        Ok(files.commit()?)
    }

    /// The report of the study after its files were `written`.
    pub fn report(&self, out: &mut impl Write, written: &[PathBuf]) -> std::io::Result<()> {
        print_report(
            out,
            &self.inputs.set,
            self.result,
            &self.summaries,
            &self.failures,
            self.inputs.options.photons,
        )?;
        let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
        writeln!(out, "wrote {}", names.join(", "))?;
        Ok(())
    }
}

/// `profiles.nc`'s data set ([`dial::profiles_dataset`]) with the study's global attributes
/// ([`study_globals`]): what the command line writes and the Python package returns.
pub fn profiles_nc(
    outcomes: &[crate::study::dial::ProfileOutcome],
    title: &str,
    history: &str,
    scene: &Scene,
    set: &ProfileSet,
    seed: u64,
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    let mut nc = dial::profiles_dataset(outcomes)?;
    study_globals(&mut nc, title, history, scene, set, seed);
    Ok(nc)
}

/// `summary.nc`'s data set ([`dial::summary_dataset`]) with the study's global attributes.
pub fn summary_nc(
    summaries: &[crate::study::dial::Summary],
    title: &str,
    history: &str,
    scene: &Scene,
    set: &ProfileSet,
    seed: u64,
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    let mut nc = dial::summary_dataset(summaries)?;
    study_globals(&mut nc, title, history, scene, set, seed);
    Ok(nc)
}

/// The global attributes of a study's `profiles.nc` and `summary.nc`
/// ([`crate::netcdf::study_globals`]): the scene's file name (not its path: a merge of shards
/// has it absolute) and text, the seed and the profile set.
pub fn study_globals(
    nc: &mut crate::netcdf::Dataset,
    title: &str,
    history: &str,
    scene: &Scene,
    set: &ProfileSet,
    seed: u64,
) {
    let file = scene.path.file_name().map_or_else(
        || scene.path.display().to_string(),
        |f| f.to_string_lossy().into_owned(),
    );
    crate::netcdf::study_globals(
        nc,
        &crate::netcdf::StudyAttributes {
            title,
            history,
            scene_file: Some(&file),
            scene_text: Some(scene.text()),
            seed: Some(seed),
            profile_set: Some(&set.name),
        },
    );
}

/// Header of `profiles.csv`, one row per profile, line pair and retrieved quantity.
pub const PROFILES_HEADER: &str = "profile_id,class,pair,method,altitude_bottom_m,altitude_top_m,truth_ppm,retrieved_ppm,error_ppm,retrieved_noisy_ppm,error_noisy_ppm,retrieved_own_profile_ppm";

/// `profiles.csv`: one row per profile that ran, line pair and retrieved quantity.
pub fn profiles_csv(result: &StudyResult) -> String {
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

/// `summary.csv`: one row per class (and `all`), pair and retrieved quantity.
pub fn summary_csv(summaries: &[Summary]) -> String {
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

/// `budget.csv`: one row per class, pair, quantity and error source.
pub fn budget_csv(summaries: &[Summary], steps: &BudgetSteps, scene: &Scene) -> String {
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

/// Header of `failed.csv`, one row per profile that failed.
pub const FAILED_HEADER: &str = "index,profile_id,class,reason";

/// `failed.csv`: one row per profile that failed, in the study's order: its 0-based index in
/// the study (the order of `profiles.csv`, which is its noise seed's), id, latitude class and
/// reason (the header alone when none failed).
pub fn failed_csv(outcomes: &[ProfileOutcome]) -> String {
    let mut s = format!("{FAILED_HEADER}\n");
    for (i, o) in outcomes.iter().enumerate() {
        if let Err(e) = &o.records {
            let _ = writeln!(
                s,
                "{i},{},{},{}",
                csv_field(&o.id),
                csv_field(o.class.name()),
                csv_field(e)
            );
        }
    }
    s
}

/// `summary.json`: the study's set-up, size and timing.
pub fn summary_json(
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
        .filter(|m| m.method == crate::retrieval::Method::Ipda)
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
