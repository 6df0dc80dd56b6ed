//! Instrument and retrieval: the laser's line shape against an independent spectral average,
//! noisy measurements against the noise formula, noise-free retrievals against the truth,
//! combined Monte Carlo channels against their own covariances, multiple scattering in IPDA,
//! and retrievals that cannot be done.

use std::path::Path;

use lidarsim::input::InputError;
use lidarsim::instrument::signals::Signals;
use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::pipeline::{self, RunError, RunOutput};
use lidarsim::retrieval::{Method, Quantity, RetrievalError};
use lidarsim::returns::{Order, Source};
use lidarsim::rng::{Stream, streams};
use lidarsim::scene::Scene;
use lidarsim::spectroscopy::{LineFilter, LineList, layer_optical_depths_at};
use lidarsim::transport::{self, TallyLayout};

/// An airborne CO2 IPDA/DIAL at 8 km, nadir, no particles: Rayleigh air, CO2 (built-in band
/// model), a Lambertian surface; on-line 2.2 GHz up R16e. Each test changes what it studies.
const SCENE: &str = r#"description = "retrieval test"
[lidar]
altitude_m = 8000.0
zenith_angle_deg = 180.0
beam_divergence_full_angle_mrad = 0.1
beam_profile = "gaussian"
telescope_diameter_m = 0.5
optical_efficiency = 0.5
fov_full_angle_mrad = [0.2, 1.0]
[[channel]]
name = "on"
wavenumber_cm1 = 6360.04
[[channel]]
name = "off"
wavenumber_cm1 = 6360.61
[laser]
pulse_energy_j = 0.05
repetition_rate_hz = 100.0
line_shape = "gaussian"
linewidth_fwhm_mhz = 30.0
[receiver]
filter_bandwidth_ghz = 1.0
filter_transmission = 0.8
quantum_efficiency = 0.8
gain = 10.0
ionization_ratio = 0.45
nep_w_per_sqrt_hz = 4.0e-14
bandwidth_mhz = 10.0
[retrieval]
target = "surface"
dial_cell_m = 1000.0
averaging_shots = 2000
realisations = 200
[gates]
start_m = 1000.0
end_m = 8100.0
width_m = 20.0
[atmosphere]
standard = "us_standard"
co2_ppm = 420.0
layer_thickness_m = 100.0
top_m = 60000.0
[gas_absorption]
molecules = ["CO2"]
[surface]
altitude_m = 0.0
albedo = 0.3
[simulation]
photons = 100000
seed = 7
"#;

fn scene(text: &str) -> Scene {
    Scene::from_toml(Path::new("test.toml"), text).expect("test scene")
}

/// Run `s` with `photons` photons traced whatever `multiple_scattering` says (as `--photons N`
/// does; the test scene is clear sky, where "auto" would skip the Monte Carlo).
fn run(s: &Scene, photons: u64) -> RunOutput {
    let mut s = forced(s);
    s.simulation.photons = photons;
    pipeline::run(&s).expect("run")
}

fn forced(s: &Scene) -> Scene {
    let mut s = s.clone();
    s.simulation.multiple_scattering = lidarsim::scene::MultipleScattering::Always;
    s
}

/// Surface-gate line return of line `line` from the analytic lidar equation.
fn surface_return(s: &Scene, line: usize) -> f64 {
    let atm = OpticalAtmosphere::build(s).unwrap();
    let lines = s.sampling.combine(&lidar_eq::single_scatter(s, &atm));
    let g = ((8000.0 - s.gates.start_m) / s.gates.width_m) as usize;
    lines.mean.energy(line, 0, g, Order::Exactly(1)).unwrap()
}

/// Vertical optical depth of `lines` from the ground to the lidar at 8 km at each of `nus`,
/// straight from the spectroscopy stage on the scene's molecular layers.
fn vertical_depths_below_8_km(s: &Scene, lines: &LineList, nus: &[f64]) -> Vec<f64> {
    let atm = s.atmosphere.as_ref().unwrap();
    let gas = s.gas.as_ref().unwrap();
    let edges: Vec<f64> = s
        .molecular_edges()
        .unwrap()
        .into_iter()
        .filter(|e| *e <= 8000.0)
        .collect();
    let tau = layer_optical_depths_at(&atm.profile, lines, &edges, nus, &gas.options).unwrap();
    (0..nus.len())
        .map(|i| tau.iter().map(|l| l[i]).sum())
        .collect()
}

