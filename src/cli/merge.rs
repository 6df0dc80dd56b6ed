//! `lidarsim merge DIR... [--out DIR]`: fold the shards of `lidarsim run`, `lidarsim dial` or
//! `lidarsim select-lines` ([`lidarsim::products::merge`]) and write the files of the command.

use std::path::PathBuf;

use lidarsim::output;
use lidarsim::products::merge::{self, Merged};

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
    /// For the shards of a study (`dial`, `select-lines`): make any failed profile an error
    /// (as their `--strict`): exit 2 with the counts by reason, nothing written.
    #[arg(long)]
    pub strict: bool,
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let shards = merge::find(&args.inputs)?;
    // Before the work: a merge must not fail at its end on a name it could have refused now.
    output::check_paths(&shards.files(&args.out))?;
    match shards.merge()? {
        Merged::Select(merged) => {
            let study = &merged.study;
            outln!(
                "merged {} select-lines shards of {} profiles",
                merged.shards,
                study.len()
            );
            if !study.options.plots && !args.no_plots {
                outln!("the shards ran with --no-plots: no figures");
            }
            outln!("{}", lidarsim::products::select::setup_line(study));
            super::write::select(
                &args.out,
                args.no_plots,
                study,
                &merged.outcomes,
                lidarsim::study::FailurePolicy::strict_if(args.strict),
            )
        }
        Merged::Dial(merged) => {
            outln!(
                "merged {} dial shards of {} profiles of {}",
                merged.shards,
                merged.inputs.set.len(),
                merged.inputs.scene.path.display()
            );
            let (inputs, result) = (&merged.inputs, &merged.result);
            super::write::dial(
                &args.out,
                args.no_plots,
                true,
                inputs,
                result,
                lidarsim::study::FailurePolicy::strict_if(args.strict),
            )
        }
        Merged::Run(merged) => {
            outln!(
                "merged {} shards of {}",
                merged.shards,
                merged.scene.path.display()
            );
            super::write::run(&args.out, args.no_plots, true, &merged.scene, &merged.run)
        }
    }
}
