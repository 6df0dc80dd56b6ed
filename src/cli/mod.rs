//! One module per subcommand; each has `Args` (clap) and `run(Args) -> anyhow::Result<()>`.

pub mod bench;
pub mod dial;
pub mod figures;
pub mod lbl;
pub mod mie;
pub mod plot;
pub mod profiles;
pub mod progress;
pub mod run;
pub mod select_lines;
pub mod study_figures;
