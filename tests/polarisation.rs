//! Polarised transport: exact checks of the co- and cross-polarised returns
//! and the depolarisation ratio.

use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::returns::Order;
use lidarsim::transport::McResult;

use crate::transport::{edited, run, scene_text};

/// A ground lidar looking up, polarisation `POL`, fields of view `FOV`, divergence `DIV`.
const LIDAR: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = DIV
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = FOV
polarisation = "POL"
"#;

/// [`LIDAR`] followed by `rest`.
fn lidar(pol: &str, fov: &str, div: &str, rest: &str) -> String {
    LIDAR
        .replace("POL", pol)
        .replace("FOV", fov)
        .replace("DIV", div)
        + rest
}

/// At 355 nm, gates 500–3000 m; the medium `BODY` follows, and up to order 2 is traced.
const AT_355: &str = r#"
[[channel]]
name = "355"
wavelength_nm = 355.0
[gates]
start_m = 500.0
end_m = 3000.0
width_m = 250.0
BODY
[simulation]
max_order = 2
multiple_scattering = "always"
"#;

fn lidar_355(pol: &str, fov: &str, div: &str, body: &str) -> String {
    lidar(pol, fov, div, &AT_355.replace("BODY", body))
}

/// [`lidar_355`] through Rayleigh air (US standard atmosphere), then `extra` (an optional HG
/// cloud).
fn air(pol: &str, fov: &str, div: &str, extra: &str) -> String {
    let body =
        format!("[atmosphere]\nstandard = \"us_standard\"\nlayer_thickness_m = 100.0\n{extra}");
    lidar_355(pol, fov, div, &body)
}

/// The Rayleigh depolarisation factor ρ of the scene's air at channel 0, read back from the
/// scalar phase function's P(0)/P(90°) = 2/(1 + ρ)·… : P(μ) ∝ (1 + ρ) + (1 − ρ)μ² (Bucholtz
/// 1995, eq. 12 with γ = ρ/(2 − ρ)), so P(1)/P(0) = 2/(1 + ρ).
fn rho_of(atm: &OpticalAtmosphere) -> f64 {
    let p = atm
        .phases
        .iter()
        .find(|p| matches!(***p, lidarsim::particles::phase::PhaseFunction::Rayleigh(_)))
        .expect("molecules");
    2.0 * p.eval(0.0) / p.eval(1.0) - 1.0
}

/// δ of one bin of a polarised Monte Carlo run, and its standard error (first order, with the
/// covariance of co and cross).
fn mc_delta(r: &McResult, f: usize, g: usize, order: Order) -> (f64, f64) {
    let p = &r.polarised.as_ref().expect("polarised run").channels;
    let o = p.co.order_index(order).unwrap();
    let i = p.co.index(0, f, g, o);
    let (c, x) = (p.co.energy_j[i], p.cross.energy_j[i]);
    let (sc, sx) = (p.co.stderr_j[i], p.cross.stderr_j[i]);
    let d = x / c;
    let rel = (sc / c).powi(2) + (sx / x).powi(2) - 2.0 * p.cov_j2[i] / (c * x);
    (d, d * rel.max(0.0).sqrt())
}

/// (b) Single backscatter by air depolarises δ = ρ/(2 − ρ) (Behrendt & Nakamura 2002, Opt.
/// Express 10, 805; from the Rayleigh scattering matrix of Hansen & Travis 1974): the analytic
/// returns to 1e-9 in every gate and field of view, the Monte Carlo's order 1 within 3 of its
/// standard errors (exactly, in fact: on a pencil beam every order-1 estimate is a backscatter
/// at 180°).
#[test]
fn single_backscatter_by_air_depolarises_rho_over_two_minus_rho() {
    let scene = scene_text(&air("linear", "[1.0, 20.0]", "0.0", ""));
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let rho = rho_of(&atm);
    let expected = rho / (2.0 - rho);
    // Bucholtz's ρ at 355 nm is about 0.03; δ about 0.0153.
    assert!((0.01..0.02).contains(&expected), "δ {expected}");
    let (co, cross) = lidar_eq::single_scatter_polarised(&scene, &atm).unwrap();
    let total = lidar_eq::single_scatter(&scene, &atm);
    for f in 0..2 {
        for g in 0..total.range_m.len() {
            let i = co.index(0, f, g, 0);
            assert!(
                (cross.energy_j[i] / co.energy_j[i] - expected).abs() < 1e-9 * expected,
                "analytic FOV {f} gate {g}"
            );
            let sum = co.energy_j[i] + cross.energy_j[i];
            assert!((sum - total.energy_j[i]).abs() < 1e-12 * total.energy_j[i]);
        }
    }
    let r = run(&scene, 20_000, |_| {});
    for f in 0..2 {
        for g in 0..total.range_m.len() {
            let (d, se) = mc_delta(&r, f, g, Order::Exactly(1));
            assert!(
                (d - expected).abs() <= 3.0 * se + 1e-12,
                "MC FOV {f} gate {g}: {d} ± {se} against {expected}"
            );
        }
    }
}

