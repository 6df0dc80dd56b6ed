//! `lidarsim bench` (not implemented yet).

/// Arguments of `lidarsim bench`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`lidarsim bench` is not implemented yet")
}
