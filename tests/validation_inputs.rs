//! Issue 11 item 1: every input path validated. Hostile edits of the shipped scenes, command
//! lines and input files are refused with exit code 2 and one message naming the file, the line
//! and the key at fault; problems too large for memory or time are refused at once, before any
//! large allocation; negative numbers reach the range checks.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::util::{lidarsim, lidarsim_bin, lidarsim_ok, project_root, shared_file};

/// A shipped scene with one or more keys set (a key missing from its section is added right
/// under the section header), written where its relative paths still resolve.
struct Edited {
    _dir: tempfile::TempDir,
    path: PathBuf,
    /// 1-based line of the first edited key in the written file.
    line: usize,
}

/// `edits`: (section as written between the brackets, key, TOML value). For an array of
/// tables (`layer`) the first one is edited.
fn edit_scene(scene: &str, edits: &[(&str, &str, &str)]) -> Edited {
    let text = std::fs::read_to_string(project_root().join("scenes").join(scene)).unwrap();
    // Relative paths (phase tables) are relative to the scene's folder: make them absolute.
    let text = text.replace(
        "\"../phase_functions/",
        &format!("\"{}/phase_functions/", project_root().display()),
    );
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut first_line = 0;
    for (n, (section, key, value)) in edits.iter().enumerate() {
        let header = |l: &str| {
            let t = l.trim();
            t == format!("[{section}]") || t == format!("[[{section}]]")
        };
        let start = lines
            .iter()
            .position(|l| header(l))
            .unwrap_or_else(|| panic!("{scene} has no [{section}]"));
        let end = lines[start + 1..]
            .iter()
            .position(|l| l.trim_start().starts_with('['))
            .map_or(lines.len(), |e| start + 1 + e);
        let new = format!("{key} = {value}");
        let at = match (start + 1..end).find(|&i| {
            lines[i]
                .split_once('=')
                .is_some_and(|(k, _)| k.trim() == *key)
        }) {
            Some(i) => {
                lines[i] = new;
                i
            }
            None => {
                lines.insert(start + 1, new);
                // A line inserted above the first edit moves it down.
                if n > 0 && start < first_line {
                    first_line += 1;
                }
                start + 1
            }
        };
        if n == 0 {
            first_line = at;
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(scene);
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    Edited {
        _dir: dir,
        path,
        line: first_line + 1,
    }
}

fn stderr_of(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A clean refusal: exit code 2, no panic, one line of error (an option's value refused by
/// the argument parser included).
fn assert_refused(what: &str, out: &Output) -> String {
    let stderr = stderr_of(out);
    assert_eq!(out.status.code(), Some(2), "{what}: {stderr}");
    assert!(!stderr.contains("panicked"), "{what}: {stderr}");
    assert!(stderr.starts_with("lidarsim: error: "), "{what}: {stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{what}: {stderr}");
    stderr
}

/// `lidarsim args…` with its address space capped at 1 GiB (where the shell can do so): a run
/// that tried to allocate for a problem it should have refused would abort instead of exiting
/// with 2.
fn lidarsim_small<I, S>(args: I) -> (Output, Duration)
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let started = Instant::now();
    let out = if cfg!(unix) && Path::new("/bin/sh").exists() {
        Command::new("/bin/sh")
            .env(crate::util::NO_MIE_CACHE.0, crate::util::NO_MIE_CACHE.1)
            .arg("-c")
            .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
            .arg(lidarsim_bin())
            .args(args)
            .output()
            .expect("sh runs")
    } else {
        lidarsim(args)
    };
    (out, started.elapsed())
}

/// Run an edited scene (analytic only, no figures) and expect its refusal at `key`.
fn refused_at(scene: &str, edits: &[(&str, &str, &str)], key: &str, failures: &mut Vec<String>) {
    let e = edit_scene(scene, edits);
    let out_dir = e.path.with_file_name("out");
    let (out, took) = lidarsim_small([
        "run".as_ref(),
        e.path.as_os_str(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out_dir.as_os_str(),
    ]);
    let stderr = stderr_of(&out);
    let want = format!("{}:{}: `{key}`", e.path.display(), e.line);
    let ok = out.status.code() == Some(2)
        && !stderr.contains("panicked")
        && stderr.trim_end().lines().count() == 1
        && stderr.starts_with("lidarsim: error: ")
        && stderr.contains(&want)
        && !out_dir.exists();
    if !ok {
        failures.push(format!(
            "{scene} {edits:?}: expected exit 2 and `{want}`, got {:?}: {stderr}",
            out.status.code()
        ));
    }
    // Validation reads the scene and stops: nothing slow happens before a refusal.
    if took > Duration::from_secs(5) {
        failures.push(format!("{scene} {edits:?}: refused only after {took:?}"));
    }
}

/// One key set in a scene: (section, key, TOML value).
type Edit<'a> = (&'a str, &'a str, &'a str);

const GROUND: &str = "ground_rayleigh_aerosol_cloud.toml";
const IPDA: &str = "spaceborne_co2_ipda.toml";

/// The issue's examples and one hostile value for most keys: NaN, ±infinity, absurd magnitudes
/// and wrong signs, each named at its own key (never at a key compared with it later).
#[test]
fn bad_scene_values_are_refused_at_their_own_line_and_key() {
    // (scene, edits, the key the error must name)
    let cases: &[(&str, &[Edit], &str)] = &[
        // The issue's panicking clamp.
        (
            GROUND,
            &[("surface", "altitude_m", "nan")],
            "surface.altitude_m",
        ),
        (
            IPDA,
            &[("surface", "altitude_m", "nan")],
            "surface.altitude_m",
        ),
        (
            GROUND,
            &[("lidar", "altitude_m", "nan")],
            "lidar.altitude_m",
        ),
        (
            GROUND,
            &[("lidar", "altitude_m", "inf")],
            "lidar.altitude_m",
        ),
        (
            GROUND,
            &[("lidar", "altitude_m", "-inf")],
            "lidar.altitude_m",
        ),
        (
            IPDA,
            &[("lidar", "altitude_km", "1e300")],
            "lidar.altitude_km",
        ),
        (
            GROUND,
            &[("lidar", "azimuth_deg", "nan")],
            "lidar.azimuth_deg",
        ),
        (
            GROUND,
            &[("lidar", "azimuth_deg", "inf")],
            "lidar.azimuth_deg",
        ),
        (
            GROUND,
            &[("lidar", "zenith_angle_deg", "nan")],
            "lidar.zenith_angle_deg",
        ),
        (
            GROUND,
            &[("lidar", "pulse_energy_j", "1e300")],
            "lidar.pulse_energy_j",
        ),
        (
            GROUND,
            &[("lidar", "telescope_diameter_m", "1e9")],
            "lidar.telescope_diameter_m",
        ),
        (
            GROUND,
            &[("lidar", "fov_full_angle_mrad", "[0.5, nan]")],
            "lidar.fov_full_angle_mrad",
        ),
        (
            GROUND,
            &[("lidar", "beam_divergence_full_angle_mrad", "-inf")],
            "lidar.beam_divergence_full_angle_mrad",
        ),
        (
            GROUND,
            &[("channel", "wavelength_nm", "1e300")],
            "channel.wavelength_nm",
        ),
        (GROUND, &[("gates", "end_m", "inf")], "gates.end_m"),
        (GROUND, &[("gates", "start_m", "nan")], "gates.start_m"),
        // A NaN base was blamed on `top_m` ("must be above `base_m`").
        (GROUND, &[("layer", "base_m", "nan")], "layer.base_m"),
        (
            GROUND,
            &[("layer", "extinction_per_km", "1e18")],
            "layer.extinction_per_km",
        ),
        (
            GROUND,
            &[("layer", "single_scattering_albedo", "nan")],
            "layer.single_scattering_albedo",
        ),
        (
            GROUND,
            &[("layer", "absorption_per_m", "-1.0")],
            "layer.absorption_per_m",
        ),
        (
            GROUND,
            &[("atmosphere", "layer_thickness_m", "nan")],
            "atmosphere.layer_thickness_m",
        ),
        (
            GROUND,
            &[("atmosphere", "top_m", "nan")],
            "atmosphere.top_m",
        ),
        (IPDA, &[("atmosphere", "top_m", "inf")], "atmosphere.top_m"),
        (
            IPDA,
            &[("atmosphere", "co2_ppm", "-420.0")],
            "atmosphere.co2_ppm",
        ),
        (GROUND, &[("surface", "albedo", "inf")], "surface.albedo"),
        (
            IPDA,
            &[("laser", "pulse_energy_j", "1e300")],
            "laser.pulse_energy_j",
        ),
        (
            IPDA,
            &[("laser", "repetition_rate_hz", "inf")],
            "laser.repetition_rate_hz",
        ),
        (
            IPDA,
            &[("laser", "linewidth_fwhm_mhz", "1e300")],
            "laser.linewidth_fwhm_mhz",
        ),
        (
            IPDA,
            &[("laser", "frequency_jitter_rms_mhz", "nan")],
            "laser.frequency_jitter_rms_mhz",
        ),
        (
            IPDA,
            &[("laser", "impurity_wavenumber_cm1", "[6360.055, -1.0]")],
            "laser.impurity_wavenumber_cm1",
        ),
        (
            IPDA,
            &[("receiver", "nep_w_per_sqrt_hz", "1e300")],
            "receiver.nep_w_per_sqrt_hz",
        ),
        (IPDA, &[("receiver", "gain", "nan")], "receiver.gain"),
        (
            IPDA,
            &[("receiver", "filter_bandwidth_ghz", "1e300")],
            "receiver.filter_bandwidth_ghz",
        ),
        (
            IPDA,
            &[("background", "solar_irradiance_w_per_m2_um", "1e300")],
            "background.solar_irradiance_w_per_m2_um",
        ),
        (
            IPDA,
            &[("retrieval", "averaging_length_km", "inf")],
            "retrieval.averaging_length_km",
        ),
        (
            IPDA,
            &[("retrieval", "platform_speed_m_per_s", "-7200.0")],
            "retrieval.platform_speed_m_per_s",
        ),
        (
            IPDA,
            &[("gas_absorption", "wing_cm1", "1e300")],
            "gas_absorption.wing_cm1",
        ),
        (
            GROUND,
            &[("simulation", "max_order", "0")],
            "simulation.max_order",
        ),
        (
            GROUND,
            &[("simulation", "threads", "100000")],
            "simulation.threads",
        ),
        (
            GROUND,
            &[("simulation", "batches", "1000000000")],
            "simulation.batches",
        ),
        (
            GROUND,
            &[("simulation", "photons", "100000000000000")],
            "simulation.photons",
        ),
        // Nonsense the issue found accepted: gates wholly beyond the surface the beam meets.
        (
            IPDA,
            &[
                ("gates", "start_m", "460000.0"),
                ("gates", "end_m", "470050.0"),
            ],
            "gates.start_m",
        ),
        // Absorption asked for a molecule the line source has no line of (the band model is
        // CO2 only; the atmosphere carries H2O).
        (
            IPDA,
            &[("gas_absorption", "molecules", "[\"H2O\"]")],
            "gas_absorption.molecules",
        ),
    ];
    let mut failures = Vec::new();
    for (scene, edits, key) in cases {
        refused_at(scene, edits, key, &mut failures);
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// A line file with lines of another molecule only: refused at `molecules`, naming the file.
#[test]
fn a_line_file_without_the_requested_molecule_is_refused() {
    let Some(h2o) = shared_file("data/hitran/H2O_161_6000-6400_HITRAN2016.par") else {
        return;
    };
    let lines = format!("\"{}\"", h2o.display());
    let mut failures = Vec::new();
    refused_at(
        IPDA,
        &[
            ("gas_absorption", "molecules", "[\"CO2\"]"),
            ("gas_absorption", "lines", &lines),
        ],
        "gas_absorption.molecules",
        &mut failures,
    );
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// The problem sizes of the issue (10⁷ gates, 10⁵ fields of view, 2·10⁴ channels, 1 mm
/// molecular layers) are refused in well under a second, within a 1 GiB address space, naming
/// the product and the key of its largest factor.
#[test]
fn problems_too_large_are_refused_fast_and_before_allocating() {
    let fovs: Vec<String> = (0..100_000)
        .map(|i| format!("{}", 0.001 + i as f64 * 0.0099))
        .collect();
    let fovs = format!("[{}]", fovs.join(", "));
    type Owned<'a> = (&'a str, &'a str, String);
    let cases: Vec<(&str, Vec<Owned>, &str)> = vec![
        (
            GROUND,
            vec![
                ("gates", "width_m", "1.0".into()),
                ("gates", "end_m", "10000100.0".into()),
            ],
            "gates.width_m",
        ),
        (
            GROUND,
            vec![("lidar", "fov_full_angle_mrad", fovs)],
            "lidar.fov_full_angle_mrad",
        ),
        (
            GROUND,
            vec![("atmosphere", "layer_thickness_m", "0.001".into())],
            "atmosphere.layer_thickness_m",
        ),
        (
            GROUND,
            vec![
                ("gates", "width_m", "1.0".into()),
                ("simulation", "max_order", "1000".into()),
            ],
            "gates.width_m",
        ),
    ];
    let mut failures = Vec::new();
    for (scene, edits, key) in &cases {
        let edits: Vec<(&str, &str, &str)> =
            edits.iter().map(|(s, k, v)| (*s, *k, v.as_str())).collect();
        let started = Instant::now();
        refused_at(scene, &edits, key, &mut failures);
        if started.elapsed() > Duration::from_secs(1) {
            failures.push(format!("{key}: refused only after {:?}", started.elapsed()));
        }
    }
    // 2·10⁴ channels: the returns would hold every channel and every pair of lines.
    let mut text = std::fs::read_to_string(project_root().join("scenes").join(GROUND)).unwrap();
    text = text.replace(
        "\"../phase_functions/",
        &format!("\"{}/phase_functions/", project_root().display()),
    );
    let first = text.find("[[channel]]").unwrap();
    let mut channels = String::new();
    for i in 0..20_000 {
        channels.push_str(&format!(
            "[[channel]]\nname = \"c{i}\"\nwavelength_nm = {}\n",
            1000.0 + i as f64 * 0.001
        ));
    }
    let end = text.find("[gates]").unwrap();
    text.replace_range(first..end, &channels);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many_channels.toml");
    std::fs::write(&path, &text).unwrap();
    let (out, took) = lidarsim_small([
        "run".as_ref(),
        path.as_os_str(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--out".as_ref(),
        dir.path().join("out").as_os_str(),
    ]);
    let stderr = assert_refused("2·10⁴ channels", &out);
    assert!(
        stderr.contains("many_channels.toml:") && stderr.contains("the returns"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(1), "2·10⁴ channels: {took:?}");
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

/// Command-line sizes: `--threads 100000`, a huge `--n`, 1 mm layers in `lbl`: refused at once.
#[test]
fn command_line_sizes_are_refused_fast() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.csv").to_string_lossy().into_owned();
    let cases: Vec<(&str, Vec<&str>, &str)> = vec![
        (
            "threads",
            vec!["run", "--threads", "100000", "--photons", "0"],
            "--threads",
        ),
        (
            "ensemble count",
            vec![
                "profiles",
                "generate",
                "--n",
                "100000000000",
                "--seed",
                "1",
                "--atmosphere",
                "us_standard",
                "--out",
                &out,
            ],
            "--n",
        ),
        (
            "ensemble size",
            vec![
                "profiles",
                "generate",
                "--n",
                "1000000",
                "--seed",
                "1",
                "--atmosphere",
                "us_standard",
                "--out",
                &out,
            ],
            "levels",
        ),
        (
            "lbl layers",
            vec![
                "lbl",
                "--atmosphere",
                "us_standard",
                "--sensor-altitude-m",
                "10000",
                "--zenith-deg",
                "180",
                "--layer-m",
                "0.001",
                "--start-cm1",
                "6360",
                "--end-cm1",
                "6361",
                "--step-cm1",
                "0.01",
                "--out",
                &out,
            ],
            "--layer-m",
        ),
        (
            "lbl rows",
            vec![
                "lbl",
                "--atmosphere",
                "us_standard",
                "--sensor-altitude-m",
                "10000",
                "--zenith-deg",
                "180",
                "--layer-m",
                "1",
                "--start-cm1",
                "6300",
                "--end-cm1",
                "6400",
                "--step-cm1",
                "0.001",
                "--out",
                &out,
            ],
            "the output",
        ),
        (
            "bench threads",
            vec!["bench", "--threads", "1,100000"],
            "--threads",
        ),
    ];
    for (what, args, words) in cases {
        let (o, took) = lidarsim_small(&args);
        let stderr = assert_refused(what, &o);
        assert!(stderr.contains(words), "{what}: {stderr}");
        assert!(took < Duration::from_secs(1), "{what}: {took:?}");
        assert!(!Path::new(&out).exists(), "{what}");
    }
}

/// A negative number reaches the range check of its option (not "unexpected argument"), and
/// one that is meaningful is accepted.
#[test]
fn negative_numbers_reach_the_range_checks() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.csv").to_string_lossy().into_owned();
    let lbl = |step: &str| {
        lidarsim([
            "lbl",
            "--pressure-atm",
            "1",
            "--temperature-k",
            "296",
            "--start-cm1",
            "6360",
            "--end-cm1",
            "6361",
            "--step-cm1",
            step,
            "--out",
            &out,
        ])
    };
    let stderr = assert_refused("negative step", &lbl("-0.01"));
    assert!(
        stderr.contains("--step-cm1") && stderr.contains("-0.01") && stderr.contains("must lie in"),
        "{stderr}"
    );
    assert!(!stderr.contains("unexpected argument"), "{stderr}");
    for (what, args, option) in [
        (
            "negative photons",
            vec!["run", "--photons", "-5"],
            "--photons",
        ),
        (
            "NaN epsilon",
            vec!["run", "--ddis-epsilon", "NaN"],
            "--ddis-epsilon",
        ),
        (
            "negative size parameter",
            vec![
                "mie",
                "--refractive-index",
                "1.33",
                "--size-parameter",
                "-1",
            ],
            "--size-parameter",
        ),
        (
            "infinite pressure",
            vec![
                "lbl",
                "--pressure-atm",
                "inf",
                "--temperature-k",
                "296",
                "--start-cm1",
                "6360",
                "--end-cm1",
                "6361",
                "--step-cm1",
                "0.01",
                "--out",
                &out,
            ],
            "--pressure-atm",
        ),
        (
            "hot gas",
            vec![
                "lbl",
                "--pressure-atm",
                "1",
                "--temperature-k",
                "1500",
                "--start-cm1",
                "6360",
                "--end-cm1",
                "6361",
                "--step-cm1",
                "0.01",
                "--out",
                &out,
            ],
            "--temperature-k",
        ),
    ] {
        let stderr = assert_refused(what, &lidarsim(&args));
        assert!(stderr.contains(option), "{what}: {stderr}");
        assert!(!stderr.contains("unexpected argument"), "{what}: {stderr}");
    }
    assert!(!Path::new(&out).exists());
    // Meaningful negative values: offsets below a line centre.
    let sel = dir.path().join("select");
    lidarsim_ok([
        "select-lines",
        "--atmosphere",
        "us_standard",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--max-j",
        "16",
        "--offsets-ghz",
        "-0.5",
        "--layer-m",
        "2000",
        "--top-km",
        "30",
        "--no-plots",
        "--out",
        &sel.to_string_lossy(),
    ]);
    assert!(sel.join("sensitivities.csv").is_file());
}

/// `mie` with an absurd refractive index: refused, not `null` in the output.
#[test]
fn mie_refuses_refractive_indices_out_of_range() {
    for m in ["1e300", "1.5+1e300i", "-1.33", "1.33-0.1i"] {
        let out = lidarsim(["mie", "--refractive-index", m, "--size-parameter", "10"]);
        let stderr = assert_refused(m, &out);
        assert!(stderr.contains("--refractive-index"), "{m}: {stderr}");
        assert!(out.stdout.is_empty(), "{m}");
    }
    let ok = lidarsim_ok([
        "mie",
        "--refractive-index",
        "100+100i",
        "--size-parameter",
        "10",
    ]);
    assert!(!ok.contains("null"), "{ok}");
}

/// A profile set: one generated with `profiles generate`, with a field replaced.
fn profile_set(dir: &Path, mut edit: impl FnMut(&mut Vec<String>)) -> PathBuf {
    let clean = dir.join("clean.csv");
    lidarsim_ok([
        "profiles",
        "generate",
        "--n",
        "2",
        "--seed",
        "1",
        "--atmosphere",
        "us_standard",
        "--out",
        &clean.to_string_lossy(),
    ]);
    let mut lines: Vec<String> = std::fs::read_to_string(&clean)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    edit(&mut lines);
    let path = dir.join("edited.csv");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    path
}

/// A profile at 1500 K: refused with the file, the line and the column, printed once, by the
/// set reader and through a scene that uses the set.
#[test]
fn a_profile_at_1500_k_is_refused_at_its_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let mut line_no = 0;
    let set = profile_set(dir.path(), |lines| {
        let header = lines
            .iter()
            .position(|l| l.starts_with("profile,"))
            .unwrap();
        let col = lines[header]
            .split(',')
            .position(|c| c == "temperature_K")
            .unwrap();
        let row = header + 4;
        let mut f: Vec<String> = lines[row].split(',').map(str::to_string).collect();
        f[col] = "1500".into();
        lines[row] = f.join(",");
        line_no = row + 1;
    });
    let want = format!("{}:{line_no}: `temperature_K`", set.display());
    let stderr = assert_refused(
        "profiles info",
        &lidarsim(["profiles".as_ref(), "info".as_ref(), set.as_os_str()]),
    );
    assert!(stderr.contains(&want), "{stderr}");
    assert_eq!(
        stderr.matches("1500 must lie in").count(),
        1,
        "printed once: {stderr}"
    );

    let scene = edit_scene(
        IPDA,
        &[
            (
                "atmosphere",
                "profile_file",
                &format!("\"{}\"", set.display()),
            ),
            ("atmosphere", "profile_id", "\"mid-0001\""),
        ],
    );
    let text = std::fs::read_to_string(&scene.path)
        .unwrap()
        .replace("standard = \"us_standard\"\n", "");
    std::fs::write(&scene.path, text).unwrap();
    let out = lidarsim([
        "run".as_ref(),
        scene.path.as_os_str(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--out".as_ref(),
        dir.path().join("out").as_os_str(),
    ]);
    let stderr = assert_refused("scene with the set", &out);
    assert!(
        stderr.contains("`atmosphere.profile_file`") && stderr.contains(&want),
        "{stderr}"
    );
    assert_eq!(
        stderr.matches("1500 must lie in").count(),
        1,
        "printed once: {stderr}"
    );
}

/// A UTF-8 byte-order mark at the start of a text file is not part of its first line.
#[test]
fn a_byte_order_mark_is_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let bom = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, format!("\u{feff}{text}")).unwrap();
        p
    };
    // A profile set whose first line is a comment, and one whose first line is the header.
    let set = profile_set(dir.path(), |_| {});
    let text = std::fs::read_to_string(&set).unwrap();
    let headed: String = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("{l}\n"))
        .collect();
    for (name, text) in [
        ("commented.csv", text.as_str()),
        ("headed.csv", headed.as_str()),
    ] {
        let p = bom(name, text);
        let stdout = lidarsim_ok(["profiles".as_ref(), "info".as_ref(), p.as_os_str()]);
        assert!(stdout.contains("mid-0002"), "{name}: {stdout}");
    }
    // A phase-function table.
    let table =
        std::fs::read_to_string(project_root().join("phase_functions/bissonnette_c1_1064nm.txt"))
            .unwrap();
    let p = bom("table.txt", &table);
    let read = lidarsim::particles::table::PhaseTable::read(&p).expect("table with a BOM");
    assert_eq!(read.meta("wavelength_nm"), Some("1064"));
    // A HITRAN file and a CSV line list.
    if let Some(par) = shared_file("data/hitran/CO2_626_6000-6400_HITRAN2016.par") {
        let p = bom("lines.par", &std::fs::read_to_string(par).unwrap());
        let filter = lidarsim::spectroscopy::LineFilter::window(6359.0, 6361.0);
        let l = lidarsim::spectroscopy::LineList::read(&p, &filter).expect("par with a BOM");
        assert!(!l.is_empty());
    }
    let csv = "molec_id,local_iso_id,nu,sw,elower,gamma_air,n_air,delta_air\n2,1,6359.967244,1.779e-23,106.1297,0.0747,0.67,-0.00551\n";
    let p = bom("lines.csv", csv);
    let l =
        lidarsim::spectroscopy::LineList::read(&p, &Default::default()).expect("csv with a BOM");
    assert_eq!(l.len(), 1);
}

/// Hostile fields of line lists and phase tables: refused at file, line and field.
#[test]
fn line_list_and_phase_table_fields_out_of_range_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let header = "molec_id,local_iso_id,nu,sw,elower,gamma_air,n_air,delta_air\n";
    for (field, row) in [
        ("sw", "2,1,6359.9,1e300,106.1,0.0747,0.67,-0.0055"),
        ("gamma_air", "2,1,6359.9,1.7e-23,106.1,1e300,0.67,-0.0055"),
        ("nu", "2,1,-6359.9,1.7e-23,106.1,0.0747,0.67,-0.0055"),
        ("delta_air", "2,1,6359.9,1.7e-23,106.1,0.0747,0.67,inf"),
    ] {
        let p = dir.path().join(format!("{field}.csv"));
        std::fs::write(&p, format!("{header}{row}\n")).unwrap();
        let e = lidarsim::spectroscopy::LineList::read(&p, &Default::default()).unwrap_err();
        let shown = e.to_string();
        assert!(
            shown.contains(&format!("{field}.csv:2: `{field}`")),
            "{field}: {shown}"
        );
    }
    let table = "# wavelength_nm = 1064\n# refractive_index = none\n# distribution = none\ntheta_deg,phase_4pi\n0,1\n90,1e300\n180,1\n";
    let p = dir.path().join("t.txt");
    std::fs::write(&p, table).unwrap();
    let e = lidarsim::particles::table::PhaseTable::read(&p).unwrap_err();
    assert_eq!(
        (e.line, e.field.as_deref()),
        (Some(6), Some("phase_4pi")),
        "{e}"
    );
}

/// A ground lidar at `WL` nm under a layer of water drops (log-normal, median radius `RG` µm,
/// σ_g 1.5): Mie theory on the fly. The `particles` key is on line 21.
const DROPS: &str = r#"[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = 1.0
[[channel]]
name = "c"
wavelength_nm = WL
[gates]
start_m = 1000.0
end_m = 1400.0
width_m = 10.0
[[layer]]
name = "drops"
base_m = 1000.0
top_m = 1300.0
extinction_per_km = 1.0
particles = { distribution = "lognormal", median_radius_um = RG, sigma_g = 1.5, refractive_index = "M" }
"#;

/// Mie work beyond its limit (README, "Limits"), refused in well under a second within a 1 GiB
/// address space, naming the product and the limit: a layer of 1 mm drops at 532 nm (hours of
/// Mie theory) at its file, line and key, and `lidarsim mie` for them with a phase table. Work
/// above a minute but below the limit is allowed with a warning that says how long it may take
/// (drops so absorbing that the size integration converges at once, so the test is quick).
#[test]
fn mie_work_beyond_the_limit_is_refused_fast() {
    let dir = tempfile::tempdir().unwrap();
    let scene = |wl: &str, rg: &str, m: &str| {
        DROPS
            .replace("WL", wl)
            .replace("RG", rg)
            .replace("\"M\"", &format!("\"{m}\""))
    };
    let path = dir.path().join("rain.toml");
    std::fs::write(&path, scene("532.0", "1000.0", "1.33+0i")).unwrap();
    let out_dir = dir.path().join("out");
    let (out, took) = lidarsim_small([
        "run".as_ref(),
        path.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out_dir.as_os_str(),
    ]);
    let stderr = assert_refused("1 mm drops", &out);
    assert!(
        stderr.contains(&format!(
            "{}:21: `layer.particles`: Mie work",
            path.display()
        )) && stderr.contains("term-angles")
            && stderr.contains("limit of 4e13"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(1), "{took:?}");
    assert!(!out_dir.exists());

    let table = dir.path().join("t.txt");
    let (out, took) = lidarsim_small([
        "mie",
        "--distribution",
        "lognormal",
        "--refractive-index",
        "1.33+0i",
        "--median-radius-um",
        "1000",
        "--sigma-g",
        "1.5",
        "--wavelength-nm",
        "532",
        "--out",
        table.to_str().unwrap(),
    ]);
    let stderr = assert_refused("mie at 1000 µm", &out);
    assert!(
        stderr.contains("Mie work") && stderr.contains("angles") && stderr.contains("Limits"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(1), "{took:?}");
    assert!(!table.exists());

    // Allowed, with the warning before the work.
    let path = dir.path().join("soot.toml");
    std::fs::write(&path, scene("532.0", "20.0", "1.5+0.5i")).unwrap();
    let out = lidarsim([
        "run".as_ref(),
        path.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out_dir.as_os_str(),
    ]);
    let stderr = stderr_of(&out);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "lidarsim: warning: {}:21: `layer.particles`: Mie work",
            path.display()
        )) && stderr.contains("up to about"),
        "{stderr}"
    );
}

/// A scene of the project: a shipped one (`scenes/NAME`) or a validation one
/// (`validation/NAME`), parsed.
fn project_scene(path: &str) -> lidarsim::scene::Scene {
    let p = project_root().join(path);
    lidarsim::scene::Scene::read(&p).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// [`project_scene`] with text replacements (each must occur).
fn edited_scene(path: &str, edits: &[(&str, &str)]) -> lidarsim::scene::Scene {
    let p = project_root().join(path);
    let text = std::fs::read_to_string(&p).unwrap();
    let text = crate::transport::edited(&text, edits);
    lidarsim::scene::Scene::from_toml(&p, &text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The Monte Carlo work estimate (`pipeline::McWork`: events per photon from the scattering
/// optical depth of the longest path that can still reach the last gate and the largest
/// single-scattering albedo) against the events the transport counts (scatterings and surface
/// reflections per photon, fixed seed): at least the count, and at most 40 times it, on shipped
/// and validation scenes and extremes — thin and thick, isotropic and forward-peaked, absorbing,
/// gates far beyond a cloud, an albedo-1 surface. The closest cases are I3RC experiment 2 (a
/// semi-infinite conservative cloud whose photons use their whole path) and an isotropic layer
/// of optical depth 1 (forced collisions), both about 0.8 of the estimate; the loosest, gates
/// 9 km beyond a thin forward-peaked layer (0.07: the estimate lets every path stay in the
/// layer).
#[test]
fn monte_carlo_work_estimate_bounds_the_counted_events() {
    use lidarsim::optics::OpticalAtmosphere;
    use lidarsim::pipeline::monte_carlo_work;
    let c1 = "scenes/bissonnette_c1.toml";
    let hg = |g: &str| format!("phase = {{ kind = \"henyey_greenstein\", g = {g} }}");
    let c1_table =
        "phase = { kind = \"table\", file = \"../phase_functions/bissonnette_c1_1064nm.txt\" }";
    let hg0 = hg("0.0");
    let hg85 = hg("0.85");
    let cases: Vec<(&str, lidarsim::scene::Scene)> = vec![
        ("bissonnette_c1", project_scene(c1)),
        (
            "ground_rayleigh_aerosol_cloud",
            project_scene("scenes/ground_rayleigh_aerosol_cloud.toml"),
        ),
        (
            "spaceborne_nadir_aerosol",
            project_scene("scenes/spaceborne_nadir_aerosol.toml"),
        ),
        (
            "I3RC exp. 2",
            project_scene("validation/i3rc_case7/exp2.toml"),
        ),
        (
            "C.1 × 0.01",
            edited_scene(
                c1,
                &[("extinction_per_km = 17.23", "extinction_per_km = 0.1723")],
            ),
        ),
        (
            "C.1 × 10, gates to 3 km",
            edited_scene(
                c1,
                &[
                    ("extinction_per_km = 17.23", "extinction_per_km = 172.3"),
                    ("end_m = 1400.0", "end_m = 3000.0"),
                ],
            ),
        ),
        (
            "C.1 × 10, albedo 0.5",
            edited_scene(
                c1,
                &[
                    ("extinction_per_km = 17.23", "extinction_per_km = 172.3"),
                    (
                        "single_scattering_albedo = 0.999908",
                        "single_scattering_albedo = 0.5",
                    ),
                ],
            ),
        ),
        (
            "isotropic, optical depth 1",
            edited_scene(
                c1,
                &[
                    (c1_table, &hg0),
                    ("extinction_per_km = 17.23", "extinction_per_km = 3.33"),
                ],
            ),
        ),
        (
            "g = 0.85, optical depth 0.6, gates to 10 km",
            edited_scene(
                c1,
                &[
                    (c1_table, &hg85),
                    ("extinction_per_km = 17.23", "extinction_per_km = 2.0"),
                    ("end_m = 1400.0", "end_m = 10000.0"),
                ],
            ),
        ),
        (
            "fog over an albedo-1 surface",
            edited_scene(
                c1,
                &[
                    (
                        "[simulation]",
                        "[surface]\naltitude_m = 0.0\nalbedo = 1.0\n[simulation]",
                    ),
                    ("base_m = 1000.0", "base_m = 0.0"),
                    ("top_m = 1300.0", "top_m = 100.0"),
                    ("[lidar]\naltitude_m = 0.0", "[lidar]\naltitude_m = 0.001"),
                    ("start_m = 1000.0", "start_m = 10.0"),
                    ("end_m = 1400.0", "end_m = 1010.0"),
                ],
            ),
        ),
    ];
    let mut report = Vec::new();
    let mut failures = Vec::new();
    for (name, scene) in &cases {
        let atm = OpticalAtmosphere::build(scene).unwrap();
        let photons = 10_000;
        let estimate = monte_carlo_work(scene, &atm, photons);
        let r = crate::transport::run(scene, photons, |_| {});
        let counted =
            (r.stats.collisions + r.stats.surface_reflections) as f64 / r.stats.photons as f64;
        let ratio = counted / estimate.events_per_photon;
        report.push(format!(
            "{name}: {counted:.2} of {:.2} events per photon ({ratio:.3})",
            estimate.events_per_photon
        ));
        if !(1.0 / 40.0..=1.0).contains(&ratio) {
            failures.push(report.last().unwrap().clone());
        }
    }
    assert!(
        failures.is_empty(),
        "{}\nall:\n{}",
        failures.join("\n"),
        report.join("\n")
    );
}

/// Every run the project ships or documents is at least a hundredfold below the limit of
/// Monte Carlo work: the shipped scenes at their own photons, the validation scenes at the
/// photons of their scripts (I3RC case 7: 10⁶, Platt: 2·10⁶), and the README's largest, the C.1
/// cloud with 10¹⁰ photons over 100 Slurm shards. A thick cloud (extinction 17 m⁻¹, gates to
/// 10 km) with 10⁹ photons is refused in milliseconds at `simulation.photons` with the product
/// and the limit; 10⁹ photons of C.1 are allowed with a warning.
#[test]
fn monte_carlo_work_of_shipped_runs_is_a_hundredfold_below_the_limit() {
    use lidarsim::limits::MAX_MC_WORK;
    use lidarsim::optics::OpticalAtmosphere;
    use lidarsim::pipeline::monte_carlo_work;
    let mut runs: Vec<(String, lidarsim::scene::Scene, u64)> = Vec::new();
    for entry in std::fs::read_dir(project_root().join("scenes")).unwrap() {
        let p = entry.unwrap().path();
        let rel = format!("scenes/{}", p.file_name().unwrap().to_string_lossy());
        let scene = project_scene(&rel);
        let photons = scene.simulation.photons;
        runs.push((rel, scene, photons));
    }
    for e in 1..=6 {
        let rel = format!("validation/i3rc_case7/exp{e}.toml");
        runs.push((rel.clone(), project_scene(&rel), 1_000_000));
    }
    for t in [1, 10] {
        let rel = format!("validation/platt/tau{t}.toml");
        runs.push((rel.clone(), project_scene(&rel), 2_000_000));
    }
    runs.push((
        "C.1, 10¹⁰ photons".into(),
        project_scene("scenes/bissonnette_c1.toml"),
        10_000_000_000,
    ));
    let mut largest = (String::new(), 0.0);
    for (name, scene, photons) in &runs {
        let atm = OpticalAtmosphere::build(scene).unwrap();
        let w = monte_carlo_work(scene, &atm, *photons).work();
        assert!(w * 100.0 <= MAX_MC_WORK, "{name}: {w:e}");
        if w > largest.1 {
            largest = (name.clone(), w);
        }
    }
    assert_eq!(largest.0, "C.1, 10¹⁰ photons", "{largest:?}");

    let scene = edited_scene(
        "scenes/bissonnette_c1.toml",
        &[
            ("extinction_per_km = 17.23", "extinction_per_km = 17230.0"),
            ("end_m = 1400.0", "end_m = 10000.0"),
        ],
    );
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    assert!(
        monte_carlo_work(&scene, &atm, 1_000_000_000)
            .check()
            .is_err()
    );
    let c1 = project_scene("scenes/bissonnette_c1.toml");
    let atm = OpticalAtmosphere::build(&c1).unwrap();
    let w = monte_carlo_work(&c1, &atm, 1_000_000_000);
    assert!(w.check().is_ok() && w.warning().is_some());

    // Through the binary: refused at the scene's key, before any photon.
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(project_root().join("scenes/bissonnette_c1.toml"))
        .unwrap()
        .replace("extinction_per_km = 17.23", "extinction_per_km = 17230.0")
        .replace("end_m = 1400.0", "end_m = 10000.0")
        .replace(
            "\"../phase_functions/",
            &format!("\"{}/phase_functions/", project_root().display()),
        );
    let path = dir.path().join("fog.toml");
    std::fs::write(&path, &text).unwrap();
    let line = text.lines().position(|l| l.starts_with("photons")).unwrap() + 1;
    let out_dir = dir.path().join("out");
    let (out, took) = lidarsim_small([
        "run".as_ref(),
        path.as_os_str(),
        "--photons".as_ref(),
        "1000000000".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out_dir.as_os_str(),
    ]);
    let stderr = assert_refused("thick fog", &out);
    assert!(
        stderr.contains(&format!(
            "fog.toml:{line}: `simulation.photons`: Monte Carlo work"
        )) && stderr.contains("channel-events")
            && stderr.contains("limit of 3e13"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(2), "{took:?}");
    assert!(!out_dir.exists());
}

/// Study sizes (README, "Limits"): `bench --study` (3N profiles × thread counts × repeats)
/// and `dial` (profiles × line evaluations, and with photons × five traced truths) beyond
/// their limits are refused in well under a second, before an ensemble is drawn, naming the
/// product and the limit; the README's own studies (`bench --study 1000` at its defaults,
/// `dial --ensemble 1000` of the study scene, and of the airborne DIAL scene with its photons)
/// are a hundredfold below.
#[test]
fn study_sizes_are_refused_fast_and_shipped_studies_are_far_below() {
    use lidarsim::limits::{MAX_MC_WORK, MAX_STUDY_WORK};
    use lidarsim::pipeline::study_work;
    let study = project_scene("scenes/study_co2_ipda.toml");
    let bench = study_work(&study, 3 * 1000 * 2 * 3, 0).unwrap();
    assert!(bench.check().is_ok() && bench.line_evaluations() * 100.0 <= MAX_STUDY_WORK);
    let dial = study_work(&study, 3000, 0).unwrap();
    assert!(dial.line_evaluations() * 100.0 <= MAX_STUDY_WORK);
    let airborne = project_scene("scenes/airborne_co2_dial.toml");
    let photons = airborne.simulation.photons;
    let w = study_work(&airborne, 3000, photons).unwrap();
    assert!(w.mc_work() * 100.0 <= MAX_MC_WORK && w.line_evaluations() * 100.0 <= MAX_STUDY_WORK);

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let airborne_path = project_root().join("scenes/airborne_co2_dial.toml");
    for (what, args, words) in [
        (
            "bench --study",
            vec!["bench", "--study", "40000", "--repeat", "1000"],
            "line evaluations",
        ),
        (
            "dial with photons",
            vec![
                "dial",
                airborne_path.to_str().unwrap(),
                "--ensemble",
                "40000",
                "--photons",
                "100000000",
                "--no-plots",
                "--out",
                out.to_str().unwrap(),
            ],
            "study Monte Carlo work",
        ),
    ] {
        let (o, took) = lidarsim_small(&args);
        let stderr = assert_refused(what, &o);
        assert!(
            stderr.contains(words)
                && stderr.contains("more than the limit")
                && stderr.contains("Limits"),
            "{what}: {stderr}"
        );
        assert!(took < Duration::from_secs(1), "{what}: {took:?}");
    }
    assert!(!out.exists());
}
