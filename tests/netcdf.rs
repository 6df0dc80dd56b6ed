//! `run.nc` opened by real NetCDF clients (xarray and netCDF4-python, `tests/netcdf_check.py`):
//! every number equals the CSV files beside it, and the CF attributes are there; so do `sensitivities.nc` of `lidarsim select-lines` and `profiles.nc` and
//! `summary.nc` of `lidarsim dial`. Without Python, xarray or netCDF4 the test prints one line and skips, except in CI
//! (`CI` set), where `.ci/run` installs them and their absence is a failure.

use std::path::Path;
use std::process::Command;

use crate::util::{lidarsim_ok, project_root};

/// The Python interpreter (`$LIDARSIM_PYTHON`, else `python3`) if it can import xarray and
/// netCDF4; otherwise `None` after printing why.
fn python() -> Option<String> {
    let python = std::env::var("LIDARSIM_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&python)
        .args(["-c", "import xarray, netCDF4"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(python);
    }
    let why = format!(
        "{python} with xarray and netCDF4 is absent (python3 -m pip install --user xarray netCDF4)"
    );
    assert!(
        std::env::var_os("CI").is_none_or(|v| v.is_empty()),
        "CI: {why}"
    );
    println!("skipped: {why}");
    None
}

fn run(scene: Option<&Path>, photons: &str, out: &Path) {
    let mut args = vec!["run".as_ref()];
    if let Some(s) = scene {
        args.push(s.as_os_str());
    }
    args.extend([
        "--photons".as_ref(),
        photons.as_ref(),
        "--seed".as_ref(),
        "7".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    lidarsim_ok(args);
}

#[test]
fn run_nc_holds_the_numbers_of_the_csv_files() {
    let Some(python) = python() else {
        return;
    };
    let root = project_root();
    let tmp = tempfile::tempdir().unwrap();
    // A channel name that CSV must quote (comma, double quote) and that is not ASCII.
    let c1 = std::fs::read_to_string(root.join("scenes/bissonnette_c1.toml"))
        .unwrap()
        .replace("name = \"1064\"", "name = \"1064, \\\"Nd:YAG\\\" µ\"")
        .replace(
            "\"../phase_functions/",
            &format!("\"{}/phase_functions/", root.display()),
        );
    assert!(c1.contains("Nd:YAG") && c1.contains(&*root.display().to_string()));
    let c1_path = tmp.path().join("c1.toml");
    std::fs::write(&c1_path, c1).unwrap();
    // The default scene (IPDA: mixing ratio and slant column; signals), the airborne DIAL
    // (number density too; with 2000 photons far Monte Carlo cells are empty: fill values),
    // C.1 (many orders, no receiver) and an analytic-only run.
    let airborne = root.join("scenes/airborne_co2_dial.toml");
    let cases: [(Option<&Path>, &str, &str); 4] = [
        (None, "20000", "default"),
        (Some(&airborne), "2000", "airborne"),
        (Some(&c1_path), "2000", "c1"),
        (Some(&airborne), "0", "analytic"),
    ];
    let mut check = Command::new(&python);
    check.arg(root.join("tests/netcdf_check.py"));
    for (scene, photons, name) in cases {
        let out = tmp.path().join(name);
        run(scene, photons, &out);
        check
            .arg(&out)
            .arg(scene.map_or("-".as_ref(), |s| s.as_os_str()));
    }
    let out = check.output().expect("python runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    print!("{stdout}");
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(stdout.matches(" equal in run.nc").count(), 4, "{stdout}");
}

#[test]
fn sensitivities_nc_holds_the_numbers_of_sensitivities_csv() {
    let Some(python) = python() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("select");
    // Two atmospheres, every line with J'' <= 4 at every offset: line labels and rankings.
    let o = out.to_string_lossy().into_owned();
    lidarsim_ok([
        "select-lines",
        "--atmosphere",
        "us_standard,tropical",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--layer-m",
        "2000",
        "--top-km",
        "30",
        "--max-j",
        "4",
        "--no-plots",
        "--out",
        &o,
    ]);
    let check = Command::new(&python)
        .arg(project_root().join("tests/netcdf_check.py"))
        .arg("--sensitivities")
        .arg(&out)
        .output()
        .expect("python runs");
    let stdout = String::from_utf8_lossy(&check.stdout);
    print!("{stdout}");
    assert!(
        check.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&check.stderr)
    );
    assert!(stdout.contains("sensitivity rows equal"), "{stdout}");
}

#[test]
fn dial_nc_files_hold_the_numbers_of_profiles_and_summary_csv() {
    let Some(python) = python() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("study.toml");
    std::fs::write(&scene, crate::study::SCENE).unwrap();
    let out = tmp.path().join("dial");
    // The study scene of tests/study.rs, analytic: 4 profiles of each class and the class
    // `all`, two line pairs (text columns, fill values where a group's spread is undefined).
    let (sc, o) = (
        scene.to_string_lossy().into_owned(),
        out.to_string_lossy().into_owned(),
    );
    lidarsim_ok([
        "dial",
        &sc,
        "--ensemble",
        "4",
        "--on",
        "on,side",
        "--no-plots",
        "--out",
        &o,
    ]);
    let check = Command::new(&python)
        .arg(project_root().join("tests/netcdf_check.py"))
        .arg("--dial")
        .arg(&out)
        .output()
        .expect("python runs");
    let stdout = String::from_utf8_lossy(&check.stdout);
    print!("{stdout}");
    assert!(
        check.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&check.stderr)
    );
    assert!(
        stdout.contains("24 profile rows equal in profiles.nc"),
        "{stdout}"
    );
    assert!(
        stdout.contains("summary rows equal in summary.nc"),
        "{stdout}"
    );
}
