//! Line selection (`lidarsim select-lines`, `lidarsim::study::select`): the sensitivities
//! against finite differences built by hand from the line-by-line optical depths, the frequency
//! sensitivity against the slope of the cross-sections, the sign of the temperature sensitivity
//! against the line-strength law, and the command line's contract.

use lidarsim::atmosphere::{SetMember, StandardAtmosphere, StateShift, shift_member};
use lidarsim::instrument::line_shape::MHZ_PER_CM1;
use lidarsim::retrieval::LayerColumns;
use lidarsim::spectroscopy::layers::curtis_godson_layers;
use lidarsim::spectroscopy::{
    LblOptions, LineFilter, LineList, cross_section_at, layer_optical_depths_at,
};
use lidarsim::study::select::{
    self, GHZ_PER_CM1, GridSpec, MemberResult, OnPosition, Steps, StudyConfig,
};

use crate::util::{lidarsim, lidarsim_ok};

const OFF_CM1: f64 = 6360.610;
/// Coarse grid (1 km layers to 40 km, below every AFGL top: the edges are exactly these).
const LAYER_M: f64 = 1000.0;
const TOP_M: f64 = 40_000.0;

/// The band model plus one artificial H2O line 0.25 cm⁻¹ above R16e, so that the other-gas
/// absorption the retrieval subtracts is not zero and the humidity sensitivity has a spectral
/// part.
fn lines() -> LineList {
    let mut l = LineList::co2_30012_band_model();
    let mut h2o = l
        .lines
        .iter()
        .find(|x| x.local_lower_quanta().trim() == "R 16e")
        .unwrap()
        .clone();
    h2o.molecule_id = 1;
    h2o.iso_id = 1;
    h2o.nu_cm1 += 0.25;
    h2o.sw_cm_per_molecule = 2e-25;
    h2o.elower_cm1 = 300.0;
    h2o.quanta = [b' '; 60];
    l.lines.push(h2o);
    l.lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
    l
}

fn centre(label: &str) -> f64 {
    select::band_lines(&LineList::co2_30012_band_model())
        .into_iter()
        .find(|b| b.label == label)
        .unwrap()
        .nu_cm1
}

fn position(label: &str, offset_ghz: f64) -> OnPosition {
    OnPosition {
        nu_cm1: centre(label) + offset_ghz / GHZ_PER_CM1,
        line: Some(label.into()),
        offset_ghz,
    }
}

fn us_standard() -> SetMember {
    let mut m = StandardAtmosphere::UsStandard.member();
    m.profile.rescale_gas("CO2", 420e-6).unwrap();
    m
}

fn config(positions: Vec<OnPosition>) -> StudyConfig {
    StudyConfig {
        lines: lines(),
        options: LblOptions::default(),
        off_cm1: OFF_CM1,
        positions,
        grid: GridSpec {
            layer_m: LAYER_M,
            top_m: TOP_M,
        },
        steps: Steps::CONTRACT,
        noise: None,
        spectra: Vec::new(),
    }
}

fn run(member: &SetMember, cfg: &StudyConfig) -> MemberResult {
    select::study_member(member, cfg).unwrap()
}

/// Vertical optical depths summed over the grid at `nus`: (all gases, CO2 only, others only).
fn column_tau(
    profile: &lidarsim::atmosphere::Profile,
    edges: &[f64],
    nus: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let all = lines();
    let co2 = all.filtered(&LineFilter {
        molecules: Some(vec![2]),
        ..Default::default()
    });
    let opts = LblOptions::default();
    let sum = |l: &LineList| -> Vec<f64> {
        let t = layer_optical_depths_at(profile, l, edges, nus, &opts).unwrap();
        (0..nus.len())
            .map(|k| t.iter().map(|row| row[k]).sum())
            .collect()
    };
    (sum(&all), sum(&co2))
}

fn xco2(profile: &lidarsim::atmosphere::Profile, edges: &[f64]) -> f64 {
    let c = LayerColumns::new(profile, edges, "CO2").unwrap();
    c.gas_per_m2.iter().sum::<f64>() / c.dry_air_per_m2.iter().sum::<f64>()
}