/// A layer of non-depolarising dipoles (Rayleigh phase matrix with ρ = 0, extinction
/// 0.5 km⁻¹ over 3 km: multiple scattering a few per cent) and no other air, for [`lidar_355`].
const DIPOLES: &str = r#"
[[layer]]
name = "dipoles"
base_m = 0.0
top_m = 3000.0
extinction_per_km = 0.5
single_scattering_albedo = 1.0
phase = { kind = "rayleigh", depolarization_factor = 0.0 }
"#;

/// (d) With a uniform beam whose divergence equals the field of view, source and receiver are
/// reciprocal; for a medium whose scatterers' Jones matrices are symmetric in backscattering
/// (spheres, non-depolarising dipoles) the whole return's backscattering matrix then has
/// F₄₄ = F₁₁ − 2F₂₂ after the axial average, so δ_C = 2δ_L/(1 − δ_L) in every gate and order
/// (Mishchenko & Hovenier 1995, Opt. Lett. 20, 1356; `docs/transport.md`, "Polarisation").
/// Two independent runs, compared within 3 combined standard errors (orders 2 and 3+, where
/// the depolarisation comes from, and the total).
#[test]
fn circular_and_linear_depolarisation_obey_mishchenko_hovenier() {
    let scene = |pol: &str| scene_text(&lidar_355(pol, "20.0", "20.0", DIPOLES));
    let lin = run(&scene("linear"), 100_000, |_| {});
    let circ = run(&scene("circular"), 100_000, |o| o.sim.seed = 2);
    let orders = [Order::Exactly(2), Order::AtLeast(3), Order::Total];
    let judged = assert_mishchenko_hovenier(&lin, &circ, &orders);
    assert!(judged >= 15, "{judged}");
}

/// Compares δ_C with 2δ_L/(1 − δ_L) within 3 combined standard errors in every gate and
/// order both runs resolve to 10 %; returns how many bins were judged.
fn assert_mishchenko_hovenier(lin: &McResult, circ: &McResult, orders: &[Order]) -> usize {
    let mut judged = 0;
    for g in 0..lin.returns.range_m.len() {
        for &order in orders {
            let (dl, sl) = mc_delta(lin, 0, g, order);
            let (dc, sc) = mc_delta(circ, 0, g, order);
            if !(dl > 0.0 && sl < 0.1 * dl && sc < 0.1 * dc) {
                continue;
            }
            judged += 1;
            let predicted = 2.0 * dl / (1.0 - dl);
            let s_pred = 2.0 * sl / (1.0 - dl).powi(2);
            assert!(
                (dc - predicted).abs() <= 3.0 * (sc * sc + s_pred * s_pred).sqrt(),
                "gate {g} {order:?}: δ_C {dc} ± {sc}, 2δ_L/(1 − δ_L) {predicted} ± {s_pred}"
            );
        }
    }
    judged
}

/// An HG cloud (g = 0.8) 1500–1700 m, optical depth 1, for [`air`].
const HG_CLOUD: &str = r#"
[[layer]]
name = "cloud"
base_m = 1500.0
top_m = 1700.0
extinction_per_km = 5.0
single_scattering_albedo = 0.99
phase = { kind = "henyey_greenstein", g = 0.8 }
"#;

