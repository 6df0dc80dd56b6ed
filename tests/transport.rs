//! Monte Carlo transport against independent truth: the analytic single-scatter lidar equation
//! and hard-target equation, the exact two-way transmission of an absorber, conservation of
//! energy, and itself at another thread count or with variance reduction off.
//!
//! Tolerances: a Monte Carlo bin agrees when |MC − truth| ≤ 4σ + 1 % of the truth (σ its batch
//! standard error), and only bins with a relative standard error below 10 % are judged, where
//! 100 batch means are close enough to normal for a 4σ test (with a handful of hits per gate the
//! batch error itself is unreliable). Seeds are fixed.

use std::path::Path;

use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::returns::{Order, Returns};
use lidarsim::scene::Scene;
use lidarsim::scene::Simulation;
use lidarsim::transport::{self, McResult, RunStats, TallyLayout};

use crate::util::project_root;

pub(crate) const K_SIGMA: f64 = 4.0;
pub(crate) const REL_SLACK: f64 = 0.01;
pub(crate) const MAX_REL_SE: f64 = 0.10;

/// What a test changes of a run: the scene's settings and the tallies' layout.
pub(crate) struct Knobs {
    pub(crate) sim: Simulation,
    pub(crate) layout: TallyLayout,
}

/// The Monte Carlo of `scene` with `photons` and its settings and layout changed by `configure`.
pub(crate) fn run(scene: &Scene, photons: u64, configure: impl FnOnce(&mut Knobs)) -> McResult {
    let atm = OpticalAtmosphere::build(scene).expect("optics");
    let mut knobs = Knobs {
        sim: scene.simulation.clone(),
        layout: TallyLayout::default(),
    };
    knobs.sim.photons = photons;
    configure(&mut knobs);
    let mut scene = scene.clone();
    scene.simulation = knobs.sim;
    transport::run(&scene, &atm, &knobs.layout).expect("transport")
}

pub(crate) fn analytic(scene: &Scene) -> Returns {
    lidar_eq::single_scatter(scene, &OpticalAtmosphere::build(scene).expect("optics"))
}

/// `text` with each `from` replaced by its `to`. Every `from` must occur: a scene edit that
/// silently missed would leave a test checking the unedited scene.
pub(crate) fn edited(text: &str, edits: &[(&str, &str)]) -> String {
    edits.iter().fold(text.to_string(), |t, (from, to)| {
        assert!(t.contains(from), "no {from:?} to replace in the scene");
        t.replace(from, to)
    })
}

/// A scene from text, the Mie disk cache off (its Mie layers must not write into the user's
/// cache).
pub(crate) fn scene_text(text: &str) -> Scene {
    crate::util::scene_from_toml(Path::new("test.toml"), text).expect("test scene")
}