/// XCO2 retrieved − true [ppm] by hand: a monochromatic IPDA's DAOD is linear in the scale s of
/// the assumed CO2, D(s) = s D_CO2,assumed + D_other,assumed, so
/// X_ret = X_assumed (D_true − D_other,assumed)/D_CO2,assumed.
fn hand_error_ppm(
    truth: &lidarsim::atmosphere::Profile,
    assumed: &lidarsim::atmosphere::Profile,
    edges: &[f64],
    on: f64,
) -> f64 {
    let (t_all, _) = column_tau(truth, edges, &[on, OFF_CM1]);
    let (a_all, a_co2) = column_tau(assumed, edges, &[on, OFF_CM1]);
    let d_true = t_all[0] - t_all[1];
    let d_co2 = a_co2[0] - a_co2[1];
    let d_other = (a_all[0] - a_co2[0]) - (a_all[1] - a_co2[1]);
    (xco2(assumed, edges) * (d_true - d_other) / d_co2 - xco2(truth, edges)) * 1e6
}

fn shifted(m: &SetMember, s: StateShift) -> lidarsim::atmosphere::Profile {
    shift_member(m, &s).unwrap().profile
}

/// Per K, per hPa and per 10 % H2O against finite differences made by hand (shifted profiles,
/// optical depths of `layer_optical_depths_at`, columns of `LayerColumns`, the linear IPDA
/// retrieval written out). Tolerance 1e-8 ppm: both sides sum the same layer optical depths
/// (in another order) and the study's Newton iteration stops at |Δs| ≤ 1e-14, so they agree to
/// ~1e-11 ppm on X ≈ 420 ppm; the sensitivities themselves are 0.05–2 ppm.
#[test]
fn state_sensitivities_match_hand_finite_differences() {
    let m = us_standard();
    let positions = vec![position("R16e", 2.0), position("R26e", -1.0)];
    let cfg = config(positions.clone());
    let r = run(&m, &cfg);
    let expected_edges: Vec<f64> = (0..=40).map(|i| i as f64 * LAYER_M).collect();
    assert_eq!(r.edges_m, expected_edges);
    let none = shifted(&m, StateShift::NONE);
    let warm = shifted(
        &m,
        StateShift {
            temperature_k: 1.0,
            ..StateShift::NONE
        },
    );
    let high_ps = shifted(
        &m,
        StateShift {
            surface_pressure_hpa: 1.0,
            ..StateShift::NONE
        },
    );
    let wet = shifted(
        &m,
        StateShift {
            h2o_factor: 1.1,
            ..StateShift::NONE
        },
    );
    let e = &r.edges_m;
    for (p, got) in positions.iter().zip(&r.positions) {
        let per_k = hand_error_ppm(&warm, &none, e, p.nu_cm1);
        let per_hpa = hand_error_ppm(&none, &high_ps, e, p.nu_cm1);
        let per_h2o = hand_error_ppm(&wet, &none, e, p.nu_cm1);
        for (name, hand, study) in [
            ("per K", per_k, got.dxco2_per_k_ppm),
            ("per hPa", per_hpa, got.dxco2_per_hpa_ppm),
            ("per 10 % H2O", per_h2o, got.dxco2_per_10pct_h2o_ppm),
        ] {
            assert!(
                (hand - study).abs() < 1e-8,
                "{} {name}: hand {hand} ppm, study {study} ppm",
                p.nu_cm1
            );
            // Not a vacuous agreement: every sensitivity is a real effect here.
            assert!(hand.abs() > 0.01, "{} {name}: {hand}", p.nu_cm1);
        }
        // An assumed surface pressure too high puts too much CO2 in the reference: X low, by
        // about X/p_s = 420/1013 ppm per hPa for a weighting function spread over the column.
        assert!(
            (-0.8..-0.15).contains(&got.dxco2_per_hpa_ppm),
            "{}",
            got.dxco2_per_hpa_ppm
        );
        // DAOD: on minus off, all gases, by hand.
        let (all, _) = column_tau(&none, e, &[p.nu_cm1, OFF_CM1]);
        assert!((got.daod_one_way - (all[0] - all[1])).abs() < 1e-12);
        assert!((got.t2_on - (-2.0 * all[0]).exp()).abs() < 1e-12);
    }
}

