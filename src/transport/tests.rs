use super::setup::{backward_max, forward_half_width, scatter_classes, similar_phase};
use super::*;
use crate::particles::phase::{HenyeyGreenstein, PhaseFunction};
use crate::transport::testing::{CLOUD, edited, with_setup};

/// [`CLOUD`]'s lidar with a second channel "b" at 1064 nm, over layers `(base_m, top_m)`
/// of extinctions `[a, b]` km⁻¹ and HG asymmetries `[g_a, g_b]` in the two channels, no air.
fn two_channel_scene(layers: &[(f64, f64)], ext: [f64; 2], g: [f64; 2]) -> String {
    let head = CLOUD.split("[[layer]]").next().unwrap_or_default();
    let mut text = edited(
        head,
        &[(
            "wavelength_nm = 1064.0\n",
            "wavelength_nm = 1064.0\n[[channel]]\nname = \"b\"\nwavelength_nm = 1064.0\n",
        )],
    );
    for (i, (base, top)) in layers.iter().enumerate() {
        text += &format!(
            "[[layer]]\nname = \"l{i}\"\nbase_m = {base}\ntop_m = {top}\n\
             extinction_per_km = [{}, {}]\nsingle_scattering_albedo = 1.0\n\
             phase = [{{ kind = \"henyey_greenstein\", g = {} }}, \
             {{ kind = \"henyey_greenstein\", g = {} }}]\n",
            ext[0], ext[1], g[0], g[1]
        );
    }
    text
}

/// Where a collision lands (`Setup::altitude_at_tau`), by its documented rule at the ties:
/// a target optical depth exactly on a layer edge is in the layer above going up (the last
/// edge at or below it) and in the layer below going down (the last edge strictly below);
/// at the column's very top it is in the top layer (capped), whatever layer the flight
/// starts in (`hint`, checked first). Three layers of optical depth 0.5 (cumulative 0,
/// 0.5, 1, 1.5), so every target is exact.
#[test]
fn collisions_on_layer_edges_land_by_the_documented_rule() {
    let three = [(1000.0, 2000.0), (2000.0, 3000.0), (3000.0, 4000.0)];
    with_setup(
        &two_channel_scene(&three, [0.5, 0.5], [0.5, 0.5]),
        |s, atm| {
            let cum = &s.classes[0].cum;
            let e = &atm.edges_m;
            let n = cum.len() - 1;
            assert_eq!(n, 3);
            for hint in [0, 1, 2, n] {
                // Up from the bottom to edge 2: layer 2, at its base.
                assert_eq!(
                    s.altitude_at_tau(0, cum[0], 1.0, cum[2], hint),
                    (e[2], 2),
                    "{hint}"
                );
                // Down from the top to edge 2: layer 1, at its top.
                let tau = cum[n] - cum[2];
                assert_eq!(
                    s.altitude_at_tau(0, cum[n], -1.0, tau, hint),
                    (e[2], 1),
                    "{hint}"
                );
                // Up to the very top: the top layer.
                assert_eq!(
                    s.altitude_at_tau(0, cum[0], 1.0, cum[n], hint),
                    (e[n], n - 1),
                    "{hint}"
                );
            }
        },
    );
}

