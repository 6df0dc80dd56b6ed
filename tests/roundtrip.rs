//! Issue 37, item 6: every file lidarsim writes is read back, by lidarsim where it has a
//! reader for it, and otherwise by a standard parser (the `csv` crate, `netcdf3`, serde_json):
//!
//! * CSV text fields with commas, double quotes and line breaks (channel names, and the line
//!   pairs made of them) through `run`, `dial` and the merge of shards, against the names the
//!   scene gave;
//! * profile sets: `profiles generate` → `profiles info`, `dial --profiles`, `select-lines
//!   --profiles`; `profiles convert` → `profiles info`; a covariance written with
//!   `--covariance-out` and read with `--covariance` gives the same ensemble;
//! * shard files: `run --shard` → `merge`, from a directory whose path holds a space, a comma, a
//!   quote and non-ASCII text, for a scene with such channel names;
//! * `mie --distribution` phase and matrix tables → a scene's `phase = { kind = "table" }` and
//!   `{ kind = "matrix_table" }`, against the backscatter `mie` printed;
//! * `lbl --save-table` → the gas optical-depth table reader, against the CSV `lbl` wrote;
//! * an output path that is not a regular file (a FIFO) is not replaced.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::util::path_arg as s;
use crate::util::{
    absolute_paths, check_csv_text, check_written, lidarsim, lidarsim_ok, project_root, read_csv,
    shared_file,
};

/// The distinct values of column `name`.
fn column(path: &Path, name: &str) -> BTreeSet<String> {
    let (header, rows) = read_csv(path);
    let k = header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("{}: no column {name} in {header:?}", path.display()));
    rows.into_iter().map(|r| r[k].clone()).collect()
}

/// A text variable of a NetCDF-3 file (a char array, one row per value, padded with NULs).
fn netcdf_texts(path: &Path, variable: &str, count: usize) -> BTreeSet<String> {
    let mut r = netcdf3::FileReader::open(path).unwrap();
    let v = r.read_var(variable).unwrap();
    let bytes: Vec<u8> = match v {
        netcdf3::DataVector::U8(b) => b,
        netcdf3::DataVector::I8(b) => b.into_iter().map(|x| x as u8).collect(),
        other => panic!("{variable}: not text: {other:?}"),
    };
    assert!(
        count > 0 && bytes.len().is_multiple_of(count),
        "{variable}: {} bytes",
        bytes.len()
    );
    bytes
        .chunks(bytes.len() / count)
        .map(|row| {
            let end = row.iter().position(|&b| b == 0).unwrap_or(row.len());
            String::from_utf8(row[..end].to_vec()).unwrap()
        })
        .collect()
}

/// Names with every character RFC 4180 quotes (comma, double quote, line break) and non-ASCII.
const ON: &str = "on, \"R16e\"\nline µ";
const OFF: &str = "off,ref";

/// The airborne DIAL scene with its channels so named (the retrieval's `on` and `off` given),
/// its relative paths absolute.
fn quoted_scene() -> String {
    let text = absolute_paths(
        &std::fs::read_to_string(project_root().join("scenes/airborne_co2_dial.toml")).unwrap(),
    );
    let toml = |v: &str| toml::Value::String(v.into()).to_string();
    let out = text
        .replace("name = \"on\"", &format!("name = {}", toml(ON)))
        .replace("name = \"off\"", &format!("name = {}", toml(OFF)))
        .replace(
            "target = \"surface\"",
            &format!(
                "target = \"surface\"\non = {}\noff = {}",
                toml(ON),
                toml(OFF)
            ),
        );
    assert_ne!(out, text);
    out
}

/// Channel names with commas, quotes and line breaks come back from every CSV and from run.nc
/// as the scene gave them; every file written parses and holds finite numbers.
#[test]
fn channel_names_with_commas_quotes_and_line_breaks_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("quoted.toml");
    std::fs::write(&scene, quoted_scene()).unwrap();
    let out = dir.path().join("out");
    lidarsim_ok([
        "run",
        &s(&scene),
        "--photons",
        "2000",
        "--no-plots",
        "--out",
        &s(&out),
    ]);
    let names: BTreeSet<String> = [ON, OFF].map(String::from).into();
    for file in ["returns.csv", "signals.csv"] {
        assert_eq!(column(&out.join(file), "channel"), names, "{file}");
    }
    let pairs = column(&out.join("retrieval.csv"), "channel_pair");
    assert_eq!(pairs, [format!("{ON}/{OFF}")].into(), "retrieval.csv");
    assert_eq!(
        netcdf_texts(&out.join("run.nc"), "channel", 2),
        names,
        "run.nc"
    );
    check_written(&out).unwrap();
}