/// Compare MC order 1 with the analytic equation in every judged bin; returns (judged, bins
/// with signal). A bin has signal where the analytic energy exceeds 1e-4 of the largest
/// atmospheric (non-surface) return of its channel and FOV.
pub(crate) fn check_order1(name: &str, mc: &Returns, an: &Returns) -> (usize, usize) {
    let (mut judged, mut with_signal) = (0, 0);
    let mut failures = Vec::new();
    for k in 0..an.channels.len() {
        for f in 0..an.fov_full_angle_mrad.len() {
            let values: Vec<f64> = (0..an.range_m.len())
                .map(|g| an.energy(k, f, g, Order::Exactly(1)).unwrap())
                .collect();
            // The surface gate can outshine the atmosphere by orders of magnitude; leave the
            // largest gate out when it is more than 100 times its neighbours' maximum.
            let mut sorted = values.clone();
            sorted.sort_by(|a, b| b.total_cmp(a));
            let reference = if sorted.len() > 1 && sorted[0] > 100.0 * sorted[1] {
                sorted[1]
            } else {
                sorted[0]
            };
            for (g, &a) in values.iter().enumerate() {
                if a <= 1e-4 * reference {
                    continue;
                }
                with_signal += 1;
                let m = mc.energy(k, f, g, Order::Exactly(1)).unwrap();
                let se = mc.stderr(k, f, g, Order::Exactly(1)).unwrap();
                // A bin no photon reached (0 ± 0) is unresolved, not known exactly.
                if !(m > 0.0 && se <= MAX_REL_SE * m) {
                    continue;
                }
                judged += 1;
                if (m - a).abs() > K_SIGMA * se + REL_SLACK * a {
                    failures.push(format!(
                        "{name}: channel {} FOV {} mrad gate {} m: MC {m:.5e} ± {se:.2e}, analytic {a:.5e} ({:+.2} σ)",
                        an.channels[k],
                        an.fov_full_angle_mrad[f],
                        an.range_m[g],
                        (m - a) / se
                    ));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} bins disagree:\n{}",
        failures.len(),
        failures.join("\n")
    );
    (judged, with_signal)
}

/// Every scene shipped in scenes/: MC single scattering equals the lidar equation.
#[test]
fn order1_matches_lidar_equation_for_every_shipped_scene() {
    let dir = project_root().join("scenes");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    names.sort();
    assert!(
        names.len() >= 3,
        "expected at least three scenes in {}",
        dir.display()
    );
    for path in names {
        let scene = Scene::read(&path).unwrap();
        // Enough photons for the sparse gates of the space-borne and Rayleigh scenes (the
        // space-borne one is then well sampled up to about 12 km), few enough for CI (one to
        // three seconds each on two cores).
        let mc = run(&scene, 1_000_000, |_| {});
        assert_histories_end_once(&path.display().to_string(), &mc.stats);
        let an = analytic(&scene);
        let (judged, with_signal) = check_order1(&path.display().to_string(), &mc.returns, &an);
        assert!(
            judged * 2 >= with_signal && judged > 0,
            "{}: only {judged} of {with_signal} gates with signal were sampled well enough",
            path.display()
        );
    }
}

const HARD_TARGET: &str = r#"
[lidar]
altitude_m = 3000.0
zenith_angle_deg = 160.0
pulse_energy_j = 0.05
beam_divergence_full_angle_mrad = 0.2
telescope_diameter_m = 0.5
optical_efficiency = 0.8
fov_full_angle_mrad = [0.1, 0.4]
[[channel]]
name = "a"
wavelength_nm = 1572.0
[gates]
start_m = 2000.0
end_m = 3500.0
width_m = 15.0
[[layer]]
name = "haze"
base_m = 200.0
top_m = 1800.0
extinction_per_km = 0.3
single_scattering_albedo = 0.9
phase = { kind = "henyey_greenstein", g = 0.75 }
absorption_per_m = 2e-5
[surface]
altitude_m = 0.0
albedo = 0.25
"#;

/// The hard-target return of a Lambertian surface seen at 20° off nadir through an absorbing,
/// scattering haze equals E₀ η A/R² · ρ cos θ/π · T² · overlap.
#[test]
fn surface_return_matches_hard_target_equation() {
    let scene = scene_text(HARD_TARGET);
    let mc = run(&scene, 200_000, |_| {});
    let an = analytic(&scene);
    let range = 3000.0 / (20.0f64).to_radians().cos();
    let g = ((range - 2000.0) / 15.0) as usize;
    for f in 0..2 {
        let a = an.energy(0, f, g, Order::Exactly(1)).unwrap();
        let m = mc.returns.energy(0, f, g, Order::Exactly(1)).unwrap();
        let se = mc.returns.stderr(0, f, g, Order::Exactly(1)).unwrap();
        assert!(a > 0.0);
        assert!(
            (m - a).abs() <= K_SIGMA * se + REL_SLACK * a,
            "FOV {f}: MC {m:e} ± {se:e}, analytic {a:e}"
        );
    }
    // The hard target dominates its gate: independent closed form for the 0.4 mrad FOV, which
    // holds the whole 0.2 mrad beam. Two-way transmission through 1600 m of haze along the slant.
    let tau = (0.3e-3 + 2e-5) * 1600.0 / (20.0f64).to_radians().cos();
    let area = std::f64::consts::PI * 0.25 * 0.25;
    let closed = 0.05 * 0.8 * area / (range * range) * 0.25 * (20.0f64).to_radians().cos()
        / std::f64::consts::PI
        * (-2.0 * tau).exp();
    let a = an.energy(0, 1, g, Order::Exactly(1)).unwrap();
    assert!(
        (a / closed - 1.0).abs() < 0.02,
        "{a:e} vs closed form {closed:e}"
    );
    check_order1("hard target", &mc.returns, &an);
}

const TWO_CHANNELS: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 0.01
beam_divergence_full_angle_mrad = 0.1
telescope_diameter_m = 0.3
optical_efficiency = 1.0
fov_full_angle_mrad = 0.3
[[channel]]
name = "off"
wavelength_nm = 1572.0
[[channel]]
name = "on"
wavelength_nm = 1572.0
[gates]
start_m = 200.0
end_m = 3000.0
width_m = 20.0
[atmosphere]
standard = "us_standard"
layer_thickness_m = 100.0
[[layer]]
name = "aerosol"
base_m = 0.0
top_m = 2000.0
extinction_per_km = 0.2
single_scattering_albedo = 0.95
phase = { kind = "henyey_greenstein", g = 0.7 }
[[layer]]
name = "absorber"
base_m = 0.0
top_m = 2500.0
absorption_per_m = [0.0, 3e-4]
"#;

/// One photon path carries both channels: the on/off ratio of the order-1 returns equals the
/// analytic two-way transmission ratio exp(−2∫k dr) gate by gate, with almost no noise.
#[test]
fn absorbing_and_clear_channels_ratio_is_two_way_transmission() {
    let scene = scene_text(TWO_CHANNELS);
    let mc = run(&scene, 200_000, |_| {});
    let an = analytic(&scene);
    let mut judged = 0;
    for g in 0..an.range_m.len() {
        let (off, on) = (
            mc.returns.energy(0, 0, g, Order::Exactly(1)).unwrap(),
            mc.returns.energy(1, 0, g, Order::Exactly(1)).unwrap(),
        );
        let se = mc.returns.stderr(0, 0, g, Order::Exactly(1)).unwrap();
        if !(se < MAX_REL_SE * off) {
            continue;
        }
        judged += 1;
        let ratio_an = an.energy(1, 0, g, Order::Exactly(1)).unwrap()
            / an.energy(0, 0, g, Order::Exactly(1)).unwrap();
        // Independent truth: for a gate [r, r+Δr] inside the absorber, T² varies by e^{−2kΔr}
        // across it, so the gate ratio lies between the values at its ends.
        let r0 = an.range_m[g] - 10.0;
        let t2 = |r: f64| (-2.0 * 3e-4 * r.min(2500.0)).exp();
        assert!(ratio_an <= t2(r0) * (1.0 + 1e-12) && ratio_an >= t2(r0 + 20.0) * (1.0 - 1e-12));
        // Correlated sampling: the MC ratio differs from the analytic one only through the
        // distribution of hits inside the gate, well below 0.5 % here.
        assert!(
            ((on / off) / ratio_an - 1.0).abs() < 5e-3,
            "gate {} m: MC ratio {} vs analytic {}",
            an.range_m[g],
            on / off,
            ratio_an
        );
    }
    assert!(judged > 50, "only {judged} gates judged");
    check_order1("two channels", &mc.returns, &an);
}

const SLAB: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = 1.0
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = 1.0
end_m = 10000001.0
width_m = 10000000.0
[[layer]]
name = "slab"
base_m = 1000.0
top_m = 1500.0
extinction_per_m = 4e-3
single_scattering_albedo = SSA
phase = { kind = "henyey_greenstein", g = 0.6 }
[simulation]
max_order = 3
"#;

/// Energy conservation in a flux tally: what leaves up, leaves down, is absorbed or is still
/// travelling at the last gate adds up to what was emitted; a non-absorbing slab absorbs
/// nothing. Slab optical depth 2, gates to 10 000 km so nothing is cut.
#[test]
fn slab_conserves_energy() {
    for ssa in [1.0, 0.9] {
        let scene = scene_text(&SLAB.replace("SSA", &ssa.to_string()));
        let mc = run(&scene, 100_000, |o| o.layout.flux = true);
        assert_energy_conserved(&format!("ϖ = {ssa}"), &mc);
        assert_histories_end_once(&format!("ϖ = {ssa}"), &mc.stats);
        let f = &mc.flux;
        assert!(f.cut[0] < 1e-6, "ϖ = {ssa}: cut {}", f.cut[0]);
        if ssa == 1.0 {
            assert_eq!(f.absorbed[0], 0.0);
        } else {
            assert!(
                f.absorbed[0] > 0.05,
                "ϖ = {ssa}: absorbed {}",
                f.absorbed[0]
            );
        }
        // The direct beam alone transmits e^{−2}: transmission must exceed it.
        assert!(f.down[0] > (-2.0f64).exp(), "ϖ = {ssa}: down {}", f.down[0]);
    }
}

/// Energy conservation in a flux tally (channel 0): what leaves up, leaves down, is absorbed or
/// is cut adds up to what was emitted, within K_SIGMA of the parts' errors added in quadrature
/// (conservative: the parts are anti-correlated).
pub(crate) fn assert_energy_conserved(what: &str, mc: &McResult) {
    assert_energy_conserved_in(what, mc, 0);
}

/// [`assert_energy_conserved`] in channel k.
pub(crate) fn assert_energy_conserved_in(what: &str, mc: &McResult, k: usize) {
    let (f, e) = (&mc.flux, &mc.flux_stderr);
    let total = f.up[k] + f.down[k] + f.absorbed[k] + f.cut[k];
    let se =
        (e.up[k].powi(2) + e.down[k].powi(2) + e.absorbed[k].powi(2) + e.cut[k].powi(2)).sqrt();
    assert!(
        (total - 1.0).abs() <= K_SIGMA * se + 1e-9,
        "{what}, channel {k}: energy {total} ± {se} (up {}, down {}, absorbed {}, cut {})",
        f.up[k],
        f.down[k],
        f.absorbed[k],
        f.cut[k]
    );
}

/// Every photon history ends exactly once: the packets emitted and the copies split off them
/// are each ended in one of four ways, cut (no gate can still receive it), escaped, ended by
/// Russian roulette, or given zero weight (a range-stratified collision where nothing
/// scatters: the disparate pair's gates start below its cloud, so some of its histories end
/// so). A count of histories, independent of their weights.
pub(crate) fn assert_histories_end_once(what: &str, s: &RunStats) {
    let begun = s.photons + s.splits;
    let ended = s.cut + s.escaped + s.roulette_kills + s.zero_weight;
    assert_eq!(
        begun, ended,
        "{what}: {begun} histories begun ({} photons, {} copies), {ended} ended ({} cut, {} \
         escaped, {} by roulette, {} with zero weight)",
        s.photons, s.splits, s.cut, s.escaped, s.roulette_kills, s.zero_weight
    );
    // A collision makes at most one local estimate, and so does a flight that meets the
    // surface, which then reflects or collides before it.
    let most = 2 * s.collisions + s.surface_reflections;
    assert!(
        s.local_estimates <= most,
        "{what}: {} local estimates from {} collisions and {} reflections",
        s.local_estimates,
        s.collisions,
        s.surface_reflections
    );
}

/// A photon whose flight meets no scatterer before the last gate escapes: under a slab whose
/// base is above the last gate every history ends so on its first flight, with no collision
/// and no return (exact counts, whatever the variance reductions).
#[test]
fn histories_that_meet_no_scatterer_escape() {
    let scene = scene_text(
        &SLAB
            .replace("SSA", "1.0")
            .replace("end_m = 10000001.0", "end_m = 901.0")
            .replace("width_m = 10000000.0", "width_m = 100.0"),
    );
    let mc = run(&scene, 5_000, |_| {});
    let s = &mc.stats;
    assert_histories_end_once("under the slab", s);
    assert_eq!((s.photons, s.escaped, s.collisions), (5_000, 5_000, 0));
    assert!(mc.returns.energy_j.iter().all(|e| *e == 0.0));
}

/// A pencil beam's first collision lies on the axis of the field of view and, with gates that
/// span the whole path, inside a gate: with plain local estimates (no crossing estimate to
/// take a flight's share first) and without range stratification (which would draw a share of
/// first collisions uniformly over the 10 000 km gate, mostly outside the slab, where they end
/// with zero weight), every photon makes at least one local estimate, and no collision more
/// than one.
#[test]
fn every_first_collision_on_the_axis_makes_a_local_estimate() {
    let scene = scene_text(&SLAB.replace("SSA", "0.9"));
    let mc = run(&scene, 5_000, |o| {
        plain_local_estimates(o);
        o.sim.variance_reduction.range_stratification = 0.0;
    });
    let s = &mc.stats;
    assert_histories_end_once("slab", s);
    assert!(
        s.photons <= s.local_estimates && s.local_estimates <= s.collisions,
        "{} photons, {} local estimates, {} collisions",
        s.photons,
        s.local_estimates,
        s.collisions
    );
}

/// The same slab seen from above, over a Lambertian surface of albedo 0.3: energy is conserved
/// too when photons meet the ground, where the collision forced before it leaves the surface
/// its share of the absorption in expectation (`down` counts what the ground absorbs).
#[test]
fn slab_over_a_surface_conserves_energy() {
    for ssa in [1.0, 0.9] {
        let text = edited(
            SLAB,
            &[
                ("SSA", &ssa.to_string()),
                (
                    "altitude_m = 0.0\nzenith_angle_deg = 0.0",
                    "altitude_m = 3000.0\nzenith_angle_deg = 180.0",
                ),
            ],
        ) + "[surface]\naltitude_m = 0.0\nalbedo = 0.3\n";
        let scene = scene_text(&text);
        let mc = run(&scene, 100_000, |o| o.layout.flux = true);
        assert_energy_conserved(&format!("ϖ = {ssa}, over the ground"), &mc);
        assert_histories_end_once(&format!("ϖ = {ssa}, over the ground"), &mc.stats);
        let f = &mc.flux;
        assert!(f.cut[0] < 1e-6, "ϖ = {ssa}: cut {}", f.cut[0]);
        // The ground absorbs 0.7 of what reaches it, at least the direct beam's e^{−2}.
        assert!(
            f.down[0] > 0.7 * (-2.0f64).exp(),
            "ϖ = {ssa}: down {}",
            f.down[0]
        );
    }
}

/// The same slab over the ground with a second channel that scatters 100 times less: two
/// scattering classes, each collision drawn from the mixture of their free-path densities and
/// the surface branch taken by their mean collision probability (`photon.rs`); energy is
/// conserved in both channels.
#[test]
fn two_scattering_classes_over_a_surface_conserve_energy() {
    let text = edited(
        SLAB,
        &[
            ("SSA", "0.9"),
            (
                "altitude_m = 0.0\nzenith_angle_deg = 0.0",
                "altitude_m = 3000.0\nzenith_angle_deg = 180.0",
            ),
            (
                "wavelength_nm = 1064.0\n",
                "wavelength_nm = 1064.0\n[[channel]]\nname = \"b\"\nwavelength_nm = 1064.0\n",
            ),
            ("extinction_per_m = 4e-3", "extinction_per_m = [4e-3, 4e-5]"),
        ],
    ) + "[surface]\naltitude_m = 0.0\nalbedo = 0.3\n";
    let scene = scene_text(&text);
    let mc = run(&scene, 100_000, |o| o.layout.flux = true);
    for k in 0..2 {
        assert_energy_conserved_in("two classes over the ground", &mc, k);
    }
    assert_histories_end_once("two classes over the ground", &mc.stats);
    assert!(mc.stats.surface_reflections > 0);
}

/// A horizontal beam inside the slab (zenith 90°): its first flight stays in the layer to the
/// last gate, 10⁷ m away, so none of it passes uncollided (e^{−σ s} = 0) and energy is
/// conserved with nothing cut.
#[test]
fn a_horizontal_beam_conserves_energy() {
    let text = edited(
        SLAB,
        &[
            ("SSA", "0.9"),
            (
                "altitude_m = 0.0\nzenith_angle_deg = 0.0",
                "altitude_m = 1250.0\nzenith_angle_deg = 90.0",
            ),
        ],
    );
    let mc = run(&scene_text(&text), 20_000, |o| o.layout.flux = true);
    assert_energy_conserved("a horizontal beam", &mc);
    assert_histories_end_once("a horizontal beam", &mc.stats);
    assert!(mc.flux.cut[0] < 1e-6, "cut {}", mc.flux.cut[0]);
}

/// Over bare ground, with no atmosphere, every photon meets the surface once, reflects and
/// escapes: exact counts. The beam (0.2 mrad) lies inside the wider field of view (0.4 mrad)
/// and the ground inside the gates, so every reflection also makes a local estimate.
#[test]
fn over_bare_ground_every_photon_reflects_once_and_escapes() {
    let text = HARD_TARGET
        .split("[[layer]]")
        .next()
        .unwrap_or_default()
        .to_string()
        + "[surface]\naltitude_m = 0.0\nalbedo = 0.25\n";
    let mc = run(&scene_text(&text), 5_000, |_| {});
    let s = &mc.stats;
    assert_histories_end_once("bare ground", s);
    assert_eq!(
        (s.photons, s.surface_reflections, s.escaped, s.collisions),
        (5_000, 5_000, 5_000, 0)
    );
    assert_eq!(s.local_estimates, 5_000);
}

/// Same scene and seed → the same numbers, bit for bit, at 1 and 2 threads.
#[test]
fn identical_results_at_one_and_two_threads() {
    let scene = scene_text(TWO_CHANNELS);
    let a = run(&scene, 20_000, |o| {
        o.sim.threads = 1;
        o.layout.flux = true
    });
    let b = run(&scene, 20_000, |o| {
        o.sim.threads = 2;
        o.layout.flux = true
    });
    assert_eq!(a.threads, 1);
    assert_eq!(b.threads, 2);
    assert_eq!(a.returns, b.returns);
    assert_eq!(a.flux, b.flux);
    assert_eq!(a.stats, b.stats);
}

/// Batches traced one by one in any order (as shards or ranks would) and folded in batch order
/// give the run's numbers bit for bit; a fold refuses a batch out of order or an incomplete run.
#[test]
fn batches_traced_apart_and_folded_in_order_equal_the_run() {
    let mut scene = scene_text(TWO_CHANNELS);
    scene.simulation.photons = 4_000;
    scene.simulation.batches = 8;
    let atm = OpticalAtmosphere::build(&scene).expect("optics");
    let layout = TallyLayout {
        flux: true,
        ..TallyLayout::default()
    };
    let whole = transport::run(&scene, &atm, &layout).expect("transport");
    let plan = transport::Plan::new(&scene, &atm, &layout).expect("plan");
    let mut tallies: Vec<_> = (0..plan.batches())
        .rev()
        .map(|b| plan.trace_batch(b))
        .collect();
    tallies.reverse();
    let mut fold = plan.fold();
    assert!(
        fold.add(tallies[1].clone()).is_err(),
        "batch 1 before batch 0"
    );
    for t in tallies {
        fold.add(t).expect("in order");
    }
    let parts = fold.finish(0.0, 1).expect("all batches");
    assert_eq!(parts.returns, whole.returns);
    assert_eq!(parts.flux, whole.flux);
    assert_eq!(parts.flux_stderr, whole.flux_stderr);
    assert_eq!(parts.stats, whole.stats);
    assert!(plan.fold().finish(0.0, 1).is_err(), "no batch folded");
    // A batch of another shape (its bins cut short, its flux tally right) is refused.
    let mut short = plan.trace_batch(0);
    short.bins.pop();
    assert!(plan.fold().add(short).is_err(), "a batch of another shape");
}

/// A cloud 300 m thick whose extinction differs 2500-fold between two channels: optical depth
/// 750 in one, 0.3 in the other.
const DISPARATE_PAIR: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.2
telescope_diameter_m = 0.3
optical_efficiency = 1.0
fov_full_angle_mrad = [2.0]
CHANNELS
[gates]
start_m = 900.0
end_m = 1500.0
width_m = 30.0
[[layer]]
name = "cloud"
base_m = 1000.0
top_m = 1300.0
extinction_per_km = EXTINCTION
single_scattering_albedo = 1.0
phase = [PHASES]
[simulation]
max_order = 4
seed = 3
"#;

/// Channels whose scattering differs by orders of magnitude share one photon path (each
/// collision drawn from the mixture of their free-path densities): each channel of the pair,
/// in either order, equals the same channel run alone within 4.5 combined standard errors in
/// every gate and order both runs resolve, its single scattering equals the lidar equation,
/// and every number is finite. (Sampling on channel 0 alone gave NaN beyond 1260 m for the
/// thin channel when the thick one came first.) The two also scatter with different phase
/// functions (HG g = 0.85 and 0.5), so that a direction drawn from one class's phase function
/// must be weighted by the classes' mean, DDIS included (weighting by the drawn class's own
/// value put the thick channel's total 21 % low).
#[test]
fn channels_whose_scattering_differs_2500_fold_match_each_run_alone() {
    let channel = |name: &str| format!("[[channel]]\nname = \"{name}\"\nwavelength_nm = 1064.0\n");
    let phase = |name: &str| {
        let g = if name == "thick" { 0.85 } else { 0.5 };
        format!("{{ kind = \"henyey_greenstein\", g = {g} }}")
    };
    let scene = |names: &[&str], ext: &str| {
        let chans: String = names.iter().map(|n| channel(n)).collect();
        let phases: Vec<String> = names.iter().map(|n| phase(n)).collect();
        scene_text(
            &DISPARATE_PAIR
                .replace("CHANNELS", &chans)
                .replace("EXTINCTION", ext)
                .replace("PHASES", &phases.join(", ")),
        )
    };
    let photons = 200_000;
    let thick = run(&scene(&["thick"], "2500.0"), photons, |_| {});
    let thin = run(&scene(&["thin"], "1.0"), photons, |_| {});
    for (names, ext) in [
        (["thick", "thin"], "[2500.0, 1.0]"),
        (["thin", "thick"], "[1.0, 2500.0]"),
    ] {
        let pair_scene = scene(&names, ext);
        let pair = run(&pair_scene, photons, |o| o.sim.seed = 4);
        assert_histories_end_once(&format!("{names:?}"), &pair.stats);
        let r = &pair.returns;
        assert!(
            r.energy_j
                .iter()
                .chain(&r.stderr_j)
                .all(|v| v.is_finite() && *v >= 0.0),
            "{names:?}: non-finite or negative returns"
        );
        check_order1(&format!("{names:?}"), r, &analytic(&pair_scene));
        let mut judged = 0;
        for (k, name) in names.iter().enumerate() {
            let alone = if *name == "thick" { &thick } else { &thin };
            for g in 0..r.range_m.len() {
                for order in [
                    Order::Exactly(1),
                    Order::Exactly(2),
                    Order::Exactly(4),
                    Order::AtLeast(5),
                    Order::Total,
                ] {
                    let (a, sa) = (
                        r.energy(k, 0, g, order).unwrap(),
                        r.stderr(k, 0, g, order).unwrap(),
                    );
                    let (b, sb) = (
                        alone.returns.energy(0, 0, g, order).unwrap(),
                        alone.returns.stderr(0, 0, g, order).unwrap(),
                    );
                    if !(sa < MAX_REL_SE * a && sb < MAX_REL_SE * b) {
                        continue;
                    }
                    judged += 1;
                    // hypot: the squares of errors near 1e-185 would underflow.
                    let z = (a - b) / sa.hypot(sb);
                    assert!(
                        z.abs() < 4.5,
                        "{names:?} channel {name} gate {} m {order:?}: {a:e} ± {sa:e}, alone {b:e} ± {sb:e}",
                        r.range_m[g]
                    );
                }
            }
        }
        assert!(judged >= 20, "{names:?}: only {judged} bins judged");
    }
}

const HG_CLOUD: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.5
telescope_diameter_m = 1.0
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0, 5.0]
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = 500.0
end_m = 800.0
width_m = 20.0
[[layer]]
name = "cloud"
base_m = 500.0
top_m = 700.0
extinction_per_km = 10.0
single_scattering_albedo = 0.99
phase = { kind = "henyey_greenstein", g = 0.5 }
[simulation]
max_order = 3
"#;

/// Detector-directed importance sampling changes the variance, not the mean. With a mild
/// forward peak (HG g = 0.5: P(0°)/P(180°) = 27, still above the DDIS threshold) plain sampling
/// has no heavy tail and is trustworthy; both estimators of the multiply scattered returns agree
/// within their combined errors. (With HG g = 0.8, P(0°)/P(180°) ≈ 700, plain sampling needs
/// millions of photons before its batch errors can be believed: that is what DDIS is for.)
#[test]
fn ddis_is_unbiased() {
    ddis_agrees_with_plain(&scene_text(HG_CLOUD), 2);
}

/// Plain local estimates and DDIS alone (no alignment splitting, no cone estimate; seed `seed`),
/// 200 000 photons each: multiply scattered returns agree.
fn ddis_agrees_with_plain(scene: &Scene, seed: u64) {
    let plain = run(scene, 200_000, plain_local_estimates);
    let ddis = run(scene, 200_000, |o| {
        o.sim.variance_reduction.ddis_epsilon = 0.3;
        o.sim.variance_reduction.alignment_splitting = 0.0;
        o.sim.variance_reduction.cone_estimate = false;
        o.sim.seed = seed
    });
    multiple_scattering_agrees(&plain, &ddis);
}

/// DDIS in a layer of two scatterers with different phase functions (HG g = 0.6 and 0.2, equal
/// extinction; the mixture's P(0°) = 5.9 is above the DDIS threshold): a direction is drawn from
/// the phase function of one scatterer, picked by its share, so the density of the directions
/// is the mixture's, and the DDIS weight uses the mixture's phase function. Multiply scattered
/// returns agree with plain local estimates of the same scene. (Weighting by the picked
/// scatterer's own phase function moved these returns by less than their errors: the test
/// guards the two-scatterer path, not that choice.)
#[test]
fn ddis_is_unbiased_in_a_mixture_of_scatterers() {
    let text = HG_CLOUD
        .replace("extinction_per_km = 10.0", "extinction_per_km = 5.0")
        .replace("g = 0.5 }", "g = 0.6 }")
        + r#"[[layer]]
name = "cloud, second scatterer"
base_m = 500.0
top_m = 700.0
extinction_per_km = 5.0
single_scattering_albedo = 0.99
phase = { kind = "henyey_greenstein", g = 0.2 }
"#;
    ddis_agrees_with_plain(&scene_text(&text), 7);
}

/// Alignment splitting (a photon split before it scatters, by w·P(Θ_rx) of its direction)
/// changes the variance, not the mean. Its reference set low (0.1, below P(180°) = 0.22 of HG
/// g = 0.5) so that nearly every collision where DDIS applies splits (all with a weight above
/// 0.9): multiply scattered returns agree with plain local estimates.
#[test]
fn alignment_splitting_is_unbiased() {
    let scene = scene_text(HG_CLOUD);
    let plain = run(&scene, 200_000, plain_local_estimates);
    let split = run(&scene, 100_000, |o| {
        o.sim.variance_reduction.ddis_epsilon = 0.3;
        o.sim.variance_reduction.alignment_splitting = 0.1;
        o.sim.variance_reduction.cone_estimate = false;
        o.sim.seed = 4
    });
    eprintln!(
        "{} copies from {} photons",
        split.stats.splits, split.stats.photons
    );
    assert!(
        split.stats.splits > split.stats.photons / 2,
        "{} copies from {} photons: the test does not exercise the splitting",
        split.stats.splits,
        split.stats.photons
    );
    multiple_scattering_agrees(&plain, &split);
}

/// Russian roulette's alignment importance (where DDIS applies, a photon is played at
/// w·P(Θ_rx)/reference instead of w, so that photons heading for the receiver are spared)
/// changes the variance, not the mean. In a strongly forward-peaked cloud (HG g = 0.9,
/// P(0°) = 190) with the reference lowered to 1, so that it spares nearly every photon DDIS
/// turns toward the receiver: energy is conserved in the flux tally (what leaves up and down,
/// is absorbed or is cut at the last gate adds up to what was emitted), every history ends
/// once, and the multiply scattered returns agree with those of roulette on the weight alone
/// (the estimator checked against plain local estimates above; plain local estimates would
/// need millions of photons here).
#[test]
fn roulette_alignment_is_unbiased() {
    let scene = scene_text(&edited(HG_CLOUD, &[("g = 0.5 }", "g = 0.9 }")]));
    let weight_only = run(&scene, 200_000, |o| {
        o.sim.variance_reduction.roulette_alignment = 0.0;
        o.layout.flux = true;
        o.sim.seed = 9
    });
    let spared = run(&scene, 200_000, |o| {
        o.sim.variance_reduction.roulette_alignment = 1.0;
        o.layout.flux = true;
        o.sim.seed = 10
    });
    for (what, mc) in [("weight alone", &weight_only), ("alignment", &spared)] {
        assert_energy_conserved(what, mc);
        assert_histories_end_once(what, &mc.stats);
    }
    // It acts: the photons it spares scatter on (16 % more collisions in the same number of
    // photons; those spared are ended later, so the number of roulette kills hardly changes).
    let (a, b) = (&weight_only.stats, &spared.stats);
    eprintln!("collisions {} → {}", a.collisions, b.collisions);
    assert!(
        b.collisions > a.collisions + a.collisions / 20,
        "collisions {} → {}: the test does not exercise the importance",
        a.collisions,
        b.collisions
    );
    multiple_scattering_agrees(&weight_only, &spared);
}

/// The cone estimate (a virtual last scattering drawn inside each field of view, combined with
/// the walk's own local estimates by the balance heuristic) changes the variance, not the mean:
/// with every variance reduction on, orders 2, 3, 4+ and the total agree with plain local
/// estimates (no DDIS, no cone estimate) in every gate and field of view both resolve.
#[test]
fn cone_estimate_is_unbiased() {
    cone_agrees_with_plain(&scene_text(HG_CLOUD));
}

/// Plain local estimates (400 000 photons) and every variance reduction on (100 000, seed 3):
/// multiply scattered returns agree.
fn cone_agrees_with_plain(scene: &Scene) {
    let plain = plain_reference(scene);
    let cone = run(scene, 100_000, |o| o.sim.seed = 3);
    multiple_scattering_agrees(&plain, &cone);
}

/// The crossing estimate (the walk's next local estimate in expectation over where along the
/// flight it collides inside the fields of view) and the DDIS crossing (the same along a
/// direction drawn about the receiver's at every DDIS scattering, combined with the walk's by
/// the balance heuristic) change the variance, not the mean: alone (no cone estimate, so they
/// serve both fields of view) and with the cone estimate at its rate (it serves the 1 mrad
/// field of view, they the 20 mrad one), multiply scattered returns agree with plain local
/// estimates.
#[test]
fn crossing_estimates_are_unbiased() {
    // 20 mrad: a footprint of optical depth 0.07, beyond the cone estimate's 0.03.
    let scene = scene_text(&HG_CLOUD.replace("[1.0, 5.0]", "[1.0, 20.0]"));
    let plain = plain_reference(&scene);
    let crossing = run(&scene, 100_000, |o| {
        o.sim.variance_reduction.cone_estimate = false;
        o.sim.seed = 5
    });
    multiple_scattering_agrees(&plain, &crossing);
    let both = run(&scene, 100_000, |o| o.sim.seed = 6);
    multiple_scattering_agrees(&plain, &both);
}

/// The cone estimate in a strongly forward-peaked cloud (HG g = 0.9). The walk's own local
/// estimates inside a field of view are weighted against the cone estimate from the previous
/// collision by the balance heuristic, and here they keep a large share: without them the
/// double scattering at 5 mrad is about a fifth lower (4 % at g = 0.5), so the two weights must
/// add up to one. The reference is the same scene without the cone estimate (DDIS and the
/// crossing estimates, each checked against plain local estimates above); plain local
/// estimates would need millions of photons here, where P(0°)/P(180°) = 6859.
#[test]
fn cone_estimate_is_unbiased_in_a_forward_peaked_cloud() {
    let scene = scene_text(&edited(HG_CLOUD, &[("g = 0.5 }", "g = 0.9 }")]));
    let reference = run(&scene, 400_000, |o| {
        o.sim.variance_reduction.cone_estimate = false;
        o.sim.seed = 8
    });
    let cone = run(&scene, 100_000, |o| o.sim.seed = 3);
    multiple_scattering_agrees(&reference, &cone);
}

/// The cone estimate seen from above: a lidar at 2 km looking down on the cloud (now 1300 to
/// 1500 m), over a layer of optical depth 40 far below the gates (isotropic, so it does not
/// narrow the fields of view the cone estimate serves). Optical depths are cumulative from the
/// ground, so the receiver's is 42, not 0, and the distance in optical depth from a collision to
/// the receiver, which decides whether the cone estimate is worth making, must be taken from it.
/// Multiply scattered returns agree with plain local estimates.
#[test]
fn cone_estimate_is_unbiased_seen_from_above_an_optically_thick_column() {
    let text = edited(
        HG_CLOUD,
        &[
            (
                "altitude_m = 0.0\nzenith_angle_deg = 0.0",
                "altitude_m = 2000.0\nzenith_angle_deg = 180.0",
            ),
            (
                "base_m = 500.0\ntop_m = 700.0",
                "base_m = 1300.0\ntop_m = 1500.0",
            ),
        ],
    ) + r#"[[layer]]
name = "fog"
base_m = 0.0
top_m = 100.0
extinction_per_km = 400.0
single_scattering_albedo = 1.0
phase = { kind = "henyey_greenstein", g = 0.0 }
"#;
    cone_agrees_with_plain(&scene_text(&text));
}

/// The cone estimate on a slant path: the lidar of [`HG_CLOUD`] tilted 60° from the zenith, so
/// the cloud (500 to 700 m up) lies 1000 to 1400 m along the beam. The cone estimate's rays
/// cross the layers over a range 1/cos θ of their depth. Multiply scattered returns agree
/// with plain local estimates.
#[test]
fn cone_estimate_is_unbiased_on_a_slant_path() {
    let text = edited(
        HG_CLOUD,
        &[
            ("zenith_angle_deg = 0.0", "zenith_angle_deg = 60.0"),
            (
                "start_m = 500.0\nend_m = 800.0\nwidth_m = 20.0",
                "start_m = 1000.0\nend_m = 1600.0\nwidth_m = 40.0",
            ),
        ],
    );
    cone_agrees_with_plain(&scene_text(&text));
}

/// Two channels that scatter alike, 10 and 11 km⁻¹: one scattering class, whose second channel
/// carries the ratio (σ_1/σ_0) e^{−(τ_1 − τ_0)} of its scattering to channel 0's (ALIS). The
/// crossing estimate's point, drawn on channel 0's optical depth along the flight, must carry
/// that ratio too. Alone (no cone estimate, so it serves both fields of view), the multiply
/// scattered returns of both channels agree with plain local estimates.
#[test]
fn crossing_estimate_is_unbiased_for_channels_that_scatter_alike() {
    let text = edited(
        HG_CLOUD,
        &[
            ("[1.0, 5.0]", "[1.0, 20.0]"),
            (
                "[[channel]]\nname = \"a\"\nwavelength_nm = 1064.0\n",
                "[[channel]]\nname = \"a\"\nwavelength_nm = 1064.0\n\
                 [[channel]]\nname = \"b\"\nwavelength_nm = 1064.0\n",
            ),
            (
                "extinction_per_km = 10.0",
                "extinction_per_km = [10.0, 11.0]",
            ),
        ],
    );
    let scene = scene_text(&text);
    let plain = plain_reference(&scene);
    let crossing = run(&scene, 100_000, |o| {
        o.sim.variance_reduction.cone_estimate = false;
        o.sim.seed = 5
    });
    multiple_scattering_agrees(&plain, &crossing);
}

/// The reference the variance reductions are checked against: plain local estimates, without
/// range stratification, over 400 000 photons.
fn plain_reference(scene: &Scene) -> McResult {
    run(scene, 400_000, |o| {
        plain_local_estimates(o);
        o.sim.variance_reduction.range_stratification = 0.0;
    })
}

/// Plain local estimates: no DDIS (and so no alignment splitting or DDIS crossing), no cone or
/// crossing estimate; the reference the variance reductions are checked against.
fn plain_local_estimates(o: &mut Knobs) {
    o.sim.variance_reduction.ddis_epsilon = 0.0;
    o.sim.variance_reduction.alignment_splitting = 0.0;
    o.sim.variance_reduction.roulette_alignment = 0.0;
    o.sim.variance_reduction.cone_estimate = false;
    o.sim.variance_reduction.crossing_estimate = false;
    o.sim.variance_reduction.ddis_crossing = false;
}

/// Every (channel, field of view, gate) of a run's returns.
fn bins(r: &Returns) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
    let (nf, ng) = (r.fov_full_angle_mrad.len(), r.range_m.len());
    (0..r.channels.len())
        .flat_map(move |k| (0..nf).flat_map(move |f| (0..ng).map(move |g| (k, f, g))))
}

