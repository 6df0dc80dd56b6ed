//! `run.nc` opened by real NetCDF clients (xarray and netCDF4-python, `tests/netcdf_check.py`):
//! every number equals the CSV files beside it, and the CF attributes are there; so do `sensitivities.nc` of `lidarsim select-lines` and `profiles.nc` and
//! `summary.nc` of `lidarsim dial`. `run.nc`'s Jacobians against `jacobians.csv` are read
//! here too, by the `netcdf3` crate's reader, without Python. Without Python, xarray or netCDF4 the test prints one line and skips, except in CI
//! (`CI` set), where `.ci/run` installs them and their absence is a failure.

use std::path::Path;
use std::process::Command;

use crate::util::{check_netcdf, lidarsim_ok, project_root, read_csv};

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
    // With Jacobians (jacobians.csv, jacobian_j_m).
    let jacobians = tmp.path().join("jacobians.toml");
    std::fs::write(&jacobians, JACOBIAN_SCENE).unwrap();
    let cases: [(Option<&Path>, &str, &str); 5] = [
        (None, "20000", "default"),
        (Some(&airborne), "2000", "airborne"),
        (Some(&c1_path), "2000", "c1"),
        (Some(&airborne), "0", "analytic"),
        (Some(&jacobians), "4000", "jacobians"),
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
    assert_eq!(stdout.matches(" equal in run.nc").count(), 5, "{stdout}");
    assert_eq!(
        stdout
            .matches(" jacobians.csv rows equal in jacobian_j_m")
            .count(),
        1,
        "{stdout}"
    );
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

/// A scene with Jacobians (`[simulation] jacobians = true`): two lines (one name CSV must
/// quote), two fields of view, a coarse molecular atmosphere with a cloud in it (layers with
/// molecules and with or without particles) and a cloud above its top (particles, no molecules:
/// no molecular-scattering derivative there).
const JACOBIAN_SCENE: &str = r#"description = "Jacobians in run.nc: a cloud in a coarse molecular atmosphere, a cloud above it"

[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.1
beam_divergence_full_angle_mrad = 0.2
telescope_diameter_m = 0.5
optical_efficiency = 0.5
fov_full_angle_mrad = [0.5, 2.0]

[[channel]]
name = "532, \"green\""
wavelength_nm = 532.0

[[channel]]
name = "1064"
wavelength_nm = 1064.0

[gates]
start_m = 900.0
end_m = 1500.0
width_m = 50.0

[atmosphere]
standard = "us_standard"
layer_thickness_m = 500.0
top_m = 1300.0

[[layer]]
name = "cloud"
base_m = 1000.0
top_m = 1200.0
extinction_per_km = 5.0
single_scattering_albedo = 0.99
phase = { kind = "henyey_greenstein", g = 0.8 }

[[layer]]
name = "cloud above the molecules"
base_m = 1300.0
top_m = 1450.0
extinction_per_km = 2.0
single_scattering_albedo = 0.9
phase = { kind = "henyey_greenstein", g = 0.7 }

[simulation]
max_order = 4
jacobians = true
"#;

/// Text rows of a char variable of `run.nc`, NULs stripped.
fn nc_texts(r: &mut netcdf3::FileReader, name: &str) -> Vec<String> {
    let n = r.data_set().get_var(name).unwrap().get_dims()[1].size();
    r.read_var_u8(name)
        .unwrap()
        .chunks(n)
        .map(|c| String::from_utf8(c.iter().copied().take_while(|b| *b != 0).collect()).unwrap())
        .collect()
}

/// `run.nc`'s `jacobian_j_m` and `jacobian_stderr_j_m`, read by the `netcdf3` crate, against
/// `jacobians.csv` read by the `csv` crate: each row's bin holds its derivative and error (as
/// the CSV prints them, `{:.9e}`) and its layer's edges; every bin no row names is
/// `_FillValue` (the molecular scattering of the layers above the molecular atmosphere, the
/// particle quantities of layers without particles); the layout is (channel, FOV, gate,
/// jacobian_order, layer, jacobian_quantity), channels the lines as in `energy_j`.
#[test]
fn run_nc_jacobians_are_the_rows_of_jacobians_csv() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("jacobians.toml");
    std::fs::write(&scene, JACOBIAN_SCENE).unwrap();
    let out = tmp.path().join("out");
    run(Some(&scene), "4000", &out);
    check_netcdf(&out.join("run.nc")).unwrap();
    let (header, rows) = read_csv(&out.join("jacobians.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();

    let mut r = netcdf3::FileReader::open(out.join("run.nc")).unwrap();
    let ds = r.data_set();
    let dims: Vec<String> = ds
        .get_var("jacobian_j_m")
        .unwrap()
        .get_dims()
        .iter()
        .map(|d| d.name())
        .collect();
    assert_eq!(
        dims,
        [
            "channel",
            "fov_full_angle_mrad",
            "range_m",
            "jacobian_order",
            "layer",
            "jacobian_quantity"
        ]
    );
    let fill = ds.get_var_attr_f64("jacobian_j_m", "_FillValue").unwrap()[0];
    assert_eq!(fill, 9.969_209_968_386_869e36);
    let channels = nc_texts(&mut r, "channel");
    assert_eq!(channels, ["532, \"green\"", "1064"]);
    let orders = nc_texts(&mut r, "jacobian_order");
    assert_eq!(orders, ["total", "1st", "2nd+"]);
    let quantities = nc_texts(&mut r, "jacobian_quantity");
    let fov = r.read_var_f64("fov_full_angle_mrad").unwrap();
    let range = r.read_var_f64("range_m").unwrap();
    let layer = r.read_var_f64("layer").unwrap();
    let (bottom, top) = (
        r.read_var_f64("layer_bottom_m").unwrap(),
        r.read_var_f64("layer_top_m").unwrap(),
    );
    let value = r.read_var_f64("jacobian_j_m").unwrap();
    let stderr = r.read_var_f64("jacobian_stderr_j_m").unwrap();
    let shape = [
        channels.len(),
        fov.len(),
        range.len(),
        orders.len(),
        layer.len(),
        quantities.len(),
    ];
    assert_eq!(value.len(), shape.iter().product::<usize>());

    let find = |list: &[String], x: &str| list.iter().position(|y| y == x).unwrap();
    let findf = |list: &[f64], x: &str| {
        let x: f64 = x.parse().unwrap();
        list.iter().position(|y| *y == x).unwrap()
    };
    let mut seen = vec![false; value.len()];
    // One unit per column: ∂E/∂θ of a coefficient θ [1/m] is in J m, the derivative per
    // relative change of the gases (`gas_amount`) in J; a row fills its unit's two columns
    // and leaves the other's empty.
    assert!(!header.iter().any(|h| h == "unit" || h == "derivative"));
    for row in &rows {
        assert_eq!(row[col("source")], "mc");
        let gas = row[col("quantity")] == "gas_amount";
        let (own, other) = if gas { ("j", "j_m") } else { ("j_m", "j") };
        for v in ["derivative", "stderr"] {
            assert!(
                row[col(&format!("{v}_{own}"))].parse::<f64>().is_ok()
                    && row[col(&format!("{v}_{other}"))].is_empty(),
                "{row:?}"
            );
        }
        // The derivative per relative change of the gases is the CSV's only.
        if gas {
            continue;
        }
        let l = findf(&layer, &row[col("layer")]);
        let idx = [
            // The CSV marks a name that reads as a number (`'1064`; README, "Text in CSV files").
            find(
                &channels,
                lidarsim::output::csv_text_value(&row[col("channel")]),
            ),
            findf(&fov, &row[col("fov_full_angle_mrad")]),
            findf(&range, &row[col("range_m")]),
            find(&orders, &row[col("order")]),
            l,
            find(&quantities, &row[col("quantity")]),
        ];
        let k = idx.iter().zip(shape).fold(0, |k, (i, n)| k * n + i);
        assert!(!seen[k], "two rows for one bin: {row:?}");
        seen[k] = true;
        assert_eq!(
            row[col("layer_bottom_m")].parse::<f64>().unwrap(),
            bottom[l]
        );
        assert_eq!(row[col("layer_top_m")].parse::<f64>().unwrap(), top[l]);
        assert_eq!(
            format!("{:.9e}", value[k]),
            row[col("derivative_j_m")],
            "{row:?}"
        );
        assert_eq!(
            format!("{:.9e}", stderr[k]),
            row[col("stderr_j_m")],
            "{row:?}"
        );
    }
    for (k, s) in seen.iter().enumerate() {
        if !s {
            // Undefined, or exactly 0 (light cannot reach the layer in the gate's time: the
            // CSV leaves such rows out).
            assert!(
                (value[k], stderr[k]) == (fill, fill) || (value[k], stderr[k]) == (0.0, 0.0),
                "bin {k}: {} {}",
                value[k],
                stderr[k]
            );
        }
    }
    // Undefined derivatives exist (no molecules in the top layers, no particles in the
    // lowest), and so do defined ones of every quantity.
    let missing = value.iter().filter(|v| **v == fill).count();
    assert!(missing > 0 && missing < seen.len() / 2, "{missing}");
    for q in &quantities {
        assert!(rows.iter().any(|r| r[col("quantity")] == *q), "{q}");
    }
    assert_eq!(
        (bottom[0], *top.last().unwrap()),
        (0.0, 1450.0),
        "{bottom:?} {top:?}"
    );
}

/// The CF checkers in a virtual environment (`$LIDARSIM_CF_VENV`, else `target/cf-venv`,
/// made and filled from PyPI when absent): `cfchecks` (cfchecker) and the IOOS
/// `compliance-checker`, and the CF standard-name table compliance-checker ships (cfchecks
/// would download one). `None` after one line when they cannot be installed; in CI (`CI`
/// set) that is a failure, as for xarray above (`.ci/run` installs cfchecker's UDUNITS-2
/// library).
fn cf_checkers() -> Option<(std::path::PathBuf, std::path::PathBuf)> {
    let venv = std::env::var_os("LIDARSIM_CF_VENV")
        .map_or_else(|| project_root().join("target/cf-venv"), Into::into);
    let (cfchecks, cc) = (
        venv.join("bin/cfchecks"),
        venv.join("bin/compliance-checker"),
    );
    let mut why = String::new();
    if !(cfchecks.is_file() && cc.is_file()) {
        let python = std::env::var("LIDARSIM_PYTHON").unwrap_or_else(|_| "python3".into());
        let made = Command::new(&python)
            .args(["-m", "venv"])
            .arg(&venv)
            .output()
            .is_ok_and(|o| o.status.success())
            && Command::new(venv.join("bin/python"))
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--quiet",
                    "--disable-pip-version-check",
                ])
                .args(["cfchecker", "compliance-checker"])
                .output()
                .is_ok_and(|o| o.status.success());
        if !made {
            why = format!(
                "cfchecker and compliance-checker could not be installed into {} (pip install cfchecker compliance-checker)",
                venv.display()
            );
        }
    }
    let table = Command::new(venv.join("bin/python"))
        .args([
            "-c",
            "import compliance_checker, os; print(os.path.join(os.path.dirname(compliance_checker.__file__), 'data', 'cf-standard-name-table.xml'))",
        ])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| std::path::PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()))
        .filter(|p| p.is_file());
    // cfchecker loads the UDUNITS-2 C library when it starts.
    let runs = Command::new(&cfchecks)
        .arg("--help")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("cfchecks"));
    if why.is_empty() && table.is_none() {
        why = "compliance-checker's CF standard-name table is missing".into();
    }
    if why.is_empty() && !runs {
        why = format!(
            "{} does not start (it needs the UDUNITS-2 library: apt-get install libudunits2-0)",
            cfchecks.display()
        );
    }
    if why.is_empty() {
        return Some((venv, table.unwrap()));
    }
    assert!(
        std::env::var_os("CI").is_none_or(|v| v.is_empty()),
        "CI: {why}"
    );
    println!("skipped: {why}");
    None
}