/// The same names through `dial`: its tables' line pairs and the NetCDF files.
#[test]
fn dial_line_pairs_with_quoted_names_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("quoted.toml");
    std::fs::write(&scene, quoted_scene()).unwrap();
    let out = dir.path().join("study");
    lidarsim_ok([
        "dial",
        &s(&scene),
        "--ensemble",
        "2",
        "--class",
        "mid",
        "--photons",
        "0",
        "--no-plots",
        "--threads",
        "1",
        "--out",
        &s(&out),
    ]);
    let pair: BTreeSet<String> = [format!("{ON}/{OFF}")].into();
    for file in ["profiles.csv", "summary.csv", "budget.csv"] {
        assert_eq!(column(&out.join(file), "pair"), pair, "{file}");
    }
    // profiles.nc has the pairs on their own dimension (one here).
    assert_eq!(netcdf_texts(&out.join("profiles.nc"), "pair", 1), pair);
}

/// `profiles generate` → `profiles info` (lidarsim's reader): the same ids, level counts and
/// surface pressures as the file read by a standard CSV parser; → `dial --profiles` and
/// `select-lines --profiles --per-profile`: one entry per id of the set.
#[test]
fn generated_profile_sets_are_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("set.csv");
    lidarsim_ok([
        "profiles",
        "generate",
        "--class",
        "tropical",
        "--n",
        "3",
        "--seed",
        "11",
        "--out",
        &s(&set),
    ]);
    // The set as a standard parser reads it: per id, its levels and first pressure.
    let (header, rows) = read_csv(&set);
    let col = |n: &str| header.iter().position(|h| h == n).unwrap();
    let (id, p) = (col("profile"), col("pressure_hPa"));
    let mut expected: Vec<(String, usize, f64)> = Vec::new();
    for r in &rows {
        match expected.last_mut() {
            Some(e) if e.0 == r[id] => e.1 += 1,
            _ => expected.push((r[id].clone(), 1, r[p].parse().unwrap())),
        }
    }
    assert_eq!(expected.len(), 3);
    let info = lidarsim_ok(["profiles", "info", &s(&set)]);
    check_csv_text("profiles info", &info).unwrap();
    let mut r = csv::Reader::from_reader(info.as_bytes());
    let got: Vec<(String, usize, f64)> = r
        .records()
        .map(|rec| {
            let rec = rec.unwrap();
            (
                rec[0].to_string(),
                rec[3].parse().unwrap(),
                rec[4].parse().unwrap(),
            )
        })
        .collect();
    assert_eq!(got.len(), expected.len());
    for (g, e) in got.iter().zip(&expected) {
        assert_eq!((&g.0, g.1), (&e.0, e.1));
        // Printed with two decimals in hPa.
        assert!((g.2 - e.2).abs() <= 0.005 + 1e-9, "{g:?} against {e:?}");
    }
    let ids: BTreeSet<String> = expected.iter().map(|e| e.0.clone()).collect();
    let study = dir.path().join("study");
    lidarsim_ok([
        "dial",
        &s(&project_root().join("scenes/study_co2_ipda.toml")),
        "--profiles",
        &s(&set),
        "--no-plots",
        "--threads",
        "1",
        "--out",
        &s(&study),
    ]);
    assert_eq!(column(&study.join("profiles.csv"), "profile_id"), ids);
    let sel = dir.path().join("select");
    lidarsim_ok([
        "select-lines",
        "--profiles",
        &s(&set),
        "--per-profile",
        "--on-cm1",
        "6360.04",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--top-km",
        "30",
        "--layer-m",
        "1000",
        "--no-plots",
        "--threads",
        "1",
        "--out",
        &s(&sel),
    ]);
    let atmospheres = column(&sel.join("sensitivities.csv"), "atmosphere");
    assert!(ids.is_subset(&atmospheres), "{ids:?} in {atmospheres:?}");
}

