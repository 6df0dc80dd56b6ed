//! Ensemble studies (`lidarsim dial`): the ensemble that goes in against the covariance asked
//! for, the analytic random error against the spread of noisy retrievals, the budget's
//! knowledge rows against finite differences computed here from line-by-line optical depths,
//! the class-mean virtual-σ error against its closed form and a hand calculation, failed
//! profiles, thread counts, and the command line.

use std::path::Path;

use lidarsim::atmosphere::{
    ErrorModel, LatitudeClass, ProfileSet, SetMember, StandardAtmosphere, StateShift,
    class_ensemble, shift_member,
};
use lidarsim::retrieval::{LayerColumns, Method};
use lidarsim::scene::Scene;
use lidarsim::spectroscopy::{LineList, layer_optical_depths_at, tips};
use lidarsim::study::dial::{self, ProfileOutcome, Source, StudyOptions};

use crate::util::{lidarsim, lidarsim_ok, read_csv};

/// A space-borne CO2 IPDA, nadir from 450 km, monochromatic on-line 2.2 GHz up R16e and
/// off-line in the trough, built-in band model, no Rayleigh scattering (so the measured
/// differential optical depth is the gas's alone), 1 km layers to 50 km.
pub(crate) const SCENE: &str = r#"description = "study test"
[lidar]
altitude_km = 450.0
zenith_angle_deg = 180.0
beam_divergence_full_angle_mrad = 0.15
beam_profile = "gaussian"
telescope_diameter_m = 1.5
optical_efficiency = 0.5
fov_full_angle_mrad = 0.2
[[channel]]
name = "on"
wavenumber_cm1 = 6360.04
[[channel]]
name = "side"
wavenumber_cm1 = 6360.01
[[channel]]
name = "off"
wavenumber_cm1 = 6360.61
[laser]
pulse_energy_j = 0.03
repetition_rate_hz = 50.0
[receiver]
filter_bandwidth_ghz = 1.0
filter_transmission = 0.8
quantum_efficiency = 0.8
gain = 10.0
ionization_ratio = 0.45
nep_w_per_sqrt_hz = 4.0e-14
bandwidth_mhz = 10.0
[retrieval]
gas = "CO2"
on = "on"
off = "off"
target = "surface"
averaging_shots = 350
[gates]
start_m = 449800.0
end_m = 450050.0
width_m = 50.0
[atmosphere]
standard = "us_standard"
co2_ppm = 420.0
layer_thickness_m = 1000.0
top_m = 50000.0
rayleigh = false
[gas_absorption]
molecules = ["CO2"]
[surface]
altitude_m = 0.0
albedo = 0.2
[simulation]
photons = 0
seed = 3
"#;

fn scene() -> Scene {
    Scene::from_toml(Path::new("study.toml"), SCENE).expect("test scene")
}

fn options(s: &Scene) -> StudyOptions {
    StudyOptions::from_scene(s).expect("scene has a retrieval")
}

fn set_of(name: &str, members: Vec<SetMember>) -> ProfileSet {
    ProfileSet {
        name: name.into(),
        members,
        notes: Vec::new(),
    }
}

fn ipda_records(o: &ProfileOutcome) -> Vec<&dial::Record> {
    o.records
        .as_ref()
        .expect("profile ran")
        .iter()
        .filter(|r| r.method == Method::Ipda)
        .collect()
}

/// Vertical optical depth of CO2 of the whole column at the on- and off-line, and the column's
/// CO2 and dry-air amounts, of `profile` on the scene's grid (cut to the profile's top).
fn column(s: &Scene, profile: &lidarsim::atmosphere::Profile) -> (f64, f64, f64, f64) {
    let mut edges = s.molecular_edges().unwrap();
    let top = profile
        .altitude_m
        .last()
        .unwrap()
        .min(*edges.last().unwrap());
    edges.retain(|z| *z < top);
    edges.push(top);
    let gas = s.gas.as_ref().unwrap();
    let nu = [s.lines[0].wavenumber_cm1, s.lines[2].wavenumber_cm1];
    let tau = layer_optical_depths_at(profile, &gas.lines, &edges, &nu, &gas.options).unwrap();
    let on: f64 = tau.iter().map(|t| t[0]).sum();
    let off: f64 = tau.iter().map(|t| t[1]).sum();
    let cols = LayerColumns::new(profile, &edges, "CO2").unwrap();
    let (co2, dry) = (
        cols.gas_per_m2.iter().sum::<f64>(),
        cols.dry_air_per_m2.iter().sum::<f64>(),
    );
    (on, off, co2, dry)
}