/// (e) A polarised run's intensity is the scalar run's where polarisation cannot change it:
/// through Henyey-Greenstein scatterers, which stand in as non-depolarising matrices, co +
/// cross of a linearly polarised run equals the unpolarised run's total of the same seed in
/// every bin (to rounding: the same random numbers, and the matrix weight (F₁₁ + F₁₂q)/F₁₁ is 1).
/// So too with a second channel that scatters a little more (5.5 against 5 km⁻¹, one
/// scattering class): its ALIS ratio (σ_1/σ_0) e^{−(τ_1 − τ_0)} takes the polarised paths of the
/// crossing estimate (the 20 mrad field of view) as it takes the scalar ones.
/// Through air it does not beyond single scattering: a polarised source changes the intensity
/// of multiply scattered light (Mishchenko, Lacis & Travis 1994, JQSRT 51, 491), order 2 of
/// the air in these scenes by +15 to +20 % (`docs/transport.md`, "Polarisation").
#[test]
fn polarised_intensity_equals_the_scalar_run_through_non_depolarising_scatterers() {
    let no_air = |pol: &str| {
        air(pol, "[1.0, 20.0]", "0.5", HG_CLOUD).replace(
            "layer_thickness_m = 100.0",
            "layer_thickness_m = 100.0\nrayleigh = false",
        )
    };
    let two_channels = |pol: &str| {
        edited(
            &no_air(pol),
            &[
                (
                    "[[channel]]\nname = \"355\"\nwavelength_nm = 355.0\n",
                    "[[channel]]\nname = \"355\"\nwavelength_nm = 355.0\n\
                     [[channel]]\nname = \"355b\"\nwavelength_nm = 355.0\n",
                ),
                ("extinction_per_km = 5.0", "extinction_per_km = [5.0, 5.5]"),
            ],
        )
    };
    for (what, text) in [
        ("one channel", &no_air as &dyn Fn(&str) -> String),
        ("two channels", &two_channels),
    ] {
        let scalar = run(&scene_text(&text("none")), 20_000, |_| {});
        let pol = run(&scene_text(&text("linear")), 20_000, |_| {});
        assert!(scalar.polarised.is_none());
        let (a, b) = (&scalar.returns, &pol.returns);
        let mut nonzero = 0;
        for (i, (x, y)) in a.energy_j.iter().zip(&b.energy_j).enumerate() {
            assert!(
                (x - y).abs() <= 1e-12 * x.abs().max(1e-300),
                "{what}: bin {i}: scalar {x:e}, polarised {y:e}"
            );
            nonzero += usize::from(*x > 0.0);
        }
        assert!(nonzero >= 16 * a.channels.len(), "{what}: {nonzero}");
        let p = &pol.polarised.as_ref().unwrap().channels;
        for i in 0..b.energy_j.len() {
            let sum = p.co.energy_j[i] + p.cross.energy_j[i];
            assert!((sum - b.energy_j[i]).abs() <= 1e-12 * b.energy_j[i].abs().max(1e-300));
        }
    }
}

/// An unknown `polarisation` is refused with the file, line and key.
#[test]
fn unknown_polarisation_is_refused() {
    let text = air("elliptical", "1.0", "0.0", "");
    let err = lidarsim::scene::Scene::from_toml(std::path::Path::new("p.toml"), &text)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("p.toml") && err.contains("polarisation") && err.contains("elliptical"),
        "{err}"
    );
}

/// At 532 nm, a small-droplet water cloud (log-normal, median radius 1 µm: spheres by Mie),
/// no air, for [`LIDAR`].
const SPHERES: &str = r#"
[[channel]]
name = "532"
wavelength_nm = 532.0
[gates]
start_m = 900.0
end_m = 1400.0
width_m = 25.0
[[layer]]
name = "droplets"
base_m = 1000.0
top_m = 1200.0
extinction_per_km = 10.0
particles = { distribution = "lognormal", median_radius_um = 1.0, sigma_g = 1.5, refractive_index = "1.337+1.8e-9i" }
[simulation]
max_order = 3
multiple_scattering = "always"
"#;

fn spheres(pol: &str, fov: &str, div: &str) -> lidarsim::scene::Scene {
    scene_text(&lidar(pol, fov, div, SPHERES))
}

