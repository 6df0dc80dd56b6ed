//! `lidarsim select-lines`: sensitivities of a CO2 IPDA's XCO2 to temperature, laser frequency,
//! surface pressure and humidity errors, and its random error, for candidate on-line positions
//! (method: `lidarsim::study::select`, docs/retrieval.md; the study's set-up:
//! `lidarsim::study::select_study`). Writes `DIR/sensitivities.csv`, `DIR/sensitivities.nc` and,
//! unless `--no-plots`, per atmosphere `transmission_<atm>.png` (Figure 4 of the reference study) and
//! `errors_<atm>.png` (Figure 5); with `--shard I/N` only the shard file of a slice of the
//! profiles (`lidarsim::study::select_shard`), which `lidarsim merge` puts together.

use std::path::PathBuf;

use anyhow::Context;

use lidarsim::atmosphere::StandardAtmosphere;
use lidarsim::output;
use lidarsim::products;
use lidarsim::shard::ShardSpec;
use lidarsim::study::select::Uncertainties;
use lidarsim::study::select_shard;
use lidarsim::study::select_study::{SelectOptions, SelectSource, SelectStudy, ranges};

/// Arguments of `lidarsim select-lines`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene whose instrument sets the random error (TOML); `-` reads it from standard input
    /// (relative paths inside it then resolve against the current directory); without it the
    /// embedded default scene.
    #[arg(value_name = "SCENE")]
    scene: Option<PathBuf>,
    #[command(flatten)]
    overrides: super::SceneOverrides,
    /// The scene by its former option; hidden, kept so that scripts written before the scene
    /// became the first argument still run.
    #[arg(
        long = "scene",
        value_name = "FILE",
        hide = true,
        conflicts_with = "scene"
    )]
    scene_option: Option<PathBuf>,
    /// Built-in AFGL atmospheres, comma-separated (tropical, midlatitude_summer,
    /// midlatitude_winter, subarctic_summer, subarctic_winter, us_standard).
    #[arg(
        long,
        value_delimiter = ',',
        required_unless_present_any = ["profiles", "ensemble"],
        conflicts_with_all = ["profiles", "ensemble"]
    )]
    atmosphere: Vec<StandardAtmosphere>,
    /// A lidarsim profile-set CSV; statistics per latitude class.
    #[arg(long, value_name = "SET", conflicts_with = "ensemble")]
    profiles: Option<PathBuf>,
    /// Instead of a set: N members per class around the class's AFGL mean with the
    /// representative NWP forecast-error covariance (as `lidarsim dial --ensemble`: class i of
    /// tropical, mid, high takes seed S + i).
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = super::count_usize(2, lidarsim::limits::MAX_ENSEMBLE_LEVELS))]
    ensemble: Option<usize>,
    /// Seed of --ensemble.
    #[arg(long, default_value_t = 1, requires = "ensemble")]
    seed: u64,
    /// Latitude class of --profiles or --ensemble: high, mid, tropical, or all (one group per
    /// class).
    #[arg(long, default_value = "all", value_parser = super::latitude_class)]
    class: String,
    /// With --profiles: also one row per profile id (atmosphere = the id).
    #[arg(long)]
    per_profile: bool,
    /// HITRAN .par line files (repeatable; e.g. CO2 and H2O). Without: the built-in CO2
    /// 30012←00001 band model (CO2 626 only, approximate).
    #[arg(long, value_name = "FILE")]
    lines: Vec<PathBuf>,
    /// On-line positions [cm⁻¹], comma-separated. Without: scan the band's lines (--max-j,
    /// --offsets-ghz).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = super::real(ranges::WAVENUMBER_CM1))]
    on_cm1: Vec<f64>,
    /// The off-line [cm⁻¹].
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(ranges::WAVENUMBER_CM1))]
    off_cm1: f64,
    /// CO2 of every profile [ppm]: well mixed, this dry-air mole fraction at every level (the
    /// profile's own CO2 replaced or added).
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(ranges::CO2_PPM))]
    co2_ppm: f64,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Scan: largest J″ of the band's lines.
    #[arg(long, default_value_t = 40, allow_negative_numbers = true, value_parser = super::count_u32(0, ranges::MAX_J))]
    max_j: u32,
    /// Scan: offsets from each line's centre [GHz], comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        default_value = "-3,-2.5,-2,-1.5,-1,-0.5,0,0.5,1,1.5,2,2.5,3",
        value_parser = super::real(ranges::OFFSET_GHZ),
    )]
    offsets_ghz: Vec<f64>,
    /// Layer thickness of the grid [m].
    #[arg(long, default_value_t = 250.0, allow_negative_numbers = true, value_parser = super::real(ranges::LAYER_M))]
    layer_m: f64,
    /// Top of the grid [km] (clipped to the lowest top of the profiles).
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true, value_parser = super::real(ranges::TOP_KM))]
    top_km: f64,
    /// Line wing cutoff [cm⁻¹].
    #[arg(long, default_value_t = 25.0, allow_negative_numbers = true, value_parser = super::real(ranges::WING_CM1))]
    wing_cm1: f64,
    /// Uncertainty of the assumed temperature [K] (total error).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(ranges::TEMPERATURE_K))]
    temperature_uncertainty_k: f64,
    /// Uncertainty of the laser frequency [MHz] (total error).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(ranges::FREQUENCY_MHZ))]
    frequency_uncertainty_mhz: f64,
    /// Uncertainty of the assumed surface pressure [hPa] (total error).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(ranges::SURFACE_PRESSURE_HPA))]
    surface_pressure_uncertainty_hpa: f64,
    /// Uncertainty of the assumed humidity [%] (total error).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = super::real(ranges::H2O_PERCENT))]
    h2o_uncertainty_percent: f64,
    /// Lines drawn in the figures, comma-separated labels.
    #[arg(long, value_delimiter = ',', default_value = "R16e,R26e")]
    figure_lines: Vec<String>,
    /// Do not draw figures.
    #[arg(long)]
    no_plots: bool,
    /// Worker threads, 0 for all cores; at most the cores available.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = super::threads())]
    threads: usize,
    /// Make any failed profile an error: exit 2 with one line of the counts by reason (and the
    /// first profile of each), and nothing written. Without it a study where some profiles fail
    /// (cannot be run, are supersaturated, a retrieval fails) succeeds, leaves them out of the
    /// statistics and lists them in DIR/failed.csv (index,profile_id,group,reason); one where
    /// every profile fails is an error either way. A shard does not decide: give it to `merge`.
    #[arg(long, conflicts_with = "shard")]
    strict: bool,
    /// Study only shard I of N (0 ≤ I < N) of the profiles and write their results raw to
    /// DIR/shard-I-of-N.lshard; `lidarsim merge` puts the N files together into this study's
    /// outputs.
    #[arg(long, value_name = "I/N", value_parser = clap::value_parser!(ShardSpec))]
    shard: Option<ShardSpec>,
}