/// Scattering classes by their documented rule (`scatter_classes`): two channels share one
/// where the columns' scattering optical depths differ by at most 0.5 and, in every layer
/// of optical depth above 0.1, every scatterer's coefficients are within a factor 2 and its
/// phase functions within a factor 2 at every angle.
#[test]
fn scatter_classes_follow_their_rule() {
    let cloud = [(1000.0, 1300.0)];
    let three = [(1000.0, 1300.0), (1300.0, 1600.0), (1600.0, 1900.0)];
    // What, layers, extinctions [km⁻¹], asymmetries, the classes expected.
    type Case<'a> = (&'a str, &'a [(f64, f64)], [f64; 2], [f64; 2], Vec<usize>);
    let cases: [Case; 7] = [
        // τ 0.3 and 0.45: within a factor 2, alike.
        ("factor 1.5", &cloud, [1.0, 1.5], [0.5, 0.5], vec![0]),
        // τ 0.12 and 0.39: the columns are close, the coefficients not.
        ("factor 3.25", &cloud, [0.4, 1.3], [0.5, 0.5], vec![0, 1]),
        (
            "factor 3.25, the other way",
            &cloud,
            [1.3, 0.4],
            [0.5, 0.5],
            vec![0, 1],
        ),
        // τ 0.03 and 0.09: too thin for the coefficients to matter.
        ("thin, factor 3", &cloud, [0.1, 0.3], [0.5, 0.5], vec![0]),
        // P(0°) 6 against 190.
        ("g 0.5 and 0.9", &cloud, [1.0, 1.0], [0.5, 0.9], vec![0, 1]),
        // Columns 4.5 and 4.95 through three layers: each layer alike, the columns close.
        (
            "three layers, close",
            &three,
            [5.0, 5.5],
            [0.5, 0.5],
            vec![0],
        ),
        // Columns 4.5 and 5.13: each layer alike (factor 1.14), the columns 0.63 apart.
        (
            "three layers, apart",
            &three,
            [5.0, 5.7],
            [0.5, 0.5],
            vec![0, 1],
        ),
    ];
    for (what, layers, ext, g, expect) in cases {
        with_setup(&two_channel_scene(layers, ext, g), |_, atm| {
            assert!(!atm.grey_scattering, "{what}");
            assert_eq!(scatter_classes(atm), expect, "{what}");
        });
    }
}

/// Phase functions alike within a factor 2 at every angle: a table equal to isotropic
/// scattering within 2× at 0° and 180° but 4× it at 90° is not alike (the scan must reach
/// the angles between the poles); HG g = 0.5 and 0.55 are (their ratio stays in 0.72–1.32).
#[test]
fn similar_phase_looks_at_every_angle() {
    use crate::particles::phase::TabulatedPhase;
    let iso = PhaseFunction::Isotropic;
    let bump = PhaseFunction::Tabulated(Box::new(
        TabulatedPhase::from_angles(&[0.0, 80.0, 90.0, 100.0, 180.0], &[1.0, 1.0, 6.0, 1.0, 1.0])
            .unwrap(),
    ));
    assert!(bump.eval(1.0) > 0.5 && bump.eval(-1.0) > 0.5 && bump.eval(0.0) > 2.0);
    assert!(!similar_phase(&iso, &bump));
    assert!(similar_phase(&iso, &iso));
    let hg = |g| PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(g).unwrap());
    assert!(similar_phase(&hg(0.5), &hg(0.55)));
    assert!(!similar_phase(&hg(0.5), &hg(0.9)));
}

/// The forward half-width of Henyey-Greenstein phase functions against the closed form:
/// P(Θ)/P(0) = [(1 − g)²/(1 + g² − 2g cos Θ)]^{3/2} = ½ at
/// cos Θ = (1 + g² − 2^{2/3}(1 − g)²)/(2g); isotropic scattering never falls to half.
#[test]
fn forward_half_width_of_henyey_greenstein() {
    for g in [0.3, 0.5, 0.85, 0.95, 0.999] {
        let hg = PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(g).unwrap());
        let exact =
            ((1.0 + g * g - 2f64.powf(2.0 / 3.0) * (1.0 - g) * (1.0 - g)) / (2.0 * g)).acos();
        let found = forward_half_width(|mu| hg.eval(mu));
        assert!(
            (found - exact).abs() < 1e-9 * exact.max(1.0) + 1e-12,
            "g {g}: {found} against {exact}"
        );
    }
    let flat = forward_half_width(|_| 1.0);
    assert_eq!(flat, std::f64::consts::PI);
}

