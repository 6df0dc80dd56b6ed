//! Attenuated backscatter β′ and the range-corrected signal (issue 40, item 4;
//! `src/backscatter.rs`): the analytic order 1 against β T² O worked by hand, the Monte Carlo's
//! order 1 against the analytic one on C.1 within its errors, every row of `backscatter.csv`
//! against its `returns.csv` row and the lidar equation's factors, per-line lidar constants and
//! polarised rows.

use std::collections::HashMap;
use std::path::Path;

use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::returns::Order;
use lidarsim::scene::Scene;

use crate::util::{lidarsim_ok, project_root, read_csv};

/// A ground lidar looking up (one ray: the beam is vertical) into a homogeneous HG layer
/// 500–3000 m (extinction 2e-4 m⁻¹, ϖ = 0.9, g = 0.7), no air; a uniform beam of 0.2 mrad and
/// fields of view 0.1 mrad (overlap sin²(0.025 mrad)/sin²(0.05 mrad)) and 1 mrad (overlap 1);
/// gates of 50 m from 400 m, the first two in clear air.
const HG_LAYER: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.5
beam_divergence_full_angle_mrad = 0.2
telescope_diameter_m = 0.3
optical_efficiency = 0.4
fov_full_angle_mrad = [0.1, 1.0]
[[channel]]
name = "532"
wavelength_nm = 532.0
[gates]
start_m = 400.0
end_m = 2400.0
width_m = 50.0
[[layer]]
name = "haze"
base_m = 500.0
top_m = 3000.0
extinction_per_m = 2e-4
single_scattering_albedo = 0.9
phase = { kind = "henyey_greenstein", g = 0.7 }
"#;

/// E₁(x) for 0 < x ≤ 2 from its series, −γ − ln x − Σ_{k≥1} (−x)^k/(k·k!) (Abramowitz &
/// Stegun 5.1.11), summed until the terms vanish.
fn e1_minus_euler_log(x: f64) -> f64 {
    // Returns E₁(x) + γ + ln x = −Σ (−x)^k/(k k!): the differences of E₁ need no γ.
    let (mut term, mut sum) = (1.0, 0.0);
    for k in 1..200 {
        term *= -x / k as f64;
        let t = term / k as f64;
        sum -= t;
        if t.abs() < 1e-18 * sum.abs() {
            break;
        }
    }
    sum
}

/// ∫_{r₁}^{r₂} e^{−a r}/r² dr = e^{−a r₁}/r₁ − e^{−a r₂}/r₂ − a (E₁(a r₁) − E₁(a r₂)),
/// with E₁(a r₁) − E₁(a r₂) = ln(r₂/r₁) + S(a r₁) − S(a r₂), S = E₁ + γ + ln.
fn exp_over_r2_integral(a: f64, r1: f64, r2: f64) -> f64 {
    let de1 = (r2 / r1).ln() + e1_minus_euler_log(a * r1) - e1_minus_euler_log(a * r2);
    (-a * r1).exp() / r1 - (-a * r2).exp() / r2 - a * de1
}

