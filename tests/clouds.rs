//! Multiple scattering in clouds against closed forms that hold for every order of scattering
//! (the validation runs of `validation/i3rc_case7` and `validation/platt` at test size).

use lidarsim::returns::Order;

use crate::transport::{K_SIGMA, analytic, run, scene_text};

/// A lidar 1000 km above a thick cloud of extinction 40 km⁻¹ (I3RC Phase 3 Case 7 geometry),
/// 5 mrad field of view, gates 0–300 m of apparent depth below the cloud top.
const FAR_CLOUD: &str = r#"
[lidar]
altitude_m = 1000600.0
zenith_angle_deg = 180.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = 5.0
[[channel]]
name = "532"
wavelength_nm = 532.0
[gates]
start_m = 1000000.0
end_m = 1000300.0
width_m = 15.0
[[layer]]
name = "cloud"
base_m = 0.0
top_m = 600.0
extinction_per_km = 40.0
single_scattering_albedo = 1.0
phase = { kind = "henyey_greenstein", g = 0.85 }
ABSORPTION
[simulation]
seed = 3
max_order = 4
"#;

/// A uniform absorber κ added to a cloud (its scattering unchanged) multiplies the return at
/// apparent depth d by e^{−2κd}, whatever the scattering order: every path that arrives at
/// time 2d/c has travelled 2d inside the cloud (to x²/2R ≈ 0.05 m for a spot of x ≲ 300 m seen
/// from R = 1000 km). Two independent runs, so this checks absorption in the weights, the
/// local estimates' attenuation toward the receiver and the range gating of multiply
/// scattered light together. Within a 15 m gate e^{−2κd} is taken at the centre (an error
/// below 2e-3 here).
#[test]
fn absorber_in_a_far_cloud_scales_every_order_by_two_way_path() {
    let kappa = 2e-3;
    let clear = scene_text(&FAR_CLOUD.replace("ABSORPTION", ""));
    let absorbing =
        scene_text(&FAR_CLOUD.replace("ABSORPTION", &format!("absorption_per_m = {kappa}")));
    let a = run(&clear, 80_000, |_| {});
    let b = run(&absorbing, 80_000, |_| {});
    let mut judged = 0;
    for g in 0..a.returns.range_m.len() {
        let d = a.returns.range_m[g] - 1.0e6;
        let (ea, sa) = (
            a.returns.energy(0, 0, g, Order::Total).unwrap(),
            a.returns.stderr(0, 0, g, Order::Total).unwrap(),
        );
        let (eb, sb) = (
            b.returns.energy(0, 0, g, Order::Total).unwrap(),
            b.returns.stderr(0, 0, g, Order::Total).unwrap(),
        );
        if !(sa < 0.1 * ea && sb < 0.1 * eb) {
            continue;
        }
        judged += 1;
        let t = (-2.0 * kappa * d).exp();
        let sigma = (sb * sb + (t * sa).powi(2)).sqrt();
        assert!(
            (eb - t * ea).abs() <= K_SIGMA * sigma + 0.01 * t * ea,
            "gate at depth {d} m: absorbing {eb:.4e} ± {sb:.1e}, clear × e^(−2κd) {:.4e} ± {:.1e}",
            t * ea,
            t * sa
        );
    }
    assert!(judged >= 15, "only {judged} of 20 gates judged");
}

/// Platt's integral for single scattering: ∫β e^{−2τ(r)} dr over a homogeneous cloud of
/// optical depth τ is (1 − e^{−2τ})/(2S), S = σ/β the lidar ratio (Platt 1979, J. Appl.
/// Meteorol. 18, 1130), here of the analytic returns summed over gates that cover the cloud.
#[test]
fn analytic_single_scatter_integral_is_platt_closed_form() {
    for (top, g) in [(1058.04f64, 0.85f64), (1580.38, 0.5)] {
        let scene = scene_text(&format!(
            r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = 1.0
[[channel]]
name = "1064"
wavelength_nm = 1064.0
[gates]
start_m = 990.0
end_m = 1600.0
width_m = 2.0
[[layer]]
name = "cloud"
base_m = 1000.0
top_m = {top}
extinction_per_km = 17.23
single_scattering_albedo = 1.0
phase = {{ kind = "henyey_greenstein", g = {g} }}
"#
        ));
        let an = analytic(&scene);
        let area = std::f64::consts::PI * 0.25;
        let gamma: f64 = (0..an.range_m.len())
            .map(|i| {
                let r = an.range_m[i];
                an.energy(0, 0, i, Order::Exactly(1)).unwrap() * r * r / area
            })
            .sum();
        let tau = 17.23e-3 * (top - 1000.0);
        // Henyey-Greenstein at 180°: (1 − g²)/(1 + g)³, normalised to 4π.
        let s = 4.0 * std::f64::consts::PI * (1.0 + g).powi(3) / (1.0 - g * g);
        let platt = (1.0 - (-2.0 * tau).exp()) / (2.0 * s);
        assert!(
            (gamma / platt - 1.0).abs() < 1e-4,
            "τ = {tau}: Σ β' Δr = {gamma:.6e}, (1 − e^(−2τ))/(2S) = {platt:.6e}"
        );
    }
}