/// Laser line shapes ride as channels: a narrow line converges to the monochromatic return (as
/// FWHM², the first non-vanishing term of a symmetric line), and a wide Gaussian or Lorentzian
/// line gives the line-shape-weighted two-way transmission computed here independently, by a
/// dense direct integration over frequency of line-by-line optical depths of the same layers.
#[test]
fn line_shape_narrow_converges_to_monochromatic_and_wide_to_the_spectral_average() {
    // No Rayleigh scattering, and a filter wide enough to pass the widest line whole.
    let base = SCENE
        .replacen("[atmosphere]", "[atmosphere]\nrayleigh = false", 1)
        .replacen(
            "filter_bandwidth_ghz = 1.0",
            "filter_bandwidth_ghz = 1000.0",
            1,
        );
    let mono = scene(&base.replacen(
        "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0",
        "line_shape = \"monochromatic\"",
        1,
    ));
    let e_mono = surface_return(&mono, 0);
    let with = |shape: &str, fwhm: f64, nodes: usize| {
        scene(&base.replacen(
            "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0",
            &format!(
                "line_shape = \"{shape}\"\nlinewidth_fwhm_mhz = {fwhm}\nline_shape_nodes = {nodes}"
            ),
            1,
        ))
    };
    // Narrow: 1 kHz is the monochromatic return; 1, 10, 100 MHz depart as FWHM².
    let rel = |fwhm: f64| surface_return(&with("gaussian", fwhm, 5), 0) / e_mono - 1.0;
    assert!(rel(1e-3).abs() < 1e-12, "1 kHz: {:e}", rel(1e-3));
    let (d1, d10, d100) = (rel(1.0), rel(10.0), rel(100.0));
    println!("narrow line vs monochromatic: 1 MHz {d1:e}, 10 MHz {d10:e}, 100 MHz {d100:e}");
    assert!((d10 / d1 / 100.0 - 1.0).abs() < 0.01 && (d100 / d10 / 100.0 - 1.0).abs() < 0.05);

    // Wide: T̄² = ∫ g(x) T²(ν₀ + x) dx against the mono return T²(ν₀). Independent truth: the
    // slant optical depth from the spectroscopy stage on the scene's molecular grid at every
    // frequency of a dense grid, integrated by the midpoint rule.
    let lines = &mono.gas.as_ref().unwrap().lines;
    let nu0 = 6360.04;
    let t2 = |offsets_mhz: &[f64]| -> Vec<f64> {
        let nus: Vec<f64> = offsets_mhz.iter().map(|x| nu0 + x / 29_979.245_8).collect();
        vertical_depths_below_8_km(&mono, lines, &nus)
            .into_iter()
            .map(|tau| (-2.0 * tau).exp())
            .collect()
    };
    let t2_0 = t2(&[0.0])[0];
    // Gaussian of 2 GHz FWHM, 9 nodes; truth over ±7σ on 4001 midpoints.
    let sigma = 2000.0 / (2.0 * (2.0f64.ln() * 2.0).sqrt());
    let n = 4001;
    let h = 14.0 * sigma / n as f64;
    let xs: Vec<f64> = (0..n)
        .map(|i| -7.0 * sigma + (i as f64 + 0.5) * h)
        .collect();
    let g =
        |x: f64| (-0.5 * (x / sigma).powi(2)).exp() / (sigma * (2.0 * std::f64::consts::PI).sqrt());
    let truth: f64 = xs
        .iter()
        .zip(t2(&xs))
        .map(|(x, t)| g(*x) * t * h)
        .sum::<f64>()
        / t2_0;
    let got = surface_return(&with("gaussian", 2000.0, 9), 0) / e_mono;
    println!(
        "2 GHz Gaussian line: T̄²/T² {got} vs {truth} (rel {:e})",
        got / truth - 1.0
    );
    assert!(
        truth < 0.99,
        "the line must be wide enough to matter: {truth}"
    );
    assert!((got / truth - 1.0).abs() < 1e-6, "{got} vs {truth}");
    // Lorentzian of 300 MHz FWHM behind a 1 GHz filter (its far wings blocked), 16 nodes;
    // truth in θ = arctan(x/γ) on 20001 midpoints over the pass band (dx = γ sec²θ dθ turns
    // the Lorentzian into the uniform density 1/π). Both lines pass the filter's 0.8.
    let gamma: f64 = 150.0;
    let lorentz = scene(
        &base
            .replacen(
                "filter_bandwidth_ghz = 1000.0",
                "filter_bandwidth_ghz = 1.0",
                1,
            )
            .replacen(
                "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0",
                "line_shape = \"lorentzian\"\nlinewidth_fwhm_mhz = 300.0\nline_shape_nodes = 16",
                1,
            ),
    );
    let t_b = (500.0 / gamma).atan();
    let m = 20001;
    let xs: Vec<f64> = (0..m)
        .map(|i| gamma * (-t_b + (i as f64 + 0.5) * 2.0 * t_b / m as f64).tan())
        .collect();
    let truth: f64 =
        t2(&xs).iter().sum::<f64>() * (2.0 * t_b / std::f64::consts::PI) / m as f64 / t2_0;
    let got = surface_return(&lorentz, 0) / e_mono;
    println!(
        "300 MHz Lorentzian line behind a 1 GHz filter: T̄²/T² {got} vs {truth} (rel {:e})",
        got / truth - 1.0
    );
    assert!(
        truth < 0.9,
        "the filter must cut the wings (18 % of the energy): {truth}"
    );
    assert!((got / truth - 1.0).abs() < 1e-9, "{got} vs {truth}");
}

/// The noisy measurement of a gate, summed over N shots with the laser's energy or frequency
/// jittering from shot to shot: 10⁴ realisations have the sample variance of the formula
/// Var = N·Var_gate + N·(N_s/P)²·Var_shot(signal), Var_shot = P²ε_E² for energy jitter and
/// S²σ² + ½C²σ⁴ for a frequency jitter δ ~ N(0, σ²) acting through P + Sδ + ½Cδ², within 4
/// standard errors (standard error of a sample variance ≈ Var·√(2/(n − 1)), the counts being
/// near Gaussian). Both the shot-by-shot draw (20 shots) and the joint-normal draw of the shot
/// sums (1000 shots) are checked.
#[test]
fn noisy_measurements_have_the_variance_of_the_formula() {
    for (what, laser) in [
        ("energy jitter", "pulse_energy_jitter_fraction = 0.05"),
        ("frequency jitter", "frequency_jitter_rms_mhz = 100.0"),
    ] {
        let s = scene(&SCENE.replacen(
            "linewidth_fwhm_mhz = 30.0",
            &format!("linewidth_fwhm_mhz = 30.0\n{laser}"),
            1,
        ));
        let out = run(&s, 0);
        let sig: &Signals = &out.signals[0];
        let g = ((8000.0 - s.gates.start_m) / s.gates.width_m) as usize;
        let (line, fov) = (0, 0);
        let gate = sig.gate(line, fov, g);
        let (p, slope, curv) = sig.window_energy(line, fov, g..g + 1);
        let sj = s.laser.frequency_jitter_rms_mhz;
        let eps = s.laser.pulse_energy_jitter_fraction;
        let var_signal =
            p * p * eps * eps + slope * slope * sj * sj + 0.5 * (curv * sj * sj).powi(2);
        let pe_per_j = gate.signal_pe / p;
        for shots in [20u64, 1000] {
            let n = shots as f64;
            let formula = n * gate.variance_pe2 + n * pe_per_j * pe_per_j * var_signal;
            // The laser's part must be resolved by the test, not hidden in the detector's.
            assert!(
                n * pe_per_j * pe_per_j * var_signal > 0.3 * formula,
                "{what}"
            );
            let reals = 10_000;
            let mut rngs = streams(3, Stream::Instrument, 1);
            let window = [sig.window(line, fov, g..g + 1)];
            let xs: Vec<f64> = (0..reals)
                .map(|_| sig.realise(&s.laser, &window, shots, &mut rngs[0]).0[0])
                .collect();
            let mean = xs.iter().sum::<f64>() / reals as f64;
            let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (reals - 1) as f64;
            let se = formula * (2.0 / (reals - 1) as f64).sqrt();
            println!(
                "{what}, {shots} shots: sample variance {var:.6e}, formula {formula:.6e} ({:+.2} standard errors)",
                (var - formula) / se
            );
            assert!(
                (var - formula).abs() < 4.0 * se,
                "{what}, {shots} shots: {var} vs {formula}"
            );
            // The mean is N·N_s (the jitter's curvature bias is inside P already).
            let se_mean = (formula / reals as f64).sqrt();
            assert!(
                (mean - n * gate.signal_pe).abs() < 4.0 * se_mean,
                "{what}: {mean}"
            );
        }
    }
}

