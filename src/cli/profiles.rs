//! `lidarsim profiles` (not implemented yet).

/// Arguments of `lidarsim profiles`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`lidarsim profiles` is not implemented yet")
}