/// (a) Single backscatter by spheres does not depolarise: the order-1 cross-polarised return
/// is 0 in every gate and field of view, analytic and Monte Carlo, for linear and circular
/// light (F22 = F11 and F44 = F33 = −F11 at 180° for spheres). Multiple scattering then
/// depolarises: δ of order 2 is positive.
#[test]
fn single_backscatter_by_spheres_does_not_depolarise() {
    for pol in ["linear", "circular"] {
        let scene = spheres(pol, "[1.0, 10.0]", "0.0");
        let atm = OpticalAtmosphere::build(&scene).unwrap();
        let (co, cross) = lidar_eq::single_scatter_polarised(&scene, &atm).unwrap();
        let r = run(&scene, 20_000, |_| {});
        let p = &r.polarised.as_ref().unwrap().channels;
        let o1 = p.co.order_index(Order::Exactly(1)).unwrap();
        let mut lit = 0;
        for f in 0..2 {
            for g in 0..co.range_m.len() {
                let i = co.index(0, f, g, 0);
                assert!(
                    cross.energy_j[i].abs() <= 1e-12 * co.energy_j[i],
                    "{pol} analytic"
                );
                let j = p.co.index(0, f, g, o1);
                assert!(
                    p.cross.energy_j[j].abs() <= 1e-12 * p.co.energy_j[j].max(1e-300),
                    "{pol} MC FOV {f} gate {g}: co {:e} cross {:e}",
                    p.co.energy_j[j],
                    p.cross.energy_j[j]
                );
                lit += usize::from(p.co.energy_j[j] > 0.0);
            }
        }
        assert!(lit >= 10, "{pol}: {lit}");
        let (d2, s2) = mc_delta(&r, 1, 8, Order::Exactly(2));
        assert!(d2 > 5.0 * s2, "{pol}: order-2 δ {d2} ± {s2}");
    }
}

/// (d) for spheres: with a uniform beam as wide as the field of view, δ_C = 2δ_L/(1 − δ_L) in
/// every gate and order the two runs resolve (Mishchenko & Hovenier 1995): spheres' Jones
/// matrices are diagonal in their scattering planes, so every path's is symmetric in
/// backscattering (`docs/transport.md`, "Polarisation").
#[test]
fn spheres_obey_mishchenko_hovenier() {
    let lin = run(&spheres("linear", "10.0", "10.0"), 40_000, |_| {});
    let circ = run(&spheres("circular", "10.0", "10.0"), 40_000, |o| {
        o.sim.seed = 2
    });
    let orders = [Order::Exactly(2), Order::Exactly(3), Order::Total];
    let judged = assert_mishchenko_hovenier(&lin, &circ, &orders);
    assert!(judged >= 10, "{judged}");
}