/// Per MHz: the slope of the on-line's DAOD with frequency by hand from cross-sections at ν and
/// ν + 1 MHz in each Curtis-Godson layer (σ × column), divided by the assumed CO2 DAOD:
/// dX = X (D(ν + 1 MHz) − D(ν))/D_CO2(ν). Tolerance as above.
#[test]
fn frequency_sensitivity_is_the_slope_of_the_daod() {
    let m = us_standard();
    let positions = vec![
        position("R16e", 2.0),
        position("R16e", -2.0),
        position("R26e", 0.5),
    ];
    let cfg = config(positions.clone());
    let r = run(&m, &cfg);
    let none = shifted(&m, StateShift::NONE);
    let layers = curtis_godson_layers(&none, &r.edges_m).unwrap();
    let all = lines();
    let opts = LblOptions::default();
    for (p, got) in positions.iter().zip(&r.positions) {
        let nus = [p.nu_cm1, p.nu_cm1 + 1.0 / MHZ_PER_CM1, OFF_CM1];
        let (mut tau, mut tau_co2) = ([0.0; 3], [0.0; 3]);
        for l in &layers {
            for (gi, gas) in l.gas_names.iter().enumerate() {
                let id = match gas.as_str() {
                    "CO2" => 2,
                    "H2O" => 1,
                    _ => continue,
                };
                let sigma = cross_section_at(&all, id, &l.state_for(gi), &nus, &opts).unwrap();
                for k in 0..3 {
                    let t = sigma[k] * l.gas_columns_per_cm2[gi];
                    tau[k] += t;
                    if id == 2 {
                        tau_co2[k] += t;
                    }
                }
            }
        }
        let slope = (tau[1] - tau[2]) - (tau[0] - tau[2]);
        let hand = xco2(&none, &r.edges_m) * slope / (tau_co2[0] - tau_co2[2]) * 1e6;
        assert!(
            (hand - got.dxco2_per_mhz_ppm).abs() < 1e-8,
            "{}: hand {hand}, study {}",
            p.nu_cm1,
            got.dxco2_per_mhz_ppm
        );
        assert!(hand.abs() > 0.01, "{hand}");
    }
    // Up the high-frequency side of R16e the absorption falls with frequency (the truth absorbs
    // less than assumed: X low); down the other side it rises.
    assert!(r.positions[0].dxco2_per_mhz_ppm < 0.0);
    assert!(r.positions[1].dxco2_per_mhz_ppm > 0.0);
}

/// The sign of the temperature sensitivity, thought through. With the pressure levels fixed
/// (shift_member keeps p, re-levels z), a warmer truth changes only the cross-sections. The line
/// strength goes as S ∝ e^{−c₂E″/T}/Q(T), so d ln S/dT = c₂E″/T² − d ln Q/dT:
/// * R16e (E″ = 106 cm⁻¹): c₂E″/T² ≈ 0.0023/K at 260 K < d ln Q/dT ≈ 1/T + vibration ≈ 0.0045/K,
///   so S falls with T; 2 GHz up its side the Lorentz wing ∝ S γ_L, and γ_L ∝ T^−0.7 falls too.
///   The warmer truth absorbs less than the assumed (colder) state predicts: XCO2 retrieved
///   LOW, dX/dK < 0.
/// * R40e (E″ = 640 cm⁻¹): c₂E″/T² ≈ 0.0136/K ≫ d ln Q/dT, so S rises with T; at the line
///   centre σ ∝ S/γ rises further: dX/dK > 0.
///
/// The d ln S/dT of both are computed here from the TIPS partition sum, independently of the
/// study, and the signs compared.
#[test]
fn temperature_sensitivity_sign_follows_the_line_strength() {
    let band = select::band_lines(&LineList::co2_30012_band_model());
    let list = LineList::co2_30012_band_model();
    let e_lower = |label: &str| {
        let nu = band.iter().find(|b| b.label == label).unwrap().nu_cm1;
        list.lines
            .iter()
            .find(|l| l.nu_cm1 == nu)
            .unwrap()
            .elower_cm1
    };
    let dlns_dt = |label: &str, t: f64| {
        let c2 = 1.438_776_9;
        let ln_s = |t: f64| {
            -c2 * e_lower(label) / t
                - lidarsim::spectroscopy::tips::partition_sum(2, 1, t)
                    .unwrap()
                    .ln()
        };
        ln_s(t + 0.5) - ln_s(t - 0.5)
    };
    assert!(dlns_dt("R16e", 260.0) < 0.0);
    assert!(dlns_dt("R40e", 260.0) > 0.0);
    let r = run(
        &us_standard(),
        &config(vec![position("R16e", 2.0), position("R40e", 0.0)]),
    );
    assert!(
        r.positions[0].dxco2_per_k_ppm < -0.1,
        "{}",
        r.positions[0].dxco2_per_k_ppm
    );
    assert!(
        r.positions[1].dxco2_per_k_ppm > 0.1,
        "{}",
        r.positions[1].dxco2_per_k_ppm
    );
}

const CONTRACT: &str = "atmosphere,nu_on_cm1,nu_off_cm1,daod_one_way,wf_peak_hpa,dxco2_per_k_ppm,dxco2_per_mhz_ppm,dxco2_per_hpa_ppm,dxco2_per_10pct_h2o_ppm";

