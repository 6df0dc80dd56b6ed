//! Output that is never half-written: a failed command leaves its output
//! directory as it was, with no temporary entry; CSV text fields survive a standard CSV parser.
//! The failure modes the CLI cannot reach on demand (a producer failing after the first file, a
//! rename failing midway, a simulated full disk) are tested on `OutputSet` in `src/output/`.

use std::path::{Path, PathBuf};

use crate::util::{assert_no_non_finite, file_names, lidarsim, lidarsim_bin, lidarsim_ok};

/// Every entry under `dir`, recursively, with the contents of files.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Option<Vec<u8>>)> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p.clone());
                out.push((p, None));
            } else {
                out.push((p.clone(), Some(std::fs::read(&p).unwrap())));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn run_refuses_a_directory_named_like_an_output_and_changes_nothing() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("out");
    // An earlier run's outputs, a file of the user's, and a directory named like an output.
    lidarsim_ok([
        "run".as_ref(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    std::fs::write(out.join("notes.txt"), "mine\n").unwrap();
    std::fs::remove_file(out.join("summary.json")).unwrap();
    std::fs::create_dir(out.join("summary.json")).unwrap();
    std::fs::write(out.join("summary.json/keep"), "x").unwrap();
    let before = snapshot(root.path());

    let r = lidarsim([
        "run".as_ref(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--seed".as_ref(),
        "2".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(
        err.trim_end(),
        format!(
            "lidarsim: error: cannot write {}: a directory of that name is in the way",
            out.join("summary.json").display()
        )
    );
    assert_eq!(snapshot(root.path()), before);
}

#[test]
fn a_run_replaces_every_file_of_an_earlier_run() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("out");
    std::fs::create_dir(&out).unwrap();
    for f in [
        "returns.csv",
        "signals.csv",
        "retrieval.csv",
        "summary.json",
    ] {
        std::fs::write(out.join(f), "from an earlier run\n").unwrap();
    }
    std::fs::write(out.join("notes.txt"), "mine\n").unwrap();
    lidarsim_ok([
        "run".as_ref(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    for f in [
        "returns.csv",
        "signals.csv",
        "retrieval.csv",
        "summary.json",
    ] {
        let text = std::fs::read_to_string(out.join(f)).unwrap();
        assert_ne!(text, "from an earlier run\n", "{f} is still the old one");
    }
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine\n"
    );
    assert_eq!(
        file_names(&root.path().join("out")),
        [
            "backscatter.csv",
            "notes.txt",
            "retrieval.csv",
            "returns.csv",
            "run.nc",
            "signals.csv",
            "summary.json"
        ]
    );
    assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 1);
}

/// The shell script run in a private mount namespace: a 64 KiB tmpfs holding an earlier
/// `returns.csv`, then `lidarsim run` into it (its CSV files need about 120 KiB) twice: into
/// the existing directory and into a new one. Prints the exit codes and what the tmpfs holds.
const FULL_DISK_SCRIPT: &str = r#"
D=$1; BIN=$2
mount -t tmpfs -o size=64k tmpfs "$D" || exit 0
echo mounted
mkdir "$D/out" && printf 'old\n' > "$D/out/returns.csv"
"$BIN" run --photons 0 --no-plots --out "$D/out" >/dev/null; echo "exit $?"
"$BIN" run --photons 0 --no-plots --out "$D/new" >/dev/null; echo "exit $?"
find "$D" -mindepth 1 | sort
cat "$D/out/returns.csv"
"#;

#[test]
fn a_full_disk_exits_2_and_leaves_nothing_behind() {
    let root = tempfile::tempdir().unwrap();
    let d = root.path().join("disk");
    std::fs::create_dir(&d).unwrap();
    // `unshare -rm`: a user and mount namespace, so that no root is needed where user
    // namespaces are allowed, and the tmpfs goes away with the script whatever happens.
    let r = std::process::Command::new("unshare")
        .env(crate::util::NO_MIE_CACHE.0, crate::util::NO_MIE_CACHE.1)
        .args(["-rm", "sh", "-c", FULL_DISK_SCRIPT, "sh"])
        .arg(&d)
        .arg(lidarsim_bin())
        .output();
    let stdout = r
        .as_ref()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    if !stdout.starts_with("mounted\n") {
        // The same failure, simulated through an injected writer, is tested in src/output/.
        println!("skipped: cannot mount a tmpfs here (unshare -rm, mount -t tmpfs)");
        return;
    }
    let o = r.unwrap();
    let d = d.display();
    assert_eq!(
        stdout,
        format!("mounted\nexit 2\nexit 2\n{d}/out\n{d}/out/returns.csv\nold\n")
    );
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 2, "{err}");
    for (line, dir) in lines.iter().zip(["out", "new"]) {
        assert!(
            line.starts_with(&format!("lidarsim: error: cannot write {d}/{dir}/"))
                && line.contains("No space left on device"),
            "{err}"
        );
    }
}

#[test]
fn channel_names_with_commas_quotes_and_newlines_survive_a_csv_parser() {
    let root = tempfile::tempdir().unwrap();
    let odd = "a,b \"c\"\nd";
    let scene = root.path().join("scene.toml");
    std::fs::write(
        &scene,
        r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.1
beam_divergence_full_angle_mrad = 0.2
telescope_diameter_m = 0.3
optical_efficiency = 0.5
fov_full_angle_mrad = [1.0]

[[channel]]
name = "plain"
wavelength_nm = 1064.0

[[channel]]
name = "a,b \"c\"\nd"
wavelength_nm = 532.0

[gates]
start_m = 100.0
end_m = 1000.0
width_m = 100.0

[atmosphere]
standard = "us_standard"
layer_thickness_m = 100.0

[simulation]
photons = 2000
multiple_scattering = "always"
seed = 1
max_order = 2
"#,
    )
    .unwrap();
    let out = root.path().join("out");
    lidarsim_ok([
        "run".as_ref(),
        scene.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let mut reader = csv::Reader::from_path(out.join("returns.csv")).unwrap();
    assert_eq!(
        reader.headers().unwrap(),
        vec![
            "source",
            "channel",
            "fov_full_angle_mrad",
            "range_m",
            "order",
            "energy_j",
            "stderr_j",
            "polarisation"
        ]
    );
    let mut rows = [0usize; 2];
    for rec in reader.records() {
        let rec = rec.unwrap();
        assert_eq!(rec.len(), 8);
        match &rec[1] {
            "plain" => rows[0] += 1,
            c if c == odd => rows[1] += 1,
            c => panic!("unexpected channel {c:?}"),
        }
        let e: f64 = rec[5].parse().unwrap();
        assert!(e.is_finite() && e >= 0.0);
    }
    // Both channels have the same rows: mc (9 gates × total, 1, 2, 3+, 2+) and analytic
    // (9 × 1).
    assert_eq!(rows, [9 * 5 + 9, 9 * 5 + 9]);
}

/// Found by the scene fuzz: the shipped airborne DIAL scene at 2000 photons has far DIAL cells
/// where no photon scored, and its Monte Carlo retrievals there wrote `NaN` into
/// retrieval.csv. A value that cannot be computed is an empty field; analytic rows are whole.
#[test]
fn retrieval_csv_holds_no_nan_and_leaves_what_cannot_be_computed_empty() {
    let dir = tempfile::tempdir().unwrap();
    let scene = crate::util::project_root().join("scenes/airborne_co2_dial.toml");
    lidarsim_ok([
        "run".as_ref(),
        scene.as_os_str(),
        "--photons".as_ref(),
        "2000".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        dir.path().as_os_str(),
    ]);
    let mut r = csv::Reader::from_path(dir.path().join("retrieval.csv")).unwrap();
    let header: Vec<String> = r.headers().unwrap().iter().map(str::to_string).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (mut empty_mc, mut rows) = (0, 0);
    for rec in r.records() {
        let rec = rec.unwrap();
        rows += 1;
        let analytic = &rec[col("source")] == "analytic";
        // A row's values are in the columns of its quantity's unit; the others are empty.
        let unit = match &rec[col("quantity")] {
            "mixing_ratio" => "ppm",
            "slant_column" => "molecules_per_m2",
            "number_density" => "molecules_per_m3",
            q => panic!("quantity {q}"),
        };
        let simulated = [
            format!("simulated_error_per_shot_pair_{unit}"),
            format!("simulated_error_averaged_{unit}"),
            format!("simulated_bias_averaged_{unit}"),
        ];
        if rec[col(&format!("retrieved_{unit}"))].is_empty() {
            empty_mc += 1;
        }
        for (name, field) in header.iter().zip(rec.iter()) {
            if ["method", "source", "order", "channel_pair", "quantity"].contains(&name.as_str()) {
                continue;
            }
            let other_unit = ["ppm", "molecules_per_m2", "molecules_per_m3"]
                .iter()
                .any(|u| *u != unit && name.ends_with(&format!("_{u}")));
            if other_unit {
                assert!(field.is_empty(), "`{name}` of a {unit} row: {rec:?}");
                continue;
            }
            if field.is_empty() {
                // Only Monte Carlo estimates and the simulated figures may be missing.
                assert!(
                    !analytic || simulated.contains(name),
                    "an analytic row lacks `{name}`: {rec:?}"
                );
                continue;
            }
            let v: f64 = field.parse().unwrap_or(f64::NAN);
            assert!(v.is_finite(), "`{name}` = `{field}`: {rec:?}");
        }
        if analytic {
            let truth: f64 = rec[col(&format!("truth_{unit}"))].parse().unwrap();
            let retrieved: f64 = rec[col(&format!("retrieved_{unit}"))].parse().unwrap();
            assert!((retrieved / truth - 1.0).abs() < 0.01, "{rec:?}");
        }
    }
    assert!(rows > 100, "{rows} rows");
    // The case this test is about: some far cells have no Monte Carlo signal at 2000 photons.
    assert!(empty_mc > 0, "every Monte Carlo cell had a signal");
    // And no other file of the run holds NaN or inf either.
    assert_eq!(
        assert_no_non_finite(dir.path()).len(),
        5,
        "4 CSV files (backscatter.csv too) and run.nc"
    );
}

/// A ground lidar with linear polarisation under an HG cloud at 1500–1700 m, no air: the gates
/// below the cloud receive nothing.
pub(crate) const POLARISED_CLOUD: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.5
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = 1.0
polarisation = "linear"
[[channel]]
name = "355"
wavelength_nm = 355.0
[gates]
start_m = 500.0
end_m = 3000.0
width_m = 250.0
[[layer]]
name = "cloud"
base_m = 1500.0
top_m = 1700.0
extinction_per_km = 5.0
single_scattering_albedo = 1.0
phase = { kind = "henyey_greenstein", g = 0.8 }
[simulation]
photons = 20000
max_order = 2
multiple_scattering = "always"
"#;

/// Issue 37, item 5: `depolarisation.csv` follows the contract of every CSV file: a bin with
/// no co-polarised return in returns.csv (below the cloud; above it, orders 1 and 2) has no
/// ratio, and its δ and error are empty fields (they were `NaN`); every other bin's δ is a
/// finite number ≥ 0, and no file of the run holds `NaN` or `inf`.
#[test]
fn depolarisation_csv_leaves_bins_without_a_co_polarised_return_empty() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("pol.toml");
    std::fs::write(&scene, POLARISED_CLOUD).unwrap();
    let out = dir.path().join("out");
    lidarsim_ok([
        "run".as_ref(),
        scene.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert_eq!(
        assert_no_non_finite(&out).len(),
        4,
        "three CSV files (backscatter.csv too) and run.nc"
    );
    // The co-polarised energy of every bin: (source, range, order) → J.
    let mut co = std::collections::HashMap::new();
    let mut r = csv::Reader::from_path(out.join("returns.csv")).unwrap();
    for rec in r.records() {
        let rec = rec.unwrap();
        if &rec[7] == "co" {
            let e: f64 = rec[5].parse().unwrap();
            co.insert(
                (rec[0].to_string(), rec[3].to_string(), rec[4].to_string()),
                e,
            );
        }
    }
    let mut r = csv::Reader::from_path(out.join("depolarisation.csv")).unwrap();
    let (mut empty, mut rows) = (0, 0);
    for rec in r.records() {
        let rec = rec.unwrap();
        rows += 1;
        let e = co[&(rec[0].to_string(), rec[3].to_string(), rec[4].to_string())];
        if e > 0.0 {
            let delta: f64 = rec[5].parse().unwrap();
            let se: f64 = rec[6].parse().unwrap();
            assert!(delta >= 0.0 && se >= 0.0, "{rec:?}");
        } else {
            assert_eq!((&rec[5], &rec[6]), ("", ""), "{rec:?}");
            empty += 1;
        }
    }
    assert_eq!(rows, co.len());
    // Below the cloud (4 gates) every row (Monte Carlo total, 1, 2, 3+, 2+ and the analytic
    // one); above it orders 1 and 2 of the Monte Carlo and the analytic row (5 gates).
    assert_eq!(empty, 4 * 6 + 5 * 3, "{rows} rows");
}

/// Issue 37, item 5: a second run into a directory removes the earlier run's outputs it does
/// not rewrite, with the commit, so that no stale file stays beside the new ones: the airborne
/// DIAL scene (signals, retrieval, figures, run.nc), then C.1 without `[receiver]` and
/// `[retrieval]`, `--no-netcdf`; then a merge of C.1 shards with figures off into a directory
/// holding the airborne run's files again. Files of other names (the user's `notes.txt`, a
/// `profiles.csv` that `run` never writes) stay.
#[test]
fn a_run_or_merge_removes_the_earlier_outputs_it_does_not_rewrite() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("out");
    let airborne = crate::util::project_root().join("scenes/airborne_co2_dial.toml");
    let c1 = crate::util::project_root().join("scenes/bissonnette_c1.toml");
    let first = |out: &Path| {
        lidarsim_ok([
            "run".as_ref(),
            airborne.as_os_str(),
            "--photons".as_ref(),
            "0".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ]);
        std::fs::write(out.join("notes.txt"), "mine\n").unwrap();
        std::fs::write(out.join("profiles.csv"), "mine too\n").unwrap();
        assert_eq!(
            file_names(out),
            [
                "backscatter.csv",
                "dial.png",
                "notes.txt",
                "profiles.csv",
                "retrieval.csv",
                "returns.csv",
                "returns.png",
                "run.nc",
                "signals.csv",
                "summary.json"
            ]
        );
    };
    first(&out);
    lidarsim_ok([
        "run".as_ref(),
        c1.as_os_str(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--no-netcdf".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert_eq!(
        file_names(&out),
        [
            "backscatter.csv",
            "notes.txt",
            "profiles.csv",
            "returns.csv",
            "returns.png",
            "summary.json"
        ]
    );
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine\n"
    );
    assert_eq!(
        std::fs::read_to_string(out.join("profiles.csv")).unwrap(),
        "mine too\n"
    );
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("bissonnette_c1.toml"), "{summary}");

    let merged = root.path().join("merged");
    first(&merged);
    let shards = root.path().join("shards");
    for i in 0..2 {
        lidarsim_ok([
            "run".as_ref(),
            c1.as_os_str(),
            "--photons".as_ref(),
            "400".as_ref(),
            "--shard".as_ref(),
            format!("{i}/2").as_ref(),
            "--out".as_ref(),
            shards.as_os_str(),
        ]);
    }
    lidarsim_ok([
        "merge".as_ref(),
        shards.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        merged.as_os_str(),
    ]);
    assert_eq!(
        file_names(&merged),
        [
            "backscatter.csv",
            "notes.txt",
            "profiles.csv",
            "returns.csv",
            "run.nc",
            "summary.json"
        ]
    );
    // A merge into the shards' own directory leaves the shards.
    lidarsim_ok([
        "merge".as_ref(),
        shards.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        shards.as_os_str(),
    ]);
    assert_eq!(
        file_names(&shards),
        [
            "backscatter.csv",
            "returns.csv",
            "run.nc",
            "shard-0-of-2.lshard",
            "shard-1-of-2.lshard",
            "summary.json"
        ]
    );
}

/// The same for the studies: a `dial` study with figures and NetCDF files, then one with
/// `--no-plots --no-netcdf` into the same directory; a `select-lines` study of two atmospheres
/// with figures, then of one without. The second leaves only its own files (and the user's).
#[test]
fn a_study_removes_the_earlier_studys_outputs_it_does_not_rewrite() {
    let root = tempfile::tempdir().unwrap();
    let scene = root.path().join("study.toml");
    std::fs::write(&scene, crate::study::SCENE).unwrap();
    let out = root.path().join("dial");
    let dial = |extra: &[&str]| {
        let mut args: Vec<std::ffi::OsString> = vec![
            "dial".into(),
            scene.clone().into(),
            "--ensemble".into(),
            "2".into(),
            "--class".into(),
            "mid".into(),
            "--out".into(),
            out.clone().into(),
        ];
        args.extend(extra.iter().map(|a| a.into()));
        lidarsim_ok(args)
    };
    dial(&[]);
    std::fs::write(out.join("notes.txt"), "mine\n").unwrap();
    assert!(out.join("errors.png").is_file() && out.join("profiles.nc").is_file());
    dial(&["--no-plots", "--no-netcdf"]);
    assert_eq!(
        file_names(&out),
        [
            "budget.csv",
            "failed.csv",
            "notes.txt",
            "profiles.csv",
            "summary.csv",
            "summary.json"
        ]
    );

    let out = root.path().join("select");
    let select = |atmospheres: &str, extra: &[&str]| {
        let mut args: Vec<std::ffi::OsString> = [
            "select-lines",
            "--atmosphere",
            atmospheres,
            "--on-cm1",
            "6360.04",
            "--off-cm1",
            "6360.61",
            "--co2-ppm",
            "420",
            "--layer-m",
            "2000",
        ]
        .iter()
        .map(|a| a.into())
        .collect();
        args.extend(["--out".into(), out.clone().into()]);
        args.extend(extra.iter().map(|a| a.into()));
        lidarsim_ok(args)
    };
    select("tropical,us_standard", &[]);
    std::fs::write(out.join("notes.txt"), "mine\n").unwrap();
    assert!(out.join("transmission_us_standard.png").is_file());
    select("tropical", &["--no-plots"]);
    assert_eq!(
        file_names(&out),
        [
            "failed.csv",
            "notes.txt",
            "sensitivities.csv",
            "sensitivities.nc"
        ]
    );
}