/// The ensemble drawn for a class has the covariance that was asked for: per-level variances
/// of T and ln H2O within sampling error of the error model's (a sample variance of n draws
/// has a relative standard deviation of √(2/(n−1)), 7 % at n = 400; the bound is 4.5 of them),
/// and the T correlation of neighbouring levels within 0.1 of the model's.
#[test]
fn ensemble_statistics_match_the_covariance_asked_for() {
    let class = LatitudeClass::Mid;
    let n = 400;
    let (set, _) = class_ensemble(class, n, 11).unwrap();
    let afgl = set_of(
        "afgl",
        class
            .afgl_atmospheres()
            .iter()
            .map(|s| s.member())
            .collect(),
    );
    let mean = afgl.mean_member().unwrap().profile;
    let cov = ErrorModel::representative()
        .scaled_for_class(class)
        .covariance(&mean)
        .unwrap();
    let sd = cov.std_devs();
    let levels = mean.len();
    let bound = 4.5 * (2.0 / (n as f64 - 1.0)).sqrt();
    let sample = |f: &dyn Fn(&SetMember, usize) -> f64, k: usize| -> (f64, Vec<f64>) {
        let v: Vec<f64> = set.members.iter().map(|m| f(m, k)).collect();
        let m = v.iter().sum::<f64>() / n as f64;
        let d: Vec<f64> = v.iter().map(|x| x - m).collect();
        (d.iter().map(|x| x * x).sum::<f64>() / (n as f64 - 1.0), d)
    };
    let mut checked_q = 0;
    let t_of = |m: &SetMember, k: usize| m.profile.temperature_k[k] - mean.temperature_k[k];
    let q_of = |m: &SetMember, k: usize| {
        (m.profile.gas("H2O").unwrap()[k] / mean.gas("H2O").unwrap()[k]).ln()
    };
    for k in 0..levels {
        let (var_t, _) = sample(&t_of, k);
        if sd[k] > 0.0 {
            let r = var_t / (sd[k] * sd[k]);
            assert!(
                (r - 1.0).abs() < bound,
                "T variance at level {k}: ratio {r}"
            );
        }
        // ln H2O where no member can reach the 100 % RH cap (the mean below 30 % RH: a cap
        // needs a 4σ draw).
        let e = mean.gas("H2O").unwrap()[k] * mean.pressure_pa[k];
        let e_s = lidarsim::atmosphere::humidity::saturation_vapour_pressure_pa(
            mean.temperature_k[k],
            lidarsim::atmosphere::SaturationOver::Water,
        );
        let s = sd[levels + k];
        if e < 0.3 * e_s && s > 0.0 {
            let (var_q, _) = sample(&q_of, k);
            let r = var_q / (s * s);
            assert!(
                (r - 1.0).abs() < bound,
                "ln q variance at level {k}: ratio {r}"
            );
            checked_q += 1;
        }
    }
    assert!(checked_q > 10, "only {checked_q} humidity levels checked");
    // Neighbouring-level temperature correlation.
    for k in (5..levels - 1).step_by(7) {
        let (va, da) = sample(&t_of, k);
        let (vb, db) = sample(&t_of, k + 1);
        let c = da.iter().zip(&db).map(|(a, b)| a * b).sum::<f64>() / (n as f64 - 1.0);
        let r = c / (va * vb).sqrt();
        let asked = cov.matrix[(k, k + 1)] / (sd[k] * sd[k + 1]);
        assert!(
            (r - asked).abs() < 0.1,
            "T correlation {k}/{}: {r} vs {asked}",
            k + 1
        );
    }
}

/// One noisy measurement per profile, from the profile's own noise seed: the spread of
/// noisy − noise-free retrievals over 1500 profiles equals the analytic random error within
/// 10 % (the ratio of standard deviations has a relative sampling error of 1/√(2n) = 1.8 %).
#[test]
fn analytic_random_error_matches_the_spread_of_noisy_retrievals() {
    let s = scene();
    let (set, _) = class_ensemble(LatitudeClass::Tropical, 1500, 5).unwrap();
    let result = dial::run(&s, &set, &options(&s), &|| {}).unwrap();
    let summary = dial::summarise(&result.outcomes);
    let ipda = summary
        .iter()
        .find(|m| m.method == Method::Ipda)
        .expect("an IPDA summary");
    assert_eq!(ipda.profiles, 1500);
    println!(
        "noise ratio over 1500 profiles: {:.4} (random error rms {:.4} ppm)",
        ipda.noise_ratio, ipda.sources[0].rms_ppm
    );
    assert!(
        (ipda.noise_ratio - 1.0).abs() < 0.1,
        "sd(noisy − noise-free) / analytic = {}",
        ipda.noise_ratio
    );
}

/// The temperature, surface-pressure and humidity rows equal finite differences computed here
/// from line-by-line optical depths of the shifted profiles: for a monochromatic laser the
/// IPDA retrieves X = X_ref · D_measured / D_ref (D_measured: the truth's differential optical
/// depth; X_ref and D_ref: the assumed profile's), so a row is
/// X_ref,shifted · D/D_ref,shifted − X_ref,0 · D/D_ref,0 with both references re-levelled
/// (`shift_member`). Agreement to 1e-6 relative: only rounding differs.
#[test]
fn knowledge_rows_equal_independent_finite_differences() {
    let s = scene();
    let (set, _) = class_ensemble(LatitudeClass::High, 3, 2).unwrap();
    let result = dial::run(&s, &set, &options(&s), &|| {}).unwrap();
    let steps = options(&s).steps;
    for (member, outcome) in set.members.iter().zip(&result.outcomes) {
        let rec = ipda_records(outcome)[0];
        let truth = s.with_profile(member.profile.clone()).unwrap();
        let truth_member = SetMember {
            meta: member.meta.clone(),
            profile: truth.atmosphere.as_ref().unwrap().profile.clone(),
        };
        let (on, off, co2, dry) = column(&s, &truth_member.profile);
        let d_true = on - off;
        assert!((rec.truth_ppm - co2 / dry * 1e6).abs() < 1e-9 * rec.truth_ppm);
        let retrieved = |shift: StateShift| {
            let p = shift_member(&truth_member, &shift).unwrap().profile;
            let (on, off, co2, dry) = column(&s, &p);
            co2 / dry * 1e6 * d_true / (on - off)
        };
        let none = StateShift::NONE;
        let x0 = retrieved(none);
        let rows = [
            (
                Source::Temperature,
                retrieved(StateShift {
                    temperature_k: -steps.temperature_k,
                    ..none
                }) - x0,
            ),
            (
                Source::Humidity,
                retrieved(StateShift {
                    h2o_factor: 1.0 / (1.0 + steps.humidity_fraction),
                    ..none
                }) - x0,
            ),
            (
                Source::SurfacePressure,
                retrieved(StateShift {
                    surface_pressure_hpa: steps.surface_pressure_hpa,
                    ..none
                }) - x0,
            ),
        ];
        for (src, want) in rows {
            let j = Source::ALL.iter().position(|x| *x == src).unwrap();
            let got = rec.budget_ppm[j];
            println!(
                "{} {}: {got:.6} ppm (finite difference {want:.6})",
                member.meta.id,
                src.label()
            );
            assert!(
                (got - want).abs() < 1e-6 * want.abs() + 1e-9,
                "{} row of {}: {got} ppm, finite difference {want} ppm",
                src.label(),
                member.meta.id
            );
        }
        // A colder assumed atmosphere on the line's side: the assumed cross-section is larger
        // (line strength and width both grow as T falls there), so less CO2 is retrieved.
        assert!(rows[0].1 < 0.0);
    }
}

