//! `lidarsim lbl` (not implemented yet).

/// Arguments of `lidarsim lbl`.
#[derive(clap::Args, Debug)]
pub struct Args {}

/// Run the subcommand.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`lidarsim lbl` is not implemented yet")
}