/// The backward hemisphere's bound is at least the phase function's largest value there and
/// close to it: for the C.1 droplet table, every tabulated angle from 90° to 180° (the glory
/// at 180° included), at most 10 % above the largest (the bound adds the largest change
/// between neighbouring points of its grid, 0.046 on the glory's flank against a largest
/// value of 0.64); for HG g = 0.85 the value at 90°, (1 − g²)/(1 + g²)^{3/2}, where it
/// decreases monotonically toward the back, within 1 %.
#[test]
fn backward_bound_holds_and_is_tight() {
    let table = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
    let c1 = PhaseFunction::Tabulated(Box::new(
        crate::particles::phase::TabulatedPhase::from_table(&table).unwrap(),
    ));
    let largest = table
        .theta_deg
        .iter()
        .filter(|t| **t >= 90.0)
        .map(|t| c1.eval(t.to_radians().cos().min(0.0)))
        .fold(0.0f64, f64::max);
    let bound = backward_max(|mu| c1.eval(mu));
    assert!(
        bound >= largest && bound <= 1.1 * largest,
        "{bound} against {largest}"
    );
    let g: f64 = 0.85;
    let hg = PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(g).unwrap());
    let at_90 = (1.0 - g * g) / (1.0 + g * g).powf(1.5);
    let bound = backward_max(|mu| hg.eval(mu));
    assert!(
        bound >= at_90 && bound <= 1.01 * at_90,
        "{bound} against {at_90}"
    );
}

/// The tracer compiled for one channel is the general one with its per-channel loops
/// unrolled: on one-channel scenes (a cloud seen from the ground with every estimator on,
/// the same polarised, and a cloud over a reflecting surface seen from above) both give the
/// same tallies and counters, bit for bit, batch by batch.
#[test]
fn one_channel_tracer_is_the_general_one() {
    let polarised = edited(
        CLOUD,
        &[(
            "fov_full_angle_mrad = [1.0]",
            "fov_full_angle_mrad = [1.0, 5.0]\npolarisation = \"linear\"",
        )],
    );
    let from_above = edited(
        CLOUD,
        &[
            ("altitude_m = 0.0", "altitude_m = 2000.0"),
            ("zenith_angle_deg = 0.0", "zenith_angle_deg = 180.0"),
        ],
    ) + "[surface]\naltitude_m = 0.0\nalbedo = 0.3\n";
    for text in [CLOUD.to_string(), polarised, from_above] {
        let mut scene = Scene::from_toml(std::path::Path::new("scene.toml"), &text).unwrap();
        scene.simulation.photons = 6000;
        scene.simulation.batches = 3;
        let atm = OpticalAtmosphere::build(&scene).unwrap();
        let plan = Plan::new(&scene, &atm, &TallyLayout::default()).unwrap();
        assert_eq!(plan.setup.atm.n_channels, 1);
        // Copies made by splitting follow the copy paths too.
        let (mut splits, mut reflections) = (0, 0);
        for index in 0..plan.batches() {
            let one = plan.trace_batch_by::<true>(index, &mut plan.streams[index].clone());
            let any = plan.trace_batch_by::<false>(index, &mut plan.streams[index].clone());
            assert!(one.stats.collisions > 0);
            splits += one.stats.splits;
            reflections += one.stats.surface_reflections;
            assert_eq!(one, any, "batch {index} of\n{text}");
        }
        assert!(splits > 0);
        assert_eq!(reflections > 0, text.contains("[surface]"));
    }
}

/// A plan whose stop flag is set traces no more photons (a batch looks at the flag before its
/// first photon) and the run ends with `Stopped`, not with a result; one never stopped gives
/// the numbers of a plan without a flag, bit for bit.
#[test]
fn a_stopped_plan_ends_without_a_result() {
    use std::sync::atomic::AtomicBool;
    let mut scene = Scene::from_toml(std::path::Path::new("scene.toml"), CLOUD).unwrap();
    scene.simulation.photons = 3 * (STOP_CHECK_PHOTONS + 7);
    scene.simulation.batches = 3;
    let atm = OpticalAtmosphere::build(&scene).unwrap();
    let layout = TallyLayout::default();
    let plain = run_plan(&Plan::new(&scene, &atm, &layout).unwrap(), &quiet).unwrap();
    let never = AtomicBool::new(false);
    let watched = Plan::new(&scene, &atm, &layout).unwrap().stop_when(&never);
    let same = run_plan(&watched, &quiet).unwrap();
    assert_eq!(plain.returns, same.returns);
    let stop = AtomicBool::new(true);
    let stopped = Plan::new(&scene, &atm, &layout).unwrap().stop_when(&stop);
    assert_eq!(stopped.trace_batch(0).stats.photons, 0);
    assert!(matches!(
        run_plan(&stopped, &quiet),
        Err(TransportError::Stopped)
    ));
}