/// With the class-mean virtual σ and the profile's own dry-air column, the noise-free error
/// of each profile is X (Δσ_own/Δσ_mean − 1), Δσ = D/N of the column: computed here from
/// line-by-line optical depths of the profile and of the set's mean. Then the hand
/// calculation for profiles 1 K warmer and colder than their mean: in the Lorentz regime
/// σ ∝ S(T) γ/(Δν² + γ²), so d ln σ/dT = c₂E″/T² − d ln Q/dT − (n/T)(Δν² − γ²)/(Δν² + γ²),
/// evaluated at the D-weighted mean pressure and temperature of the column; the study's error
/// has its sign and is within 10 % of its size (a single effective layer, the Doppler part of
/// the profile and the off-line neglected; measured: 0.03 % and 0.2 %).
#[test]
fn mean_profile_sigma_error_is_the_cross_section_ratio_and_matches_a_hand_calculation() {
    let s = scene();
    let base = StandardAtmosphere::MidlatitudeSummer.member();
    let warm = shift_member(
        &base,
        &StateShift {
            temperature_k: 1.0,
            ..StateShift::NONE
        },
    )
    .unwrap();
    let cold = shift_member(
        &base,
        &StateShift {
            temperature_k: -1.0,
            ..StateShift::NONE
        },
    )
    .unwrap();
    let mut warm = warm;
    let mut cold = cold;
    warm.meta.id = "warm".into();
    cold.meta.id = "cold".into();
    let set = set_of("±1 K", vec![warm.clone(), cold.clone()]);
    let result = dial::run(&s, &set, &options(&s), &|| {}).unwrap();
    let mean = s
        .with_profile(set.mean_member().unwrap().profile)
        .unwrap()
        .atmosphere
        .unwrap()
        .profile;
    let (on_m, off_m, co2_m, _) = column(&s, &mean);
    let dsigma_mean = (on_m - off_m) / co2_m;
    for (member, outcome) in set.members.iter().zip(&result.outcomes) {
        let rec = ipda_records(outcome)[0];
        let truth = s
            .with_profile(member.profile.clone())
            .unwrap()
            .atmosphere
            .unwrap()
            .profile;
        let (on, off, co2, dry) = column(&s, &truth);
        let x = co2 / dry * 1e6;
        let want = x * ((on - off) / co2 / dsigma_mean - 1.0);
        assert!(
            (rec.error_ppm() - want).abs() < 1e-6 * want.abs() + 1e-9,
            "{}: error {} ppm, closed form {want} ppm",
            member.meta.id,
            rec.error_ppm()
        );
    }
    // Hand calculation at the D-weighted mean state of the column.
    let edges = s.molecular_edges().unwrap();
    let gas = s.gas.as_ref().unwrap();
    let nu_on = s.lines[0].wavenumber_cm1;
    let tau = layer_optical_depths_at(
        &mean,
        &gas.lines,
        &edges,
        &[nu_on, s.lines[2].wavenumber_cm1],
        &gas.options,
    )
    .unwrap();
    let layers = lidarsim::spectroscopy::layers::curtis_godson_layers(&mean, &edges).unwrap();
    let w: Vec<f64> = tau.iter().map(|t| t[0] - t[1]).collect();
    let wsum: f64 = w.iter().sum();
    let p_atm = layers
        .iter()
        .zip(&w)
        .map(|(l, w)| w * l.pressure_pa)
        .sum::<f64>()
        / wsum
        / 101_325.0;
    let t = layers
        .iter()
        .zip(&w)
        .map(|(l, w)| w * l.temperature_k)
        .sum::<f64>()
        / wsum;
    let band = LineList::co2_30012_band_model();
    let r16 = band
        .lines
        .iter()
        .min_by(|a, b| {
            (a.nu_cm1 - 6359.967)
                .abs()
                .total_cmp(&(b.nu_cm1 - 6359.967).abs())
        })
        .unwrap();
    let c2 = 1.438_776_9;
    let q = |t: f64| tips::partition_sum(2, 1, t).unwrap();
    let dlnq = (q(t + 0.5).ln() - q(t - 0.5).ln()) / 1.0;
    let gamma = r16.gamma_air_cm1_per_atm * p_atm * (296.0 / t).powf(r16.n_air);
    let dnu = nu_on - (r16.nu_cm1 + r16.delta_air_cm1_per_atm * p_atm);
    let lorentz = (dnu * dnu - gamma * gamma) / (dnu * dnu + gamma * gamma);
    let dln_sigma = c2 * r16.elower_cm1 / (t * t) - dlnq - r16.n_air / t * lorentz;
    for (id, dt) in [("warm", 1.0), ("cold", -1.0)] {
        let o = result.outcomes.iter().find(|o| o.id == id).unwrap();
        let got = ipda_records(o)[0].error_ppm();
        let hand = 420.0 * dln_sigma * dt;
        println!(
            "{id}: study {got:.4} ppm, hand calculation {hand:.4} ppm (p {p_atm:.3} atm, T {t:.1} K)"
        );
        assert!(
            got.signum() == hand.signum() && (got / hand - 1.0).abs() < 0.1,
            "{id}: study {got} ppm, hand calculation {hand} ppm (p {p_atm:.3} atm, T {t:.1} K)"
        );
    }
}