/// `lidarsim select-lines`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let scene_path = a.scene.as_ref().or(a.scene_option.as_ref());
    let scene = products::read_scene(
        scene_path.map(PathBuf::as_path),
        &a.overrides.set,
        a.shard.is_some(),
    )?;
    let study = SelectStudy::build(options(&a)?, scene)?;
    // Before the work; the figures' names depend on the groups and are checked when written.
    let out_files = match a.shard {
        Some(spec) => vec![a.out.join(spec.file_name())],
        None => vec![
            a.out.join("sensitivities.csv"),
            a.out.join("sensitivities.nc"),
            a.out.join(products::select::FAILED_CSV),
        ],
    };
    output::check_paths(&out_files)?;
    outln!("{}", products::select::setup_line(&study));
    let pool = lidarsim::study::thread_pool(a.threads).map_err(anyhow::Error::msg)?;
    if let Some(spec) = a.shard {
        let n = spec.batches(study.len()).len();
        return super::run_study_shard(spec, n, "select-lines shard", &pool, |tick| {
            select_shard::run(&study, spec, &a.out, tick)
        });
    }
    let bar = super::progress::Progress::new(study.len(), "select-lines", "profiles");
    let outcomes = pool.install(|| study.study(0..study.len(), &|| bar.tick()));
    bar.finish();
    // On the same threads: the summary computes each group's figure spectra in parallel.
    pool.install(|| {
        super::write::select(
            &a.out,
            a.no_plots,
            &study,
            &outcomes,
            lidarsim::study::FailurePolicy::strict_if(a.strict),
        )
    })
}

/// The study's options from the command line. A shard names its files by their absolute
/// paths, so that shards started from different directories agree.
fn options(a: &Args) -> anyhow::Result<SelectOptions> {
    let path = |p: &PathBuf| -> anyhow::Result<PathBuf> {
        match a.shard {
            Some(_) => {
                std::fs::canonicalize(p).with_context(|| format!("cannot read {}", p.display()))
            }
            None => Ok(p.clone()),
        }
    };
    let source = match (&a.profiles, a.ensemble) {
        (Some(p), _) => SelectSource::Set(path(p)?),
        (None, Some(n)) => SelectSource::Ensemble(n),
        (None, None) => SelectSource::Atmospheres(a.atmosphere.clone()),
    };
    Ok(SelectOptions {
        source,
        seed: a.seed,
        class: a.class.clone(),
        per_profile: a.per_profile,
        lines: a.lines.iter().map(path).collect::<anyhow::Result<_>>()?,
        on_cm1: a.on_cm1.clone(),
        off_cm1: a.off_cm1,
        co2_ppm: a.co2_ppm,
        max_j: a.max_j,
        offsets_ghz: a.offsets_ghz.clone(),
        layer_m: a.layer_m,
        top_km: a.top_km,
        wing_cm1: a.wing_cm1,
        uncertainties: Uncertainties {
            temperature_k: a.temperature_uncertainty_k,
            frequency_mhz: a.frequency_uncertainty_mhz,
            surface_pressure_hpa: a.surface_pressure_uncertainty_hpa,
            h2o_percent: a.h2o_uncertainty_percent,
        },
        figure_lines: a.figure_lines.clone(),
        plots: !a.no_plots,
    })
}