/// The contract: header first columns in order, one row per atmosphere and on-line position.
#[test]
fn cli_writes_one_row_per_atmosphere_and_position() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_string_lossy().into_owned();
    let on = [6360.0337, 6362.4704];
    let stdout = lidarsim_ok([
        "select-lines",
        "--atmosphere",
        "us_standard,tropical",
        "--on-cm1",
        "6360.0337,6362.4704",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--layer-m",
        "2000",
        "--top-km",
        "30",
        "--no-plots",
        "--out",
        &out,
    ]);
    assert!(stdout.contains("us_standard: 1 profiles"), "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("sensitivities.csv")).unwrap();
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert!(header.starts_with(&format!("{CONTRACT},")), "{header}");
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    for atm in ["us_standard", "tropical"] {
        for nu in on {
            let n = rows
                .iter()
                .filter(|r| r[0] == atm && (r[1].parse::<f64>().unwrap() - nu).abs() < 1e-6)
                .count();
            assert_eq!(n, 1, "{atm} {nu}: {csv}");
        }
    }
    for r in &rows {
        assert_eq!(r.len(), header.split(',').count());
        assert_eq!(r[2].parse::<f64>().unwrap(), 6360.61);
        for v in &r[3..9] {
            assert!(v.parse::<f64>().unwrap().is_finite(), "{r:?}");
        }
        assert!(!dir.path().join("transmission_us_standard.png").exists());
    }
}

/// A bad off-line: exit code 2 and one line naming the option and the value; no output.
#[test]
fn cli_rejects_a_bad_off_line() {
    for bad in ["1000", "-5", "nan"] {
        let dir = tempfile::tempdir().unwrap();
        let out_dir = dir.path().join("out");
        let out = lidarsim([
            "select-lines".as_ref(),
            "--atmosphere".as_ref(),
            "us_standard".as_ref(),
            "--off-cm1".as_ref(),
            bad.as_ref(),
            "--co2-ppm".as_ref(),
            "420".as_ref(),
            "--out".as_ref(),
            out_dir.as_os_str(),
        ]);
        assert_eq!(out.status.code(), Some(2), "{bad}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.starts_with("lidarsim: error: --off-cm1 ")
                && stderr.to_lowercase().contains(bad),
            "{stderr}"
        );
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(!out_dir.exists());
    }
}

/// A profile set of tropical profiles (hydrostatic altitudes from 0 m), each (id, latitude,
/// temperature offset \[K\], its first n of ten levels from 1013 to 1 hPa).
pub fn tropical_set(profiles: &[(&str, f64, f64, usize)]) -> String {
    let mut text =
        String::from("profile,latitude_deg,longitude_deg,pressure_hPa,temperature_K,H2O_ppmv\n");
    let levels = [
        (1013.0, 299.0, 20000.0),
        (850.0, 290.0, 12000.0),
        (700.0, 282.0, 6000.0),
        (500.0, 267.0, 2000.0),
        (300.0, 242.0, 300.0),
        (200.0, 220.0, 30.0),
        (100.0, 195.0, 5.0),
        (50.0, 205.0, 4.0),
        (10.0, 225.0, 4.0),
        (1.0, 260.0, 4.0),
    ];
    for &(id, lat, t_off, n) in profiles {
        for (p, t, q) in &levels[..n] {
            text.push_str(&format!("{id},{lat},0,{p},{},{q}\n", t + t_off));
        }
    }
    text
}

