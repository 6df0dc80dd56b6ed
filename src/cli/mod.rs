//! One module per subcommand; each has `Args` (clap) and `run(Args) -> anyhow::Result<()>`.

/// `println!` that hands a write error (a closed pipe: `lidarsim profiles info SET | head`) to
/// the enclosing command with `?` instead of panicking; `main` ends quietly on a broken pipe.
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($t)*)?;
    }};
}

pub mod bench;
pub mod dial;
pub mod lbl;
pub mod merge;
pub mod mie;
pub mod profiles;
pub mod progress;
pub mod run;
pub mod select_lines;
pub mod write;

use lidarsim::input::{Bounds, check_count, check_finite_range, parse_count};
use lidarsim::shard::{ShardError, ShardSpec};
use lidarsim::study::shard::StudyShardReport;

/// `--set KEY=VALUE` of every command that reads a scene (flattened into its arguments).
#[derive(clap::Args, Debug, Clone)]
pub struct SceneOverrides {
    /// Override a value of the scene (repeatable): a dotted key and a TOML value, e.g.
    /// `--set simulation.photons=1e6`, `--set lidar.fov_full_angle_mrad=[1,2]`,
    /// `--set atmosphere.co2_ppm=410`, `--set channel.0.wavenumber_cm1=6360` (the first
    /// `[[channel]]`); a bare word is a string. Applied to the scene's text before it is read,
    /// so the value is checked as the file's is; an error in it names `--set KEY`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<lidarsim::scene::SceneOverride>,
}

/// A clap value parser for a real option: a finite number inside `bounds` (unit as the
/// option's name says), so that a bad value is refused by the parser with the option named.
/// Options using it also set `allow_negative_numbers`, so that `-0.01` reaches the check
/// instead of being taken for an unknown flag.
pub fn real(
    bounds: Bounds,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |text| {
        let v: f64 = text
            .trim()
            .parse()
            .map_err(|_| format!("`{text}` is not a number"))?;
        check_finite_range(v, bounds)
    }
}

/// A clap value parser for a count in `lo..=hi`, written as people do (`1000000`,
/// `1_000_000`, `1e6`, `2.5e5`: [`lidarsim::input::parse_count`]).
pub fn count(lo: u64, hi: u64) -> impl Fn(&str) -> Result<u64, String> + Clone + Send + Sync {
    move |text| check_count(parse_count(text)?, lo, hi)
}

/// [`count`] for options held as `usize`.
pub fn count_usize(
    lo: u64,
    hi: u64,
) -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync {
    let c = count(lo, hi);
    move |text| c(text).map(|v| v as usize)
}

/// [`count`] for options held as `u32`.
pub fn count_u32(lo: u32, hi: u32) -> impl Fn(&str) -> Result<u32, String> + Clone + Send + Sync {
    let c = count(lo.into(), hi.into());
    move |text| c(text).map(|v| v as u32)
}

/// Worker threads of a run: 0 (all cores) to [`lidarsim::limits::MAX_THREADS`].
pub fn threads() -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync {
    count_usize(0, lidarsim::limits::MAX_THREADS)
}

/// A clap value parser for `--class`: a latitude class of a study (`tropical`, `mid`, `high`)
/// or `all`, refused with the option named (by `main`) and the names known.
pub fn latitude_class(text: &str) -> Result<String, String> {
    lidarsim::study::dial::classes(text)
        .map(|_| text.to_string())
        .map_err(|_| format!("{text}: unknown latitude class (known: tropical, mid, high, all)"))
}

/// The CF `history` attribute of a NetCDF file written now by this command line.
pub fn netcdf_history() -> String {
    lidarsim::netcdf::history(std::env::args_os())
}

/// `lidarsim dial … --shard I/N` and `lidarsim select-lines … --shard I/N`: run `shard` (which
/// studies the `n` profiles of shard `spec` and writes its file) on `pool` with a progress bar
/// labelled `what`, and print what it did.
pub fn run_study_shard(
    spec: ShardSpec,
    n: usize,
    what: &str,
    pool: &rayon::ThreadPool,
    shard: impl FnOnce(&(dyn Fn() + Sync)) -> Result<StudyShardReport, ShardError> + Send,
) -> anyhow::Result<()> {
    let bar = progress::Progress::new(n, what, "profiles");
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_latitude_class_is_refused_with_the_names_known() {
        for c in ["tropical", "mid", "high", "all"] {
            assert_eq!(latitude_class(c).as_deref(), Ok(c));
        }
        assert_eq!(
            latitude_class("a"),
            Err("a: unknown latitude class (known: tropical, mid, high, all)".to_string())
        );
    }
}