/// Orders 2, 3, 4+ and the total of two runs of one scene agree within 4.5 combined standard
/// errors, in every channel, wherever both resolve them to 10 %.
fn multiple_scattering_agrees(a: &McResult, b: &McResult) {
    let r = &a.returns;
    let mut judged = 0;
    let mut chi2 = 0.0;
    for (k, f, g) in bins(r) {
        for order in [
            Order::Exactly(2),
            Order::Exactly(3),
            Order::AtLeast(4),
            Order::Total,
        ] {
            let (x, sx) = (
                r.energy(k, f, g, order).unwrap(),
                r.stderr(k, f, g, order).unwrap(),
            );
            let (y, sy) = (
                b.returns.energy(k, f, g, order).unwrap(),
                b.returns.stderr(k, f, g, order).unwrap(),
            );
            if !(sx < MAX_REL_SE * x && sy < MAX_REL_SE * y) {
                continue;
            }
            let z = (x - y) / (sx * sx + sy * sy).sqrt();
            judged += 1;
            chi2 += z * z;
            assert!(
                z.abs() < 4.5,
                "channel {k} FOV {f} gate {g} {order:?}: {x:e} ± {sx:e} vs {y:e} ± {sy:e}"
            );
        }
    }
    assert!(judged > 20, "{judged}");
    // The z are correlated across orders, so only a loose check of their spread.
    eprintln!("{judged} bins judged, mean z² = {}", chi2 / judged as f64);
    assert!(
        chi2 / (judged as f64) < 2.0,
        "mean z² = {}",
        chi2 / judged as f64
    );
}

