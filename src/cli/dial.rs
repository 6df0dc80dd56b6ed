//! `lidarsim dial [SCENE] (--profiles SET | --ensemble N) [--class C] [--on NAMES] --out DIR`:
//! a scene's retrievals over a profile ensemble with an error budget (`lidarsim::study::dial`).

use std::path::PathBuf;

use lidarsim::input::Bounds;
use lidarsim::output;
use lidarsim::products::dial::{DialRequest, FILES};
use lidarsim::shard::ShardSpec;
use lidarsim::study::dial::{self, BudgetSteps};
use lidarsim::study::shard as study_shard;

/// Arguments of `lidarsim dial`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file (TOML) with `[laser]`/`[receiver]`/`[retrieval]`; `-` reads it from
    /// standard input (relative paths inside it then resolve against the current directory);
    /// without it the embedded default scene.
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub overrides: super::SceneOverrides,
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
    /// Make any failed profile an error: exit 2 with one line of the counts by reason (and the
    /// first profile of each), and nothing written. Without it a study where some profiles fail
    /// (cannot be run, are supersaturated, a retrieval fails) succeeds, leaves them out of the
    /// statistics and lists them in DIR/failed.csv (index,profile_id,class,reason); one where
    /// every profile fails is an error either way. A shard does not decide: give it to `merge`.
    #[arg(long, conflicts_with = "shard")]
    pub strict: bool,
    /// Do not write profiles.nc and summary.nc (the CF NetCDF files of profiles.csv and
    /// summary.csv).
    #[arg(long)]
    pub no_netcdf: bool,
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let out_files = match args.shard {
        Some(spec) => vec![args.out.join(spec.file_name())],
        None => FILES.map(|f| args.out.join(f)).to_vec(),
    };
    // Before the work: a study must not fail at its end on a name it could have refused now.
    output::check_paths(&out_files)?;
    let inputs = request(&args).resolve()?;
    let policy = lidarsim::study::FailurePolicy::strict_if(args.strict);
    lidarsim::products::dial::check_before_run(&inputs, policy)?;
    let pool = lidarsim::study::thread_pool(args.threads).map_err(anyhow::Error::msg)?;
    if let Some(spec) = args.shard {
        let n = spec.batches(inputs.set.len()).len();
        return super::run_study_shard(spec, n, "dial shard", &pool, |tick| {
            study_shard::run(&inputs, spec, &args.out, tick)
        });
    }
    let bar = super::progress::Progress::new(inputs.set.len(), "dial", "profiles");
    let result =
        pool.install(|| dial::run(&inputs.scene, &inputs.set, &inputs.options, &|| bar.tick()))?;
    bar.finish();
    super::write::dial(
        &args.out,
        args.no_plots,
        !args.no_netcdf,
        &inputs,
        &result,
        policy,
    )
}

/// The request of the command line ([`DialRequest::resolve`] makes the study's inputs).
fn request(args: &Args) -> DialRequest {
    // Each step was checked by the argument parser (finite, signed where a sign means a
    // direction of the error).
    let steps = BudgetSteps {
        temperature_k: args.budget_temperature_k,
        humidity_fraction: args.budget_humidity_percent / 100.0,
        surface_pressure_hpa: args.budget_surface_pressure_hpa,
        frequency_offset_mhz: args.budget_frequency_offset_mhz,
        linewidth_fraction: args.budget_linewidth_percent / 100.0,
    };
    DialRequest {
        scene: args.scene.clone(),
        overrides: args.overrides.set.clone(),
        profiles: args.profiles.clone(),
        ensemble: args.ensemble,
        seed: args.seed,
        class: args.class.clone(),
        on: args.on.clone(),
        photons: args.photons,
        steps,
        shard: args.shard.is_some(),
    }
}