/// The simulated spread of noisy retrievals equals the analytic random error (DESIGN §3 with
/// the energy monitor and frequency jitter added) within its sampling error: IPDA per shot pair
/// and averaged, DIAL averaged where the averaged signal is strong. The mean of the averaged
/// ones equals the noise-free retrieval within its standard error (on- and off-line pulses of
/// different energy, so that the monitored energies must enter right). Twice: with a small
/// frequency jitter (0.3 MHz rms), and with one of 10 MHz that must raise the IPDA error per
/// shot pair by a fifth or more (it does by a third), so that the jitter's own term is judged.
#[test]
fn simulated_random_errors_equal_the_analytic_formula() {
    // The analytic IPDA error per shot pair of the first field of view, for each jitter.
    let mut per_shot_pair = Vec::new();
    for jitter_mhz in [0.3, 10.0] {
        let s = scene(&SCENE.replacen(
            "linewidth_fwhm_mhz = 30.0",
            &format!("linewidth_fwhm_mhz = 30.0\nfrequency_jitter_rms_mhz = {jitter_mhz}\npulse_energy_jitter_fraction = 0.05\nenergy_monitor_error_fraction = 0.002"),
            1,
        )
        .replacen("realisations = 200", "realisations = 4000", 1)
        .replacen("averaging_shots = 2000", "averaging_shots = 100000", 1)
        .replacen("pulse_energy_j = 0.05", "pulse_energy_j = [0.05, 0.03]", 1)
        .replacen("[gates]", "[background]\nradiance_w_per_m2_sr_um = 20.0\n[gates]", 1));
        let out = run(&s, 0);
        let mut judged = 0;
        let mut first_ipda = None;
        for p in &out.products {
            let averaged_ok = p.random_error_averaged < 0.05 * p.truth;
            // Standard error of a sample standard deviation: σ/√(2(n − 1)); the first-order
            // formula itself is good to O(1/SNR²) ≈ 0.3 % here.
            let tol = |sd: f64| 4.0 * sd / (2.0 * 3999.0f64).sqrt() + 0.005 * sd;
            if p.method == Method::Ipda {
                let (a, b) = (
                    p.random_error_per_shot_pair,
                    p.simulated_error_per_shot_pair,
                );
                assert!(
                    (a - b).abs() < tol(a),
                    "jitter {jitter_mhz} MHz, IPDA per shot pair: {a} vs simulated {b}"
                );
                println!(
                    "jitter {jitter_mhz} MHz, IPDA per shot pair: analytic {a:.4} ppm, simulated {b:.4} ppm"
                );
                first_ipda.get_or_insert(a);
            }
            if averaged_ok {
                judged += 1;
                // Unbiased: the log's own bias, 1/(2 SNR²) of the averaged signal, is ~1e-9.
                let (m, se) = (
                    p.simulated_mean_averaged,
                    p.simulated_error_averaged / 4000f64.sqrt(),
                );
                assert!(
                    (m - p.retrieved).abs() < 4.0 * se,
                    "jitter {jitter_mhz} MHz, {:?} {:?} {:?}: mean of the simulated {m} vs {} (standard error {se})",
                    p.method,
                    p.quantity,
                    p.range_m,
                    p.retrieved
                );
                let (a, b) = (p.random_error_averaged, p.simulated_error_averaged);
                assert!(
                    (a - b).abs() < tol(a),
                    "jitter {jitter_mhz} MHz, {:?} {:?} {:?}: averaged {a} vs simulated {b}",
                    p.method,
                    p.quantity,
                    p.range_m
                );
            }
        }
        assert!(judged >= 8, "{judged} products judged");
        per_shot_pair.push(first_ipda.expect("an IPDA product"));
    }
    assert!(
        per_shot_pair[1] > 1.2 * per_shot_pair[0],
        "the 10 MHz jitter must matter: {per_shot_pair:?}"
    );
}

