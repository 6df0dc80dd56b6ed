//! Extreme physical scenes: optical depths to 1000, Henyey-Greenstein g = ±0.9999,
//! single-scattering albedos exactly 0 and 1, a 1 mm layer among 500 thin ones, horizontal and
//! grazing beams, a 1000 km range in 5 m gates, a channel with absorption optical depth 50.
//! Each gives finite, non-negative returns and error bars, its single scattering equals the
//! analytic lidar equation wherever the Monte Carlo resolves it, and, where the flux tally is
//! on, the energy is conserved. Photon counts are small; each case runs in well under a second
//! (printed, never asserted) and its collisions are bounded by the path-length cut.

use std::time::Instant;

use lidarsim::returns::{Order, Returns};
use lidarsim::scene::Scene;
use lidarsim::transport::McResult;

use crate::transport::{analytic, assert_energy_conserved, check_order1, run, scene_text};

const BASE: &str = r#"
[lidar]
altitude_m = ALTITUDE
zenith_angle_deg = ZENITH
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.2
telescope_diameter_m = 0.3
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0, 5.0]
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = GATE_START
end_m = GATE_END
width_m = GATE_WIDTH
LAYERS
[simulation]
max_order = 4
seed = 11
"#;

fn scene(altitude_m: f64, zenith_deg: f64, gates: (f64, f64, f64), layers: &str) -> Scene {
    scene_text(
        &BASE
            .replace("ALTITUDE", &altitude_m.to_string())
            .replace("ZENITH", &zenith_deg.to_string())
            .replace("GATE_START", &gates.0.to_string())
            .replace("GATE_END", &gates.1.to_string())
            .replace("GATE_WIDTH", &gates.2.to_string())
            .replace("LAYERS", layers),
    )
}

fn layer(base_m: f64, top_m: f64, ext_per_km: f64, ssa: f64, phase: &str) -> String {
    format!(
        "[[layer]]\nname = \"l{base_m}\"\nbase_m = {base_m}\ntop_m = {top_m}\nextinction_per_km = {ext_per_km}\nsingle_scattering_albedo = {ssa}\nphase = {phase}\n"
    )
}

const HG85: &str = "{ kind = \"henyey_greenstein\", g = 0.85 }";

/// Finite and non-negative energies and errors; order 1 against the lidar equation; the run.
fn check(name: &str, s: &Scene, photons: u64, flux: bool) -> McResult {
    let t = Instant::now();
    let mc = run(s, photons, |o| o.layout.flux = flux);
    let r: &Returns = &mc.returns;
    assert!(
        r.energy_j
            .iter()
            .chain(&r.stderr_j)
            .all(|v| v.is_finite() && *v >= 0.0),
        "{name}: a return or error bar is not finite and non-negative"
    );
    let (judged, signal) = check_order1(name, r, &analytic(s));
    println!(
        "{name}: {photons} photons, {} collisions, {:.3} s; order 1 judged in {judged} of {signal} bins with signal",
        mc.stats.collisions,
        t.elapsed().as_secs_f64()
    );
    if flux {
        assert_energy_conserved(name, &mc);
    }
    assert_received_at_most_emitted(name, s, r);
    mc
}

/// The energy received over all gates and orders in the widest field of view is at most the
/// energy emitted times the optical efficiency (within 4 standard errors of the sum): the
/// receiver is one of the ways energy leaves the scene, however close or peaked the scatterers.
pub(crate) fn assert_received_at_most_emitted(name: &str, s: &Scene, r: &Returns) {
    let widest = (0..r.fov_full_angle_mrad.len())
        .max_by(|a, b| r.fov_full_angle_mrad[*a].total_cmp(&r.fov_full_angle_mrad[*b]))
        .unwrap();
    let emitted = s.lidar.pulse_energy_j * s.lidar.optical_efficiency;
    for k in 0..r.channels.len() {
        let (mut sum, mut var) = (0.0, 0.0);
        for g in 0..r.range_m.len() {
            sum += r.energy(k, widest, g, Order::Total).unwrap();
            var += r.stderr(k, widest, g, Order::Total).unwrap().powi(2);
        }
        assert!(
            sum - 4.0 * var.sqrt() <= emitted,
            "{name}, channel {k}: received {sum:e} ± {:e} J of {emitted:e} J emitted",
            var.sqrt()
        );
    }
}