/// Issue 40's identity: the analytic order-1 β′ of a gate is the 1/r²-weighted gate mean of
/// β T² O, here β O e^{2σ·500} ∫ e^{−2σr}/r² dr · r₁r₂/Δr with β = ϖ σ P_HG(180°)/(4π),
/// P_HG(180°) = (1 − g²)/(1 + g)³, the integral in closed form through E₁ (not the code's
/// quadrature), and O = 1 or sin²(α/2)/sin²(b/2) for the uniform beam. To 1e-12 in every gate
/// of the layer, for both fields of view; exactly 0 in the clear gates. The closed form is
/// first checked against the point value β T²(r_w) O at the gate's 1/r²-weighted mean range
/// (to the second order in σΔr, 1e-4).
#[test]
fn analytic_order_one_is_beta_t2_overlap_by_hand() {
    let scene = Scene::from_toml(Path::new("hg.toml"), HG_LAYER).unwrap();
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let analytic = lidar_eq::single_scatter(&scene, &atm);
    let b = lidarsim::products::run::backscatter_of(&scene, &analytic);
    let (sigma, omega, g) = (2e-4, 0.9, 0.7);
    let p180 = (1.0 - g * g) / (1.0f64 + g).powi(3);
    let beta = omega * sigma * p180 / (4.0 * std::f64::consts::PI);
    let overlaps = [
        (0.025e-3f64).sin().powi(2) / (0.05e-3f64).sin().powi(2),
        1.0,
    ];
    let mut compared = 0;
    for (f, o) in overlaps.iter().enumerate() {
        for gate in 0..40 {
            let (r1, r2) = (400.0 + 50.0 * gate as f64, 450.0 + 50.0 * gate as f64);
            let got = b
                .attenuated_backscatter(0, f, gate, Order::Exactly(1))
                .unwrap();
            if r2 <= 500.0 {
                assert_eq!(got, 0.0, "clear gate {gate}");
                continue;
            }
            let mean_t2 =
                (2.0 * sigma * 500.0).exp() * exp_over_r2_integral(2.0 * sigma, r1, r2) * r1 * r2
                    / (r2 - r1);
            let want = beta * o * mean_t2;
            // The 1/r²-weighted mean range r_w = r₁r₂ ln(r₂/r₁)/Δr (below the centre by
            // ≈ Δr²/(6 r), 0.8 m in the first gate: 3e-4 in T²).
            let rw = r1 * r2 * (r2 / r1).ln() / (r2 - r1);
            let point = beta * o * (-2.0 * sigma * (rw - 500.0)).exp();
            assert!((want / point - 1.0).abs() < 1e-4, "{want} vs {point}");
            assert!(
                (got / want - 1.0).abs() < 1e-12,
                "FOV {f}, gate {gate}: β′ {got:e} vs {want:e} ({:e})",
                got / want - 1.0
            );
            compared += 1;
        }
    }
    assert_eq!(compared, 2 * 38);
}

/// One row of `backscatter.csv` or `returns.csv`, keyed by its grid columns.
type Key = (String, String, String, String, String, String);

fn rows_by_key(path: &Path) -> (Vec<String>, Vec<(Key, Vec<String>)>) {
    let (header, rows) = read_csv(path);
    let col = |n: &str| header.iter().position(|h| h == n).unwrap();
    let idx = [
        col("source"),
        col("channel"),
        col("fov_full_angle_mrad"),
        col("range_m"),
        col("order"),
        col("polarisation"),
    ];
    let keyed = rows
        .into_iter()
        .map(|r| {
            let k = (
                r[idx[0]].clone(),
                // The CSV marks a channel name that reads as a number (`'1064`).
                lidarsim::output::csv_text_value(&r[idx[1]]).to_string(),
                r[idx[2]].clone(),
                r[idx[3]].clone(),
                r[idx[4]].clone(),
                r[idx[5]].clone(),
            );
            (k, r)
        })
        .collect();
    (header, keyed)
}

fn num(s: &str) -> f64 {
    s.parse()
        .unwrap_or_else(|e| panic!("`{s}` is not a number: {e}"))
}

/// Both files print 10 significant digits: two roundings of ≤ 5e-10 each.
fn same_printed(a: f64, b: f64) -> bool {
    a == b || (a / b - 1.0).abs() < 1.5e-9
}

