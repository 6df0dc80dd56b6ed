//! The command line: `lidarsim run` writes exactly the contract columns, reports bad input with
//! file, line and key and exit code 2, and writes nothing half-way.

use crate::util::{lidarsim, lidarsim_ok};

const HEADER: &str = "source,channel,fov_full_angle_mrad,range_m,order,energy_j,stderr_j";

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
        assert_eq!(f.len(), 7, "{line}");
        let energy: f64 = f[5].parse().unwrap();
        let stderr: f64 = f[6].parse().unwrap();
        let _: f64 = f[2].parse().unwrap();
        let _: f64 = f[3].parse().unwrap();
        assert!(energy >= 0.0 && energy.is_finite(), "{line}");
        match f[0] {
            "mc" => {
                mc += 1;
                assert!(
                    f[4] == "total" || f[4].trim_end_matches('+').parse::<u32>().is_ok(),
                    "{line}"
                );
            }
            "analytic" => {
                analytic += 1;
                assert_eq!(f[4], "1", "{line}");
                assert_eq!(stderr, 0.0, "{line}");
            }
            other => panic!("source {other}"),
        }
    }
    // Default scene: 2 lines, 2 FOVs, 201 gates; MC orders total, 1..5, 6+.
    assert_eq!(analytic, 2 * 2 * 201);
    assert_eq!(mc, 2 * 2 * 201 * 7);
    assert!(dir.path().join("summary.json").is_file());
}

#[test]
fn bad_scene_exits_2_naming_file_line_and_key_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("bad.toml");
    let good = lidarsim::scene::DEFAULT_SCENE_TOML;
    let text = good.replacen("pulse_energy_j = 0.03", "pulse_energy_j = -1", 1);
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
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.toml:"), "{stderr}");
    assert!(
        stderr.contains("`laser.pulse_energy_j`: -1 must be > 0"),
        "{stderr}"
    );
    assert!(
        !out_dir.exists(),
        "an output directory was created for a failed run"
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
