//! Shared test helpers.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The project root (where Cargo.toml is).
pub fn project_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A file under `../shared` (or under `$LIDARSIM_SHARED` when set), or `None` after printing one
/// line naming the missing file: tests that need "tests only" data skip when it is absent.
pub fn shared_file(relative: &str) -> Option<PathBuf> {
    let base = std::env::var_os("LIDARSIM_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| project_root().join("../shared"));
    let p = base.join(relative);
    if p.is_file() {
        Some(p)
    } else {
        println!("skipped: {} is absent", p.display());
        None
    }
}

/// The records of a HITRAN `.par` file whose line position (columns 4–15) lies in
/// [`lo_cm1`, `hi_cm1`), each with its newline: a small line file for a test scene.
pub fn par_records_in(path: &Path, lo_cm1: f64, hi_cm1: f64) -> String {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| {
            l.get(3..15)
                .and_then(|nu| nu.trim().parse::<f64>().ok())
                .is_some_and(|nu| (lo_cm1..hi_cm1).contains(&nu))
        })
        .map(|l| format!("{l}\n"))
        .collect()
}

/// Path of the lidarsim binary built for these tests.
pub fn lidarsim_bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_lidarsim"))
}

/// Run `lidarsim` with arguments and return its output.
pub fn lidarsim<I, S>(args: I) -> std::process::Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    std::process::Command::new(lidarsim_bin())
        .args(args)
        .output()
        .expect("lidarsim runs")
}

/// Run `lidarsim`, require success (showing its stderr otherwise) and return its stdout.
pub fn lidarsim_ok<I, S>(args: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let out = lidarsim(args);
    assert!(
        out.status.success(),
        "lidarsim failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}
