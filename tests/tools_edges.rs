//! `bench --depth` and `mie` at their edges (FUZZ_FINDINGS.md F4, F16): the `--plain`
//! reference's refusals name the file, the line and the column before any work; a size
//! distribution without index contrast is refused at once, and one with a little contrast ends
//! fast with the cross-sections the Rayleigh–Gans scaling predicts.

use std::path::Path;
use std::time::{Duration, Instant};

use crate::util::{lidarsim, non_finite_word};

/// Fields of view and gate depths of the scan (`src/benchmark/depth.rs`).
const FOVS_MRAD: [f64; 5] = [0.5, 1.0, 2.0, 5.0, 10.0];

/// A complete reference as `bench --write-plain` writes it, with made-up positive numbers.
fn reference() -> Vec<String> {
    let mut lines = vec![
        "# plain local estimate of C.1, orders >= 2, 1000 photons (test)".to_string(),
        "fov_full_angle_mrad,depth_m,ms_energy_j,var_per_photon_j2,s_per_photon,photons"
            .to_string(),
    ];
    for fov in FOVS_MRAD {
        for i in 0..25 {
            let depth = 50 + 10 * i;
            lines.push(format!("{fov},{depth},1e-9,1e-15,1e-6,1000"));
        }
    }
    lines
}

/// `bench --depth` with `lines` as the `--plain` file: exit 2 naming `file_line` (the file and
/// line, e.g. `plain.csv:7`) and `what`, nothing written, before any work (well under the time
/// of the runs: 2000 photons twice).
fn refused(dir: &Path, lines: &[String], file_line: &str, what: &str) {
    let plain = dir.join("plain.csv");
    std::fs::write(&plain, lines.join("\n") + "\n").unwrap();
    let out = dir.join("depth");
    let t = Instant::now();
    let o = lidarsim([
        "bench",
        "--depth",
        out.to_str().unwrap(),
        "--plain",
        plain.to_str().unwrap(),
        "--photons",
        "2000",
        "--threads",
        "1",
        "--repeat",
        "1",
    ]);
    let took = t.elapsed();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{what}: {err}");
    assert!(
        err.contains(file_line) && err.contains(what),
        "expected {file_line} and {what}: {err}"
    );
    assert!(!out.join("fom_depth.csv").exists(), "{what}: written");
    assert!(took < Duration::from_secs(2), "{what}: {took:?}");
}

#[test]
fn bench_plain_reference_refusals_name_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Line 3 of the file is the first cell.
    let edit = |row: usize, col: usize, v: &str| {
        let mut l = reference();
        let mut f: Vec<String> = l[row].split(',').map(String::from).collect();
        f[col] = v.to_string();
        l[row] = f.join(",");
        l
    };
    refused(d, &edit(2, 5, "0"), "plain.csv:3", "photons");
    refused(d, &edit(4, 5, "2.5"), "plain.csv:5", "photons");
    refused(d, &edit(2, 3, "-1e-15"), "plain.csv:3", "var_per_photon_j2");
    refused(d, &edit(2, 2, "-1e-9"), "plain.csv:3", "ms_energy_j");
    refused(d, &edit(3, 4, "0"), "plain.csv:4", "s_per_photon");
    refused(d, &edit(3, 4, "-1e-6"), "plain.csv:4", "s_per_photon");
    refused(d, &edit(3, 2, ""), "plain.csv:4", "ms_energy_j");
    refused(d, &edit(3, 2, "inf"), "plain.csv:4", "ms_energy_j");
    // A row with a missing field, and a missing row (a cell of the scan).
    let mut short = reference();
    short[6] = "1,90,1e-9,1e-15,1e-6".to_string();
    refused(d, &short, "plain.csv:7", "fields");
    let mut missing = reference();
    missing.remove(7);
    refused(d, &missing, "plain.csv", "no cell at 0.5 mrad, 100 m");
}