/// A profile set: class statistics, per-profile rows, a profile that cannot be studied named and
/// excluded, and the figures.
#[test]
fn cli_profile_set_classes_failures_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("set.csv");
    // Two tropical profiles (hydrostatic altitudes from 0 m); `short` ends at 700 hPa, about
    // 3 km, below one 4 km layer: it cannot cover the grid.
    let text = tropical_set(&[
        ("a", 10.0, 0.0, 10),
        ("b", -12.0, 2.0, 10),
        ("short", 5.0, 0.0, 3),
    ]);
    std::fs::write(&set, text).unwrap();
    let out = dir.path().join("out");
    let stdout = lidarsim_ok([
        "select-lines".as_ref(),
        "--profiles".as_ref(),
        set.as_os_str(),
        "--per-profile".as_ref(),
        "--max-j".as_ref(),
        "18".as_ref(),
        "--offsets-ghz=1.5,2".as_ref(),
        "--off-cm1".as_ref(),
        "6360.61".as_ref(),
        "--co2-ppm".as_ref(),
        "410".as_ref(),
        "--layer-m".as_ref(),
        "4000".as_ref(),
        "--top-km".as_ref(),
        "40".as_ref(),
        "--figure-lines".as_ref(),
        "R16e".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(
        stdout.contains("tropical: excluded 1 profile: "),
        "{stdout}"
    );
    assert!(
        stdout.contains("tropical: 2 profiles (1 excluded)"),
        "{stdout}"
    );
    let csv = std::fs::read_to_string(out.join("sensitivities.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    // J'' ≤ 18: P2..P18 (9) and R0..R18 (10) lines, two offsets each; per class, a and b.
    let positions = 19 * 2;
    for atm in ["tropical", "a", "b"] {
        let group: Vec<_> = rows.iter().filter(|r| r[0] == atm).collect();
        assert_eq!(group.len(), positions, "{atm}");
        // Ranks 1..n in order of the total error.
        let total_col = 14;
        for (k, r) in group.iter().enumerate() {
            assert_eq!(r[15], (k + 1).to_string());
            if k > 0 {
                let prev: f64 = group[k - 1][total_col].parse().unwrap();
                assert!(r[total_col].parse::<f64>().unwrap() >= prev);
            }
        }
    }
    assert!(!rows.iter().any(|r| r[0] == "short"));
    // The class mean is the mean of its two members, position by position.
    let find = |atm: &str, nu: &str| rows.iter().find(|r| r[0] == atm && r[1] == nu).unwrap();
    for r in rows.iter().filter(|r| r[0] == "tropical") {
        let (a, b) = (find("a", r[1]), find("b", r[1]));
        for col in [3, 5, 6, 7, 8] {
            let mean = 0.5 * (a[col].parse::<f64>().unwrap() + b[col].parse::<f64>().unwrap());
            let got: f64 = r[col].parse().unwrap();
            assert!(
                (got - mean).abs() <= 1e-5 * mean.abs() + 1e-12,
                "{col}: {got} {mean}"
            );
        }
        assert_eq!(r[16], "2");
        // Two different members: a spread in the on-line transmission.
        assert!(r[12].parse::<f64>().unwrap() > 0.0);
    }
    for f in ["transmission_tropical.png", "errors_tropical.png"] {
        let len = std::fs::metadata(out.join(f)).unwrap().len();
        assert!(len > 10_000, "{f}: {len} bytes");
    }
    // The figures change no table: the same study with `--no-plots` (no figure spectra, no
    // figures) writes the same tables, byte for byte.
    let bare = dir.path().join("bare");
    lidarsim_ok([
        "select-lines",
        "--profiles",
        set.to_str().unwrap(),
        "--per-profile",
        "--max-j",
        "18",
        "--offsets-ghz=1.5,2",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "410",
        "--layer-m",
        "4000",
        "--top-km",
        "40",
        "--figure-lines",
        "R16e",
        "--no-plots",
        "--out",
        bare.to_str().unwrap(),
    ]);
    for f in ["sensitivities.csv", "failed.csv"] {
        assert_eq!(
            std::fs::read(out.join(f)).unwrap(),
            std::fs::read(bare.join(f)).unwrap(),
            "{f}"
        );
    }
    assert!(!bare.join("transmission_tropical.png").exists());
}

/// The random error against the retrieval stage's analytic random error of the same IPDA: the
/// default scene with one 0.5 mrad field of view (the 0.15 mrad beam falls inside it whole),
/// run with `lidarsim run --photons 0`, and select-lines on the scene's own grid (100 m layers
/// to 80 km) and lines. Tolerance 1 %: the run's laser has a 30 MHz line and 0.1 % of its energy
/// outside the line (impurity), which select-lines leaves out (monochromatic); they change the
/// echo by ~0.1 %.
#[test]
fn random_error_matches_the_retrieval_stage() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.toml");
    let text = lidarsim::scene::DEFAULT_SCENE_TOML.replacen(
        "fov_full_angle_mrad = [0.2, 0.5]",
        "fov_full_angle_mrad = [0.5]",
        1,
    );
    assert_ne!(text, lidarsim::scene::DEFAULT_SCENE_TOML);
    std::fs::write(&scene, text).unwrap();
    let run_dir = dir.path().join("run");
    lidarsim_ok([
        "run".as_ref(),
        scene.as_os_str(),
        "--photons".as_ref(),
        "0".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        run_dir.as_os_str(),
    ]);
    let retrieval = std::fs::read_to_string(run_dir.join("retrieval.csv")).unwrap();
    let mut lines = retrieval.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let row: Vec<&str> = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .find(|r| r[col("method")] == "ipda" && r[col("source")] == "analytic")
        .unwrap();
    let expected: f64 = row[col("random_error_averaged_ppm")].parse().unwrap();
    let out = dir.path().join("select");
    lidarsim_ok([
        "select-lines".as_ref(),
        "--atmosphere".as_ref(),
        "us_standard".as_ref(),
        "--on-cm1".as_ref(),
        "6360.040".as_ref(),
        "--off-cm1".as_ref(),
        "6360.610".as_ref(),
        "--co2-ppm".as_ref(),
        "420".as_ref(),
        "--layer-m".as_ref(),
        "100".as_ref(),
        "--top-km".as_ref(),
        "80".as_ref(),
        "--scene".as_ref(),
        scene.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let csv = std::fs::read_to_string(out.join("sensitivities.csv")).unwrap();
    let got: f64 = csv
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .nth(13)
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        (got / expected - 1.0).abs() < 0.01,
        "select-lines {got} ppm, retrieval stage {expected} ppm"
    );
}

/// Issue 37, item 2: the weighting function per unit pressure, WF_l = Δτ_CO2,l/(x_l Δp_l),
/// against an independent calculation at 1 hPa resolution written here from the hydrostatic
/// equation and the cross-section. A slab [p − 1 hPa, p] of moist air holds
/// dU_dry = Δp (1 − x_w)/(m g) molecules of dry air per m² (dp = −ρ g dz with
/// ρ = n m, m = (M_d (1 − x_w) + M_w x_w)/N_A), so its CO2 optical depth per unit pressure and
/// dry-air mole fraction is WF(p) = Δσ(p, T) (1 − x_w)/(m g), Δσ the on − off cross-section at
/// the slab's p and T. T, x_w and x_CO2 at p come from the profile's levels, linear in ln p (T;
/// as `hydrostatic_altitudes_m` made the levels) and log-linear (mixing ratios), g is WGS 84
/// normal gravity at the height linear in ln p. No column routine of lidarsim is called.
///
/// AFGL atmospheres as `select-lines` takes them (CO2 at 420 ppm, re-levelled by
/// `shift_member`), band model, off-line 6360.61 cm⁻¹, 250 m layers, on-lines from the issue's
/// case (tropical, R16e + 2.1 GHz) to a flat one (subarctic winter, R4e + 3 GHz): every layer's
/// WF below 150 hPa within 1e-3 of the independent WF at the layer's centre (measured ≤ 3.4e-4;
/// before: a ±1 % sawtooth within each 1 km level interval, the pressure thickness taken with
/// ln p linear in z), and the reported peak within 3 hPa of the independent one (the issue's
/// case: 759.2 against 759.5 hPa; before: 818.4, where the independent WF is 3e-3 below its
/// maximum; subarctic winter R4e + 3 GHz: 809.8 against 809.5, before 797.9).
#[test]
fn weighting_function_matches_the_hydrostatic_equation_at_1_hpa() {
    // (atmosphere, line, offset [GHz]): the case first.
    for (atm, label, offset_ghz) in [
        (StandardAtmosphere::Tropical, "R16e", 2.1),
        (StandardAtmosphere::SubarcticWinter, "R4e", 3.0),
        (StandardAtmosphere::UsStandard, "R16e", 2.0),
        (StandardAtmosphere::MidlatitudeSummer, "P26e", -1.0),
    ] {
        check_weighting_function(atm, label, offset_ghz);
    }
}

/// One case of [`weighting_function_matches_the_hydrostatic_equation_at_1_hpa`].
fn check_weighting_function(atm: StandardAtmosphere, label: &str, offset_ghz: f64) {
    use lidarsim::atmosphere::hydrostatic::normal_gravity_m_per_s2;
    use lidarsim::instrument::laser::{Filter, Laser, Line};
    use lidarsim::retrieval::{AssumedInstrument, ReferenceState};
    use lidarsim::spectroscopy::xsec::GasState;

    let band = LineList::co2_30012_band_model();
    let on = centre(label) + offset_ghz / GHZ_PER_CM1;
    let mut member = atm.member();
    select::set_co2_column_average(&mut member.profile, 420.0).unwrap();
    let truth = shift_member(&member, &StateShift::NONE).unwrap();
    let prof = &truth.profile;

    // The study's own number: the reported peak and the weighting function behind it.
    let cfg = StudyConfig {
        lines: band.clone(),
        options: LblOptions::default(),
        off_cm1: OFF_CM1,
        positions: vec![OnPosition {
            nu_cm1: on,
            line: Some(label.into()),
            offset_ghz,
        }],
        grid: GridSpec {
            layer_m: 250.0,
            top_m: 60_000.0,
        },
        steps: Steps::CONTRACT,
        noise: None,
        spectra: Vec::new(),
    };
    let result = select::study_member(&member, &cfg).unwrap();
    let laser_lines = [
        Line {
            name: "on".into(),
            wavenumber_cm1: on,
        },
        Line {
            name: "off".into(),
            wavenumber_cm1: OFF_CM1,
        },
    ];
    let state = ReferenceState::new(
        prof,
        &result.edges_m,
        "CO2",
        &band,
        &LblOptions::default(),
        AssumedInstrument {
            laser: &Laser::ideal(1.0, 2),
            lines: &laser_lines,
            filter: &Filter::none(),
        },
    )
    .unwrap();
    let wf = select::weighting_function(prof, &state, 0, 1);
    assert_eq!(wf.peak_hpa(), result.positions[0].wf_peak_hpa);

    // The independent weighting function.
    let gas = |name: &str| prof.gases.iter().find(|g| g.name == name).unwrap();
    let (x_w, x_c) = (&gas("H2O").vmr, &gas("CO2").vmr);
    let (m_d, m_w, n_a) = (0.028_964_4, 0.018_015_28, 6.022_140_76e23);
    let lat = truth.meta.latitude_deg;
    let independent = |p_pa: f64| -> f64 {
        let p = &prof.pressure_pa;
        let i = p.iter().position(|&q| q < p_pa).unwrap() - 1;
        let s = (p[i] / p_pa).ln() / (p[i] / p[i + 1]).ln();
        let lin = |v: &[f64]| v[i] + s * (v[i + 1] - v[i]);
        let loglin = |v: &[f64]| v[i] * (v[i + 1] / v[i]).powf(s);
        let (t, w, c) = (lin(&prof.temperature_k), loglin(x_w), loglin(x_c));
        let g = normal_gravity_m_per_s2(lat, lin(&prof.altitude_m));
        let m = (m_d * (1.0 - w) + m_w * w) / n_a;
        let st = GasState {
            pressure_pa: p_pa,
            temperature_k: t,
            self_vmr: c,
        };
        let sigma =
            cross_section_at(&band, 2, &st, &[on, OFF_CM1], &LblOptions::default()).unwrap();
        // [cm²] × [molecules/cm² per hPa]
        (sigma[0] - sigma[1]) * 100.0 * (1.0 - w) / (m * g) * 1e-4
    };
    let mut worst = 0.0f64;
    for l in 0..wf.per_hpa.len() {
        let p = wf.ln_p_centre[l].exp();
        if p < 150e2 {
            break;
        }
        let rel = wf.per_hpa[l] / independent(p) - 1.0;
        worst = worst.max(rel.abs());
    }
    // The independent peak, slab by slab at 1 hPa.
    let p_s = prof.pressure_pa[0] / 100.0;
    let (mut best_p, mut best) = (0.0, 0.0);
    let mut p = p_s - 0.5;
    while p > 200.0 {
        let v = independent(p * 100.0);
        if v > best {
            (best_p, best) = (p, v);
        }
        p -= 1.0;
    }
    let reported = result.positions[0].wf_peak_hpa;
    println!(
        "weighting function, {atm:?} {label} {offset_ghz:+} GHz: layers within {worst:.1e} of the hydrostatic equation's; peak {reported:.1} hPa reported, {best_p:.1} hPa at 1 hPa resolution (there {:.2e} below the maximum)",
        1.0 - independent(reported * 100.0) / best
    );
    assert!(worst < 1e-3, "{atm:?} {label}: {worst:e}");
    // Where the weighting function is flat its peak is ill-conditioned (subarctic winter
    // R4e + 3 GHz: within 5e-5 of its maximum from 810 to 963 hPa), so it is judged twice: by
    // the independent weighting function's value there, within the layers' 1e-3, and by the
    // pressure, within 3 hPa of the 1 hPa calculation's (measured ≤ 0.7 hPa in every case).
    let below = 1.0 - independent(reported * 100.0) / best;
    assert!(
        below < 1e-3,
        "{atm:?} {label}: peak {reported} hPa, {below:e} below the maximum at {best_p} hPa"
    );
    assert!(
        (reported - best_p).abs() < 3.0,
        "{atm:?} {label}: {reported} vs {best_p}"
    );
}

/// Issue 37, item 5, and issue 42, item 3, for line selection: of four tropical profiles two
/// end at 700 hPa, about 3 km, below one 4 km layer: exit 0, the reason said once with its
/// count and first profile, failed.csv lists both with their indices; with `--strict` exit 2,
/// one line, nothing written; a class none of whose profiles can be studied beside one that
/// can: exit 0, the class has no rows; when every profile ends there, exit 2 with one line and
/// no file.
#[test]
fn cli_profiles_that_fail_are_counted_once_per_reason() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("set.csv");
    let out = dir.path().join("out");
    let run_with = |text: String, extra: &[&str]| {
        std::fs::write(&set, text).unwrap();
        let mut args: Vec<std::ffi::OsString> = [
            "select-lines",
            "--profiles",
            set.to_str().unwrap(),
            "--on-cm1",
            "6360.04",
            "--off-cm1",
            "6360.61",
            "--co2-ppm",
            "410",
            "--layer-m",
            "4000",
            "--top-km",
            "40",
            "--no-plots",
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(Into::into)
        .collect();
        args.extend(extra.iter().map(Into::into));
        lidarsim(args)
    };
    let run = |text: String| run_with(text, &[]);
    let o = run(tropical_set(&[
        ("a", 10.0, 0.0, 10),
        ("short1", 5.0, 0.0, 3),
        ("b", -12.0, 2.0, 10),
        ("short2", 6.0, 1.0, 3),
    ]));
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    let excluded: Vec<&str> = stdout
        .lines()
        .filter(|l| l.contains(" excluded "))
        .collect();
    assert_eq!(excluded.len(), 1, "{stdout}");
    assert!(
        excluded[0].starts_with("tropical: excluded 2 profiles: ")
            && excluded[0].ends_with(" (profile short1 and 1 more)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("tropical: 2 profiles (2 excluded)")
            && stdout.contains(
                "2 of 4 profiles failed and were left out of the statistics (failed.csv)"
            ),
        "{stdout}"
    );
    let failed = std::fs::read_to_string(out.join("failed.csv")).unwrap();
    let rows: Vec<&str> = failed.lines().collect();
    assert_eq!(rows[0], "index,profile_id,group,reason");
    assert_eq!(rows.len(), 3, "{failed}");
    // The second and fourth profiles of the study (0-based), those made short.
    assert!(
        rows[1].starts_with("1,short1,tropical,") && rows[2].starts_with("3,short2,tropical,"),
        "{failed}"
    );
    crate::util::assert_no_non_finite(&out);

    // --strict: the same study is an error, one line with the counts by reason, and the
    // directory as the study before left it.
    let sensitivities = std::fs::read(out.join("sensitivities.csv")).unwrap();
    let o = run_with(
        tropical_set(&[
            ("a", 10.0, 0.0, 10),
            ("short1", 5.0, 0.0, 3),
            ("b", -12.0, 2.0, 10),
            ("short2", 6.0, 1.0, 3),
        ]),
        &["--strict"],
    );
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with(&format!(
            "lidarsim: error: 2 of 4 profiles of {} failed (strict: any failed profile is an error): 2 profiles: ",
            set.display()
        )) && stderr
            .trim_end()
            .ends_with(" (profile short1 and 1 more); nothing was written"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(out.join("sensitivities.csv")).unwrap(),
        sensitivities
    );
    assert_eq!(
        std::fs::read_to_string(out.join("failed.csv")).unwrap(),
        failed
    );

    // A class (mid, latitude 45°) none of whose profiles can be studied, beside a tropical one
    // that can: exit 0, the class said once and without rows, failed.csv lists its two.
    let o = run(tropical_set(&[
        ("m1", 45.0, 0.0, 3),
        ("a", 10.0, 0.0, 10),
        ("m2", 50.0, 0.0, 3),
    ]));
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("mid: excluded 2 profiles: ")
            && stdout.contains("mid: every profile failed (2 excluded): no rows, no figures")
            && stdout.contains("tropical: 1 profiles (0 excluded)"),
        "{stdout}"
    );
    let (h, rows) = crate::util::read_csv(&out.join("sensitivities.csv"));
    let atm = h.iter().position(|c| c == "atmosphere").unwrap();
    assert!(
        !rows.is_empty() && rows.iter().all(|r| r[atm] == "tropical"),
        "{rows:?}"
    );
    let failed = std::fs::read_to_string(out.join("failed.csv")).unwrap();
    let rows: Vec<&str> = failed.lines().collect();
    // Member order: the tropical group (a), then mid (m1, m2).
    assert_eq!(rows.len(), 3, "{failed}");
    assert!(
        rows[1].starts_with("1,m1,mid,") && rows[2].starts_with("2,m2,mid,"),
        "{failed}"
    );

    let out_before = std::fs::read(out.join("sensitivities.csv")).unwrap();
    let o = run(tropical_set(&[
        ("short1", 5.0, 0.0, 3),
        ("short2", 6.0, 1.0, 3),
    ]));
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with(&format!(
            "lidarsim: error: every profile of {} failed (2 of 2): 2 profiles: ",
            set.display()
        )) && stderr
            .trim_end()
            .ends_with(" (profile short1 and 1 more); nothing was written"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(out.join("sensitivities.csv")).unwrap(),
        out_before
    );
}