/// The lookups done once for every channel give, bit for bit, what the one-channel functions
/// give channel by channel, on the default scene (16 channels, 800 layers, a two-scatterer
/// aerosol layer under Rayleigh air): a layer found from any hint is the searched one; every
/// channel's optical depths at a point, the class optical depth from a known or hinted layer,
/// the mixture phase functions and the optical depths to the receiver; a collision's layer
/// found from any hint.
#[test]
fn all_channel_lookups_are_the_one_channel_ones() {
    with_setup(crate::scene::DEFAULT_SCENE_TOML, |s, atm| {
        let nch = atm.n_channels;
        assert_eq!(nch, 16);
        let n = atm.n_layers();
        let e = &atm.edges_m;
        let mut zs: Vec<f64> = (0..=2000).map(|i| -500.0 + 41.3 * i as f64).collect();
        zs.extend(e.iter().flat_map(|z| [*z, z.next_up(), z.next_down()]));
        zs.extend([1e9, -1e9]);
        let (mut ts, mut ta, mut tau) = (vec![0.0; nch], vec![0.0; nch], vec![0.0; nch]);
        for &z in &zs {
            let l = atm.layer_of(z);
            for hint in [0, 1, l.saturating_sub(1), l, l + 1, n / 2, n - 1] {
                assert_eq!(atm.layer_near(z, hint), l, "z {z}, hint {hint}");
                let zc = z.clamp(s.bottom_m, s.top_m);
                assert_eq!(
                    s.class_tau_near(0, z, hint).to_bits(),
                    s.class_tau_at(0, z).to_bits()
                );
                assert_eq!(
                    s.class_tau_in(0, atm.layer_near(zc, hint), zc).to_bits(),
                    s.class_tau_at(0, z).to_bits()
                );
            }
            atm.cumulative_taus_in(l, z.clamp(s.bottom_m, s.top_m), &mut ts, &mut ta);
            for mu in [0.7, -0.3, 0.0] {
                s.taus_to_receiver(z, mu, 1234.5, l, &ts, &ta, &mut tau);
                for k in 0..nch {
                    let (ts_k, ta_k) = atm.cumulative_tau(z, k);
                    assert_eq!(
                        (ts[k].to_bits(), ta[k].to_bits()),
                        (ts_k.to_bits(), ta_k.to_bits())
                    );
                    let one = s.tau_to_receiver(z, mu, 1234.5, l, k, ts_k + ta_k);
                    assert_eq!(
                        tau[k].to_bits(),
                        one.to_bits(),
                        "z {z}, μ {mu}, channel {k}"
                    );
                }
            }
        }
        let mut p = vec![0.0; nch];
        for l in (0..n).step_by(7).chain([0, 1, 14, 15, 16]) {
            assert!(!atm.components[l].is_empty());
            for i in 0..=40 {
                let mu = -1.0 + i as f64 / 20.0;
                s.mixture_phases(l, mu, &mut p);
                for (k, v) in p.iter().enumerate() {
                    assert_eq!(
                        v.to_bits(),
                        s.mixture_phase(l, k, mu).to_bits(),
                        "layer {l}"
                    );
                }
            }
        }
        assert!(atm.components[0].len() == 2 && atm.components[n - 1].len() == 1);
        let top = *s.classes[0].cum.last().unwrap();
        for i in 0..=400 {
            let t0 = top * i as f64 / 400.0;
            for mu in [0.9, -0.9, 0.05, -0.05] {
                let tau_star = top * 0.003 * (i % 17) as f64;
                let searched = s.altitude_at_tau(0, t0, mu, tau_star, usize::MAX);
                for hint in [
                    0,
                    n / 3,
                    n - 1,
                    searched.1.saturating_sub(2),
                    searched.1 + 3,
                ] {
                    let hinted = s.altitude_at_tau(0, t0, mu, tau_star, hint);
                    assert_eq!(
                        (hinted.0.to_bits(), hinted.1),
                        (searched.0.to_bits(), searched.1)
                    );
                }
            }
        }
    });
}
