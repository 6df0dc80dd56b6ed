//! The command line: `lidarsim run` writes exactly the contract columns, reports bad input with
//! file, line and key and exit code 2, and writes nothing half-way.

use crate::util::{lidarsim, lidarsim_ok};

const HEADER: &str =
    "source,channel,fov_full_angle_mrad,range_m,order,energy_j,stderr_j,polarisation";

#[test]
fn run_default_scene_writes_contract_columns() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().to_string_lossy().into_owned();
    let stdout = lidarsim_ok([
        "run",
        "--photons",
        "2000",
        "--seed",
        "3",
        "--threads",
        "1",
        "--out",
        &out_dir,
    ]);
    assert!(stdout.contains("transport: 2000 photons"), "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("returns.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(HEADER));
    let (mut mc, mut analytic) = (0, 0);
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 8, "{line}");
        assert_eq!(f[7], "total", "{line}");
        let energy: f64 = f[5].parse().unwrap();
        let stderr: f64 = f[6].parse().unwrap();
        let _: f64 = f[2].parse().unwrap();
        let _: f64 = f[3].parse().unwrap();
        assert!(energy >= 0.0 && energy.is_finite(), "{line}");
        match f[0] {
            "mc" => {
                mc += 1;
                assert!(
                    f[4] == "total"
                        || ["st+", "nd+", "rd+", "th+", "st", "nd", "rd", "th"]
                            .iter()
                            .any(|s| f[4]
                                .strip_suffix(s)
                                .is_some_and(|n| n.parse::<u32>().is_ok())),
                    "{line}"
                );
            }
            "analytic" => {
                analytic += 1;
                assert_eq!(f[4], "1st", "{line}");
                assert_eq!(stderr, 0.0, "{line}");
            }
            other => panic!("source {other}"),
        }
    }
    // Default scene: 2 lines, 2 FOVs, 201 gates; MC orders total, 1..5, 6+ and 2+.
    assert_eq!(analytic, 2 * 2 * 201);
    assert_eq!(mc, 2 * 2 * 201 * 8);
    assert!(dir.path().join("summary.json").is_file());
}