/// A slab of optical depth 1000 (10 m⁻¹ over 100 m), conservative: no NaN, energy conserved,
/// the first 2 m of the cloud base (τ ≤ 20) against the lidar equation.
#[test]
fn optical_depth_1000() {
    let s = scene(
        0.0,
        0.0,
        (900.0, 1200.0, 2.0),
        &layer(1000.0, 1100.0, 10_000.0, 1.0, HG85),
    );
    let mc = check("τ = 1000", &s, 2_000, true);
    // Half or more goes back down (the slab reflects almost everything): reflection, not loss.
    assert!(mc.flux.down[0] > 0.5, "down {}", mc.flux.down[0]);
}

/// Forward and backward peaks of g = ±0.9999 (P(0°) = 2e8) in a cloud of optical depth 2.
#[test]
fn asymmetry_near_one() {
    for g in [0.9999, -0.9999] {
        let phase = format!("{{ kind = \"henyey_greenstein\", g = {g} }}");
        let s = scene(
            0.0,
            0.0,
            (900.0, 1300.0, 10.0),
            &layer(1000.0, 1200.0, 10.0, 1.0, &phase),
        );
        check(&format!("g = {g}"), &s, 20_000, true);
    }
}

/// Single-scattering albedos exactly 0 (a purely absorbing layer) and 1, one above the other:
/// the absorbing layer scatters nothing and dims what lies above it.
#[test]
fn albedo_exactly_zero_and_one() {
    let layers = layer(500.0, 800.0, 1.0, 0.0, HG85) + &layer(1000.0, 1300.0, 1.0, 1.0, HG85);
    let s = scene(0.0, 0.0, (400.0, 1400.0, 20.0), &layers);
    let mc = check("ϖ = 0 and 1", &s, 50_000, true);
    assert!(
        mc.flux.absorbed[0] > 0.2,
        "absorbed {}",
        mc.flux.absorbed[0]
    );
}

/// A 1 mm layer of optical depth 1e-3 and 500 layers 2 m thick of alternating extinction.
#[test]
fn thin_and_many_layers() {
    let mut layers = layer(600.0, 600.001, 1_000.0, 0.9, HG85);
    for i in 0..500 {
        let base = 1000.0 + 2.0 * i as f64;
        let ext = if i % 2 == 0 { 0.5 } else { 2.0 };
        layers += &layer(base, base + 2.0, ext, 0.95, HG85);
    }
    let s = scene(0.0, 0.0, (500.0, 2100.0, 10.0), &layers);
    check("1 mm + 500 layers", &s, 20_000, true);
}

/// A horizontal beam inside an aerosol layer, and a grazing one (1e-4 degree above the
/// horizontal) crossing its top.
#[test]
fn horizontal_and_grazing_beams() {
    let aerosol = layer(
        0.0,
        1000.0,
        0.5,
        0.95,
        "{ kind = \"henyey_greenstein\", g = 0.7 }",
    );
    for zenith in [90.0, 89.9999] {
        let s = scene(500.0, zenith, (100.0, 3000.0, 50.0), &aerosol);
        check(&format!("zenith {zenith}°"), &s, 20_000, true);
    }
}

/// Space-borne at 1000 km looking down through Rayleigh air and an aerosol layer, 5 m gates
/// over the last 20 km of range (4000 gates).
#[test]
fn range_1000_km_in_fine_gates() {
    let text = BASE
        .replace("ALTITUDE", "1000000.0")
        .replace("ZENITH", "180.0")
        .replace("GATE_START", "980000.0")
        .replace("GATE_END", "1000000.0")
        .replace("GATE_WIDTH", "5.0")
        .replace(
            "LAYERS",
            &("[atmosphere]\nstandard = \"us_standard\"\nlayer_thickness_m = 500.0\n".to_string()
                + &layer(
                    0.0,
                    2000.0,
                    0.2,
                    0.95,
                    "{ kind = \"henyey_greenstein\", g = 0.7 }",
                )),
        );
    check("1000 km", &scene_text(&text), 1_000_000, false);
}

