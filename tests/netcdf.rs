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
    assert_eq!(orders, ["total", "1", "2+"]);
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
    for row in &rows {
        assert_eq!(row[col("source")], "mc");
        // The derivative per relative change of the gases is the CSV's only.
        if row[col("quantity")] == "gas_amount" {
            continue;
        }
        let l = findf(&layer, &row[col("layer")]);
        let idx = [
            find(&channels, &row[col("channel")]),
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
            row[col("derivative")],
            "{row:?}"
        );
        assert_eq!(format!("{:.9e}", stderr[k]), row[col("stderr")], "{row:?}");
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