/// `backscatter.csv` has one row per row of `returns.csv`, in its order, and each is the
/// energy times the lidar equation's factors worked from the scene's numbers: β′ = E r₁r₂/(C Δr)
/// with C = E₀ η π D²/4 given per line (`constants`), RCS = E r_c², the errors alike.
fn check_rows_against_returns(dir: &Path, width_m: f64, constants: &HashMap<&str, f64>) {
    let (header, back) = rows_by_key(&dir.join("backscatter.csv"));
    assert_eq!(
        header.join(","),
        "source,channel,fov_full_angle_mrad,range_m,order,attenuated_backscatter_per_m_sr,\
         attenuated_backscatter_stderr_per_m_sr,range_corrected_signal_j_m2,\
         range_corrected_signal_stderr_j_m2,lidar_constant_j_m2,polarisation"
    );
    let (rh, ret) = rows_by_key(&dir.join("returns.csv"));
    assert_eq!(back.len(), ret.len());
    let (e_col, s_col) = (
        rh.iter().position(|h| h == "energy_j").unwrap(),
        rh.iter().position(|h| h == "stderr_j").unwrap(),
    );
    for ((kb, b), (kr, r)) in back.iter().zip(&ret) {
        assert_eq!(kb, kr);
        let (e, se) = (num(&r[e_col]), num(&r[s_col]));
        let rc = num(&kb.3);
        let (r1, r2) = (rc - 0.5 * width_m, rc + 0.5 * width_m);
        let c = constants[kb.1.as_str()];
        let factor = r1 * r2 / (c * width_m);
        assert!(same_printed(num(&b[9]), c), "{kb:?}: C {}", b[9]);
        for (got, want) in [
            (num(&b[5]), e * factor),
            (num(&b[6]), se * factor),
            (num(&b[7]), e * rc * rc),
            (num(&b[8]), se * rc * rc),
        ] {
            assert!(same_printed(got, want), "{kb:?}: {got:e} vs {want:e}");
        }
    }
}

