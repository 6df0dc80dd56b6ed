//! Every command that produces returns or a study writes its figures, on scenes with and
//! without a `[retrieval]`: the file is there, is a PNG and is not trivially small (a blank
//! canvas of the house size encodes to a few kB; a drawn figure to tens). Not a pixel test: the
//! figures are checked by eye (`validation/figures/`).

use std::path::Path;

use crate::util::{lidarsim_ok, project_root};

/// `path` is a PNG of more than `min_bytes`.
fn assert_figure(path: &Path, min_bytes: u64) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[1..4], b"PNG", "{} is not a PNG", path.display());
    assert!(
        bytes.len() as u64 > min_bytes,
        "{}: {} bytes",
        path.display(),
        bytes.len()
    );
}

/// `run` on every shipped scene (three have no retrieval) writes `returns.png`, and `dial.png`
/// where the scene retrieves a DIAL profile; `--no-plots` writes no figure.
#[test]
fn run_writes_its_figures_for_every_shipped_scene() {
    let root = project_root();
    let dir = tempfile::tempdir().unwrap();
    for (scene, dial) in [
        ("ground_rayleigh_aerosol_cloud", false),
        ("spaceborne_nadir_aerosol", false),
        ("bissonnette_c1", false),
        ("airborne_co2_dial", true),
        ("spaceborne_co2_ipda", false),
        ("study_co2_ipda", true),
    ] {
        let out = dir.path().join(scene);
        let toml = root.join("scenes").join(format!("{scene}.toml"));
        lidarsim_ok([
            "run".as_ref(),
            toml.as_os_str(),
            "--photons".as_ref(),
            "300".as_ref(),
            "--no-netcdf".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ]);
        assert_figure(&out.join("returns.png"), 20_000);
        assert_eq!(out.join("dial.png").exists(), dial, "{scene}: dial.png");
        if dial {
            assert_figure(&out.join("dial.png"), 20_000);
        }
    }
    let out = dir.path().join("no_plots");
    let toml = root.join("scenes/bissonnette_c1.toml");
    lidarsim_ok([
        "run".as_ref(),
        toml.as_os_str(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(!out.join("returns.png").exists());
}

/// `run --shard` and `merge` (a scene without a retrieval) write the run's figure too.
#[test]
fn merge_of_run_shards_writes_the_returns_figure() {
    let root = project_root();
    let dir = tempfile::tempdir().unwrap();
    let toml = root.join("scenes/ground_rayleigh_aerosol_cloud.toml");
    let shards = dir.path().join("shards");
    for i in 0..2 {
        lidarsim_ok([
            "run".as_ref(),
            toml.as_os_str(),
            "--photons".as_ref(),
            "200".as_ref(),
            "--shard".as_ref(),
            format!("{i}/2").as_ref(),
            "--out".as_ref(),
            shards.as_os_str(),
        ]);
    }
    let merged = dir.path().join("merged");
    lidarsim_ok([
        "merge".as_ref(),
        shards.as_os_str(),
        "--out".as_ref(),
        merged.as_os_str(),
    ]);
    assert_figure(&merged.join("returns.png"), 20_000);
}

/// `dial` writes its three figures with one line pair and with several.
#[test]
fn dial_writes_its_figures() {
    let root = project_root();
    let dir = tempfile::tempdir().unwrap();
    let toml = root.join("scenes/study_co2_ipda.toml");
    for (name, on) in [
        ("one", None),
        ("three", Some("R16e+0.0GHz,R16e+1.2GHz,R26e+2.2GHz")),
    ] {
        let out = dir.path().join(name);
        let mut args: Vec<std::ffi::OsString> = vec![
            "dial".into(),
            toml.clone().into(),
            "--ensemble".into(),
            "3".into(),
            "--class".into(),
            "all".into(),
            "--out".into(),
            out.clone().into(),
        ];
        if let Some(on) = on {
            args.extend(["--on".into(), on.into()]);
        }
        lidarsim_ok(args);
        for f in ["ensemble.png", "errors.png", "budget.png"] {
            assert_figure(&out.join(f), 20_000);
        }
    }
}

/// `select-lines` writes its two figures per atmosphere.
#[test]
fn select_lines_writes_its_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("select");
    lidarsim_ok([
        "select-lines".as_ref(),
        "--atmosphere".as_ref(),
        "us_standard".as_ref(),
        "--off-cm1".as_ref(),
        "6360.61".as_ref(),
        "--co2-ppm".as_ref(),
        "420".as_ref(),
        "--max-j".as_ref(),
        "26".as_ref(),
        "--layer-m".as_ref(),
        "2000".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    for f in ["transmission_us_standard.png", "errors_us_standard.png"] {
        assert_figure(&out.join(f), 20_000);
    }
}