/// Run the default scene with one replacement as `bad.toml`; require exit code 2, one line on
/// stderr naming the file, and no output directory. Returns stderr.
fn run_broken_default_scene(from: &str, to: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("bad.toml");
    let good = lidarsim::scene::DEFAULT_SCENE_TOML;
    let text = good.replacen(from, to, 1);
    assert_ne!(text, good, "the default scene changed: update this test");
    std::fs::write(&scene, text).unwrap();
    let out_dir = dir.path().join("out");
    let out = lidarsim([
        "run".as_ref(),
        scene.as_os_str(),
        "--out".as_ref(),
        out_dir.as_os_str(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        stderr.starts_with("lidarsim: error: ") && stderr.contains("bad.toml:"),
        "{stderr}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        !out_dir.exists(),
        "an output directory was created for a failed run"
    );
    stderr
}

#[test]
fn bad_scene_exits_2_naming_file_line_and_key_and_writes_nothing() {
    let stderr = run_broken_default_scene("pulse_energy_j = 0.03", "pulse_energy_j = -1");
    assert!(
        stderr.contains("`laser.pulse_energy_j`: -1 must lie in [1e-15, 1000]"),
        "{stderr}"
    );
}

#[test]
fn bench_reports_figure_of_merit() {
    let stdout = lidarsim_ok([
        "bench",
        "--photons",
        "5000",
        "--repeat",
        "1",
        "--threads",
        "1",
    ]);
    assert!(stdout.contains("FOM"), "{stdout}");
}

/// The cloudy study benchmark runs the study with a cirrus by Monte Carlo and reports the
/// transport's time and share; `--study-photons` goes with `--cloudy` only.
#[test]
fn bench_cloudy_study_reports_the_transport() {
    let stdout = lidarsim_ok([
        "bench",
        "--study",
        "1",
        "--cloudy",
        "--study-photons",
        "200",
        "--repeat",
        "1",
        "--threads",
        "1",
    ]);
    assert!(
        stdout.contains("cirrus") && stdout.contains("transport_share"),
        "{stdout}"
    );
    let row = stdout.lines().last().unwrap_or_default();
    assert!(row.trim_end().ends_with('%'), "{stdout}");
    let o = lidarsim(["bench", "--study", "1", "--study-photons", "200"]);
    assert_eq!(o.status.code(), Some(2), "{o:?}");
}

#[test]
fn zero_photons_runs_the_analytic_equation_only() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().to_string_lossy().into_owned();
    lidarsim_ok(["run", "--photons", "0", "--out", &out_dir]);
    let csv = std::fs::read_to_string(dir.path().join("returns.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(HEADER));
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 2 * 2 * 201);
    assert!(rows.iter().all(|r| r.starts_with("analytic,")));
}

/// The default scene (space-borne IPDA) prints the truth, the retrieved XCO2, its bias and the
/// random error per shot pair and per averaging length, and writes signals.csv, retrieval.csv
/// (documented columns, one row per product) and the figures beside returns.csv.
#[test]
fn default_scene_retrieves_xco2_and_writes_signals_retrieval_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().to_string_lossy().into_owned();
    let stdout = lidarsim_ok([
        "run",
        "--photons",
        "2000",
        "--threads",
        "1",
        "--out",
        &out_dir,
    ]);
    for words in [
        "truth XCO2 = ",
        "retrieved ",
        "bias ",
        "ppm per shot pair",
        "ppm averaged",
        "50 km along track (347 shot pairs)",
    ] {
        assert!(stdout.contains(words), "`{words}` missing from:\n{stdout}");
    }
    let signals = std::fs::read_to_string(dir.path().join("signals.csv")).unwrap();
    let mut lines = signals.lines();
    assert_eq!(
        lines.next(),
        Some(lidarsim::instrument::signals::CSV_HEADER)
    );
    // analytic order 1, MC order 1 and all orders × 2 lines × 2 FOVs × 201 gates.
    assert_eq!(lines.count(), 3 * 2 * 2 * 201);
    let retrieval = std::fs::read_to_string(dir.path().join("retrieval.csv")).unwrap();
    let mut lines = retrieval.lines();
    let header = lines.next().unwrap();
    assert_eq!(header, lidarsim::retrieval::products::CSV_HEADER);
    let columns: Vec<&str> = header.split(',').collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // IPDA mixing ratio and slant column × 3 sets of returns × 2 FOVs.
    assert_eq!(rows.len(), 2 * 3 * 2);
    let col = |name: &str| columns.iter().position(|c| *c == name).unwrap();
    for r in &rows {
        assert_eq!(r.len(), columns.len());
        // Each row's values in the columns of its quantity's unit, the others empty.
        let unit = match r[col("quantity")] {
            "mixing_ratio" => "ppm",
            "slant_column" => "molecules_per_m2",
            q => panic!("quantity {q}"),
        };
        for other in ["ppm", "molecules_per_m2", "molecules_per_m3"] {
            if other != unit {
                assert_eq!(r[col(&format!("truth_{other}"))], "", "{r:?}");
            }
        }
        let truth: f64 = r[col(&format!("truth_{unit}"))].parse().unwrap();
        let retrieved: f64 = r[col(&format!("retrieved_{unit}"))].parse().unwrap();
        let bias: f64 = r[col(&format!("bias_{unit}"))].parse().unwrap();
        assert!((retrieved - truth - bias).abs() <= 1e-9 * truth.abs());
        if unit == "ppm" {
            assert!((truth - 420.0).abs() < 0.1, "{truth}");
        }
    }
    // No DIAL in the default scene: the returns figure only.
    let bytes = std::fs::read(dir.path().join("returns.png")).unwrap();
    assert_eq!(&bytes[1..4], b"PNG");
    assert!(!dir.path().join("dial.png").exists());
}

/// A retrieval that cannot be done stops the run with one message naming the scene key, and
/// writes nothing.
#[test]
fn impossible_retrieval_exits_2_and_writes_nothing() {
    // Swap the lines: the "on-line" then absorbs less than the "off-line".
    let stderr =
        run_broken_default_scene("on = \"on\"\noff = \"off\"", "on = \"off\"\noff = \"on\"");
    assert!(stderr.contains("`retrieval.on`"), "{stderr}");
    assert!(
        stderr.contains("absorbs no more than the off-line"),
        "{stderr}"
    );
}

/// A reader that stops early (`lidarsim profiles info SET | head -1`) ends the command quietly:
/// exit 0, no panic ("failed printing to stdout"). The listing of 3000 profiles is larger than
/// a pipe's buffer, so the write after the reader has gone fails.
#[test]
fn a_closed_pipe_ends_a_listing_quietly() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("ens.csv");
    lidarsim_ok([
        "profiles".as_ref(),
        "generate".as_ref(),
        "--n".as_ref(),
        "3000".as_ref(),
        "--seed".as_ref(),
        "1".as_ref(),
        "--class".as_ref(),
        "mid".as_ref(),
        "--out".as_ref(),
        set.as_os_str(),
    ]);
    let mut child = crate::util::lidarsim_command()
        .args(["profiles".as_ref(), "info".as_ref(), set.as_os_str()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    // The reader (and the pipe) is dropped here, after one line.
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(first.starts_with("id,"), "{first}");
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