/// Without noise and particles the retrievals return the truth: IPDA to better than 0.05 ppm
/// (measured: 2e-4 ppm, the Rayleigh extinction's ν⁴ dispersion between the lines), DIAL per
/// cell from the analytic returns to better than 0.03 ppm (the gate average of 1/r² e^{−2τ}),
/// and from the Monte Carlo returns to the Monte Carlo error. Because on and off share photon
/// paths, that error is orders of magnitude below what independent runs would give. The
/// analytic returns carry no Monte Carlo error, whether the paths are shared or not.
#[test]
fn noise_free_retrievals_return_the_truth() {
    let s = scene(SCENE);
    let out = run(&s, 200_000);
    for fov in [0.2, 1.0] {
        for (src, order) in [
            (Source::Analytic, Order::Exactly(1)),
            (Source::MonteCarlo, Order::Exactly(1)),
            (Source::MonteCarlo, Order::Total),
        ] {
            let ipda = out.products_of(Method::Ipda, Quantity::MixingRatio, src, order, fov);
            assert_eq!(ipda.len(), 1);
            let p = ipda[0];
            // XCO2 over 0–8 km of the US standard with `co2_ppm = 420`: well mixed in dry air
            // (the default `co2_scaling`), so 420 over any column, to rounding. (Before issue
            // 42 the table's moist-air CO2 shape was scaled to 420 over the whole column, and
            // the 0–8 km truth was 420.496.)
            assert!((p.truth / 420.0 - 1.0).abs() < 1e-9, "truth {}", p.truth);
            assert!(p.bias().abs() < 0.05, "IPDA bias {} ppm", p.bias());
            assert!(p.bias().abs() < 1e-3, "IPDA bias {} ppm", p.bias());
            let column =
                out.products_of(Method::IpdaVirtual, Quantity::SlantColumn, src, order, fov);
            assert!((column[0].retrieved / column[0].truth - 1.0).abs() < 1e-5);
            let dial = out.products_of(Method::Dial, Quantity::MixingRatio, src, order, fov);
            assert_eq!(dial.len(), 6);
            if src == Source::Analytic {
                // No Monte Carlo, no Monte Carlo error, shared paths or not.
                for p in dial.iter().chain(&ipda).chain(&column) {
                    assert_eq!((p.mc_stderr, p.mc_stderr_independent), (0.0, 0.0), "{p:?}");
                }
            }
            let analytic = out.products_of(
                Method::Dial,
                Quantity::MixingRatio,
                Source::Analytic,
                Order::Exactly(1),
                fov,
            );
            for (p, a) in dial.iter().zip(&analytic) {
                assert!(
                    a.bias().abs() < 0.03,
                    "analytic DIAL bias {} at {:?}",
                    a.bias(),
                    a.range_m
                );
                if src == Source::MonteCarlo {
                    let z = (p.retrieved - a.retrieved) / p.mc_stderr;
                    assert!(
                        z.abs() < 4.0,
                        "MC DIAL {} vs analytic {} (z {z})",
                        p.retrieved,
                        a.retrieved
                    );
                    // Shared paths: the on/off ratio carries a small part of the noise of either.
                    assert!(
                        p.mc_stderr < 0.1 * p.mc_stderr_independent,
                        "{} vs {}",
                        p.mc_stderr,
                        p.mc_stderr_independent
                    );
                }
            }
            if src == Source::MonteCarlo && order == Order::Total {
                let worst = dial
                    .iter()
                    .map(|p| p.mc_stderr / p.mc_stderr_independent)
                    .fold(0.0, f64::max);
                println!(
                    "FOV {fov}: DIAL MC error with shared paths / independent paths ≤ {worst:.2e}"
                );
            }
        }
    }
}

/// A beam 30° off nadir: the noise-free retrievals return the truth, and the truths are the
/// hydrostatic atmosphere's. The slant column is the vertical one over |cos θ|, and that is
/// 420 ppm of the dry-air column Δp/(m_air g₀) (to 1 %: the water vapour's weight and g's fall
/// with height are 0.2 % and 0.1 %); a DIAL cell's number density is 420 ppm of p/(kT) at its
/// centre (to 2 %: the cell's mean against its centre, and up to 0.8 % water vapour near the
/// ground).
#[test]
fn slant_retrievals_return_the_hydrostatic_columns() {
    let s = scene(
        &SCENE
            .replacen("zenith_angle_deg = 180.0", "zenith_angle_deg = 150.0", 1)
            .replacen("end_m = 8100.0", "end_m = 9400.0", 1),
    );
    let out = run(&s, 0);
    let mu = 30f64.to_radians().cos();
    let fov = 0.2;
    let of = |m, q| out.products_of(m, q, Source::Analytic, Order::Exactly(1), fov);
    let column = of(Method::IpdaVirtual, Quantity::SlantColumn);
    assert_eq!(column.len(), 1);
    let column = column[0];
    assert!(
        (column.retrieved / column.truth - 1.0).abs() < 1e-5,
        "{column:?}"
    );
    let prof = lidarsim::atmosphere::StandardAtmosphere::UsStandard.profile();
    let level = |z: f64| prof.altitude_m.iter().position(|&a| a == z).unwrap();
    let (p0, p8) = (
        prof.pressure_pa[level(0.0)],
        prof.pressure_pa[level(8000.0)],
    );
    let (avogadro, m_air_kg_per_mol, g0) = (6.022_140_76e23, 28.9644e-3, 9.80665);
    let dry_per_m2 = (p0 - p8) / g0 / m_air_kg_per_mol * avogadro;
    let slant = 420e-6 * dry_per_m2 / mu;
    assert!(
        (column.truth / slant - 1.0).abs() < 0.01,
        "slant column {:e} against {slant:e}",
        column.truth
    );
    let ipda = of(Method::Ipda, Quantity::MixingRatio)[0];
    assert!(
        (ipda.truth - 420.0).abs() < 1.0 && ipda.bias().abs() < 1e-3,
        "{ipda:?}"
    );
    let dial = of(Method::Dial, Quantity::NumberDensity);
    assert!(dial.len() >= 6);
    for p in dial {
        assert!((p.retrieved / p.truth - 1.0).abs() < 1e-4, "{p:?}");
        // p/(kT) at the cell's centre, ln p and T linear between the profile's levels.
        let z = 0.5 * (p.altitude_m.0 + p.altitude_m.1);
        assert!(
            (p.altitude_m.1 - p.altitude_m.0 - 1000.0 * mu).abs() < 1e-6,
            "{p:?}"
        );
        let i = prof.altitude_m.partition_point(|&a| a <= z) - 1;
        let t = (z - prof.altitude_m[i]) / (prof.altitude_m[i + 1] - prof.altitude_m[i]);
        let pz = prof.pressure_pa[i] * (prof.pressure_pa[i + 1] / prof.pressure_pa[i]).powf(t);
        let tz = prof.temperature_k[i] + t * (prof.temperature_k[i + 1] - prof.temperature_k[i]);
        let n = 420e-6 * pz / (1.380_649e-23 * tz);
        assert!(
            (p.truth / n - 1.0).abs() < 0.02,
            "cell at {z:.0} m: {:e} against {n:e}",
            p.truth
        );
    }
}

