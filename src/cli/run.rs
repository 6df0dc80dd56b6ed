//! `lidarsim run` (not implemented yet).

/// Arguments of `lidarsim run`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`lidarsim run` is not implemented yet")
}