/// Every kind of NetCDF file lidarsim writes passes both CF checkers with no error:
/// `run.nc` of the default scene, the airborne DIAL (fill values), C.1 (many orders), a
/// polarised run, a run with Jacobians and an analytic-only run; `profiles.nc` and
/// `summary.nc` of `dial`; `sensitivities.nc` of `select-lines`. cfchecks (`-v 1.8`, the
/// standard-name table of compliance-checker; empty area-type and region tables, which only
/// `area_type` and `region` variables need, and lidarsim writes none) must report
/// `ERRORS detected: 0`; compliance-checker `--test=cf:1.8` must exit 0 with "All tests
/// passed!".
#[test]
fn every_netcdf_file_passes_the_cf_checkers() {
    let Some((venv, table)) = cf_checkers() else {
        return;
    };
    let root = project_root();
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let empty = t.join("empty-table.xml");
    std::fs::write(
        &empty,
        "<?xml version=\"1.0\"?><table><version_number>0</version_number><date>none</date></table>\n",
    )
    .unwrap();
    let polarised = t.join("polarised.toml");
    std::fs::write(&polarised, crate::output::POLARISED_CLOUD).unwrap();
    let jacobians = t.join("jacobians.toml");
    std::fs::write(&jacobians, JACOBIAN_SCENE).unwrap();
    let c1 = t.join("c1.toml");
    std::fs::write(
        &c1,
        std::fs::read_to_string(root.join("scenes/bissonnette_c1.toml"))
            .unwrap()
            .replace(
                "\"../phase_functions/",
                &format!("\"{}/phase_functions/", root.display()),
            ),
    )
    .unwrap();
    let airborne = root.join("scenes/airborne_co2_dial.toml");
    let mut files = Vec::new();
    let cases: [(Option<&Path>, &str, &str); 6] = [
        (None, "2000", "default"),
        (Some(&airborne), "2000", "airborne"),
        (Some(&airborne), "0", "analytic"),
        (Some(&c1), "2000", "c1"),
        (Some(&polarised), "2000", "polarised"),
        (Some(&jacobians), "2000", "jacobians"),
    ];
    for (scene, photons, name) in cases {
        let out = t.join(name);
        run(scene, photons, &out);
        files.push(out.join("run.nc"));
    }
    let study = t.join("study.toml");
    std::fs::write(&study, crate::study::SCENE).unwrap();
    let dial = t.join("dial");
    lidarsim_ok([
        "dial".as_ref(),
        study.as_os_str(),
        "--ensemble".as_ref(),
        "2".as_ref(),
        "--on".as_ref(),
        "on,side".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        dial.as_os_str(),
    ]);
    files.push(dial.join("profiles.nc"));
    files.push(dial.join("summary.nc"));
    let select = t.join("select");
    lidarsim_ok([
        "select-lines".as_ref(),
        "--atmosphere".as_ref(),
        "us_standard,tropical".as_ref(),
        "--off-cm1".as_ref(),
        "6360.61".as_ref(),
        "--co2-ppm".as_ref(),
        "420".as_ref(),
        "--on-cm1".as_ref(),
        "6358.655,6359.967".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        select.as_os_str(),
    ]);
    files.push(select.join("sensitivities.nc"));
    for f in &files {
        let out = Command::new(venv.join("bin/cfchecks"))
            .args(["-v", "1.8", "-s"])
            .arg(&table)
            .arg("-a")
            .arg(&empty)
            .arg("-r")
            .arg(&empty)
            .arg(f)
            .output()
            .expect("cfchecks runs");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains("ERRORS detected: 0"),
            "cfchecks {}:\n{text}{}",
            f.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let warnings = text.lines().filter(|l| l.starts_with("WARN")).count();
        let out = Command::new(venv.join("bin/compliance-checker"))
            .arg("--test=cf:1.8")
            .arg(f)
            .output()
            .expect("compliance-checker runs");
        let cc = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && cc.contains("All tests passed!"),
            "compliance-checker {}:\n{cc}{}",
            f.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        println!(
            "cf checks: {}: cfchecks 0 errors ({warnings} warnings), compliance-checker: all tests passed",
            f.strip_prefix(t).unwrap().display()
        );
    }
    assert_eq!(files.len(), 9);
}
