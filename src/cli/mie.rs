//! `lidarsim mie` (not implemented yet).

/// Arguments of `lidarsim mie`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`lidarsim mie` is not implemented yet")
}