/// A covariance written by `--covariance-out` and read back by `--covariance` gives the same
/// ensemble (same mean, seed and members) to the digits the set is written with.
#[test]
fn a_written_covariance_gives_the_same_ensemble() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| s(&dir.path().join(n));
    lidarsim_ok([
        "profiles",
        "generate",
        "--class",
        "mid",
        "--n",
        "3",
        "--seed",
        "9",
        "--out",
        &d("a.csv"),
        "--covariance-out",
        &d("cov.csv"),
    ]);
    lidarsim_ok([
        "profiles",
        "generate",
        "--class",
        "mid",
        "--n",
        "3",
        "--seed",
        "9",
        "--out",
        &d("b.csv"),
        "--covariance",
        &d("cov.csv"),
    ]);
    let (ha, a) = read_csv(&dir.path().join("a.csv"));
    let (hb, b) = read_csv(&dir.path().join("b.csv"));
    assert_eq!(ha, hb);
    assert_eq!(a.len(), b.len());
    for (ra, rb) in a.iter().zip(&b) {
        for ((x, y), h) in ra.iter().zip(rb).zip(&ha) {
            match (x.parse::<f64>(), y.parse::<f64>()) {
                (Ok(x), Ok(y)) => assert!(
                    (x - y).abs() <= 1e-7 * x.abs().max(1e-300),
                    "{h}: {x} against {y}"
                ),
                _ => assert_eq!(x, y, "{h}"),
            }
        }
    }
}