/// A profile that cannot be run is reported by id with the reason and left out of the
/// statistics: one supersaturated, one ending below the scene's top of the atmosphere.
#[test]
fn failed_profiles_are_reported_and_left_out() {
    let s = scene();
    let (mut set, _) = class_ensemble(LatitudeClass::Mid, 4, 9).unwrap();
    let wet = &mut set.members[1];
    for g in &mut wet.profile.gases {
        if g.name == "H2O" {
            g.vmr[0] *= 5.0;
        }
    }
    let low = &mut set.members[2].profile;
    let keep = low.altitude_m.iter().filter(|z| **z < 40_000.0).count();
    low.altitude_m.truncate(keep);
    low.pressure_pa.truncate(keep);
    low.temperature_k.truncate(keep);
    for g in &mut low.gases {
        g.vmr.truncate(keep);
    }
    let result = dial::run(&s, &set, &options(&s), &|| {}).unwrap();
    let reason = |i: usize| result.outcomes[i].records.as_ref().err().cloned();
    assert!(reason(0).is_none() && reason(3).is_none());
    let wet = reason(1).expect("supersaturated profile fails");
    assert!(wet.contains("supersaturated"), "{wet}");
    let low = reason(2).expect("short profile fails");
    assert!(low.contains("top_m") && low.contains("below"), "{low}");
    let summary = dial::summarise(&result.outcomes);
    assert!(summary.iter().all(|m| m.profiles == 2));
}

/// Profiles run in parallel with per-profile seeds: the same numbers with 1 and 2 threads.
#[test]
fn studies_do_not_depend_on_the_thread_count() {
    let s = scene();
    let (set, _) = class_ensemble(LatitudeClass::Tropical, 6, 4).unwrap();
    let mut o = options(&s);
    o.pairs.push((1, 2));
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| dial::run(&s, &set, &o, &|| {}).unwrap().outcomes)
    };
    assert_eq!(run(1), run(2));
}