/// A CO2 DIAL scene (scenes/airborne_co2_dial.toml: built-in band model, on-line on R16e,
/// off-line in the trough) takes its absorption from the line-by-line stage, and the Monte Carlo on/off ratio
/// equals the two-way differential transmission exp(−2∫(k_on − k_off) dr). The truth is computed
/// here independently of the optics and transport: Curtis-Godson layers of 10 m straight from the
/// scene's profile (the optics use 100 m layers).
#[test]
fn co2_dial_on_off_ratio_equals_differential_transmission() {
    use lidarsim::spectroscopy::layer_optical_depths_at;
    let scene =
        Scene::read(&crate::util::project_root().join("scenes/airborne_co2_dial.toml")).unwrap();
    let gas = scene
        .gas
        .as_ref()
        .expect("the airborne scene has gas absorption");
    let profile = &scene.atmosphere.as_ref().unwrap().profile;
    let nu: Vec<f64> = scene.channels.iter().map(|c| c.wavenumber_cm1).collect();
    let z_lidar = scene.lidar.altitude_m;
    let edges: Vec<f64> = (0..=800).map(|i| i as f64 * 10.0).collect();
    assert_eq!(*edges.last().unwrap(), z_lidar);
    let tau = layer_optical_depths_at(profile, &gas.lines, &edges, &nu, &gas.options).unwrap();
    // Differential optical depth from the aircraft down to altitude z (nadir: range = 8000 − z).
    let dtau_down_to = |z: f64| -> f64 {
        tau.iter()
            .enumerate()
            .map(|(l, t)| {
                let (a, b) = (edges[l], edges[l + 1]);
                let frac = ((b - z.max(a)) / (b - a)).clamp(0.0, 1.0);
                (t[0] - t[1]) * frac
            })
            .sum()
    };
    let mc = run(&scene, 200_000, |_| {});
    let r = &mc.returns;
    let ratio = |g: usize| {
        r.energy(0, 0, g, Order::Exactly(1)).unwrap()
            / r.energy(1, 0, g, Order::Exactly(1)).unwrap()
    };
    // Hard target: the gate holding the surface at 8000 m range; its atmospheric share is ~1e-4.
    let g_surface = ((8000.0 - scene.gates.start_m) / scene.gates.width_m) as usize;
    let truth = (-2.0 * dtau_down_to(0.0)).exp();
    let daod = 0.5 * (1.0 / ratio(g_surface)).ln();
    assert!(truth < 0.5, "the on-line must absorb: T² ratio {truth}");
    assert!(
        (ratio(g_surface) / truth - 1.0).abs() < 2e-3,
        "surface: MC {} vs {truth}",
        ratio(g_surface)
    );
    assert!(
        (daod / dtau_down_to(0.0) - 1.0).abs() < 2e-3,
        "DAOD {daod} vs {}",
        dtau_down_to(0.0)
    );
    // Range-resolved: gates in the boundary-layer aerosol (the off-line's relative error below
    // 10 %), truth at the gate centre; the ratio varies by 2Δk·Δr ≈ 0.4 % across a 20 m gate.
    let mut judged = 0;
    for g in 0..r.range_m.len() {
        let range = r.range_m[g];
        let z = z_lidar - range;
        let se = r.stderr(1, 0, g, Order::Exactly(1)).unwrap();
        let e = r.energy(1, 0, g, Order::Exactly(1)).unwrap();
        if !(z > 50.0 && z < 1500.0 && se < MAX_REL_SE * e) {
            continue;
        }
        judged += 1;
        let truth = (-2.0 * dtau_down_to(z)).exp();
        assert!(
            (ratio(g) / truth - 1.0).abs() < 6e-3,
            "z = {z} m: MC ratio {} vs {truth}",
            ratio(g)
        );
    }
    assert!(judged > 50, "{judged} gates judged");
}