/// (c) A tabulated matrix of non-spherical particles: the order-1 δ_L is
/// (F11 − F22)/(F11 + F22) at 180°, analytic to 1e-9 and Monte Carlo (exact here, all order-1
/// estimates being backscatter). The table (isotropic F11, F22 = 0.5, F33 = F44 = 0.5 cos Θ)
/// gives 1/3; with circular light (F11 + F44)/(F11 − F44) = 1/3 too. A linear-only table is
/// refused for a circular source, naming the key and the file.
#[test]
fn tabulated_matrix_backscatter_depolarises_as_its_elements() {
    let dir = tempfile::tempdir().unwrap();
    let mut t = String::from(
        "# wavelength_nm = 532\n# refractive_index = none\n# distribution = none\ntheta_deg,F11,F22,F33,F44,F12,F34\n",
    );
    let mut lin = String::from(
        "# wavelength_nm = 532\n# refractive_index = none\n# distribution = none\ntheta_deg,F11,F22,F33,F12\n",
    );
    for i in 0..=180 {
        let c = (i as f64).to_radians().cos();
        t.push_str(&format!("{i},1,0.5,{},{},0,0\n", 0.5 * c, 0.5 * c));
        lin.push_str(&format!("{i},1,0.5,{},0\n", 0.5 * c));
    }
    std::fs::write(dir.path().join("m.csv"), t).unwrap();
    std::fs::write(dir.path().join("lin.csv"), lin).unwrap();
    let text = |pol: &str, file: &str| {
        lidar(pol, "[1.0, 10.0]", "0.0", SPHERES).replace(
                r#"particles = { distribution = "lognormal", median_radius_um = 1.0, sigma_g = 1.5, refractive_index = "1.337+1.8e-9i" }"#,
                &format!("single_scattering_albedo = 1.0\nphase = {{ kind = \"matrix_table\", file = \"{file}\" }}"),
            )
    };
    for pol in ["linear", "circular"] {
        let path = dir.path().join(format!("{pol}.toml"));
        let scene = lidarsim::scene::Scene::from_toml(&path, &text(pol, "m.csv")).unwrap();
        let atm = OpticalAtmosphere::build(&scene).unwrap();
        let (co, cross) = lidar_eq::single_scatter_polarised(&scene, &atm).unwrap();
        let expected = 1.0 / 3.0;
        let mut lit = 0;
        for i in 0..co.energy_j.len() {
            if co.energy_j[i] > 0.0 {
                lit += 1;
                assert!((cross.energy_j[i] / co.energy_j[i] - expected).abs() < 1e-9);
            }
        }
        assert!(lit >= 10);
        let r = run(&scene, 10_000, |_| {});
        let (d, se) = mc_delta(&r, 0, 6, Order::Exactly(1));
        assert!(
            (d - expected).abs() <= 3.0 * se + 1e-12,
            "{pol}: {d} ± {se}"
        );
    }
    let path = dir.path().join("c.toml");
    let err = lidarsim::scene::Scene::from_toml(&path, &text("circular", "lin.csv"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("c.toml") && err.contains("phase") && err.contains("lin.csv"),
        "{err}"
    );
    // The same linear-only table serves a linear source.
    lidarsim::scene::Scene::from_toml(&path, &text("linear", "lin.csv")).unwrap();
}

/// Each channel keeps its own polarisation: a run with 532 and 1064 nm together (the droplets'
/// matrices differ between them, and so does their scattering) gives each channel's co- and
/// cross-polarised returns as a run of that channel alone, within 4.5 combined standard errors
/// wherever both resolve a bin to 10 %.
#[test]
fn channels_at_two_wavelengths_keep_their_own_polarisation() {
    let two = SPHERES.replace(
        "[[channel]]\nname = \"532\"\nwavelength_nm = 532.0",
        "[[channel]]\nname = \"532\"\nwavelength_nm = 532.0\n[[channel]]\nname = \"1064\"\nwavelength_nm = 1064.0",
    );
    let one_1064 = SPHERES.replace(
        "name = \"532\"\nwavelength_nm = 532.0",
        "name = \"1064\"\nwavelength_nm = 1064.0",
    );
    // The amount as a number density: an extinction would be that of the first channel.
    let text = |t: &str| {
        scene_text(&lidar("linear", "[1.0, 10.0]", "0.0", t).replace(
            "extinction_per_km = 10.0",
            "number_density_per_cm3 = 1000.0",
        ))
    };
    let both = run(&text(&two), 40_000, |_| {});
    let alone = [
        run(&text(SPHERES), 40_000, |o| o.sim.seed = 3),
        run(&text(&one_1064), 40_000, |o| o.sim.seed = 4),
    ];
    let pb = &both.polarised.as_ref().unwrap().channels;
    let mut judged = 0;
    for (k, single) in alone.iter().enumerate() {
        let ps = &single.polarised.as_ref().unwrap().channels;
        for (a, b) in [(&pb.co, &ps.co), (&pb.cross, &ps.cross)] {
            let bins = b.bins_per_channel();
            for i in 0..bins {
                let (x, sx) = (a.energy_j[k * bins + i], a.stderr_j[k * bins + i]);
                let (y, sy) = (b.energy_j[i], b.stderr_j[i]);
                if !(sx < 0.1 * x && sy < 0.1 * y) {
                    continue;
                }
                judged += 1;
                assert!(
                    (x - y).abs() <= 4.5 * (sx * sx + sy * sy).sqrt(),
                    "channel {k} bin {i}: together {x:e} ± {sx:e}, alone {y:e} ± {sy:e}"
                );
            }
        }
    }
    assert!(judged >= 40, "{judged}");
}

/// (e) for droplets: co + cross of a linearly polarised run through a cloud of spheres equals
/// the scalar run of the same seed within 3 standard errors in every bin both resolve to 5 %
/// (droplets' forward peak and glory hardly polarise: in validation/polarisation the C.1 cloud
/// at 532 nm gives orders ≥ 2 within 0.5 % of the scalar run, rms z 0.9–1.0).
#[test]
fn polarised_intensity_through_droplets_is_the_scalar_run_within_its_error() {
    let scalar = run(&spheres("none", "[1.0, 10.0]", "0.0"), 20_000, |_| {});
    let pol = run(&spheres("linear", "[1.0, 10.0]", "0.0"), 20_000, |_| {});
    let (a, b) = (&scalar.returns, &pol.returns);
    let mut judged = 0;
    for i in 0..a.energy_j.len() {
        let (x, sx, y, sy) = (a.energy_j[i], a.stderr_j[i], b.energy_j[i], b.stderr_j[i]);
        if !(sx < 0.05 * x && sy < 0.05 * y) {
            continue;
        }
        judged += 1;
        assert!(
            (x - y).abs() <= 3.0 * sx.max(sy),
            "bin {i}: scalar {x:e} ± {sx:e}, polarised {y:e} ± {sy:e}"
        );
    }
    assert!(judged >= 40, "{judged}");
}

/// A Lambertian surface depolarises completely: seen from 3 km above, with no atmosphere (the
/// surface alone returns light), a linearly polarised lidar's surface return is as strong
/// cross-polarised as co-polarised (δ = 1) in every channel, field of view and gate, and their
/// sum is the whole return.
#[test]
fn a_lambertian_surface_depolarises_completely() {
    let text = lidar(
        "linear",
        "[1.0, 4.0]",
        "0.5",
        r#"
[[channel]]
name = "532"
wavelength_nm = 532.0
[[channel]]
name = "1064"
wavelength_nm = 1064.0
[gates]
start_m = 2900.0
end_m = 3100.0
width_m = 20.0
[surface]
altitude_m = 0.0
albedo = [0.3, 0.5]
"#,
    );
    let text = edited(
        &text,
        &[(
            "altitude_m = 0.0\nzenith_angle_deg = 0.0",
            "altitude_m = 3000.0\nzenith_angle_deg = 180.0",
        )],
    );
    let mc = run(&scene_text(&text), 2_000, |_| {});
    let p = &mc.polarised.as_ref().unwrap().channels;
    let total = &mc.returns;
    let mut lit = 0;
    for i in 0..total.energy_j.len() {
        let (co, cross) = (p.co.energy_j[i], p.cross.energy_j[i]);
        assert!(
            (co - cross).abs() <= 1e-12 * co,
            "bin {i}: co {co:e}, cross {cross:e}"
        );
        assert!((co + cross - total.energy_j[i]).abs() <= 1e-12 * total.energy_j[i]);
        lit += usize::from(co > 0.0);
    }
    assert!(lit >= 4, "{lit} bins with a return");
}

/// Channel combinations of a polarised run (laser line-shape samples are combined so): an
/// identity combination is its channel, co- and cross-polarised returns and their covariance
/// included, and an on − off combination folded batch by batch has the variance its parts and
/// their co-moment give, var(a − b) = var a + var b − 2 cov(a, b). Two channels, so that the
/// second channel's and the second combination's places in the accumulator are exercised
/// (with one, an index k and −k coincide).
#[test]
fn polarised_combinations_carry_their_channels_returns_and_covariances() {
    use lidarsim::returns::Combination;
    let two = SPHERES.replace(
        "[[channel]]\nname = \"532\"\nwavelength_nm = 532.0",
        "[[channel]]\nname = \"532\"\nwavelength_nm = 532.0\n[[channel]]\nname = \"1064\"\nwavelength_nm = 1064.0",
    );
    let text = scene_text(&lidar("linear", "[1.0, 10.0]", "0.0", &two).replace(
        "extinction_per_km = 10.0",
        "number_density_per_cm3 = 1000.0",
    ));
    let combination = |name: &str, terms: Vec<(usize, f64)>| Combination {
        name: name.into(),
        terms,
    };
    let mc = run(&text, 20_000, |o| {
        o.layout.combinations = vec![
            combination("on", vec![(0, 1.0)]),
            combination("off", vec![(1, 1.0)]),
            combination("diff", vec![(0, 1.0), (1, -1.0)]),
        ];
        o.layout.combination_pairs = vec![(0, 1), (0, 2)];
    });
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs());
    let pol = mc.polarised.as_ref().expect("polarised run");
    let (ch, cb) = (&pol.channels, pol.combined.as_ref().expect("combinations"));
    let totals = mc.combined.as_ref().expect("combinations");
    let bins = ch.co.bins_per_channel();
    let mut covariances = 0;
    for k in 0..2 {
        for i in 0..bins {
            let j = k * bins + i;
            for (a, b) in [(&ch.co, &cb.co), (&ch.cross, &cb.cross)] {
                assert!(close(a.energy_j[j], b.energy_j[j]), "channel {k} bin {i}");
                assert!(close(a.stderr_j[j], b.stderr_j[j]), "channel {k} bin {i}");
            }
            assert!(
                close(mc.returns.energy_j[j], totals.energy_j[j])
                    && close(mc.returns.stderr_j[j], totals.stderr_j[j]),
                "channel {k} bin {i}: total"
            );
            assert!(
                close(ch.cov_j2[j], cb.cov_j2[j]),
                "channel {k} bin {i}: cov(co, cross) {:e} against the combination's {:e}",
                ch.cov_j2[j],
                cb.cov_j2[j]
            );
            covariances += usize::from(ch.cov_j2[j] != 0.0);
        }
    }
    let mut judged = 0;
    for f in 0..totals.fov_full_angle_mrad.len() {
        for g in 0..totals.range_m.len() {
            for o in 0..totals.orders.len() {
                let var_on = totals.covariance_j2(0, 0, f, g, o).unwrap();
                let var_off = totals.covariance_j2(1, 1, f, g, o).unwrap();
                let cov = totals.covariance_j2(0, 1, f, g, o).unwrap();
                let se = totals.stderr_j[totals.index(2, f, g, o)];
                if se > 0.0 && cov != 0.0 {
                    judged += 1;
                    let from_parts = var_on + var_off - 2.0 * cov;
                    assert!(
                        (from_parts / (se * se) - 1.0).abs() < 1e-6,
                        "fov {f} gate {g} order {o}: {from_parts:e} against {:e}",
                        se * se
                    );
                }
            }
        }
    }
    assert!(covariances >= 20 && judged >= 20, "{covariances} {judged}");
}

