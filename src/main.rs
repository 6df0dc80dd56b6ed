//! The `lidarsim` command line: parses arguments, dispatches to a subcommand, maps errors to an
//! exit code (0 success, 2 error). Each subcommand lives in its own file under `src/cli/`, which
//! calls the library (its products in `lidarsim::products`) and prints; the figures it draws
//! are in `src/figures/`, one file per command.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cli;
mod figures;

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Simulation testbed for atmospheric lidars (DIAL, IPDA): line-by-line gas absorption, Mie and
/// Rayleigh scattering, time-resolved Monte Carlo transport and the analytic lidar equation.
#[derive(Parser)]
#[command(name = "lidarsim", version, about, long_about = None)]
struct Cli {
    /// No progress reports on stderr (neither the bar on a terminal nor the log lines
    /// otherwise); errors and warnings are still printed.
    #[arg(long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene (Monte Carlo and analytic lidar equation) and write DIR/returns.csv.
    Run(cli::run::Args),
    /// Line-by-line absorption cross-sections or layer optical depths from a HITRAN file.
    Lbl(cli::lbl::Args),
    /// Atmospheric profile sets: generate perturbed ensembles, plot sets.
    Profiles(cli::profiles::Args),
    /// Mie scattering of one sphere or a size distribution; write phase-function tables.
    Mie(Box<cli::mie::Args>),
    /// Measure speed and Monte Carlo efficiency on fixed workloads.
    Bench(cli::bench::Args),
    /// Run a scene's DIAL/IPDA retrievals over a profile ensemble, with an error budget.
    Dial(Box<cli::dial::Args>),
    /// Line selection for CO2 IPDA: XCO2 sensitivities to T, frequency, surface pressure and
    /// humidity, random error and rank of candidate on-lines; write DIR/sensitivities.csv.
    SelectLines(Box<cli::select_lines::Args>),
    /// Fold the shard files of `run`, `dial` or `select-lines --shard I/N` into the files a
    /// single run writes.
    Merge(cli::merge::Args),
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse_from(join_negative_values(std::env::args_os())) {
        Ok(cli) => cli,
        Err(e) => match invalid_value(&e) {
            Some(m) => {
                eprintln!("lidarsim: error: {m}");
                return ExitCode::from(2);
            }
            None => e.exit(),
        },
    };
    cli::progress::set_quiet(cli.quiet);
    lidarsim::particles::distribution::set_progress_lines(cli::progress::library_lines_after_s());
    let result = match cli.command {
        Command::Run(a) => cli::run::run(a),
        Command::Lbl(a) => cli::lbl::run(a),
        Command::Profiles(a) => cli::profiles::run(a),
        Command::Mie(a) => cli::mie::run(*a),
        Command::Bench(a) => cli::bench::run(a),
        Command::Dial(a) => cli::dial::run(*a),
        Command::SelectLines(a) => cli::select_lines::run(*a),
        Command::Merge(a) => cli::merge::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // A closed pipe (`lidarsim run | head`) is not an error (as in ripgrep).
        Err(e)
            if e.downcast_ref::<std::io::Error>()
                .or(match e.downcast_ref::<lidarsim::products::ProductError>() {
                    Some(lidarsim::products::ProductError::Io(io)) => Some(io),
                    _ => None,
                })
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("lidarsim: error: {}", message(&e));
            ExitCode::from(2)
        }
    }
}

/// The command line with every negative number given as an option's value joined to its
/// option (`--offsets-ghz -1,1` → `--offsets-ghz=-1,1`), so that it reaches the option's own
/// parser and range check in any notation. clap takes `-1.5` and `-1e3` as values (where an
/// option allows negative numbers) but `-1e-3`, `-.5`, `-inf` and `-1,1` as unknown flags, and
/// its message then names neither the option nor the value (README: "negative numbers are
/// read as values"). A token is joined when it begins with `-`, every comma-separated piece of
/// it parses as a number (`inf` and `nan` included, which the parsers then refuse by name), and
/// the token before it is a long option without `=`; lidarsim has no flag or positional
/// argument that looks like a negative number, so nothing else changes.
fn join_negative_values(
    args: impl IntoIterator<Item = std::ffi::OsString>,
) -> Vec<std::ffi::OsString> {
    let negative_number = |t: &str| {
        t.starts_with('-')
            && t.len() > 1
            && !t.starts_with("--")
            && t.split(',')
                .all(|piece| piece.trim().parse::<f64>().is_ok())
    };
    let mut out: Vec<std::ffi::OsString> = Vec::new();
    let mut options_ended = false;
    for arg in args {
        let joined = match (out.last().and_then(|p| p.to_str()), arg.to_str()) {
            (Some(prev), Some(t))
                if !options_ended
                    && prev.starts_with("--")
                    && prev.len() > 2
                    && !prev.contains('=')
                    && negative_number(t) =>
            {
                Some(format!("{prev}={t}"))
            }
            _ => None,
        };
        match joined {
            Some(j) => *out.last_mut().expect("a previous token") = j.into(),
            None => {
                options_ended |= arg == "--";
                out.push(arg);
            }
        }
    }
    out
}

