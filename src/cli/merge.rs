//! `lidarsim run SCENE --shard I/N --out DIR` and `lidarsim merge DIR... [--out DIR]`: the
//! command-line side of [`lidarsim::shard`]; the merge also puts together the shards of
//! `lidarsim dial` and `lidarsim select-lines` ([`lidarsim::study::shard`],
//! [`lidarsim::study::select_shard`]).

use std::path::PathBuf;

use lidarsim::output;
use lidarsim::shard::{self, ShardSpec};
use lidarsim::study::shard::StudyShardReport;
use lidarsim::transport::TransportOptions;

/// Arguments of `lidarsim merge`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Directories holding shard files (`*.lshard`, from `lidarsim run --shard I/N`,
    /// `lidarsim dial --shard I/N` or `lidarsim select-lines --shard I/N`), or the files
    /// themselves: every shard of one run or study, each once.
    #[arg(required = true, value_name = "DIR")]
    pub inputs: Vec<PathBuf>,
    /// Output directory: receives the files a single run (or study) writes.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Do not draw the figures (returns.png, dial.png; a study's figures).
    #[arg(long)]
    pub no_plots: bool,
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let paths = shard::shard_paths(&args.inputs)?;
    let kind = shard::common_kind(&paths)?;
    if kind == shard::KIND_SELECT {
        // The figures' names depend on the groups and are checked when written.
        output::check_paths(&[
            args.out.join("sensitivities.csv"),
            args.out.join("sensitivities.nc"),
            args.out.join(super::select_lines::FAILED_CSV),
        ])?;
        let merged = lidarsim::study::select_shard::merge(&paths)?;
        let study = &merged.study;
        outln!(
            "merged {} select-lines shards of {} profiles",
            merged.shards,
            study.len()
        );
        if !study.options.plots && !args.no_plots {
            outln!("the shards ran with --no-plots: no figures");
        }
        super::select_lines::print_setup(study)?;
        return super::select_lines::write_outputs(
            &args.out,
            args.no_plots,
            study,
            &merged.outcomes,
        );
    }
    if kind == shard::KIND_DIAL {
        output::check_paths(&super::dial::FILES.map(|f| args.out.join(f)))?;
        let merged = lidarsim::study::shard::merge(&paths)?;
        outln!(
            "merged {} dial shards of {} profiles of {}",
            merged.shards,
            merged.inputs.set.len(),
            merged.inputs.scene.path.display()
        );
        return super::dial::write_outputs(
            &args.out,
            args.no_plots,
            true,
            &merged.inputs,
            &merged.result,
        );
    }
    // Before the work: a merge must not fail at its end on a name it could have refused now.
    output::check_paths(&super::run::FILES.map(|f| args.out.join(f)))?;
    let merged = shard::merge(&args.inputs)?;
    outln!(
        "merged {} shards of {}",
        merged.shards,
        merged.scene.path.display()
    );
    super::run::write_outputs(&args.out, args.no_plots, true, &merged.scene, &merged.run)
}

/// `lidarsim run … --shard I/N`: trace the shard's batches and write its file.
pub fn run_shard(args: &super::run::Args, spec: ShardSpec) -> anyhow::Result<()> {
    let mut scene = shard::read_scene(args.scene.as_deref())?;
    scene
        .override_simulation(args.photons, args.seed, args.threads)
        .map_err(anyhow::Error::msg)?;
    let mut opts = TransportOptions::from_scene(&scene);
    opts.ddis_epsilon = args.ddis_epsilon;
    let r = shard::run(&scene, &opts, spec, &args.out)?;
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

/// `lidarsim dial … --shard I/N` and `lidarsim select-lines … --shard I/N`: run `shard` (which
/// studies the `n` profiles of shard `spec` and writes its file) on `pool` with a progress bar
/// labelled `what`, and print what it did.
pub fn study_shard(
    spec: ShardSpec,
    n: usize,
    what: &str,
    pool: &rayon::ThreadPool,
    shard: impl FnOnce(&(dyn Fn() + Sync)) -> Result<StudyShardReport, shard::ShardError> + Send,
) -> anyhow::Result<()> {
    let bar = super::progress::Progress::new(n, what, "profiles");
    let r = pool.install(|| shard(&|| bar.tick()))?;
    bar.finish();
    outln!(
        "shard {spec}: profiles {}..{} of {} ({} failed) in {:.2} s on {} threads; wrote {}",
        r.profiles.start,
        r.profiles.end,
        r.total_profiles,
        r.failed,
        r.wall_s,
        r.threads,
        r.path.display()
    );
    Ok(())
}
