//! Physical inputs as users give them (issue 42): CO2 as a well-mixed dry-air mole fraction
//! (`co2_ppm`, `co2_scaling`, `--co2-ppm`), clouds by water content and effective radius, and the
//! warnings of implausible or misleading values — through the binary and its files, against
//! definitions, closed forms and miepython.

use std::path::Path;

use crate::util::{lidarsim, lidarsim_ok, project_root, read_csv, shared_file};
use lidarsim::scene::Scene;

fn shipped(name: &str) -> String {
    std::fs::read_to_string(project_root().join("scenes").join(name)).unwrap()
}

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// `lidarsim run PATH --photons 0 --no-plots --no-netcdf --out OUT`: the analytic lidar
/// equation alone, for the warnings and summaries of a scene.
fn analytic_run(path: &Path, out: &Path) -> std::process::Command {
    let mut c = crate::util::lidarsim_command();
    c.args([
        "run",
        &s(path),
        "--photons",
        "0",
        "--no-plots",
        "--no-netcdf",
        "--out",
        &s(out),
    ]);
    c
}

/// Run `scene_text` (written into `dir`) with the analytic lidar equation only; its stdout,
/// stderr and output directory.
fn run_text(dir: &Path, name: &str, scene_text: &str) -> (String, String, std::path::PathBuf) {
    let path = dir.join(name);
    std::fs::write(&path, scene_text).unwrap();
    let out = dir.join(format!("{name}.out"));
    let o = analytic_run(&path, &out).output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert!(o.status.success(), "{name}: {stderr}");
    (stdout, stderr, out)
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// The truths of the IPDA mixing ratio in `retrieval.csv`.
fn xco2_truths(out: &Path) -> Vec<f64> {
    let (header, rows) = read_csv(&out.join("retrieval.csv"));
    let col = |n: &str| header.iter().position(|h| h == n).unwrap();
    rows.iter()
        .filter(|r| r[col("quantity")] == "mixing_ratio" && r[col("method")] == "ipda")
        .map(|r| r[col("truth_ppm")].parse().unwrap())
        .collect()
}

/// `co2_ppm = 420` in the default scene is 420 ppm of dry air at every level: the truth XCO2
/// (the dry-air column integral of the profile between surface and top) is 420 to 1e-9, printed
/// as 420.0000, and the summary and `summary.json` say `well_mixed`. With `co2_scaling =
/// "profile_shape"` the summary says so, and the truth over the scene's column (to 80 km) is no
/// longer exactly 420 (the factor is set on the profile's whole column, to 120 km).
#[test]
fn co2_ppm_is_a_well_mixed_dry_air_mole_fraction() {
    let dir = tempfile::tempdir().unwrap();
    let text = shipped("spaceborne_co2_ipda.toml");
    let (stdout, stderr, out) = run_text(dir.path(), "wm.toml", &text);
    assert!(stdout.contains("truth XCO2 = 420.0000 ppm"), "{stdout}");
    assert!(
        stdout.contains(
            "CO2 well mixed at 420 ppm of dry air at every level (co2_scaling = well_mixed)"
        ),
        "{stdout}"
    );
    assert!(!stderr.contains("warning"), "{stderr}");
    let truths = xco2_truths(&out);
    assert!(!truths.is_empty());
    for t in truths {
        assert!((t / 420.0 - 1.0).abs() < 1e-9, "{t}");
    }
    assert_eq!(summary(&out)["atmosphere"]["co2_scaling"], "well_mixed");
    assert_eq!(summary(&out)["atmosphere"]["co2_ppm"], 420.0);

    let shape = text.replacen(
        "co2_ppm = 420.0",
        "co2_ppm = 420.0\nco2_scaling = \"profile_shape\"",
        1,
    );
    let (stdout, _, out) = run_text(dir.path(), "shape.toml", &shape);
    assert!(stdout.contains("(co2_scaling = profile_shape)"), "{stdout}");
    assert_eq!(summary(&out)["atmosphere"]["co2_scaling"], "profile_shape");
    for t in xco2_truths(&out) {
        assert!(
            (t - 420.0).abs() < 0.01 && (t / 420.0 - 1.0).abs() > 1e-7,
            "{t}"
        );
    }
}

/// A profile given by values with humid levels and a CO2 of its own: `co2_ppm = 400` replaces
/// it so that x_CO2/(1 − x_H2O) = 400 ppm at every level, and its XCO2 (N_CO2/N_dry) is 400
/// ppm to 1e-9; the scene's errors for `co2_scaling` name the file, line and the choices.
#[test]
fn co2_scaling_sets_every_level_and_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let base = shipped("spaceborne_co2_ipda.toml");
    let profile = "profile = { name = \"humid\", altitude_m = [0.0, 1000.0, 3000.0, 80000.0], \
                   pressure_pa = [101325.0, 89876.0, 70121.0, 1.05], \
                   temperature_k = [300.0, 293.5, 280.5, 198.6], \
                   gases = [{ name = \"H2O\", vmr = [0.03, 0.02, 0.008, 4e-6] }, \
                   { name = \"CO2\", vmr = [3e-4, 3.3e-4, 3.5e-4, 3e-4] }] }\nco2_ppm = 400.0";
    let text = base.replacen("standard = \"us_standard\"\nco2_ppm = 420.0", profile, 1);
    assert_ne!(text, base);
    let path = dir.path().join("humid.toml");
    std::fs::write(&path, &text).unwrap();
    let scene = Scene::read(&path).unwrap_or_else(|e| panic!("{e}"));
    let p = &scene.atmosphere.as_ref().unwrap().profile;
    let (co2, h2o) = (p.gas("CO2").unwrap(), p.gas("H2O").unwrap());
    for (c, h) in co2.iter().zip(h2o) {
        assert!((c / (1.0 - h) / 400e-6 - 1.0).abs() < 1e-12, "{c} {h}");
    }
    let x = p.column_average_dry_vmr("CO2").unwrap();
    assert!((x / 400e-6 - 1.0).abs() < 1e-9, "{x}");

    for (value, expect) in [
        (
            "co2_scaling = \"column_mean\"",
            "`atmosphere.co2_scaling`: `column_mean` is not a CO2 scaling (known: well_mixed, profile_shape)",
        ),
        ("co2_scaling = 3", "co2_scaling"),
    ] {
        let bad = base.replacen("co2_ppm = 420.0", &format!("co2_ppm = 420.0\n{value}"), 1);
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, &bad).unwrap();
        let o = lidarsim([
            "run",
            &s(&path),
            "--photons",
            "0",
            "--out",
            &s(&dir.path().join("x")),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(
            err.contains(&format!("{}:", s(&path))) && err.contains(expect),
            "{err}"
        );
    }
    let alone = base.replacen("co2_ppm = 420.0", "co2_scaling = \"well_mixed\"", 1);
    std::fs::write(&path, &alone).unwrap();
    let err = Scene::read(&path).unwrap_err().to_string();
    assert!(err.contains("co2_scaling`: goes with `co2_ppm`"), "{err}");
}

/// `profiles convert --co2-ppm 420` gives every ECMWF 52 profile (which have no CO2) 420 ppm of
/// dry air at every level: CO2_ppmv = 420 (1 − H2O_ppmv·10⁻⁶) in the written file, and `profiles
/// info` reports an XCO2 of 420.0; `--co2-scaling profile_shape` is refused for a profile
/// without CO2, naming the option and the profile ("tests only" data of ../shared).
#[test]
fn converted_profiles_get_well_mixed_co2() {
    let (Some(levels), Some(meta)) = (
        shared_file("data/profiles/ecmwf52_chevallier_101L.csv"),
        shared_file("data/profiles/ecmwf52_chevallier_meta.csv"),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("e52.csv");
    let args = |extra: &[&str]| {
        let mut a: Vec<String> = ["profiles", "convert", "--format", "ecmwf52", "--levels"]
            .map(String::from)
            .to_vec();
        a.extend([
            s(&levels),
            "--meta".into(),
            s(&meta),
            "--out".into(),
            s(&set),
        ]);
        a.extend(extra.iter().map(|x| x.to_string()));
        a
    };
    lidarsim_ok(args(&["--co2-ppm", "420"]));
    let (header, rows) = read_csv(&set);
    let col = |n: &str| header.iter().position(|h| h == n).unwrap();
    let (c, w) = (col("CO2_ppmv"), col("H2O_ppmv"));
    assert!(rows.len() > 1000);
    for r in &rows {
        let (co2, h2o): (f64, f64) = (r[c].parse().unwrap(), r[w].parse().unwrap());
        // The file's digits: relative 1e-9 of what they round.
        assert!(
            (co2 / (420.0 * (1.0 - h2o * 1e-6)) - 1.0).abs() < 1e-8,
            "{r:?}"
        );
    }
    let info = lidarsim_ok(["profiles", "info", &s(&set)]);
    let mut rd = csv::Reader::from_reader(info.as_bytes());
    let h = rd.headers().unwrap().clone();
    let x = h.iter().position(|n| n == "xco2_ppm").unwrap();
    let got: Vec<csv::StringRecord> = rd.records().map(Result::unwrap).collect();
    assert_eq!(got.len(), 49);
    for g in &got {
        assert!((g[x].parse::<f64>().unwrap() - 420.0).abs() < 1e-6, "{g:?}");
    }
    let o = lidarsim(args(&[
        "--co2-ppm",
        "420",
        "--co2-scaling",
        "profile_shape",
    ]));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--co2-ppm: profile `") && err.contains("CO2"),
        "{err}"
    );
}

/// The ground scene with its water cloud replaced by `layer` (the cloud from 2000 to 2300 m).
fn cloud_scene(layer: &str) -> String {
    let text = shipped("ground_rayleigh_aerosol_cloud.toml");
    let start = text.find("[[layer]]\nname = \"water cloud\"").unwrap();
    let end = text[start..].find("[surface]").unwrap() + start;
    format!(
        "{}[[layer]]\nname = \"water cloud\"\nbase_m = 2000.0\ntop_m = 2300.0\n{layer}\n\n{}",
        &text[..start],
        &text[end..]
    )
}

fn cloud_extinction_per_m(dir: &Path, layer: &str) -> Result<f64, String> {
    let path = dir.join("cloud.toml");
    std::fs::write(&path, cloud_scene(layer)).unwrap();
    let scene = crate::util::scene_read(&path).map_err(|e| e.to_string())?;
    let l = scene
        .layers
        .iter()
        .find(|l| l.name == "water cloud")
        .unwrap();
    Ok(l.extinction_per_m[0])
}

/// A cloud by liquid (ice) water content and effective radius with its optics given: the
/// geometric-optics extinction β = 3 Q_ext WC / (4 ρ r_eff), Q_ext = 2 (Hansen & Travis 1974),
/// by hand: 0.3 g/m³ of 10 µm droplets is 0.045 /m; 0.02 g/m³ of 30 µm ice (ρ = 917 kg/m³) is
/// 0.02e-3·1.5/(917·30e-6) /m. The layer runs through the binary.
#[test]
fn water_content_and_effective_radius_give_the_geometric_optics_extinction() {
    let dir = tempfile::tempdir().unwrap();
    let optics = "single_scattering_albedo = 1.0\nphase = { kind = \"table\", builtin = \"bissonnette_c1_1064nm\" }";
    let b = cloud_extinction_per_m(
        dir.path(),
        &format!("lwc_g_per_m3 = 0.3\nr_eff_um = 10.0\n{optics}"),
    )
    .unwrap();
    assert!((b / 0.045 - 1.0).abs() < 1e-12, "{b}");
    let b = cloud_extinction_per_m(
        dir.path(),
        &format!("iwc_g_per_m3 = 0.02\nr_eff_um = 30.0\n{optics}"),
    )
    .unwrap();
    let want = 0.02e-3 * 1.5 / (917.0 * 30e-6);
    assert!((b / want - 1.0).abs() < 1e-12, "{b} vs {want}");
    let (stdout, stderr, _) = run_text(
        dir.path(),
        "lwc.toml",
        &cloud_scene(&format!("lwc_g_per_m3 = 0.3\nr_eff_um = 10.0\n{optics}")),
    );
    assert!(stdout.contains("channel 1064"), "{stdout}");
    assert!(!stderr.contains("warning"), "{stderr}");
}

/// A Mie cloud by liquid water content: the Deirmendjian C.1 size distribution (modified gamma
/// α = 6, b = 1.5, γ = 1; ⟨r³⟩ = Γ(10)/(Γ(7) b³) = 149.33 µm³) with the water index at 1064 nm.
/// N = LWC/(ρ_w (4/3)π⟨r³⟩) particles, each with miepython's ⟨C_ext⟩ = 172.3447 µm²
/// (`../shared/reference/c1_summary.csv`): β = N ⟨C_ext⟩ within 0.5 % (the Mie stage's accuracy
/// on C.1, tests/particles.rs).
#[test]
fn mie_cloud_by_liquid_water_content_matches_miepython() {
    let Some(summary) = shared_file("reference/c1_summary.csv") else {
        return;
    };
    let text = std::fs::read_to_string(summary).unwrap();
    let row = text
        .lines()
        .find(|l| l.starts_with("1064,"))
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect::<Vec<_>>();
    let (m_re, m_im, c_ext_um2): (f64, f64, f64) = (
        row[1].parse().unwrap(),
        row[2].parse().unwrap(),
        row[3].parse().unwrap(),
    );
    let lwc = 0.1;
    let r3_um3 = 9.0 * 8.0 * 7.0 / 1.5f64.powi(3);
    let v_m3 = 4.0 / 3.0 * std::f64::consts::PI * r3_um3 * 1e-18;
    let n_per_m3 = lwc * 1e-3 / (1000.0 * v_m3);
    let want = n_per_m3 * c_ext_um2 * 1e-12;
    let dir = tempfile::tempdir().unwrap();
    let b = cloud_extinction_per_m(
        dir.path(),
        &format!(
            "lwc_g_per_m3 = {lwc}\nparticles = {{ distribution = \"modified_gamma\", alpha = 6.0, \
             b = 1.5, gamma = 1.0, refractive_index = \"{m_re}+{m_im}i\" }}"
        ),
    )
    .unwrap();
    assert!((b / want - 1.0).abs() < 5e-3, "{b} vs {want}");
}

/// A scene's first Mie computation reports its progress from inside the library while the
/// scene is resolved: as the command line's own progress, from the start with
/// `LIDARSIM_PROGRESS_AFTER_S=0`, and not at all with `--quiet` (which silences every progress
/// report of the process). The cache is off, so both runs compute.
#[test]
fn a_scenes_first_mie_computation_is_silent_with_quiet() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mie.toml");
    std::fs::write(
        &path,
        cloud_scene(
            "extinction_per_km = 5.0
particles = { distribution = \"lognormal\", \
             median_radius_um = 2.0, sigma_g = 1.5, refractive_index = \"1.33+0i\" }",
        ),
    )
    .unwrap();
    let run = |quiet: bool| {
        let mut c = analytic_run(&path, &dir.path().join(if quiet { "q" } else { "v" }));
        c.env("LIDARSIM_PROGRESS_AFTER_S", "0");
        if quiet {
            c.arg("--quiet");
        }
        let o = c.output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        err
    };
    let loud = run(false);
    assert!(loud.contains("lidarsim: Mie optics at 1064 nm: "), "{loud}");
    let quiet = run(true);
    assert!(!quiet.contains("Mie optics"), "{quiet}");
}

/// Exactly one amount: an extinction and a water content together, a water content without
/// `r_eff_um`, `r_eff_um` alone, liquid and ice together, and a water content with a
/// number density of `particles` are each refused with the file, line and key.
#[test]
fn water_content_conflicts_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let optics =
        "single_scattering_albedo = 1.0\nphase = { kind = \"henyey_greenstein\", g = 0.85 }";
    let mie = "particles = { distribution = \"lognormal\", median_radius_um = 5.0, sigma_g = 1.5, refractive_index = \"1.33+0i\" }";
    for (layer, expect) in [
        (
            format!("extinction_per_km = 5.0\nlwc_g_per_m3 = 0.3\nr_eff_um = 10.0\n{optics}"),
            "`layer.lwc_g_per_m3`: give the particles' amount as",
        ),
        (format!("lwc_g_per_m3 = 0.3\n{optics}"), "needs `r_eff_um`"),
        (
            format!("r_eff_um = 10.0\nextinction_per_km = 5.0\n{optics}"),
            "`layer.r_eff_um`: goes with `lwc_g_per_m3` or `iwc_g_per_m3`",
        ),
        (
            format!("lwc_g_per_m3 = 0.3\niwc_g_per_m3 = 0.1\nr_eff_um = 10.0\n{optics}"),
            "`layer.iwc_g_per_m3`: give `lwc_g_per_m3` (liquid) or `iwc_g_per_m3` (ice), not both",
        ),
        (
            format!("lwc_g_per_m3 = -0.3\nr_eff_um = 10.0\n{optics}"),
            "`layer.lwc_g_per_m3`",
        ),
        (
            format!("lwc_g_per_m3 = 0.3\nnumber_density_per_cm3 = 100.0\n{mie}"),
            "give the amount as `number_density_per_cm3`, as an extinction at the first channel, or as a water content",
        ),
        (
            format!("lwc_g_per_m3 = 0.3\nr_eff_um = 8.0\n{mie}"),
            "`layer.r_eff_um`: the lognormal's size is given twice",
        ),
    ] {
        let err = cloud_extinction_per_m(dir.path(), &layer).unwrap_err();
        assert!(
            err.contains("cloud.toml:") && err.contains(expect),
            "{layer}\n→ {err}"
        );
    }
    // A lognormal sized by its effective radius: the median radius r_eff exp(−5/2 ln²σ_g).
    let by_reff = cloud_extinction_per_m(
        dir.path(),
        "lwc_g_per_m3 = 0.3\nr_eff_um = 8.0\nparticles = { distribution = \"lognormal\", sigma_g = 1.5, refractive_index = \"1.33+0i\" }",
    )
    .unwrap();
    let median = 8.0 / (2.5 * 1.5f64.ln().powi(2)).exp();
    let by_median = cloud_extinction_per_m(
        dir.path(),
        &format!("lwc_g_per_m3 = 0.3\nparticles = {{ distribution = \"lognormal\", median_radius_um = {median}, sigma_g = 1.5, refractive_index = \"1.33+0i\" }}"),
    )
    .unwrap();
    assert!(
        (by_reff / by_median - 1.0).abs() < 1e-12,
        "{by_reff} {by_median}"
    );
}

/// Each warning, through the binary, printed once on stderr (`lidarsim: warning: FILE:LINE:
/// key: …`) and recorded in the summary and `summary.json`; the run still succeeds:
/// `extinction_per_km = 17230` over 290 m (optical depth 4996.7), 15 m gates behind a 3 MHz
/// detector (c/(2B) = 50.0 m), and an on-line at the R16e centre with a tenth of the pulse
/// energy (expected SNR per shot below 1).
#[test]
fn implausible_and_misleading_values_are_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    let od = cloud_scene(
        "extinction_per_km = 17230\nsingle_scattering_albedo = 1.0\nphase = { kind = \"henyey_greenstein\", g = 0.85 }",
    )
    .replacen("top_m = 2300.0", "top_m = 2290.0", 1);
    let gate = shipped("spaceborne_co2_ipda.toml")
        .replacen("bandwidth_mhz = 10.0", "bandwidth_mhz = 3.0", 1)
        .replacen("width_m = 50.0", "width_m = 15.0", 1);
    let snr = shipped("study_co2_ipda.toml")
        .replacen("on = \"R16e+2.2GHz\"", "on = \"R16e+0.0GHz\"", 1)
        .replacen("pulse_energy_j = 0.03", "pulse_energy_j = 0.003", 1);
    for (name, text, key, words) in [
        (
            "od.toml",
            od,
            "`layer.extinction_per_km`",
            vec![
                "layer `water cloud` has a vertical optical depth of 4996.7 at `1064`",
                "above 100",
            ],
        ),
        (
            "gate.toml",
            gate,
            "`gates.width_m`",
            vec![
                "gates of 15 m are shorter than c/(2B) = 50.0 m",
                "3 MHz bandwidth",
                "optimistic",
            ],
        ),
        (
            "snr.toml",
            snr,
            "`retrieval.on`",
            vec![
                "the on-line `R16e+0.0GHz` has an expected signal-to-noise ratio per shot of 0.",
                "below 1",
            ],
        ),
    ] {
        let (stdout, stderr, out) = run_text(dir.path(), name, &text);
        let warnings: Vec<&str> = stderr
            .lines()
            .filter(|l| l.starts_with("lidarsim: warning: "))
            .collect();
        assert_eq!(warnings.len(), 1, "{name}: {stderr}");
        let w = warnings[0];
        assert!(w.contains(&format!("{name}:")) && w.contains(key), "{w}");
        for word in &words {
            assert!(w.contains(word), "{name}: `{word}` missing from {w}");
        }
        let message = w.trim_start_matches("lidarsim: warning: ");
        assert!(stdout.contains(&format!("warning: {message}")), "{stdout}");
        let json = summary(&out);
        let listed = json["warnings"].as_array().unwrap();
        assert_eq!(listed.len(), 1);
        assert_eq!(listed[0].as_str().unwrap(), message);
    }
}

/// The shipped scenes give none of the warnings (the analytic lidar equation: the warnings do
/// not depend on the photons).
#[test]
fn shipped_scenes_give_no_warning() {
    let dir = tempfile::tempdir().unwrap();
    let mut names: Vec<String> = std::fs::read_dir(project_root().join("scenes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 6);
    for n in names {
        let path = project_root().join("scenes").join(&n);
        let out = dir.path().join(&n);
        let o = analytic_run(&path, &out).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{n}: {stderr}");
        assert!(!stderr.contains("warning"), "{n}: {stderr}");
        assert!(summary(&out).get("warnings").is_none(), "{n}");
    }
}