/// `profiles convert` → `profiles info`: every converted profile read back, with the level
/// count and surface pressure of the written file ("tests only" data of ../shared).
#[test]
fn converted_profile_sets_are_read_back() {
    let (Some(levels), Some(meta)) = (
        shared_file("data/profiles/ecmwf83_matricardi2008_101L.csv"),
        shared_file("data/profiles/ecmwf83_matricardi2008_meta.csv"),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("ecmwf83.csv");
    lidarsim_ok([
        "profiles",
        "convert",
        "--format",
        "ecmwf83",
        "--levels",
        &s(&levels),
        "--meta",
        &s(&meta),
        "--out",
        &s(&set),
    ]);
    let (header, rows) = read_csv(&set);
    let id = header.iter().position(|h| h == "profile").unwrap();
    let p = header.iter().position(|h| h == "pressure_hPa").unwrap();
    let mut expected: Vec<(String, usize, f64)> = Vec::new();
    for r in &rows {
        // The ids of ECMWF 83 are numbers: the set marks them as text (`'1`; README, "Text
        // in CSV files").
        let name = lidarsim::output::csv_text_value(&r[id]);
        assert_eq!(r[id], format!("'{name}"));
        assert!(name.parse::<u32>().is_ok(), "{name}");
        match expected.last_mut() {
            Some(e) if e.0 == name => e.1 += 1,
            _ => expected.push((name.to_string(), 1, r[p].parse().unwrap())),
        }
    }
    // The 80 located profiles of Matricardi (2008) (81–83 are the envelopes and the mean).
    assert_eq!(expected.len(), 80);
    let info = lidarsim_ok(["profiles", "info", &s(&set)]);
    let mut r = csv::Reader::from_reader(info.as_bytes());
    let got: Vec<csv::StringRecord> = r.records().map(Result::unwrap).collect();
    assert_eq!(got.len(), 80);
    for (g, e) in got.iter().zip(&expected) {
        // `profiles info` marks an id that reads as a number as the set does (`'1`).
        assert_eq!(lidarsim::output::csv_text_value(&g[0]), e.0);
        assert_eq!(g[3].parse::<usize>().unwrap(), e.1, "{}", e.0);
        let ps: f64 = g[4].parse().unwrap();
        assert!(
            (ps - e.2).abs() <= 0.005 + 1e-9,
            "{}: {ps} against {}",
            e.0,
            e.2
        );
    }
}

/// The output of `lidarsim run SCENE` (returns.csv) for `photons` with `extra` options.
fn run_returns(scene: &Path, out: &Path, extra: &[&str]) -> Vec<u8> {
    let mut args = vec![
        "run".to_string(),
        s(scene),
        "--no-plots".into(),
        "--out".into(),
        s(out),
    ];
    args.extend(extra.iter().map(|a| a.to_string()));
    lidarsim_ok(&args);
    std::fs::read(out.join("returns.csv")).unwrap()
}

/// A small scene with the quoted channel names: C.1's cloud, 2 fields of view, 5 gates.
fn small_quoted_scene(photons: u64) -> String {
    let toml = |v: &str| toml::Value::String(v.into()).to_string();
    format!(
        r#"description = "C.1, small, quoted names"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0, 5.0]

[[channel]]
name = {}
wavelength_nm = 1064.0

[[channel]]
name = {}
wavelength_nm = 1064.0

[gates]
start_m = 1000.0
end_m = 1100.0
width_m = 20.0

[[layer]]
name = "cloud, \"C.1\""
base_m = 1000.0
top_m = 1300.0
extinction_per_km = 17.23
single_scattering_albedo = 0.999908
phase = {{ kind = "table", file = "c1 table.txt" }}

[simulation]
photons = {photons}
batches = 4
seed = 1
max_order = 3
"#,
        toml(ON),
        toml(OFF)
    )
}

/// A directory for shards and scenes whose path holds a space, a comma, a quote and non-ASCII
/// text, with the C.1 table beside the scene under a name with a space.
fn odd_directory(root: &Path) -> PathBuf {
    let dir = root.join("a b, \"c\" µ");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(
        project_root().join("phase_functions/bissonnette_c1_1064nm.txt"),
        dir.join("c1 table.txt"),
    )
    .unwrap();
    dir
}

/// `run --shard` → `merge`, from a directory with an odd name, for a scene with quoted
/// channel names and a phase table beside it: the merge gives the single run's bytes.
#[test]
fn shards_from_an_odd_directory_merge_into_the_single_run() {
    let root = tempfile::tempdir().unwrap();
    let dir = odd_directory(root.path());
    let scene = dir.join("scene, \"q\".toml");
    std::fs::write(&scene, small_quoted_scene(400)).unwrap();
    let single = run_returns(&scene, &dir.join("single"), &["--photons", "400"]);
    let shards = dir.join("shards");
    for spec in ["0/2", "1/2"] {
        lidarsim_ok([
            "run",
            &s(&scene),
            "--shard",
            spec,
            "--photons",
            "400",
            "--out",
            &s(&shards),
        ]);
    }
    let merged = dir.join("merged");
    lidarsim_ok(["merge", &s(&shards), "--no-plots", "--out", &s(&merged)]);
    assert!(std::fs::read(merged.join("returns.csv")).unwrap() == single);
    assert_eq!(
        column(&merged.join("returns.csv"), "channel"),
        [ON, OFF].map(String::from).into()
    );
}

/// FUZZ_FINDINGS.md F3: shards run with the scene's own photon count (no `--photons`) merge.
#[test]
fn shards_run_with_the_scenes_own_photons_merge() {
    let root = tempfile::tempdir().unwrap();
    let dir = odd_directory(root.path());
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, small_quoted_scene(400)).unwrap();
    let single = run_returns(&scene, &dir.join("single"), &[]);
    let shards = dir.join("shards");
    for spec in ["0/2", "1/2"] {
        lidarsim_ok(["run", &s(&scene), "--shard", spec, "--out", &s(&shards)]);
    }
    let merged = dir.join("merged");
    let o = lidarsim(["merge", &s(&shards), "--no-plots", "--out", &s(&merged)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::read(merged.join("returns.csv")).unwrap() == single);
}

/// The analytic single-scatter return of the gate at 1010 m, first field of view, of `scene`
/// with the layer's phase function replaced by `phase`.
fn analytic_first_gate(dir: &Path, name: &str, phase: &str) -> f64 {
    let text = small_quoted_scene(400).replace(
        "phase = { kind = \"table\", file = \"c1 table.txt\" }",
        phase,
    );
    let scene = dir.join(format!("{name}.toml"));
    std::fs::write(&scene, text).unwrap();
    let out = dir.join(name);
    run_returns(&scene, &out, &["--photons", "0"]);
    let (header, rows) = read_csv(&out.join("returns.csv"));
    let e = header.iter().position(|h| h == "energy_j").unwrap();
    rows.iter()
        .find(|r| r[0] == "analytic" && r[3] == "1010")
        .map(|r| r[e].parse().unwrap())
        .expect("the analytic row of the gate at 1010 m")
}

/// `mie --distribution` → its phase table and matrix table in a scene: the single-scatter
/// return against an isotropic layer of the same extinction and albedo is P(180°) in units of
/// the isotropic 1 (the lidar equation's only difference), with P(180°) as `mie` printed it
/// (`phase_180`); the table as read by lidarsim holds that value; F11 of the matrix table gives
/// the same return (it is renormalised to 1 over the sphere: within its last per cent).
#[test]
fn mie_tables_read_back_in_a_scene() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n);
    std::fs::copy(
        project_root().join("phase_functions/bissonnette_c1_1064nm.txt"),
        d("c1 table.txt"),
    )
    .unwrap();
    let json = lidarsim_ok([
        "mie",
        "--distribution",
        "lognormal",
        "--refractive-index",
        "1.5+0.01i",
        "--wavelength-nm",
        "1064",
        "--median-radius-um",
        "0.3",
        "--sigma-g",
        "1.6",
        "--out",
        &s(&d("phase, \"a\".txt")),
        "--matrix-out",
        &s(&d("matrix µ.txt")),
    ]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let p180 = v["phase_180"].as_f64().unwrap();
    assert!(p180 > 0.0 && p180.is_finite(), "{json}");
    let table = lidarsim::particles::table::PhaseTable::read(&d("phase, \"a\".txt")).unwrap();
    let last = *table.phase_4pi.last().unwrap();
    assert_eq!(*table.theta_deg.last().unwrap(), 180.0);
    assert!((last / p180 - 1.0).abs() < 1e-6, "table {last}, mie {p180}");
    lidarsim::particles::matrix_table::MatrixTable::read(&d("matrix µ.txt")).unwrap();
    let toml = |p: &Path| toml::Value::String(s(p)).to_string();
    let iso = analytic_first_gate(dir.path(), "iso", "phase = { kind = \"isotropic\" }");
    let tab = analytic_first_gate(
        dir.path(),
        "tab",
        &format!(
            "phase = {{ kind = \"table\", file = {} }}",
            toml(&d("phase, \"a\".txt"))
        ),
    );
    let mat = analytic_first_gate(
        dir.path(),
        "mat",
        &format!(
            "phase = {{ kind = \"matrix_table\", file = {} }}",
            toml(&d("matrix µ.txt"))
        ),
    );
    // The table's values have 9 significant digits, returns.csv 10; the table is renormalised
    // to 1 over the sphere (it is within 2e-5 as written).
    assert!(
        (tab / iso / p180 - 1.0).abs() < 1e-4,
        "{tab} / {iso} against {p180}"
    );
    assert!(
        (mat / tab - 1.0).abs() < 1e-2,
        "matrix {mat} against table {tab}"
    );
}