/// Water vapour absorbing at the on-line (HITRAN 2016: an H2O line 0.015 cm⁻¹ from it, in the
/// tropical atmosphere's humid boundary layer), the beam 30° off nadir: the reference state
/// carries the other gases along the slant path, so the noise-free IPDA and virtual-cross-section
/// retrievals still return the truth, although H2O's own one-way differential optical depth,
/// computed here straight from the spectroscopy stage, is about a thousandth of the CO2's (its
/// sign flipped or the term dropped would move the column by twice or once that, against the
/// 1e-5 asked).
#[test]
fn water_vapour_at_the_on_line_is_removed_by_the_reference_state() {
    let (Some(co2), Some(h2o)) = (
        crate::util::shared_file("data/hitran/CO2_626_6000-6400_HITRAN2016.par"),
        crate::util::shared_file("data/hitran/H2O_161_6000-6400_HITRAN2016.par"),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let window = |f: &Path| crate::util::par_records_in(f, 6340.0, 6380.0);
    std::fs::write(dir.path().join("lines.par"), window(&co2) + &window(&h2o)).unwrap();
    let text = SCENE
        .replacen("standard = \"us_standard\"", "standard = \"tropical\"", 1)
        .replacen(
            "molecules = [\"CO2\"]",
            "molecules = [\"CO2\", \"H2O\"]\nlines = \"lines.par\"",
            1,
        )
        .replacen("dial_cell_m = 1000.0\n", "", 1)
        .replacen("zenith_angle_deg = 180.0", "zenith_angle_deg = 150.0", 1)
        .replacen("end_m = 8100.0", "end_m = 9400.0", 1);
    let s = Scene::from_toml(&dir.path().join("h2o.toml"), &text).expect("scene");
    let out = run(&s, 0);
    let of = |m, q| out.products_of(m, q, Source::Analytic, Order::Exactly(1), 0.2)[0];
    let column = of(Method::IpdaVirtual, Quantity::SlantColumn);
    let ipda = of(Method::Ipda, Quantity::MixingRatio);

    // One-way vertical DAOD of each gas from 8 km down to the surface (their ratio is the
    // slant path's).
    let daod = |molecule: u8| -> f64 {
        let lines = s.gas.as_ref().unwrap().lines.filtered(&LineFilter {
            molecules: Some(vec![molecule]),
            ..Default::default()
        });
        let tau = vertical_depths_below_8_km(&s, &lines, &[6360.04, 6360.61]);
        tau[0] - tau[1]
    };
    let (d_co2, d_h2o) = (daod(2), daod(1));
    println!(
        "one-way DAOD: CO2 {d_co2:.4}, H2O {d_h2o:.3e}; column retrieved/truth − 1 = {:.1e}, \
         XCO2 bias {:.1e} ppm",
        column.retrieved / column.truth - 1.0,
        ipda.bias()
    );
    assert!(
        d_h2o > 5e-4 * d_co2,
        "H2O must matter: {d_h2o:e} vs {d_co2:e}"
    );
    assert!(
        (column.retrieved / column.truth - 1.0).abs() < 1e-5,
        "{column:?}"
    );
    assert!(ipda.bias().abs() < 1e-3, "{ipda:?}");
}

/// A laser whose on-line sits x MHz off its nominal frequency, retrieved by a retrieval that
/// assumes the nominal one: XCO2 comes out as truth × DAOD(ν_on + x)/DAOD(ν_on), both
/// differential optical depths computed here straight from the spectroscopy stage on the
/// scene's molecular layers (monochromatic laser, no Rayleigh scattering, no filter).
#[test]
fn a_frequency_offset_biases_ipda_as_the_shifted_differential_optical_depth() {
    let s = scene(
        &SCENE
            .replacen("[atmosphere]", "[atmosphere]\nrayleigh = false", 1)
            .replacen(
                "filter_bandwidth_ghz = 1.0",
                "filter_bandwidth_ghz = 1000.0",
                1,
            )
            .replacen(
                "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0",
                "frequency_offset_mhz = [60.0, 0.0]",
                1,
            )
            .replacen("dial_cell_m = 1000.0\n", "", 1),
    );
    let out = run(&s, 0);
    let p = out.products_of(
        Method::Ipda,
        Quantity::MixingRatio,
        Source::Analytic,
        Order::Exactly(1),
        0.2,
    )[0];
    let nus = [6360.04 + 60.0 / 29_979.245_8, 6360.04, 6360.61];
    let tau = vertical_depths_below_8_km(&s, &s.gas.as_ref().unwrap().lines, &nus);
    let column = |i: usize| tau[i];
    let ratio = (column(0) - column(2)) / (column(1) - column(2));
    println!(
        "60 MHz offset: retrieved/truth {} vs DAOD ratio {ratio}",
        p.retrieved / p.truth
    );
    assert!(
        (ratio - 1.0).abs() > 1e-3,
        "the offset must matter: {ratio}"
    );
    assert!(
        (p.retrieved / p.truth / ratio - 1.0).abs() < 1e-9,
        "{} vs {ratio}",
        p.retrieved / p.truth
    );
}

/// Same scene and seed, same products at any thread count (the noise draws are tied to the
/// realisation, the transport to its batches).
#[test]
fn retrievals_do_not_depend_on_the_thread_count() {
    let s = scene(&SCENE.replacen(
        "linewidth_fwhm_mhz = 30.0",
        "linewidth_fwhm_mhz = 30.0\nfrequency_jitter_rms_mhz = 0.3\npulse_energy_jitter_fraction = 0.05",
        1,
    ));
    let s = forced(&s);
    let at = |threads: usize| {
        let mut s = s.clone();
        s.simulation.photons = 20_000;
        s.simulation.threads = threads;
        pipeline::run(&s).expect("run").products
    };
    let (one, two) = (at(1), at(2));
    assert!(!one.is_empty());
    // Bit for bit (NaN-free here, so PartialEq is exact equality).
    assert!(
        one.iter()
            .all(|p| p.retrieved.is_finite() && p.simulated_error_averaged.is_finite())
    );
    assert_eq!(one, two);
}

/// Monte Carlo channel combinations: an on − off combination folded batch by batch has the
/// standard error that the separately folded on and off returns and their co-moment give
/// (var(a − b) = var a + var b − 2 cov(a, b)), also when combined afterwards bin by bin
/// (`Returns::combine`); cov(a, a − b) = var a − cov(a, b); an identity combination is the
/// channel.
#[test]
fn combined_channels_carry_consistent_errors_and_covariances() {
    use lidarsim::returns::Combination;
    let s = scene(&SCENE.replacen(
        "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0",
        "line_shape = \"monochromatic\"",
        1,
    ));
    let mut s = s;
    s.simulation.photons = 20_000;
    let atm = OpticalAtmosphere::build(&s).unwrap();
    let layout = TallyLayout {
        flux: false,
        combinations: vec![
            Combination {
                name: "on".into(),
                terms: vec![(0, 1.0)],
            },
            Combination {
                name: "off".into(),
                terms: vec![(1, 1.0)],
            },
            Combination {
                name: "diff".into(),
                terms: vec![(0, 1.0), (1, -1.0)],
            },
        ],
        combination_pairs: vec![(0, 1), (0, 2)],
    };
    let mc = transport::run(&s, &atm, &layout).unwrap();
    let c = mc.combined.as_ref().unwrap();
    let r = &mc.returns;
    assert_eq!(c.energy_j[..2 * c.bins_per_channel()], r.energy_j[..]);
    assert_eq!(c.stderr_j[..2 * c.bins_per_channel()], r.stderr_j[..]);
    // The same difference combined afterwards, bin by bin, through the on/off covariance.
    let after = c.combine(&[
        Combination {
            name: "diff".into(),
            terms: vec![(0, 1.0), (1, -1.0)],
        },
        Combination {
            name: "2on-off".into(),
            terms: vec![(0, 2.0), (1, -1.0)],
        },
    ]);
    let mut judged = 0;
    for g in 0..c.range_m.len() {
        for o in 0..c.orders.len() {
            let var_on = c.covariance_j2(0, 0, 0, g, o).unwrap();
            let var_off = c.covariance_j2(1, 1, 0, g, o).unwrap();
            let cov = c.covariance_j2(0, 1, 0, g, o).unwrap();
            let direct = c.covariance_j2(2, 2, 0, g, o).unwrap();
            let from_parts = var_on + var_off - 2.0 * cov;
            if direct > 0.0 {
                judged += 1;
                assert!(
                    (from_parts / direct - 1.0).abs() < 1e-6,
                    "gate {g} order {o}: {from_parts} vs {direct}"
                );
                let se = after.stderr_j[after.index(0, 0, g, o)];
                assert!(
                    (se * se / direct - 1.0).abs() < 1e-6,
                    "gate {g} order {o}: combined afterwards {} vs {direct}",
                    se * se
                );
                // Non-unit coefficients: var(2a − b) = 4 var a + var b − 4 cov(a, b).
                let se2 = after.stderr_j[after.index(1, 0, g, o)];
                let expect = 4.0 * var_on + var_off - 4.0 * cov;
                assert!(
                    (se2 * se2 / expect - 1.0).abs() < 1e-6,
                    "gate {g} order {o}: {} vs {expect}",
                    se2 * se2
                );
                // cov(on, on − off) = var(on) − cov(on, off): the second folded pair.
                let cov_on_diff = c.covariance_j2(0, 2, 0, g, o).unwrap();
                assert!(
                    (cov_on_diff - (var_on - cov)).abs() < 1e-6 * var_on.max(direct),
                    "gate {g} order {o}: {cov_on_diff} vs {}",
                    var_on - cov
                );
            }
        }
    }
    assert!(judged > 100, "{judged}");
    // A pair that was not folded is unknown, not zero.
    let g = (0..c.range_m.len())
        .find(|g| c.stderr_j[c.index(1, 0, *g, 0)] > 0.0)
        .unwrap();
    assert_eq!(c.covariance_j2(1, 2, 0, g, 0), None);
}

/// Multiple scattering in the retrieval: through a low water cloud (τ = 1, 200–400 m), the IPDA on single
/// scattering alone is unbiased, while all orders carry a path-length bias that grows with the
/// field of view.
#[test]
fn multiple_scattering_biases_ipda_more_at_wider_fields_of_view() {
    let s = scene(
        &SCENE
            .replacen("fov_full_angle_mrad = [0.2, 1.0]", "fov_full_angle_mrad = [0.2, 2.0, 10.0]", 1)
            .replacen(
                "[surface]",
                "[[layer]]\nname = \"cloud\"\nbase_m = 200.0\ntop_m = 400.0\nextinction_per_km = 5.0\nsingle_scattering_albedo = 1.0\nphase = { kind = \"table\", builtin = \"c1_cloud_1064nm\" }\n[surface]",
                1,
            )
            .replacen("dial_cell_m = 1000.0\n", "", 1),
    );
    let out = run(&s, 200_000);
    let mut biases = Vec::new();
    for fov in [0.2, 2.0, 10.0] {
        let single = out.products_of(
            Method::Ipda,
            Quantity::MixingRatio,
            Source::MonteCarlo,
            Order::Exactly(1),
            fov,
        )[0];
        let all = out.products_of(
            Method::Ipda,
            Quantity::MixingRatio,
            Source::MonteCarlo,
            Order::Total,
            fov,
        )[0];
        println!(
            "FOV {fov} mrad: XCO2 bias single scattering {:+.4} ± {:.4} ppm, all orders {:+.4} ± {:.4} ppm",
            single.bias(),
            single.mc_stderr,
            all.bias(),
            all.mc_stderr
        );
        assert!(
            single.bias().abs() < 4.0 * single.mc_stderr + 1e-3,
            "{}",
            single.bias()
        );
        biases.push((all.bias(), all.mc_stderr));
    }
    assert!(
        biases[2].0 > biases[0].0 + 4.0 * (biases[2].1 + biases[0].1),
        "{biases:?}"
    );
    assert!(biases[2].0 > 4.0 * biases[2].1, "{biases:?}");
}

/// A study re-pairs one retrieval set-up (`Retrieval::set_pair`): a pair must be two different
/// lines of the scene's, and its on-line must absorb more than its off-line.
#[test]
fn a_pair_is_two_different_lines_the_on_line_absorbing_more() {
    let mut r = pipeline::retrieval_setup(&scene(SCENE)).unwrap();
    for (on, off) in [(0, 0), (1, 1), (0, 2), (2, 1), (7, 9)] {
        let e = r.set_pair(on, off, "x".into()).unwrap_err();
        assert!(
            matches!(e, RetrievalError::Gas(_))
                && e.to_string().contains("is not two different lines of 2"),
            "({on}, {off}): {e}"
        );
    }
    let e = r.set_pair(1, 0, "off/on".into()).unwrap_err();
    assert!(matches!(e, RetrievalError::NotAbsorbing(_)), "{e}");
    r.set_pair(0, 1, "on/off".into()).unwrap();
}

/// Retrievals that cannot be done give one error naming the scene key.
#[test]
fn impossible_retrievals_name_the_scene_key() {
    let cases: &[(&str, &str, &str, &str, &str)] = &[
        (
            "no hard target in range",
            "end_m = 8100.0",
            "end_m = 7900.0",
            "retrieval.target",
            "no hard target in range",
        ),
        (
            "range cell shorter than a gate",
            "dial_cell_m = 1000.0",
            "dial_cell_m = 10.0",
            "retrieval.dial_cell_m",
            "shorter than a gate",
        ),
        (
            "on-line absorbing no more than the off-line",
            "on = ",
            "on = ",
            "retrieval.on",
            "absorbs no more than the off-line",
        ),
        (
            "target hidden: no signal",
            "[surface]",
            "[[layer]]\nname = \"fog\"\nbase_m = 0.0\ntop_m = 100.0\nextinction_per_m = 40.0\nsingle_scattering_albedo = 0.0\nphase = { kind = \"isotropic\" }\n[surface]",
            "retrieval.target",
            "SNR ≤ 0",
        ),
        (
            // Found by the scene fuzz: a positive but subnormal echo made the random error
            // infinite (`inf` in retrieval.csv, `null` in summary.json). Such pulses are now
            // refused at their key (the retrieval's own guard stays for library callers).
            "target signal too weak for a random error",
            "pulse_energy_j = 0.05",
            "pulse_energy_j = 1e-290",
            "laser.pulse_energy_j",
            "must lie in [1e-15, 1000]",
        ),
    ];
    for (what, from, to, key, words) in cases {
        let text = if *what == "on-line absorbing no more than the off-line" {
            SCENE.replacen("[retrieval]", "[retrieval]\non = \"off\"\noff = \"on\"", 1)
        } else {
            assert!(SCENE.contains(from), "{what}");
            SCENE.replacen(from, to, 1)
        };
        let result: Result<(), InputError> = Scene::from_toml(Path::new("bad.toml"), &text)
            .and_then(|mut s| {
                s.simulation.photons = 0;
                match pipeline::run(&s) {
                    Ok(_) => Ok(()),
                    Err(RunError::Input(e)) => Err(e),
                    Err(e) => panic!("{what}: {e}"),
                }
            });
        let e = result.expect_err(what);
        assert_eq!(e.field.as_deref(), Some(*key), "{what}: {e}");
        assert!(
            e.line.is_some() && e.to_string().contains(words),
            "{what}: {e}"
        );
        assert!(e.to_string().starts_with("bad.toml:"), "{what}: {e}");
    }
}

/// 1-based line of the first occurrence of `needle` in `text`.
fn line_of(text: &str, needle: &str) -> usize {
    let at = text
        .find(needle)
        .unwrap_or_else(|| panic!("`{needle}` not in the scene"));
    text[..at].matches('\n').count() + 1
}

/// Every malformed instrument or retrieval key gives one error naming the file, the line and
/// the key (README, "Scene errors"). Each case: (what, replace, with, key, words, the text whose
/// line the error must name).
#[test]
fn malformed_instrument_and_retrieval_keys_name_file_line_and_key() {
    let cases: &[(&str, &str, &str, &str, &str, &str)] = &[
        (
            "unknown line shape",
            "line_shape = \"gaussian\"",
            "line_shape = \"voigt\"",
            "laser.line_shape",
            "is not a line shape",
            "line_shape =",
        ),
        (
            "line width missing",
            "\nlinewidth_fwhm_mhz = 30.0",
            "",
            "laser.line_shape",
            "needs `linewidth_fwhm_mhz`",
            "line_shape =",
        ),
        (
            "negative line width",
            "linewidth_fwhm_mhz = 30.0",
            "linewidth_fwhm_mhz = -3.0",
            "laser.linewidth_fwhm_mhz",
            "must lie in (0,",
            "linewidth_fwhm_mhz",
        ),
        (
            "nodes out of range",
            "linewidth_fwhm_mhz = 30.0",
            "linewidth_fwhm_mhz = 30.0\nline_shape_nodes = 0",
            "laser.line_shape_nodes",
            "must lie in 1..=64",
            "line_shape_nodes",
        ),
        (
            "table without file",
            "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0",
            "line_shape = \"table\"",
            "laser.line_shape",
            "needs `line_shape_file`",
            "line_shape =",
        ),
        (
            "missing line-shape table",
            "line_shape = \"gaussian\"\nlinewidth_fwhm_mhz = 30.0",
            "line_shape = \"table\"\nline_shape_file = \"nope.csv\"",
            "laser.line_shape_file",
            "nope.csv",
            "line_shape_file",
        ),
        (
            "purity above 1",
            "linewidth_fwhm_mhz = 30.0",
            "linewidth_fwhm_mhz = 30.0\nspectral_purity = 1.5",
            "laser.spectral_purity",
            "must lie in (0, 1]",
            "spectral_purity",
        ),
        (
            "impure without impurity",
            "linewidth_fwhm_mhz = 30.0",
            "linewidth_fwhm_mhz = 30.0\nspectral_purity = 0.99",
            "laser.spectral_purity",
            "needs `impurity_wavenumber_cm1`",
            "spectral_purity",
        ),
        (
            "impurity without impurity",
            "linewidth_fwhm_mhz = 30.0",
            "linewidth_fwhm_mhz = 30.0\nimpurity_wavenumber_cm1 = 6350.0",
            "laser.impurity_wavenumber_cm1",
            "goes with `spectral_purity` below 1",
            "impurity_wavenumber_cm1",
        ),
        (
            "pulse energy twice",
            "telescope_diameter_m = 0.5",
            "telescope_diameter_m = 0.5\npulse_energy_j = 0.1",
            "lidar.pulse_energy_j",
            "goes there",
            "pulse_energy_j = 0.1",
        ),
        (
            "pulse energies per line",
            "pulse_energy_j = 0.05",
            "pulse_energy_j = [0.05, 0.05, 0.05]",
            "laser.pulse_energy_j",
            "has 3 values",
            "pulse_energy_j =",
        ),
        (
            "monitor error 1",
            "linewidth_fwhm_mhz = 30.0",
            "linewidth_fwhm_mhz = 30.0\nenergy_monitor_error_fraction = 1.0",
            "laser.energy_monitor_error_fraction",
            "must lie in [0, 1)",
            "energy_monitor_error_fraction",
        ),
        (
            "quantum efficiency 0",
            "quantum_efficiency = 0.8",
            "quantum_efficiency = 0.0",
            "receiver.quantum_efficiency",
            "must lie in [1e-9, 1]",
            "quantum_efficiency",
        ),
        (
            "two filter widths",
            "filter_bandwidth_ghz = 1.0",
            "filter_bandwidth_ghz = 1.0\nfilter_bandwidth_nm = 1.0",
            "receiver.filter_bandwidth_ghz",
            "not both",
            "filter_bandwidth_ghz",
        ),
        (
            "gain below 1",
            "gain = 10.0",
            "gain = 0.5",
            "receiver.gain",
            "must lie in [1, 1e8]",
            "gain =",
        ),
        (
            "NEP without bandwidth",
            "\nbandwidth_mhz = 10.0",
            "",
            "receiver",
            "bandwidth_mhz",
            "[receiver]",
        ),
        (
            "background without a filter",
            "filter_bandwidth_ghz = 1.0\n",
            "",
            "background",
            "filter's width",
            "[background]",
        ),
        (
            "unknown gas",
            "[retrieval]",
            "[retrieval]\ngas = \"XYZ\"",
            "retrieval.gas",
            "not a HITRAN molecule",
            "gas = \"XYZ\"",
        ),
        (
            "gas without lines",
            "[retrieval]",
            "[retrieval]\ngas = \"H2O\"",
            "retrieval.gas",
            "has no H2O lines",
            "gas = \"H2O\"",
        ),
        (
            "unknown channel",
            "[retrieval]",
            "[retrieval]\non = \"nope\"",
            "retrieval.on",
            "no channel named `nope`",
            "on = \"nope\"",
        ),
        (
            "no receiver",
            "[receiver]\nfilter_bandwidth_ghz = 1.0\nfilter_transmission = 0.8\nquantum_efficiency = 0.8\ngain = 10.0\nionization_ratio = 0.45\nnep_w_per_sqrt_hz = 4.0e-14\nbandwidth_mhz = 10.0\n",
            "",
            "retrieval",
            "needs a [receiver]",
            "[retrieval]",
        ),
        (
            "two averagings",
            "averaging_shots = 2000",
            "averaging_shots = 2000\naveraging_length_km = 10.0\nplatform_speed_m_per_s = 200.0",
            "retrieval.averaging_shots",
            "not both",
            "averaging_shots",
        ),
        (
            "no averaging",
            "averaging_shots = 2000\n",
            "",
            "retrieval",
            "needs `averaging_shots`",
            "[retrieval]",
        ),
        (
            "cell not whole gates",
            "dial_cell_m = 1000.0",
            "dial_cell_m = 1030.0",
            "retrieval.dial_cell_m",
            "not a whole number",
            "dial_cell_m",
        ),
        (
            "unknown target",
            "target = \"surface\"",
            "target = \"cirrus\"",
            "retrieval.target",
            "neither `surface` nor a layer",
            "target =",
        ),
        (
            "too few realisations",
            "realisations = 200",
            "realisations = 5",
            "retrieval.realisations",
            "must lie in 10..=1000000",
            "realisations",
        ),
        (
            "nothing to retrieve",
            "target = \"surface\"\ndial_cell_m = 1000.0\n",
            "",
            "retrieval.target",
            "nothing to retrieve",
            "[retrieval]",
        ),
    ];
    let mut failures = Vec::new();
    for (what, from, to, key, words, at) in cases {
        assert!(SCENE.contains(from), "{what}: `{from}` is not in the scene");
        let mut text = SCENE.replacen(from, to, 1);
        if *what == "nothing to retrieve" {
            // Move the surface out of the gates so that no target is found by default either.
            text = text.replacen("end_m = 8100.0", "end_m = 7900.0", 1);
        }
        if *what == "background without a filter" {
            text = text.replacen(
                "[gates]",
                "[background]\nradiance_w_per_m2_sr_um = 10.0\n[gates]",
                1,
            );
        }
        let line = line_of(&text, at);
        match Scene::from_toml(Path::new("bad.toml"), &text) {
            Ok(_) => failures.push(format!("{what}: accepted")),
            Err(e) => {
                let shown = e.to_string();
                if !(e.field.as_deref() == Some(*key)
                    && e.line == Some(line)
                    && shown.contains(words)
                    && shown.starts_with(&format!("bad.toml:{line}: `{key}`")))
                {
                    failures.push(format!(
                        "{what}: got `{shown}` (expected line {line}, key {key})"
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}