/// One of two channels has absorption optical depth 50 in a layer (and the same scattering):
/// its returns from beyond the layer are e⁻¹⁰⁰ of the other's, finite, with finite errors,
/// and its order 1 is the lidar equation's.
#[test]
fn absorption_optical_depth_50() {
    let text = BASE
        .replace("ALTITUDE", "0.0")
        .replace("ZENITH", "0.0")
        .replace("GATE_START", "100.0")
        .replace("GATE_END", "2500.0")
        .replace("GATE_WIDTH", "20.0")
        .replace(
            "[[channel]]\nname = \"a\"\nwavelength_nm = 1064.0",
            "[[channel]]\nname = \"a\"\nwavelength_nm = 1064.0\n[[channel]]\nname = \"b\"\nwavelength_nm = 1064.0",
        )
        .replace(
            "LAYERS",
            "[[layer]]\nname = \"absorber\"\nbase_m = 500.0\ntop_m = 1500.0\nextinction_per_km = 0.2\nsingle_scattering_albedo = 0.9\nphase = { kind = \"henyey_greenstein\", g = 0.7 }\nabsorption_per_m = [0.0, 0.05]\n[[layer]]\nname = \"above\"\nbase_m = 1800.0\ntop_m = 2400.0\nextinction_per_km = 0.5\nsingle_scattering_albedo = 0.9\nphase = { kind = \"henyey_greenstein\", g = 0.7 }\n",
        );
    let s = scene_text(&text);
    let mc = check("τ_a = 50", &s, 50_000, false);
    // Order-1 returns from the upper layer: ratio b/a is e^{−100} exactly (same path, same
    // scattering; the absorber is crossed twice, vertically).
    let r = &mc.returns;
    let order = lidarsim::returns::Order::Exactly(1);
    for g in 0..r.range_m.len() {
        if !(r.range_m[g] > 1810.0 && r.range_m[g] < 2390.0) {
            continue;
        }
        let (a, b) = (
            r.energy(0, 0, g, order).unwrap(),
            r.energy(1, 0, g, order).unwrap(),
        );
        assert!(a > 0.0, "gate {}", r.range_m[g]);
        // The beam's 0.1 mrad half-divergence lengthens the slant paths by up to 5e-9 of the
        // layer: e^{−100/μ} differs from e^{−100} by up to 5e-7.
        let ratio = b / a / (-100.0f64).exp();
        assert!(
            (ratio - 1.0).abs() < 1e-6,
            "gate {}: b/a = {ratio} e⁻¹⁰⁰",
            r.range_m[g]
        );
    }
}

/// Henyey-Greenstein and double Henyey-Greenstein layers at |g| up to 1 − 1e-12 (P(0°) or
/// P(180°) up to 2e24) through whole runs with every variance reduction: every order finite and
/// non-negative, order 1 equal to the lidar equation, energy conserved, and no more received than
/// emitted. Before 28 Nov 2026 every order ≥ 2 was NaN (a cosine rounded past ±1 made the
/// denominator negative), and at g → −1 the lidar equation returned 5e7 J from a 1 J pulse
/// (P(180°) at one angle, for a peak 1e-8 rad wide inside an aperture of 1.5e-4 rad). The
/// retro-reflecting layer (g → −1) sends back what it scatters: its reflectance for τ = 3 is
/// τ/(1 + τ) = 3/4 (a one-dimensional walk), which the received total must match within 5 %.
#[test]
fn extreme_asymmetry_through_whole_runs() {
    let cases = [
        "{ kind = \"henyey_greenstein\", g = 0.99999999 }",
        "{ kind = \"henyey_greenstein\", g = -0.99999999 }",
        "{ kind = \"henyey_greenstein\", g = 0.999999999999 }",
        "{ kind = \"henyey_greenstein\", g = -0.999999999999 }",
        "{ kind = \"double_henyey_greenstein\", f = 0.5, g1 = 0.99, g2 = -0.99 }",
        "{ kind = \"double_henyey_greenstein\", f = 0.9, g1 = 0.8, g2 = -0.9999999999 }",
    ];
    for phase in cases {
        let s = scene(
            0.0,
            0.0,
            (100.0, 3000.0, 50.0),
            &layer(1000.0, 1300.0, 10.0, 1.0, phase),
        );
        let mc = check(phase, &s, 20_000, true);
        if phase.contains("-0.99999999") && !phase.contains("double") {
            let widest = 1;
            let received: f64 = (0..mc.returns.range_m.len())
                .map(|g| mc.returns.energy(0, widest, g, Order::Total).unwrap())
                .sum();
            assert!(
                (received / 0.75 - 1.0).abs() < 0.05,
                "{phase}: received {received}, a retro-reflector of τ = 3 returns 3/4"
            );
        }
    }
}