/// `lbl --save-table` → the gas optical-depth table reader: every layer's τ at every wavenumber
/// as the CSV beside it says (12 significant digits), and the layer edges.
#[test]
fn an_lbl_table_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let (csv_path, bin) = (dir.path().join("tau.csv"), dir.path().join("tau.bin"));
    lidarsim_ok([
        "lbl",
        "--atmosphere",
        "us_standard",
        "--sensor-altitude-m",
        "8000",
        "--zenith-deg",
        "180",
        "--layer-m",
        "1000",
        "--start-cm1",
        "6359.5",
        "--end-cm1",
        "6360.5",
        "--step-cm1",
        "0.05",
        "--out",
        &s(&csv_path),
        "--save-table",
        &s(&bin),
    ]);
    let table = lidarsim::spectroscopy::GasOpticalDepthTable::load(&bin).unwrap();
    let (header, rows) = read_csv(&csv_path);
    let col = |n: &str| header.iter().position(|h| h == n).unwrap();
    let (nu, bottom, tau) = (col("wavenumber_cm1"), col("bottom_m"), col("tau_vertical"));
    assert_eq!(table.grid.len, 21);
    assert_eq!(table.edges_m.len(), 9);
    assert_eq!(rows.len(), table.grid.len * 8);
    for (k, r) in rows.iter().enumerate() {
        let (i, l) = (k / 8, k % 8);
        let x: f64 = r[nu].parse().unwrap();
        assert!((x - table.grid.at(i)).abs() < 1e-6, "row {k}");
        assert_eq!(
            r[bottom].parse::<f64>().unwrap(),
            table.edges_m[l],
            "row {k}"
        );
        let t: f64 = r[tau].parse().unwrap();
        let want = table.tau_at_grid(l, i);
        assert!(
            (t - want).abs() <= 1e-11 * want.abs(),
            "row {k}: csv {t}, table {want}"
        );
    }
}

/// FUZZ_FINDINGS.md F12: an output path that is a FIFO is written through or refused, never
/// replaced by a regular file (`--out /dev/null` replaced the device when run as root).
#[cfg(unix)]
#[test]
fn an_output_that_is_a_fifo_is_not_replaced() {
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("out.csv");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        println!("skipped: mkfifo is absent");
        return;
    }
    // A reader, so that a write through the FIFO does not block (O_NONBLOCK: the open does not
    // wait for a writer).
    let _reader = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(0o4000)
        .open(&fifo)
        .unwrap();
    let ran = crate::util::lidarsim_bounded(
        &[
            "lbl",
            "--pressure-atm",
            "1",
            "--temperature-k",
            "296",
            "--start-cm1",
            "6359",
            "--end-cm1",
            "6361",
            "--step-cm1",
            "0.01",
            "--out",
        ]
        .iter()
        .map(Into::into)
        .chain([fifo.clone().into()])
        .collect::<Vec<_>>(),
        dir.path(),
        dir.path(),
        std::time::Duration::from_secs(20),
    )
    .unwrap();
    assert!(matches!(ran.code, Some(0 | 2)), "{}", ran.stderr);
    let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
    assert!(
        kind.is_fifo(),
        "exit {:?}: the FIFO was replaced by a regular file",
        ran.code
    );
}