/// The command line: files with their headers (no NetCDF with `--no-netcdf`), failed profiles
/// listed, errors named.
#[test]
fn dial_command_writes_its_tables() {
    let dir = tempfile::tempdir().unwrap();
    let scene_path = dir.path().join("study.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let out = dir.path().join("out");
    let stdout = lidarsim_ok([
        "dial".as_ref(),
        scene_path.as_os_str(),
        "--ensemble".as_ref(),
        "4".as_ref(),
        "--class".as_ref(),
        "mid".as_ref(),
        "--on".as_ref(),
        "on,side".as_ref(),
        "--no-plots".as_ref(),
        "--no-netcdf".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(stdout.contains("4 profiles"), "{stdout}");
    for f in ["profiles.nc", "summary.nc"] {
        assert!(!out.join(f).exists(), "{f} written despite --no-netcdf");
    }
    let profiles = std::fs::read_to_string(out.join("profiles.csv")).unwrap();
    let mut lines = profiles.lines();
    assert!(
        lines
            .next()
            .unwrap()
            .starts_with("profile_id,class,pair,method,")
    );
    // 4 profiles × 2 pairs × one IPDA column.
    assert_eq!(lines.count(), 8);
    let budget = std::fs::read_to_string(out.join("budget.csv")).unwrap();
    assert_eq!(budget.lines().count(), 1 + 2 * Source::ALL.len());
    let bad = lidarsim([
        "dial".as_ref(),
        scene_path.as_os_str(),
        "--ensemble".as_ref(),
        "4".as_ref(),
        "--on".as_ref(),
        "nope".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert_eq!(bad.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("no line `nope`"), "{err}");
}

/// The seams a study swaps profiles and lasers through give what the scene parser gives for
/// the same scene written with that profile or laser.
#[test]
fn swapped_profiles_and_lasers_equal_parsed_scenes() {
    let with_laser_keys = |keys: &str| {
        SCENE.replace(
            "[laser]\npulse_energy_j = 0.03\nrepetition_rate_hz = 50.0\n",
            &format!("[laser]\npulse_energy_j = 0.03\nrepetition_rate_hz = 50.0\n{keys}\n"),
        )
    };
    let parse = |text: &str| Scene::from_toml(Path::new("study.toml"), text).unwrap();
    let plain = parse(&with_laser_keys(""));
    let shaped = parse(&with_laser_keys(
        "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0\nfrequency_jitter_rms_mhz = 0.5\nspectral_purity = 0.99\nimpurity_wavenumber_cm1 = [6360.05, 6360.02, 6360.62]",
    ));
    assert!(shaped.channels.len() > plain.channels.len());
    // Monochromatic → shaped and back.
    let swapped = plain.with_laser(shaped.laser.clone()).unwrap();
    assert_eq!(swapped.channels, shaped.channels);
    assert_eq!(swapped.sampling, shaped.sampling);
    assert_eq!(
        swapped.surface.as_ref().unwrap().albedo,
        shaped.surface.as_ref().unwrap().albedo
    );
    let back = swapped.with_laser(plain.laser.clone()).unwrap();
    assert_eq!(back.channels, plain.channels);
    assert_eq!(back.surface.unwrap().albedo, plain.surface.unwrap().albedo);
    // A profile swapped in is rescaled and checked as the parser does it.
    let tropical = parse(&SCENE.replace("us_standard", "tropical"));
    let swapped = scene()
        .with_profile(StandardAtmosphere::Tropical.profile())
        .unwrap();
    assert_eq!(
        swapped.atmosphere.unwrap().profile,
        tropical.atmosphere.unwrap().profile
    );
}

/// Issue 37, item 5, the README's own example: `dial scenes/study_co2_ipda.toml --ensemble 3`.
/// From 450 km the 2 km DIAL cells have an SNR far below 1 (random errors of 1e5 ppm), so one
/// noisy measurement often has no positive signal and cannot be retrieved: that field is empty
/// in profiles.csv (it was `NaN`), and summary.csv's noisy statistics are over the profiles
/// whose measurement was retrieved, `noisy_profiles` of them (they were `NaN` for the whole
/// row). Checked against the same statistics computed here from profiles.csv, and no CSV or
/// NetCDF file holds `NaN` or `inf`.
#[test]
fn the_readme_study_writes_no_nan_and_counts_its_noisy_profiles() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let scene = crate::util::project_root().join("scenes/study_co2_ipda.toml");
    lidarsim_ok([
        "dial".as_ref(),
        scene.as_os_str(),
        "--ensemble".as_ref(),
        "3".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let mut checked: Vec<String> = crate::util::assert_no_non_finite(&out)
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    checked.sort();
    assert_eq!(
        checked,
        [
            "budget.csv",
            "failed.csv",
            "profiles.csv",
            "profiles.nc",
            "summary.csv",
            "summary.nc"
        ]
    );
    let (ph, profiles) = read_csv(&out.join("profiles.csv"));
    let pc = |name: &str| ph.iter().position(|h| h == name).unwrap();
    let (sh, summary) = read_csv(&out.join("summary.csv"));
    let sc = |name: &str| sh.iter().position(|h| h == name).unwrap();
    let num = |s: &str| -> f64 { s.parse().unwrap() };
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
    let mut partly = 0;
    for row in &summary {
        let key = |r: &Vec<String>| {
            (row[sc("class")] == "all" || r[pc("class")] == row[sc("class")])
                && r[pc("pair")] == row[sc("pair")]
                && r[pc("method")] == row[sc("method")]
                && r[pc("altitude_bottom_m")] == row[sc("altitude_bottom_m")]
        };
        let members: Vec<&Vec<String>> = profiles.iter().filter(|r| key(r)).collect();
        assert_eq!(num(&row[sc("profiles")]) as usize, members.len(), "{row:?}");
        // The noisy measurement and its error are empty together.
        for r in &members {
            assert_eq!(
                r[pc("retrieved_noisy_ppm")].is_empty(),
                r[pc("error_noisy_ppm")].is_empty(),
                "{r:?}"
            );
        }
        let noisy: Vec<&&Vec<String>> = members
            .iter()
            .filter(|r| !r[pc("retrieved_noisy_ppm")].is_empty())
            .collect();
        let n = noisy.len();
        assert_eq!(num(&row[sc("noisy_profiles")]) as usize, n, "{row:?}");
        if n < members.len() {
            partly += 1;
            assert_eq!(
                row[sc("method")],
                "dial",
                "an IPDA column lost its noisy value"
            );
        }
        let errors: Vec<f64> = noisy
            .iter()
            .map(|r| num(&r[pc("error_noisy_ppm")]))
            .collect();
        let noise: Vec<f64> = noisy
            .iter()
            .map(|r| num(&r[pc("retrieved_noisy_ppm")]) - num(&r[pc("retrieved_ppm")]))
            .collect();
        let random: Vec<f64> = noisy.iter().map(|r| num(&r[pc("random_ppm")])).collect();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let sd = |v: &[f64]| {
            let m = mean(v);
            (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (v.len() as f64 - 1.0)).sqrt()
        };
        let field = |name: &str| row[sc(name)].as_str();
        if n == 0 {
            assert_eq!(field("noisy_bias_ppm"), "", "{row:?}");
        } else {
            assert!(
                close(num(field("noisy_bias_ppm")), mean(&errors)),
                "{row:?}"
            );
        }
        if n < 2 {
            for name in ["noisy_sd_ppm", "noise_ratio"] {
                assert_eq!(field(name), "", "{name}: {row:?}");
            }
        } else {
            assert!(close(num(field("noisy_sd_ppm")), sd(&errors)), "{row:?}");
            let rms = (random.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
            assert!(
                close(num(field("noise_ratio")), sd(&noise) / rms),
                "{row:?}"
            );
        }
    }
    assert!(
        partly > 0,
        "every DIAL cell had its noisy measurement retrieved"
    );
}

/// Issue 37, item 5: the humidity step of the budget keeps the assumed humidity positive and
/// finite and a knowledge error: `--budget-humidity-percent -99.9` (an assumed humidity 1000
/// times the truth's, which wrote `inf`) is refused by its bound before any work, and the
/// bound itself, −50 % (the assumed humidity twice the truth's), gives finite rows.
#[test]
fn the_humidity_step_is_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let scene = crate::util::project_root().join("scenes/study_co2_ipda.toml");
    let run = |percent: &str| {
        lidarsim([
            "dial".as_ref(),
            scene.as_os_str(),
            "--ensemble".as_ref(),
            "2".as_ref(),
            "--class".as_ref(),
            "tropical".as_ref(),
            "--budget-humidity-percent".as_ref(),
            percent.as_ref(),
            "--no-plots".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ])
    };
    for bad in ["-99.9", "-50.01", "1000.1"] {
        let o = run(bad);
        assert_eq!(o.status.code(), Some(2), "{bad}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(
            err.trim_end(),
            format!("lidarsim: error: --budget-humidity-percent {bad} must lie in [-50, 1000]")
        );
        assert!(!out.exists(), "{bad}: output written");
    }
    let o = run("-50");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    crate::util::assert_no_non_finite(&out);
    let (h, rows) = read_csv(&out.join("profiles.csv"));
    let c = h.iter().position(|x| x == "humidity_ppm").unwrap();
    for r in &rows {
        let v: f64 = r[c].parse().unwrap();
        assert!(v.is_finite(), "{r:?}");
    }
    assert_eq!(
        rows.len(),
        2 * 6,
        "2 profiles × (1 IPDA column + 5 DIAL cells)"
    );
}

/// A generated profile set (`profiles generate --class mid --n 4`) with profiles 1 and 3 made
/// supersaturated at the surface (water vapour × 5) and profile 2 cut above 30 km (below the
/// scene's top of the atmosphere, 50 km), as (set file, its text).
fn set_with_failures(dir: &Path, keep_good: bool) -> std::path::PathBuf {
    let set = dir.join("set.csv");
    lidarsim_ok([
        "profiles".as_ref(),
        "generate".as_ref(),
        "--class".as_ref(),
        "mid".as_ref(),
        "--n".as_ref(),
        "4".as_ref(),
        "--seed".as_ref(),
        "1".as_ref(),
        "--out".as_ref(),
        set.as_os_str(),
    ]);
    let text = std::fs::read_to_string(&set).unwrap();
    let header: Vec<&str> = text
        .lines()
        .find(|l| l.starts_with("profile,"))
        .unwrap()
        .split(',')
        .collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        let id = f[0].clone();
        if !line.starts_with('#') && !line.starts_with("profile,") {
            let level: usize = f[col("level")].parse().unwrap();
            let z: f64 = f[col("altitude_m")].parse().unwrap();
            let wet = id.ends_with("0001")
                || id.ends_with("0003")
                || (!keep_good && id.ends_with("0004"));
            if wet && level == 1 {
                let q: f64 = f[col("H2O_ppmv")].parse().unwrap();
                f[col("H2O_ppmv")] = (5.0 * q).to_string();
            }
            if id.ends_with("0002") && z > 30_000.0 {
                continue;
            }
        }
        out.push_str(&f.join(","));
        out.push('\n');
    }
    std::fs::write(&set, out).unwrap();
    set
}

/// Issue 37, item 5: failures that say so. Of four profiles, two supersaturated and one too
/// short: exit 0, each reason said once with its count and first profile (not a line per
/// profile), failed.csv lists the three, and the statistics are of the one left. With the
/// fourth supersaturated too, every profile has failed: exit 2, one line on stderr naming the
/// set and the scene, with the counts by reason, and nothing written (an earlier study's files in the directory stay as
/// they were).
#[test]
fn a_study_whose_profiles_fail_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let scene_path = dir.path().join("study.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let out = dir.path().join("out");
    let run_with = |set: &Path, extra: &[&str]| {
        let mut args: Vec<std::ffi::OsString> = vec![
            "dial".into(),
            scene_path.clone().into(),
            "--profiles".into(),
            set.into(),
            "--no-plots".into(),
            "--out".into(),
            out.clone().into(),
        ];
        args.extend(extra.iter().map(Into::into));
        lidarsim(args)
    };
    let run = |set: &Path| run_with(set, &[]);
    let some = set_with_failures(dir.path(), true);
    let o = run(&some);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("4 profiles of ")
            && stdout.contains(", 3 failed and left out of the statistics (failed.csv):"),
        "{stdout}"
    );
    let failed: Vec<&str> = stdout
        .lines()
        .filter(|l| l.starts_with("  failed: "))
        .collect();
    assert_eq!(failed.len(), 2, "{stdout}");
    assert!(
        failed[0].starts_with("  failed: 2 profiles: supersaturated: relative humidity ")
            && failed[0].ends_with(" (profile mid-0001 and 1 more)"),
        "{}",
        failed[0]
    );
    assert!(
        failed[1].starts_with("  failed: 1 profile: ")
            && failed[1].contains("top_m")
            && failed[1].ends_with(" (profile mid-0002)"),
        "{}",
        failed[1]
    );
    let (h, rows) = read_csv(&out.join("failed.csv"));
    assert_eq!(h, ["index", "profile_id", "class", "reason"]);
    // The profiles made to fail: the first three of the set, 0-based.
    let ids: Vec<(&str, &str, &str)> = rows
        .iter()
        .map(|r| (r[0].as_str(), r[1].as_str(), r[2].as_str()))
        .collect();
    assert_eq!(
        ids,
        [
            ("0", "mid-0001", "mid"),
            ("1", "mid-0002", "mid"),
            ("2", "mid-0003", "mid")
        ]
    );
    assert!(rows[0][3].starts_with("supersaturated: ") && rows[1][3].contains("top_m"));
    let (h, rows) = read_csv(&out.join("summary.csv"));
    let c = h.iter().position(|x| x == "profiles").unwrap();
    assert!(
        !rows.is_empty() && rows.iter().all(|r| r[c] == "1"),
        "{rows:?}"
    );
    crate::util::assert_no_non_finite(&out);

    let before = std::fs::read(out.join("summary.csv")).unwrap();
    let names = |d: &Path| {
        let mut v: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        v.sort();
        v
    };
    let listed = names(&out);

    // --strict: the same set is an error, one line with the counts by reason, and the
    // directory as the study before left it. These three cannot be run at all, so the study is
    // refused before its work (nothing on stdout: no report of a study that did not run).
    let o = run_with(&some, &["--strict"]);
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with(&format!(
            "lidarsim: error: 3 of 4 profiles of {} through the scene {} cannot be run (strict: any failed profile is an error): 2 profiles: supersaturated: relative humidity ",
            some.display(),
            scene_path.display()
        )) && stderr.contains(" (profile mid-0001 and 1 more); 1 profile: ")
            && stderr.trim_end().ends_with(" (profile mid-0002); nothing was run"),
        "{stderr}"
    );
    assert!(
        o.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert_eq!(std::fs::read(out.join("summary.csv")).unwrap(), before);
    assert_eq!(names(&out), listed);

    let none = set_with_failures(dir.path(), false);
    let o = run(&none);
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with(&format!(
            "lidarsim: error: every profile of {} through the scene {} failed (4 of 4): 3 profiles: supersaturated: relative humidity ",
            none.display(),
            scene_path.display()
        )) && stderr.contains(" (profile mid-0001 and 2 more); 1 profile: ")
            && stderr.trim_end().ends_with(" (profile mid-0002); nothing was written"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(out.join("summary.csv")).unwrap(), before);
    assert_eq!(names(&out), listed);
}

/// Issue 42, item 3, for sharded studies: shards of a set where three of four profiles fail
/// each write their file (a shard does not decide, and `--strict` with `--shard` is refused);
/// `merge` exits 0 with the failed.csv of the single study, `merge --strict` exits 2 with one
/// line and writes nothing.
#[test]
fn a_merge_of_shards_with_failed_profiles_is_strict_on_request() {
    let dir = tempfile::tempdir().unwrap();
    let scene_path = dir.path().join("study.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let set = set_with_failures(dir.path(), true);
    let shards = dir.path().join("shards");
    let dial = |out: &Path, extra: &[&str]| {
        let mut args: Vec<std::ffi::OsString> = vec![
            "dial".into(),
            scene_path.clone().into(),
            "--profiles".into(),
            set.clone().into(),
            "--no-plots".into(),
            "--out".into(),
            out.into(),
        ];
        args.extend(extra.iter().map(Into::into));
        lidarsim(args)
    };
    let single = dir.path().join("single");
    assert_eq!(dial(&single, &[]).status.code(), Some(0));
    let o = dial(&shards, &["--shard", "0/2", "--strict"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--strict"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for i in ["0/2", "1/2"] {
        assert_eq!(dial(&shards, &["--shard", i]).status.code(), Some(0), "{i}");
    }
    let merge = |out: &Path, extra: &[&str]| {
        let mut args: Vec<std::ffi::OsString> = vec![
            "merge".into(),
            shards.clone().into(),
            "--no-plots".into(),
            "--out".into(),
            out.into(),
        ];
        args.extend(extra.iter().map(Into::into));
        lidarsim(args)
    };
    let strict = dir.path().join("strict");
    let o = merge(&strict, &["--strict"]);
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("lidarsim: error: 3 of 4 profiles of ")
            && stderr.contains("(strict: any failed profile is an error)")
            && stderr.trim_end().ends_with("; nothing was written"),
        "{stderr}"
    );
    assert!(!strict.exists());
    let merged = dir.path().join("merged");
    let o = merge(&merged, &[]);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(
        std::fs::read(merged.join("failed.csv")).unwrap(),
        std::fs::read(single.join("failed.csv")).unwrap()
    );
}

/// Issue 42, item 3, as a user met it: a profile set without CO2 (its column taken out of a
/// generated set) through a scene whose lines absorb CO2, figures on. Every profile fails:
/// exit 2, one line on stderr with the one reason, its count and first profile, and no output
/// directory at all (no empty CSV, no `ensemble.png` of profiles that were never run); the
/// same with `--strict`.
#[test]
fn a_study_of_profiles_without_co2_fails_with_one_line_and_no_files() {
    let dir = tempfile::tempdir().unwrap();
    let scene_path = dir.path().join("study.toml");
    std::fs::write(&scene_path, SCENE).unwrap();
    let generated = dir.path().join("generated.csv");
    lidarsim_ok([
        "profiles".as_ref(),
        "generate".as_ref(),
        "--class".as_ref(),
        "mid".as_ref(),
        "--n".as_ref(),
        "5".as_ref(),
        "--seed".as_ref(),
        "3".as_ref(),
        "--out".as_ref(),
        generated.as_os_str(),
    ]);
    // The set without its CO2 column.
    let text = std::fs::read_to_string(&generated).unwrap();
    let header: Vec<&str> = text
        .lines()
        .find(|l| l.starts_with("profile,"))
        .unwrap()
        .split(',')
        .collect();
    let co2 = header.iter().position(|h| *h == "CO2_ppmv").unwrap();
    let no_co2 = dir.path().join("no_co2.csv");
    let without: Vec<String> = text
        .lines()
        .map(|l| {
            if l.starts_with('#') {
                return l.to_string();
            }
            let mut f: Vec<&str> = l.split(',').collect();
            f.remove(co2);
            f.join(",")
        })
        .collect();
    std::fs::write(&no_co2, without.join("\n") + "\n").unwrap();
    let out = dir.path().join("out");
    for extra in [&[][..], &["--strict"]] {
        let mut args: Vec<std::ffi::OsString> = vec![
            "dial".into(),
            scene_path.clone().into(),
            "--profiles".into(),
            no_co2.clone().into(),
            "--out".into(),
            out.clone().into(),
        ];
        args.extend(extra.iter().map(Into::into));
        let o = lidarsim(args);
        assert_eq!(o.status.code(), Some(2), "{extra:?}");
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(stderr.lines().count(), 1, "{extra:?}: {stderr}");
        assert!(
            stderr.starts_with(&format!(
                "lidarsim: error: every profile of {} through the scene {} failed (5 of 5): 5 profiles: ",
                no_co2.display(),
                scene_path.display()
            )) && stderr.contains("has no CO2")
                && stderr
                    .trim_end()
                    .ends_with(" (profile mid-0001 and 4 more); nothing was written"),
            "{extra:?}: {stderr}"
        );
        // The one reason is said once, not once per profile.
        assert_eq!(stderr.matches("has no CO2").count(), 1, "{stderr}");
        assert!(!out.exists(), "{extra:?}: {:?}", crate::util::tree(&out));
    }
}

/// Issue 37: a Monte Carlo study with few photons (`airborne_co2_dial.toml`, a cloud, 200
/// photons per profile) leaves most DIAL cells without energy in a window, where the noise-free
/// retrieval has no logarithm. Such values are empty fields, not failed profiles (every profile
/// failed with "retrieved_ppm … is NaN" before): exit 0, no `NaN` or `inf` in any file, and
/// summary.csv's noise-free statistics over the `retrieved_profiles` whose record is whole,
/// checked against the same counts and means computed here from profiles.csv. Shards merge to
/// the same files (a merge accepts the undefined values of a Monte Carlo shard).
#[test]
fn a_monte_carlo_study_without_energy_in_a_window_writes_empty_fields() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = crate::util::project_root().join("scenes/airborne_co2_dial.toml");
    let dial = |extra: &[&str], out: &Path| {
        let mut args: Vec<std::ffi::OsString> = vec![
            "dial".into(),
            scene.clone().into(),
            "--ensemble".into(),
            "2".into(),
            "--class".into(),
            "mid".into(),
            "--photons".into(),
            "200".into(),
            "--threads".into(),
            "1".into(),
            "--out".into(),
            out.into(),
        ];
        args.extend(extra.iter().map(Into::into));
        lidarsim_ok(args)
    };
    let out = d.join("study");
    dial(&["--no-plots"], &out);
    crate::util::assert_no_non_finite(&out);
    let (_, failed) = read_csv(&out.join("failed.csv"));
    assert!(failed.is_empty(), "{failed:?}");
    let (ph, profiles) = read_csv(&out.join("profiles.csv"));
    let pc = |name: &str| ph.iter().position(|h| h == name).unwrap();
    let (sh, summary) = read_csv(&out.join("summary.csv"));
    let sc = |name: &str| sh.iter().position(|h| h == name).unwrap();
    let num = |s: &str| -> f64 { s.parse().unwrap() };
    // A record is whole when its noise-free retrieval and every budget row are there (the
    // columns from retrieved_ppm on).
    let whole = |r: &Vec<String>| {
        r[pc("retrieved_ppm")..].iter().enumerate().all(|(i, f)| {
            // The noisy pair may be empty alone.
            let c = pc("retrieved_ppm") + i;
            c == pc("retrieved_noisy_ppm") || c == pc("error_noisy_ppm") || !f.is_empty()
        })
    };
    let (mut partial, mut empty) = (0, 0);
    for row in &summary {
        let members: Vec<&Vec<String>> = profiles
            .iter()
            .filter(|r| {
                r[pc("method")] == row[sc("method")]
                    && r[pc("altitude_bottom_m")] == row[sc("altitude_bottom_m")]
            })
            .collect();
        assert_eq!(num(&row[sc("profiles")]) as usize, members.len(), "{row:?}");
        // The truth is always there.
        assert!(members.iter().all(|r| !r[pc("truth_ppm")].is_empty()));
        let defined: Vec<&&Vec<String>> = members.iter().filter(|r| whole(r)).collect();
        let n = defined.len();
        assert_eq!(num(&row[sc("retrieved_profiles")]) as usize, n, "{row:?}");
        let noisy = defined
            .iter()
            .filter(|r| !r[pc("retrieved_noisy_ppm")].is_empty())
            .count();
        assert_eq!(num(&row[sc("noisy_profiles")]) as usize, noisy, "{row:?}");
        if n == 0 {
            empty += 1;
            for c in [
                "bias_ppm",
                "sd_ppm",
                "random_error_rms_ppm",
                "total_budget_ppm",
            ] {
                assert!(row[sc(c)].is_empty(), "{c}: {row:?}");
            }
        } else {
            if n < members.len() {
                partial += 1;
            }
            let bias = defined
                .iter()
                .map(|r| num(&r[pc("error_ppm")]))
                .sum::<f64>()
                / n as f64;
            let b = num(&row[sc("bias_ppm")]);
            assert!((b - bias).abs() <= 1e-9 * bias.abs().max(1.0), "{b} {bias}");
        }
    }
    // The case is the one meant: the column is retrieved, far cells are not, one cell partly.
    assert_eq!(summary[0][sc("method")], "ipda");
    assert_eq!(summary[0][sc("retrieved_profiles")], "2");
    assert!(empty > 0 && partial > 0, "{empty} {partial}");

    // Two shards, merged: the same files.
    let shards = d.join("shards");
    for i in 0..2 {
        dial(&["--shard", &format!("{i}/2")], &shards);
    }
    let merged = d.join("merged");
    lidarsim_ok([
        "merge".as_ref(),
        shards.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        merged.as_os_str(),
    ]);
    for f in ["profiles.csv", "summary.csv", "budget.csv", "failed.csv"] {
        assert_eq!(
            std::fs::read(out.join(f)).unwrap(),
            std::fs::read(merged.join(f)).unwrap(),
            "{f}"
        );
    }
}

/// A study watched for a stop (the Python package's path, `dial::run_until`) is the study
/// while the flag stays down, and ends with `Stopped` once it is up.
#[test]
fn a_watched_study_is_the_study_until_it_is_stopped() {
    use std::sync::atomic::AtomicBool;
    let s = scene();
    let (set, _) = class_ensemble(LatitudeClass::Mid, 3, 4).unwrap();
    let whole = dial::run(&s, &set, &options(&s), &|| {}).unwrap();
    let watched = dial::run_until(&s, &set, &options(&s), &|| {}, &AtomicBool::new(false)).unwrap();
    assert_eq!(whole.outcomes, watched.outcomes);
    let stopped = dial::run_until(&s, &set, &options(&s), &|| {}, &AtomicBool::new(true));
    assert!(matches!(stopped, Err(dial::StudyError::Stopped)));
}