/// With a cached gas table, the second run computes no line-by-line absorption although its
/// gates, geometry and channels (inside the table's grid) changed, and its optical depths equal
/// those of a direct line-by-line computation to the table's interpolation accuracy.
#[test]
fn cached_gas_table_is_reused_when_gates_geometry_and_channels_change() {
    use lidarsim::optics::GasSource;
    let dir = tempfile::tempdir().unwrap();
    let airborne =
        std::fs::read_to_string(crate::util::project_root().join("scenes/airborne_co2_dial.toml"))
            .unwrap();
    let base = airborne.replacen(
        "molecules = [\"CO2\"]",
        "molecules = [\"CO2\"]\ntable = \"co2.tau\"\ntable_start_cm1 = 6358.0\ntable_end_cm1 = 6363.0",
        1,
    );
    assert_ne!(base, airborne);
    let path = dir.path().join("dial.toml");
    let build = |text: &str| {
        std::fs::write(&path, text).unwrap();
        let scene = Scene::read(&path).unwrap();
        (OpticalAtmosphere::build(&scene).unwrap(), scene)
    };
    let (first, _) = build(&base);
    assert_eq!(first.gas_source, Some(GasSource::TableComputed));
    // New gates, a slant view from another altitude, and a new on-line inside the grid.
    let changed = base
        .replacen("end_m = 8100.0", "end_m = 7100.0", 1)
        .replacen("zenith_angle_deg = 180.0", "zenith_angle_deg = 160.0", 1)
        .replacen("altitude_m = 8000.0", "altitude_m = 7000.0", 1)
        .replacen("wavenumber_cm1 = 6359.967", "wavenumber_cm1 = 6359.95", 1)
        // The surface leaves the gates: no IPDA target any more (DIAL only).
        .replacen("target = \"surface\"\n", "", 1);
    let (second, scene) = build(&changed);
    assert_eq!(second.gas_source, Some(GasSource::TableReused));
    // Against the direct line-by-line path (no table) for the changed scene.
    let direct = lidarsim::scene::Scene::from_toml(
        &path,
        &changed.replacen(
            "table = \"co2.tau\"\ntable_start_cm1 = 6358.0\ntable_end_cm1 = 6363.0",
            "",
            1,
        ),
    )
    .unwrap();
    let direct = OpticalAtmosphere::build(&direct).unwrap();
    assert_eq!(direct.gas_source, Some(GasSource::Direct));
    for k in 0..scene.channels.len() {
        let (_, a_table) = second.cumulative_tau(1e9, k);
        let (_, a_direct) = direct.cumulative_tau(1e9, k);
        assert!(
            (a_table / a_direct - 1.0).abs() < 1e-4,
            "channel {k}: {a_table} vs {a_direct}"
        );
    }
}