/// F4: cells where the plain estimate scored nothing print `—` on stdout, never `inf` or `NaN`
/// (the CSV has empty fields there).
#[test]
fn bench_depth_prints_no_inf() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("depth");
    let o = lidarsim([
        "bench",
        "--depth",
        out.to_str().unwrap(),
        "--photons",
        "2000",
        "--threads",
        "1",
        "--repeat",
        "1",
        "--batches",
        "10",
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(non_finite_word(&stdout).is_none(), "{stdout}");
    assert!(stdout.contains("least ratio"), "{stdout}");
}

fn mie_lognormal(m: &str) -> (Option<i32>, String, String, Duration) {
    let t = Instant::now();
    let o = lidarsim([
        "mie",
        "--distribution",
        "lognormal",
        "--refractive-index",
        m,
        "--wavelength-nm",
        "532",
        "--median-radius-um",
        "10",
        "--sigma-g",
        "1.5",
    ]);
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        t.elapsed(),
    )
}

/// F16: m = 1 (no contrast) took 26 s refining a size integral of rounding noise. It is refused
/// at once naming the option; a small contrast ends fast, converged, and its extinction scales
/// as |m − 1|² (Rayleigh–Gans / anomalous diffraction, van de Hulst 1957, Light Scattering by
/// Small Particles, §11.22: Qext ≈ ρ²/2 for ρ = 2x|m − 1| ≪ 1; here ρ ≤ 0.2 at |m − 1| = 1e-4,
/// a correction below ρ²/36 ≈ 0.1 %).
#[test]
fn mie_distribution_without_contrast_ends() {
    for m in ["1", "1+0i", "1.0000001", "1+1e-9i"] {
        let (code, _, err, took) = mie_lognormal(m);
        assert!(
            code == Some(2) && err.contains("--refractive-index") && err.contains("|m − 1|"),
            "{m}: {code:?} {err}"
        );
        assert!(took < Duration::from_secs(1), "{m}: {took:?}");
    }
    let cext = |m: &str| {
        let (code, out, err, took) = mie_lognormal(m);
        assert_eq!(code, Some(0), "{m}: {err}");
        assert!(took < Duration::from_secs(10), "{m}: {took:?}");
        assert!(non_finite_word(&out).is_none(), "{m}: {out}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["size_grid"][0]["converged"], true, "{m}: {out}");
        v["extinction_cross_section_um2"].as_f64().unwrap()
    };
    let (a, b) = (cext("1.00001"), cext("1.0001"));
    assert!((b / a / 100.0 - 1.0).abs() < 0.01, "{a} {b}");
}

/// F16 in a scene: a particle layer without index contrast is refused at its file and line,
/// naming the refractive index, before any work.
#[test]
fn scene_particles_without_contrast_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let root = crate::util::project_root();
    let text = std::fs::read_to_string(root.join("scenes/ground_rayleigh_aerosol_cloud.toml"))
        .unwrap()
        .replace(
            "single_scattering_albedo = 0.95\nphase = { kind = \"henyey_greenstein\", g = 0.7 }",
            "particles = { distribution = \"lognormal\", median_radius_um = 0.3, sigma_g = 1.8, \
             refractive_index = \"1\" }",
        )
        .replace(
            "../phase_functions/",
            &format!("{}/phase_functions/", root.display()),
        );
    assert!(text.contains("refractive_index = \"1\""));
    let scene = dir.path().join("s.toml");
    std::fs::write(&scene, text).unwrap();
    let out = dir.path().join("o");
    let t = Instant::now();
    let o = lidarsim([
        "run",
        scene.to_str().unwrap(),
        "--photons",
        "1000",
        "--threads",
        "1",
        "--no-plots",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("s.toml:") && err.contains("|refractive_index − 1| = 0"),
        "{err}"
    );
    assert!(t.elapsed() < Duration::from_secs(2));
    assert!(!out.join("returns.csv").exists());
}