/// The cost of detector-directed sampling and splitting stays bounded where a phase function
/// has a backward peak: a double Henyey-Greenstein of g = 0.99 and −0.99 made about 2700
/// scatterings per photon (alignment splitting copied every photon that the backward peak sent
/// back along the line of sight, 8.5 without the variance reductions). Alignment splitting is
/// not used in such layers; the run now makes fewer than 20 per photon (a count, not a time).
#[test]
fn backward_peak_does_not_multiply_the_work() {
    let s = scene(
        0.0,
        0.0,
        (100.0, 3000.0, 50.0),
        &layer(
            1000.0,
            1300.0,
            10.0,
            1.0,
            "{ kind = \"double_henyey_greenstein\", f = 0.5, g1 = 0.99, g2 = -0.99 }",
        ),
    );
    let photons = 20_000;
    let mc = check("double HG ±0.99", &s, photons, false);
    let per_photon = mc.stats.collisions as f64 / photons as f64;
    assert!(per_photon < 20.0, "{per_photon} scatterings per photon");
}

/// A phase-function table whose backscatter (or forward) peak, 1e12 over 1e-6°, the nodes
/// resolve but the receiver's aperture cannot: the local estimates and the lidar equation use
/// the table's mean over the aperture's cone, so the returns are finite, the two agree, and a
/// 1 J pulse returns less than 1 J (8.9e5 J from the Monte Carlo and 1.1e6 J from the lidar
/// equation before 28 Nov 2026). The table integrates its peak exactly: the returned single
/// scattering equals the probability mass of the peak's segment (the table's own nodes, the
/// cosine of 179.999999° rounded as the double holds it) times ∫ σ e^{−2σz} dz over the layer,
/// 1e-3 relative.
#[test]
fn unresolvable_table_peaks_are_integrated() {
    let dir = std::env::temp_dir().join(format!("lidarsim-stress-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let header = "# lidarsim phase function table\n# wavelength_nm = none\n# refractive_index = none\n# distribution = none\n# source = crafted: a peak of 1e12 over 1e-6 degrees\ntheta_deg,phase_4pi\n";
    for (name, rows) in [
        ("back", "0,1\n90,1\n179.999999,1\n180,1e12\n"),
        ("forward", "0,1e12\n0.000001,1\n90,1\n180,1\n"),
    ] {
        let path = dir.join(format!("{name}.csv"));
        std::fs::write(&path, format!("{header}{rows}")).unwrap();
        let phase = format!(
            "{{ kind = \"table\", file = {:?} }}",
            path.display().to_string()
        );
        let s = scene(
            0.0,
            0.0,
            (100.0, 3000.0, 50.0),
            &layer(1000.0, 1300.0, 10.0, 1.0, &phase),
        );
        let mc = check(name, &s, 20_000, true);
        if name == "back" {
            // The table, linear in μ: nodes μ = −1, m1 = cos(179.999999°) (as rounded), 0, 1.
            let m1 = (179.999999f64).to_radians().cos();
            let areas = [0.5 * (1e12 + 1.0) * (m1 + 1.0), 0.5 * 2.0 * (0.0 - m1), 1.0];
            let total: f64 = areas.iter().sum();
            let peak_probability = areas[0] / total;
            // Single scattering from the layer: ∫ σ e^{−2σ(z − base)} dz = (1 − e^{−6})/2,
            // σ = 0.01 /m over 300 m, all of the peak inside every aperture cone (≥ 1.1e-4 rad),
            // telescope area times … the peak's share of each scattering.
            let an = analytic(&s);
            let single: f64 = (0..an.range_m.len())
                .map(|g| an.energy(0, 0, g, Order::Exactly(1)).unwrap())
                .sum();
            let want = peak_probability * 0.5 * (1.0 - (-6.0f64).exp());
            assert!(
                (single / want - 1.0).abs() < 1e-3,
                "{name}: single scattering {single:e}, the peak's share {want:e}"
            );
        }
        drop(mc);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A downward lidar above a white (albedo 1) or grey ground at heights from 1 mm to 10 m, in
/// the US standard atmosphere, gates from 0.1 mm: the echo is the energy the aperture collects
/// from a Lambertian surface, ρ a²/(R² + a²) of the pulse on the axis, never more than ρ, and
/// the Monte Carlo equals the lidar equation. Before 28 Nov 2026 a lidar 1 mm above an
/// albedo-1 ground received 2.25e4 J of a 1 J pulse (A/R² with R = 1 mm).
#[test]
fn surface_at_any_height_returns_at_most_its_albedo() {
    for (i, (height, albedo)) in [
        (1e-3, 1.0),
        (1e-2, 1.0),
        (0.1, 0.5),
        (1.0, 1.0),
        (10.0, 0.2),
    ]
    .into_iter()
    .enumerate()
    {
        let text = BASE
            .replace("ALTITUDE", &format!("{height:?}"))
            .replace("ZENITH", "180.0")
            .replace("GATE_START", "0.0001")
            .replace("GATE_END", "20.0001")
            .replace("GATE_WIDTH", "0.5")
            .replace(
                "LAYERS",
                &format!(
                    "[atmosphere]\nstandard = \"us_standard\"\nlayer_thickness_m = 100.0\n[surface]\naltitude_m = 0.0\nalbedo = {albedo:?}\n"
                ),
            )
            .replace("seed = 11", &format!("seed = {}", 70 + i));
        let s = scene_text(&text);
        let name = format!("{height} m above albedo {albedo}");
        let mc = check(&name, &s, 20_000, true);
        // The echo's gate holds the surface's return: a²/(R² + a²) ρ on the axis (the beam's
        // 0.1 mrad makes cos θ = 1 to 5e-9), times the two-way transmission of the air (3e-5
        // from 1 over 10 m at 1064 nm), plus the air's own return in the gate (below 2e-6 of
        // the echo). Far from the aperture (a²/R² below `aperture::POINT_TOLERANCE`, 1e-3) the
        // point value ρ A/(π R²) stands for it, within that tolerance.
        let a = 0.15f64;
        let want = albedo * a * a / (height * height + a * a);
        let gate = ((height - 0.0001) / 0.5) as usize;
        let an = analytic(&s);
        let echo = an.energy(0, 1, gate, Order::Exactly(1)).unwrap();
        assert!(
            (echo / want - 1.0).abs() < lidarsim::aperture::POINT_TOLERANCE && echo <= albedo,
            "{name}: echo {echo:e}, want {want:e}"
        );
        let m = mc.returns.energy(0, 1, gate, Order::Exactly(1)).unwrap();
        assert!(
            (m / echo - 1.0).abs() < 1e-4,
            "{name}: MC echo {m:e}, analytic {echo:e}"
        );
    }
}

/// A lidar inside a dense cloud (σ = 20 /km, g = 0.85, ϖ = 1), gates from 0.5 m: scatterers a
/// few centimetres from the aperture see it under tens of degrees, where the point-receiver
/// estimate would return A/d² without bound. Finite, conserved, at most the emitted energy, and
/// the single scattering equal to the lidar equation.
#[test]
fn lidar_inside_a_dense_cloud() {
    let s = scene(
        500.0,
        0.0,
        (0.5, 300.5, 1.0),
        &layer(0.0, 1000.0, 20.0, 1.0, HG85),
    );
    check("inside a cloud", &s, 50_000, true);
}