/// Single scattering of a polarised run where air and cloud share layers (two scatterers in a
/// layer: the scattering matrix is their mixture, weighted by their shares of the layer's
/// scattering): co + cross of order 1 equals the lidar equation, in every gate of the air and
/// the cloud resolved to 10 % (within the shared tolerance of `check_order1`).
#[test]
fn polarised_single_scattering_through_air_and_cloud_is_the_lidar_equation() {
    let scene = scene_text(&air("linear", "[1.0, 20.0]", "0.0", HG_CLOUD));
    let mc = run(&scene, 40_000, |_| {});
    let (judged, with_signal) = crate::transport::check_order1(
        "air and cloud, linear",
        &mc.returns,
        &crate::transport::analytic(&scene),
    );
    assert!(
        judged >= 16 && with_signal >= 20,
        "{judged} of {with_signal}"
    );
}

/// (d) again where two kinds of scatterer share layers: non-depolarising dipoles through 3 km
/// and a layer of spheres inside them, whose scattering matrix is then the two's mixture
/// weighted by their shares of the scattering. Both kinds have Jones matrices symmetric in
/// backscattering, so their mixture obeys δ_C = 2δ_L/(1 − δ_L) too (Mishchenko & Hovenier
/// 1995), in orders 2 and 3+ and the total.
#[test]
fn dipoles_mixed_with_spheres_obey_mishchenko_hovenier() {
    let spheres = r#"
[[layer]]
name = "spheres"
base_m = 1000.0
top_m = 1200.0
extinction_per_km = 2.0
particles = { distribution = "lognormal", median_radius_um = 0.3, sigma_g = 1.5, refractive_index = "1.45+0.0i" }
"#;
    let body = format!("{DIPOLES}{spheres}");
    let scene = |pol: &str| scene_text(&lidar_355(pol, "20.0", "20.0", &body));
    let lin = run(&scene("linear"), 100_000, |_| {});
    let circ = run(&scene("circular"), 100_000, |o| o.sim.seed = 2);
    let orders = [Order::Exactly(2), Order::AtLeast(3), Order::Total];
    let judged = assert_mishchenko_hovenier(&lin, &circ, &orders);
    assert!(judged >= 15, "{judged}");
}