/// C.1 (Bissonnette et al. 1995) at 20 000 photons, seed 1, 100 batches: (a) every row of
/// `backscatter.csv` is its `returns.csv` energy times r₁r₂/(C Δr) and r_c², C = 1 J · 1 ·
/// π (1 m)²/4; (b) the Monte Carlo's order-1 β′ agrees with the analytic β′ in every gate and
/// field of view: |z| < 4.5 everywhere and the mean of z² below 2 (the batch errors are right,
/// not only generous; with the pencil beam order 1 is the same in every field of view, so these
/// are 30 independent gates, and χ²₃₀/30 > 2 has probability 1e-3; measured: largest |z| 3.1,
/// mean z² 1.4); both 0 above the cloud; (c) the analytic β′ of the first cloud gate is
/// below the cloud's β = σ ϖ P(180°)/(4π) times the two-way transmission to the gate's start,
/// and above it times that to the gate's end (T² falls across the gate).
#[test]
fn c1_backscatter_rows_and_monte_carlo_order_one_against_analytic() {
    let dir = tempfile::tempdir().unwrap();
    let scene = project_root().join("scenes/bissonnette_c1.toml");
    lidarsim_ok([
        "run".as_ref(),
        scene.as_os_str(),
        "--photons".as_ref(),
        "20000".as_ref(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        dir.path().as_os_str(),
    ]);
    let c = std::f64::consts::PI * 0.25;
    check_rows_against_returns(dir.path(), 10.0, &HashMap::from([("1064", c)]));

    let (_, back) = rows_by_key(&dir.path().join("backscatter.csv"));
    let value: HashMap<Key, (f64, f64)> = back
        .iter()
        .map(|(k, r)| (k.clone(), (num(&r[5]), num(&r[6]))))
        .collect();
    let (mut n, mut sum_z2, mut worst) = (0, 0.0, 0.0f64);
    for (k, (an, an_se)) in value.iter().filter(|(k, _)| k.0 == "analytic") {
        assert_eq!(*an_se, 0.0);
        let mut mk = k.clone();
        mk.0 = "mc".into();
        let (mc, se) = value[&mk];
        let rc = num(&k.3);
        if rc > 1300.0 {
            assert_eq!((*an, mc), (0.0, 0.0), "{k:?}: above the cloud");
            continue;
        }
        assert!(*an > 0.0 && se > 0.0, "{k:?}");
        let z = (mc - an) / se;
        worst = worst.max(z.abs());
        sum_z2 += z * z;
        n += 1;
    }
    assert_eq!(n, 6 * 30, "six fields of view, 30 cloud gates");
    assert!(worst < 4.5, "largest |z| {worst}");
    assert!(sum_z2 / (n as f64) < 2.0, "mean z² {}", sum_z2 / n as f64);

    // The cloud's first gate, [1000, 1010] m: β T²(1010) < β′ < β T²(1000) = β, with β from
    // the scene's phase table at 180° (its last row: degrees, value; the code renormalises the
    // table to 4π, a change far inside the 30 % between the bounds).
    let table =
        std::fs::read_to_string(project_root().join("phase_functions/bissonnette_c1_1064nm.txt"))
            .unwrap();
    let last: Vec<f64> = table
        .lines()
        .rfind(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .unwrap()
        .split(',')
        .map(|f| num(f.trim()))
        .collect();
    assert_eq!(last[0], 180.0);
    let beta = 17.23e-3 * 0.999908 * last[1] / (4.0 * std::f64::consts::PI);
    let first = value[&(
        "analytic".into(),
        "1064".into(),
        "0.1".into(),
        "1005".into(),
        "1st".into(),
        "total".into(),
    )]
        .0;
    let t2_end = (-2.0 * 17.23e-3 * 10.0f64).exp();
    assert!(
        first < beta && first > beta * t2_end,
        "β′ {first} not within β {beta} × [{t2_end}, 1]"
    );
}

/// Two lines of different pulse energies (`[laser] pulse_energy_j = [0.02, 0.01]`) and
/// linearly polarised light, analytic only: each line has its own C = E₀ η A (so the two
/// lines' β′ are equal, their energies 2:1), the co and cross rows are the energies' rows
/// times the same factors, and co + cross = total for β′.
#[test]
fn each_line_has_its_own_lidar_constant_and_polarised_rows_scale_alike() {
    let text = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
beam_divergence_full_angle_mrad = 0.5
telescope_diameter_m = 0.5
optical_efficiency = 0.5
fov_full_angle_mrad = 1.0
polarisation = "linear"
[[channel]]
name = "a"
wavelength_nm = 1064.0
[[channel]]
name = "b"
wavelength_nm = 1064.0
[laser]
pulse_energy_j = [0.02, 0.01]
repetition_rate_hz = 10.0
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
photons = 0
"#;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("two_lines.toml");
    std::fs::write(&path, text).unwrap();
    let out = dir.path().join("out");
    lidarsim_ok([
        "run".as_ref(),
        path.as_os_str(),
        "--no-plots".as_ref(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    let area = std::f64::consts::PI * 0.25 * 0.25;
    let constants = HashMap::from([("a", 0.02 * 0.5 * area), ("b", 0.01 * 0.5 * area)]);
    check_rows_against_returns(&out, 250.0, &constants);

    let (_, back) = rows_by_key(&out.join("backscatter.csv"));
    let beta: HashMap<Key, f64> = back.iter().map(|(k, r)| (k.clone(), num(&r[5]))).collect();
    let mut cloud_rows = 0;
    for (k, v) in beta.iter().filter(|(k, _)| k.5 == "total") {
        let other = |ch: &str, pol: &str| {
            let mut o = k.clone();
            o.1 = ch.into();
            o.5 = pol.into();
            beta[&o]
        };
        assert!(same_printed(other("b", "total"), *v), "{k:?}");
        let sum = other(&k.1, "co") + other(&k.1, "cross");
        assert!(
            (sum - v).abs() <= 2e-9 * v.abs(),
            "{k:?}: co + cross {sum:e} vs {v:e}"
        );
        if *v > 0.0 {
            cloud_rows += 1;
        }
    }
    assert!(cloud_rows >= 2, "{cloud_rows} rows in the cloud");
}
