//! `lidarsim run [SCENE|-] [--set KEY=VALUE]… [--out DIR] [--photons N] [--seed S] [--threads T] [--no-plots]`

use std::path::PathBuf;

use lidarsim::input::Bounds;
use lidarsim::output;
use lidarsim::products::{self, run::FILES};
use lidarsim::shard::{self, ShardSpec};

/// Arguments of `lidarsim run`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file (TOML); `-` reads it from standard input (relative paths inside it then
    /// resolve against the current directory). Without it the embedded default scene runs.
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub overrides: super::SceneOverrides,
    /// Output directory (created if needed); receives returns.csv, summary.json and, with a
    /// receiver and a retrieval, signals.csv, retrieval.csv and figures.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Photon packets (overrides the scene's `simulation.photons`); 0 runs only the analytic
    /// single-scatter lidar equation.
    #[arg(long, allow_negative_numbers = true, value_parser = super::count(0, lidarsim::limits::MAX_PHOTONS))]
    pub photons: Option<u64>,
    /// Random seed (overrides `simulation.seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads, 0 for all cores (overrides `simulation.threads`).
    #[arg(long, allow_negative_numbers = true, value_parser = super::threads())]
    pub threads: Option<usize>,
    /// Probability of detector-directed importance sampling near the line of sight (0 turns
    /// this variance reduction off; results are unbiased either way).
    #[arg(long, default_value_t = lidarsim::transport::DDIS_EPSILON, allow_negative_numbers = true, value_parser = super::real(Bounds::below(0.0, 1.0)))]
    pub ddis_epsilon: f64,
    /// Do not draw the figures (returns.png, dial.png).
    #[arg(long)]
    pub no_plots: bool,
    /// Trace only shard I of N (0 ≤ I < N) of the Monte Carlo batches and write them raw to
    /// DIR/shard-I-of-N.lshard; `lidarsim merge` folds the N files into this run's outputs.
    #[arg(long, value_name = "I/N", value_parser = clap::value_parser!(lidarsim::shard::ShardSpec))]
    pub shard: Option<lidarsim::shard::ShardSpec>,
    /// Do not write run.nc (the CF NetCDF file of returns, signals and retrievals).
    #[arg(long)]
    pub no_netcdf: bool,
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(spec) = args.shard {
        return run_shard(&args, spec);
    }
    let scene = scene(&args, false)?;
    // Before the work: a run must not fail at its end on a name it could have refused now.
    output::check_paths(&FILES.map(|f| args.out.join(f)))?;
    #[cfg(not(feature = "mpi"))]
    let run = {
        let bar = super::progress::Progress::new(0, "run", "batches");
        let run = lidarsim::pipeline::run_reporting(&scene, &|done, total| bar.reach(done, total));
        bar.finish();
        run?
    };
    // Under `mpirun` the ranks share the batches; rank 0 alone writes (`lidarsim::distributed`).
    #[cfg(feature = "mpi")]
    let run = match lidarsim::distributed::run(&scene)? {
        lidarsim::distributed::Outcome::Root(run) => run,
        // Other ranks: rank 0 writes the files, or reports why the run stopped and ends with
        // status 2 (mpirun's status); a rank that ended with 2 first could cut its message off.
        lidarsim::distributed::Outcome::Worker | lidarsim::distributed::Outcome::Stopped => {
            return Ok(());
        }
    };
    super::write::run(&args.out, args.no_plots, !args.no_netcdf, &scene, &run)
}

/// The scene with the command line's settings (`absolute`: read by its absolute path, as shards).
fn scene(args: &Args, absolute: bool) -> anyhow::Result<lidarsim::scene::Scene> {
    let mut scene = products::read_scene(args.scene.as_deref(), &args.overrides.set, absolute)?;
    scene.simulation.variance_reduction.ddis_epsilon = args.ddis_epsilon;
    scene
        .override_simulation(args.photons, args.seed, args.threads)
        .map_err(anyhow::Error::msg)?;
    Ok(scene)
}

/// `lidarsim run … --shard I/N`: trace the shard's batches and write its file.
fn run_shard(args: &Args, spec: ShardSpec) -> anyhow::Result<()> {
    let r = shard::run(&scene(args, true)?, spec, &args.out)?;
    outln!(
        "shard {spec}: batches {}..{} of {} ({} photons each) in {:.2} s on {} threads; wrote {}",
        r.batches.start,
        r.batches.end,
        r.total_batches,
        r.photons_per_batch,
        r.wall_s,
        r.threads,
        r.path.display()
    );
    Ok(())
}