/// An option's value refused by its range check, as one line like every other input error
/// (`--step-cm1 -0.01 must lie in (0, 100]`); other command-line errors keep clap's usage help.
fn invalid_value(e: &clap::Error) -> Option<String> {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    if e.kind() != ErrorKind::ValueValidation {
        return None;
    }
    let ContextValue::String(arg) = e.get(ContextKind::InvalidArg)? else {
        return None;
    };
    let option = arg.split_whitespace().next()?;
    let why = std::error::Error::source(e)?;
    Some(format!("{option} {why}"))
}

/// The error and its causes joined by ": ", leaving out a cause whose text the message already
/// ends with: an error type that shows its source in its own message (`"gas absorption: {0}"`)
/// would otherwise have it printed twice.
fn message(e: &anyhow::Error) -> String {
    let mut text = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !text.ends_with(&c) {
            text.push_str(": ");
            text.push_str(&c);
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cause_already_in_the_message_is_not_repeated() {
        let e = anyhow::Error::new(std::io::Error::other("disk full"))
            .context("cannot write x: disk full");
        assert_eq!(message(&e), "cannot write x: disk full");
        let e = anyhow::Error::new(std::io::Error::other("disk full")).context("cannot write x");
        assert_eq!(message(&e), "cannot write x: disk full");
    }

    /// Negative numbers in every notation reach their option; nothing else is joined.
    #[test]
    fn negative_values_are_joined_to_their_option() {
        let join = |args: &[&str]| -> Vec<String> {
            join_negative_values(args.iter().map(std::ffi::OsString::from))
                .into_iter()
                .map(|a| a.into_string().unwrap())
                .collect()
        };
        assert_eq!(
            join(&[
                "lidarsim",
                "select-lines",
                "--offsets-ghz",
                "-1,1",
                "--out",
                "d"
            ]),
            [
                "lidarsim",
                "select-lines",
                "--offsets-ghz=-1,1",
                "--out",
                "d"
            ]
        );
        for v in [
            "-1e-2",
            "-.5",
            "-inf",
            "-NaN",
            "-3",
            "-1.5e3",
            "-3,-2.5,2.5",
        ] {
            assert_eq!(
                join(&["l", "dial", "--x", v]),
                ["l", "dial", &format!("--x={v}")]
            );
        }
        // Not values: a flag, a word, an option with its value attached, after `--`.
        for args in [
            &["l", "run", "--no-plots", "--out", "d"][..],
            &["l", "run", "--out", "-d"],
            &["l", "run", "--seed=1", "-5"],
            &["l", "run", "--", "--x", "-5"],
            &["l", "run", "-h"],
        ] {
            assert_eq!(join(args), args);
        }
        // And the joined value is parsed by the option: a range error names it.
        let e = Cli::try_parse_from(join(&["lidarsim", "run", "--threads", "-1e-3"]))
            .err()
            .expect("refused");
        assert!(invalid_value(&e).unwrap().starts_with("--threads"), "{e}");
    }

    #[test]
    fn a_refused_option_value_is_one_line_naming_the_option() {
        let e = Cli::try_parse_from(["lidarsim", "run", "--threads", "100000"])
            .err()
            .expect("refused");
        assert_eq!(
            invalid_value(&e).as_deref(),
            Some("--threads 100000 must lie in 0..=1024")
        );
        let e = Cli::try_parse_from(["lidarsim", "run", "--bogus"])
            .err()
            .expect("refused");
        assert_eq!(invalid_value(&e), None);
    }
}
