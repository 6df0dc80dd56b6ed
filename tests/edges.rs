//! Edge-case scenes: the analytic single-scatter lidar equation
//! (`lidar_eq::single_scatter`) and the Monte Carlo (`transport::run`) each against an
//! independent truth, and against each other, where the beam meets no scatterer (gates below,
//! between and above particle layers; a lidar inside a gap; a downward beam with no surface,
//! past the ground), along slant paths up to 89° from the zenith, and through an optically
//! thick layer entered in the middle of a gate.
//!
//! The scenes hold particle layers only (no `[atmosphere]`: no molecules, no gases), so the
//! truth is written here from the closed form alone: E = E₀ η A_tel O ∫ β e^{−2τ(r)}/r² dr with
//! β = ϖ σ P(180°)/(4π) per layer (isotropic P = 1, Henyey-Greenstein P(180°) = (1 − g)/(1 + g)²),
//! τ(r) = Σ σ_l · (the part of the altitude interval [z₀, z₀ + μr] inside layer l)/|μ|, and
//! O = (1 − cos α)/(1 − cos β) for a uniform beam of half-angle β wider than the field of view's
//! α (1 otherwise), integrated by a fine midpoint rule on each piece of a gate inside one layer
//! (the integrand is discontinuous at layer edges).
//!
//! Tolerances and truths:
//! - analytic against that quadrature: 1e-8 relative in every gate with signal (the quadrature's
//!   own error is below 1e-10: h²/24 · |f″/f| with the step counts used), and exactly 0 where
//!   the beam meets no layer inside the gate;
//! - Monte Carlo order 1 against the analytic: the rule of `transport::check_order1`
//!   (|MC − analytic| ≤ 4σ + 1 % of the analytic, judged where the batch relative standard
//!   error is below 10 %), applied to every gate with any signal, not only those above 1e-4 of
//!   the largest;
//! - exact zeros in the Monte Carlo (energy and standard error 0.0), from the geometry of the
//!   paths: the apparent range of a return is half its path, at least the distance of its
//!   farthest scattering, and every path starts by scattering on the beam. So gates ending
//!   before the beam's first layer receive nothing in any order. A single scattering at range
//!   r arrives at r; a double scattering (first point in the beam cone, half-angle b, last in
//!   the field of view, half-angle a, at distances d₁, d₂) at most max(d₁, d₂) + √(d₁d₂)(a + b)/2,
//!   under 2 m here; so orders 1 and 2 are exactly 0 in gates more than `MARGIN_M` clear of
//!   every layer's stretch of the beam. Orders ≥ 3 are not zero there: a photon may wander
//!   sideways inside a layer and come back into the field of view late, so its apparent range
//!   can fall in a gap or beyond the last layer (it is only checked finite and non-negative).
//!
//! Seeds are fixed; photon counts keep the module to a few seconds on two cores.

use lidarsim::returns::{Order, Returns};
use lidarsim::scene::Scene;

use crate::transport::{K_SIGMA, MAX_REL_SE, REL_SLACK, analytic, check_order1, run, scene_text};

/// Analytic against the quadrature.
const REL_TOL_ANALYTIC: f64 = 1e-8;
/// Clearance of a gate from a layer's stretch of the beam for exact zeros of orders 1 and 2
/// (the excess of a double scattering's apparent range is below 2 m in these scenes).
const MARGIN_M: f64 = 10.0;

const PULSE_J: f64 = 0.1;
const EFFICIENCY: f64 = 0.7;
const TELESCOPE_M: f64 = 0.4;

#[derive(Clone, Copy, Debug)]
enum Phase {
    Isotropic,
    Hg(f64),
}

impl Phase {
    /// P(180°), normalised to 4π over the sphere.
    fn back(self) -> f64 {
        match self {
            Phase::Isotropic => 1.0,
            Phase::Hg(g) => (1.0 - g) / ((1.0 + g) * (1.0 + g)),
        }
    }
    fn toml(self) -> String {
        match self {
            Phase::Isotropic => r#"{ kind = "isotropic" }"#.into(),
            Phase::Hg(g) => format!(r#"{{ kind = "henyey_greenstein", g = {g:?} }}"#),
        }
    }
}

/// A homogeneous particle layer.
#[derive(Clone, Copy, Debug)]
struct Slab {
    base_m: f64,
    top_m: f64,
    extinction_per_m: f64,
    albedo: f64,
    phase: Phase,
}

impl Slab {
    /// Backscatter coefficient [1/(m sr)].
    fn beta(&self) -> f64 {
        self.extinction_per_m * self.albedo * self.phase.back() / (4.0 * std::f64::consts::PI)
    }
}

/// A scene: a lidar, gates and particle layers.
#[derive(Clone, Debug)]
struct Setup {
    altitude_m: f64,
    zenith_deg: f64,
    divergence_mrad: f64,
    fovs_mrad: Vec<f64>,
    start_m: f64,
    width_m: f64,
    count: usize,
    slabs: Vec<Slab>,
}

impl Setup {
    fn text(&self) -> String {
        let fovs: Vec<String> = self.fovs_mrad.iter().map(|f| format!("{f:?}")).collect();
        let mut t = format!(
            "[lidar]\naltitude_m = {:?}\nzenith_angle_deg = {:?}\npulse_energy_j = {PULSE_J:?}\n\
             beam_divergence_full_angle_mrad = {:?}\ntelescope_diameter_m = {TELESCOPE_M:?}\n\
             optical_efficiency = {EFFICIENCY:?}\nfov_full_angle_mrad = [{}]\n\
             [[channel]]\nname = \"a\"\nwavelength_nm = 1064.0\n\
             [gates]\nstart_m = {:?}\nend_m = {:?}\nwidth_m = {:?}\n",
            self.altitude_m,
            self.zenith_deg,
            self.divergence_mrad,
            fovs.join(", "),
            self.start_m,
            self.start_m + self.width_m * self.count as f64,
            self.width_m,
        );
        for (i, s) in self.slabs.iter().enumerate() {
            t += &format!(
                "[[layer]]\nname = \"l{i}\"\nbase_m = {:?}\ntop_m = {:?}\nextinction_per_m = {:?}\n\
                 single_scattering_albedo = {:?}\nphase = {}\n",
                s.base_m,
                s.top_m,
                s.extinction_per_m,
                s.albedo,
                s.phase.toml()
            );
        }
        t
    }

    fn scene(&self) -> Scene {
        let scene = scene_text(&self.text());
        assert_eq!(scene.gates.count, self.count);
        scene
    }

    fn mu(&self) -> f64 {
        self.zenith_deg.to_radians().cos()
    }

    fn gate(&self, g: usize) -> (f64, f64) {
        let a = self.start_m + g as f64 * self.width_m;
        (a, a + self.width_m)
    }

    /// One-way optical depth from the lidar to range r along the axis, from the layers' vertical
    /// extents and the slant factor 1/|μ| (`mutant`: the slant factor |μ| instead).
    fn tau(&self, r: f64, mutant: bool) -> f64 {
        let mu = self.mu();
        let z1 = self.altitude_m + mu * r;
        let (lo, hi) = (self.altitude_m.min(z1), self.altitude_m.max(z1));
        let vertical: f64 = self
            .slabs
            .iter()
            .map(|s| s.extinction_per_m * (hi.min(s.top_m) - lo.max(s.base_m)).max(0.0))
            .sum();
        if mutant {
            vertical * mu.abs()
        } else {
            vertical / mu.abs()
        }
    }

    /// The stretch of the beam (ranges) inside each layer it crosses.
    fn stretches(&self) -> Vec<(f64, f64, Slab)> {
        let mu = self.mu();
        self.slabs
            .iter()
            .filter_map(|s| {
                let (r1, r2) = (
                    (s.base_m - self.altitude_m) / mu,
                    (s.top_m - self.altitude_m) / mu,
                );
                let (lo, hi) = (r1.min(r2).max(0.0), r1.max(r2));
                (hi > lo).then_some((lo, hi, *s))
            })
            .collect()
    }

    /// Overlap of the uniform beam with a field of view (full angles).
    fn overlap(&self, fov_mrad: f64) -> f64 {
        let (a, b) = (0.5e-3 * fov_mrad, 0.5e-3 * self.divergence_mrad);
        if a >= b {
            1.0
        } else {
            // 1 − cos x = 2 sin²(x/2), without cancellation.
            (0.5 * a).sin().powi(2) / (0.5 * b).sin().powi(2)
        }
    }

    /// E₀ η A ∫_gate β e^{−2τ}/r² dr for an overlap of 1: a midpoint rule with `steps` points
    /// on each piece of the gate inside one layer (`mutant`: τ with the slant factor |μ|).
    fn reference(&self, g: usize, steps: usize, mutant: bool) -> f64 {
        let (ra, rb) = self.gate(g);
        let area = std::f64::consts::PI * 0.25 * TELESCOPE_M * TELESCOPE_M;
        let mut integral = 0.0;
        for (lo, hi, slab) in self.stretches() {
            let (a, b) = (ra.max(lo), rb.min(hi));
            if b <= a {
                continue;
            }
            let h = (b - a) / steps as f64;
            let piece: f64 = (0..steps)
                .map(|i| {
                    let r = a + (i as f64 + 0.5) * h;
                    (-2.0 * self.tau(r, mutant)).exp() / (r * r)
                })
                .sum();
            integral += slab.beta() * piece * h;
        }
        PULSE_J * EFFICIENCY * area * integral
    }

    /// Gates that end before the beam reaches its first layer: no return in any order.
    fn before_first_layer(&self, g: usize) -> bool {
        let first = self
            .stretches()
            .iter()
            .map(|s| s.0)
            .fold(f64::INFINITY, f64::min);
        self.gate(g).1 <= first - MARGIN_M
    }

    /// Gates at least `MARGIN_M` clear of every layer's stretch of the beam: no single or double
    /// scattering.
    fn clear_of_layers(&self, g: usize) -> bool {
        let (ra, rb) = self.gate(g);
        self.stretches()
            .iter()
            .all(|(lo, hi, _)| rb <= lo - MARGIN_M || ra >= hi + MARGIN_M)
    }
}

/// What a scene's checks measured.
#[derive(Debug, Default)]
struct Measured {
    /// Largest relative difference analytic vs quadrature.
    worst_rel: f64,
    /// Gates with signal (quadrature > 0) per FOV, summed over FOVs.
    with_signal: usize,
    /// Gates (× FOV) where orders 1 and 2 are exactly zero, and where all orders are.
    zero_12: usize,
    zero_all: usize,
    /// MC bins judged against the analytic, and the worst |z|.
    judged: usize,
    worst_z: f64,
    /// Largest Monte Carlo total (orders ≥ 3) in a gate clear of the layers, relative to the
    /// largest order-1 return (reported, not judged).
    late_share: f64,
}

/// The analytic against the quadrature (1e-8; exact zeros where the beam meets no layer in the
/// gate), the Monte Carlo's exact zeros, and its order 1 against the analytic gate by gate.
fn check(name: &str, setup: &Setup, photons: u64, seed: u64, steps: usize) -> Measured {
    let scene = setup.scene();
    let an = analytic(&scene);
    let mut m = Measured::default();
    let mut failures = Vec::new();
    for g in 0..setup.count {
        let reference = setup.reference(g, steps, false);
        for (f, fov) in setup.fovs_mrad.iter().enumerate() {
            let truth = reference * setup.overlap(*fov);
            let a = an.energy(0, f, g, Order::Exactly(1)).unwrap();
            if truth == 0.0 {
                if a != 0.0 {
                    failures.push(format!(
                        "gate {:?}: analytic {a:e}, no layer",
                        setup.gate(g)
                    ));
                }
                continue;
            }
            m.with_signal += 1;
            let rel = (a / truth - 1.0).abs();
            m.worst_rel = m.worst_rel.max(rel);
            if !(rel <= REL_TOL_ANALYTIC) {
                failures.push(format!(
                    "gate {:?} FOV {fov}: analytic {a:.12e}, quadrature {truth:.12e} ({rel:.1e})",
                    setup.gate(g)
                ));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{name}: analytic vs quadrature:\n{}",
        failures.join("\n")
    );
    assert!(m.with_signal > 0, "{name}: no gate with signal");

    let mc = run(&scene, photons, |o| o.sim.seed = seed).returns;
    assert!(
        mc.energy_j
            .iter()
            .chain(&mc.stderr_j)
            .all(|v| v.is_finite() && *v >= 0.0),
        "{name}: non-finite or negative Monte Carlo returns"
    );
    for g in 0..setup.count {
        for f in 0..setup.fovs_mrad.len() {
            let orders: &[Order] = if setup.before_first_layer(g) {
                m.zero_all += 1;
                &[Order::Total, Order::Exactly(1), Order::Exactly(2)]
            } else if setup.clear_of_layers(g) {
                m.zero_12 += 1;
                m.late_share = m.late_share.max(mc.energy(0, f, g, Order::Total).unwrap());
                &[Order::Exactly(1), Order::Exactly(2)]
            } else {
                &[]
            };
            for o in orders {
                let (e, se) = (
                    mc.energy(0, f, g, *o).unwrap(),
                    mc.stderr(0, f, g, *o).unwrap(),
                );
                if e != 0.0 || se != 0.0 {
                    failures.push(format!(
                        "gate {:?} FOV {f} {o:?}: MC {e:e} ± {se:e}, truth 0",
                        setup.gate(g)
                    ));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{name}: Monte Carlo where nothing can return:\n{}",
        failures.join("\n")
    );
    check_order1(name, &mc, &an);
    (m.judged, m.worst_z) = order1_against(name, &mc, &an);
    m.late_share /= an.energy_j.iter().fold(0.0, |a: f64, b| a.max(*b));
    eprintln!("{name}: {m:?}");
    m
}

/// Monte Carlo order 1 against the analytic in every bin with any signal, by the rule of
/// `check_order1`; returns the bins judged and the worst |z|.
fn order1_against(name: &str, mc: &Returns, an: &Returns) -> (usize, f64) {
    let (mut judged, mut worst) = (0, 0.0f64);
    let mut failures = Vec::new();
    for f in 0..an.fov_full_angle_mrad.len() {
        for g in 0..an.range_m.len() {
            let a = an.energy(0, f, g, Order::Exactly(1)).unwrap();
            let m = mc.energy(0, f, g, Order::Exactly(1)).unwrap();
            let se = mc.stderr(0, f, g, Order::Exactly(1)).unwrap();
            if !(a > 0.0 && m > 0.0 && se <= MAX_REL_SE * m) {
                continue;
            }
            judged += 1;
            let z = (m - a) / se;
            worst = worst.max(z.abs());
            if (m - a).abs() > K_SIGMA * se + REL_SLACK * a {
                failures.push(format!(
                    "FOV {} gate {} m: MC {m:.5e} ± {se:.2e}, analytic {a:.5e} ({z:+.2} σ)",
                    an.fov_full_angle_mrad[f], an.range_m[g]
                ));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{name}: {} bins disagree:\n{}",
        failures.len(),
        failures.join("\n")
    );
    (judged, worst)
}

/// Two layers with a gap: isotropic haze 1000–2000 m, a Henyey-Greenstein layer 3000–4000 m.
fn two_layers() -> Vec<Slab> {
    vec![
        Slab {
            base_m: 1000.0,
            top_m: 2000.0,
            extinction_per_m: 2e-4,
            albedo: 0.95,
            phase: Phase::Isotropic,
        },
        Slab {
            base_m: 3000.0,
            top_m: 4000.0,
            extinction_per_m: 5e-4,
            albedo: 0.85,
            phase: Phase::Hg(0.6),
        },
    ]
}

/// 100 m gates offset by 50 m, so that every layer edge falls in the middle of a gate.
fn layered(altitude_m: f64, zenith_deg: f64, count: usize) -> Setup {
    Setup {
        altitude_m,
        zenith_deg,
        divergence_mrad: 0.2,
        fovs_mrad: vec![0.1, 0.5],
        start_m: 150.0,
        width_m: 100.0,
        count,
        slabs: two_layers(),
    }
}

/// A ground lidar looking up through layers at 1000–2000 m and 3000–4000 m, gates 150–5050 m
/// (layer edges mid-gate), FOVs 0.1 mrad (overlap 1/4 with the 0.2 mrad beam) and 0.5 mrad:
/// the analytic equals the quadrature in the layers and is exactly 0 below, in the gap and
/// above; the Monte Carlo is exactly 0 in every order below 1000 m, in orders 1 and 2 in the
/// gap and above 4000 m, and its order 1 equals the analytic in the layers.
#[test]
fn gates_below_inside_a_gap_and_above_the_layers() {
    let setup = layered(0.0, 0.0, 49);
    let m = check("ground, up", &setup, 300_000, 11, 20_000);
    // Below: 150–950 m (8 gates); gap: 2050–2950 (9); above: 4050–5050 (10); two FOVs.
    assert_eq!(m.zero_all, 2 * 8, "{m:?}");
    assert_eq!(m.zero_12, 2 * (9 + 10), "{m:?}");
    assert!(m.judged >= 30, "{m:?}");
}

/// A lidar inside the gap (2500 m) looking up and looking down (no surface): each sees one
/// layer from 500 to 1500 m range; the analytic equals the quadrature there and is 0 elsewhere;
/// the Monte Carlo is exactly 0 in every order before 500 m and in orders 1 and 2 beyond
/// 1500 m, and its order 1 equals the analytic in the layer.
#[test]
fn lidar_inside_the_gap_looking_up_and_down() {
    for (zenith, seed) in [(0.0, 12), (180.0, 13)] {
        let mut setup = layered(2500.0, zenith, 24);
        setup.start_m = 50.0;
        let name = format!("in the gap, zenith {zenith}");
        let m = check(&name, &setup, 200_000, seed, 20_000);
        // Before: 50–450 m (4 gates); beyond: 1550–2450 m (9); two FOVs.
        assert_eq!(m.zero_all, 2 * 4, "{name}: {m:?}");
        assert_eq!(m.zero_12, 2 * 9, "{name}: {m:?}");
        assert!(m.judged >= 15, "{name}: {m:?}");
    }
}

/// A downward beam from 6000 m with no surface, gates 150–7550 m (down to z = −1550 m, below
/// the ground): the layers at 2000–3000 m and 4000–5000 m range equal the quadrature, nothing
/// returns before 2000 m in any order, nor in orders 1 and 2 in the gap or beyond 5000 m (past
/// the ground too), and the Monte Carlo's order 1 equals the analytic.
#[test]
fn downward_beam_without_surface_past_the_ground() {
    let setup = layered(6000.0, 180.0, 74);
    let m = check("down from 6000 m", &setup, 300_000, 14, 20_000);
    // Before: 150–1950 m (18 gates); gap 3050–3950 (9); beyond: 5050–7550 (25); two FOVs.
    assert_eq!(m.zero_all, 2 * 18, "{m:?}");
    assert_eq!(m.zero_12, 2 * (9 + 25), "{m:?}");
    assert!(m.judged >= 30, "{m:?}");
}

/// Slant paths at zenith 0°, 30°, 60° and 89° through one layer (1000–2000 m, σ = 1e-3 /m,
/// ϖ = 0.9, slant optical depth 1 to 57): 40 gates across its slant range base/μ to top/μ
/// (57–115 km at 89°), its base mid-gate. The analytic equals the quadrature with τ(r) =
/// σ (r − base/μ) to 1e-8, the Monte Carlo's order 1 equals the analytic gate by gate, and
/// (the test's power) a slant factor μ in place of 1/μ would move the analytic far beyond both
/// tolerances. Pencil beam: the analytic takes every ray at the axis' μ, which a diverging
/// beam at 89° would not be (a 0.1 mrad half-angle changes μ by 0.6 %).
#[test]
fn slant_paths_at_0_30_60_and_89_degrees() {
    let slab = Slab {
        base_m: 1000.0,
        top_m: 2000.0,
        extinction_per_m: 1e-3,
        albedo: 0.9,
        phase: Phase::Hg(0.3),
    };
    for (zenith, seed) in [(0.0, 21), (30.0, 22), (60.0, 23), (89.0, 24)] {
        let mu = f64::cos(f64::to_radians(zenith));
        let (r_base, r_top) = (slab.base_m / mu, slab.top_m / mu);
        let width_m = (r_top - r_base) / 40.0;
        let setup = Setup {
            altitude_m: 0.0,
            zenith_deg: zenith,
            divergence_mrad: 0.0,
            fovs_mrad: vec![0.2],
            start_m: r_base - 2.5 * width_m,
            width_m,
            count: 45,
            slabs: vec![slab],
        };
        let name = format!("slant, zenith {zenith}");
        let m = check(&name, &setup, 200_000, seed, 100_000);
        assert_eq!(m.zero_all, 2, "{name}: {m:?}");
        assert_eq!(m.zero_12, 2, "{name}: {m:?}");
        assert_eq!(m.with_signal, 41, "{name}: {m:?}");
        assert!(m.judged >= 4, "{name}: {m:?}");
        // The test's power: with the slant factor |μ| in τ instead of 1/|μ|, the middle of the
        // layer (gate 22, τ = 0.5/μ against 0.5 μ) would be off by 25 % at 30° and far more
        // beyond, against a tolerance of 1e-8 (analytic) and a few per cent (Monte Carlo).
        if zenith > 0.0 {
            let an = analytic(&setup.scene());
            let g = 22;
            let (a, mutant) = (
                an.energy(0, 0, g, Order::Exactly(1)).unwrap(),
                setup.reference(g, 100_000, true),
            );
            assert!(
                !((a - mutant).abs() <= 0.2 * a),
                "{name}: the slant factor μ would not be seen: {a:e} vs {mutant:e}"
            );
        }
    }
}

/// An optically thick layer: σ = 0.05 /m from 1000 to 1600 m (optical depth 30), 300 m gates
/// from 850 m (15 optical depths per gate), the beam entering mid-gate at 1000 m and leaving
/// mid-gate at 1600 m. The analytic equals a midpoint rule of 10⁶ steps per gate piece to 1e-8
/// in every gate (down to e^{−45} of the first), and the Monte Carlo's order 1 equals it in every
/// gate it resolves to 10 % (range stratification reaches the deep gates).
#[test]
fn optically_thick_layer_entered_mid_gate() {
    let setup = Setup {
        altitude_m: 0.0,
        zenith_deg: 0.0,
        divergence_mrad: 0.2,
        fovs_mrad: vec![1.0],
        start_m: 850.0,
        width_m: 300.0,
        count: 4,
        slabs: vec![Slab {
            base_m: 1000.0,
            top_m: 1600.0,
            extinction_per_m: 0.05,
            albedo: 0.6,
            phase: Phase::Isotropic,
        }],
    };
    let m = check("thick layer", &setup, 200_000, 31, 1_000_000);
    assert_eq!(m.with_signal, 3, "{m:?}");
    assert_eq!(m.zero_12, 1, "{m:?}");
    assert!(m.judged >= 2, "{m:?}");
}

/// A horizontal beam (zenith 90°) from 1500 m inside a homogeneous layer 1000–2000 m: the
/// optical depth is taken along the level path (the analytic equals the closed form of a
/// homogeneous medium: `lidar_eq`'s unit test), and the Monte Carlo's order 1 equals the
/// analytic in every gate, out to a two-way optical depth of 4.6 at 2.3 km.
#[test]
fn horizontal_beam_inside_a_layer() {
    let scene = scene_text(
        r#"
[lidar]
altitude_m = 1500.0
zenith_angle_deg = 90.0
pulse_energy_j = 0.1
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 0.4
optical_efficiency = 0.7
fov_full_angle_mrad = [0.2, 1.0]
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = 300.0
end_m = 2300.0
width_m = 100.0
[[layer]]
base_m = 1000.0
top_m = 2000.0
extinction_per_m = 1e-3
single_scattering_albedo = 0.9
phase = { kind = "henyey_greenstein", g = 0.3 }
"#,
    );
    let mc = run(&scene, 200_000, |o| o.sim.seed = 41);
    let (judged, with_signal) = check_order1("horizontal", &mc.returns, &analytic(&scene));
    assert!(
        judged >= 36 && with_signal == 40,
        "{judged} of {with_signal}"
    );
}

/// A homogeneous HG layer from the ground to 1000 m seen by a lidar at `altitude_m` pointing
/// `zenith_deg` from the zenith, with a wide beam (2 mrad full angle) and fields of view of 1
/// mrad (overlap 1/4) and 4 mrad (the whole beam), gates 100–3000 m, and optionally a black
/// or white ground.
fn near_horizontal(altitude_m: f64, zenith_deg: f64, layer: (f64, f64), surface: bool) -> Scene {
    let mut t = format!(
        r#"
[lidar]
altitude_m = {altitude_m:?}
zenith_angle_deg = {zenith_deg:?}
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 2.0
telescope_diameter_m = 0.3
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0, 4.0]
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = 100.0
end_m = 3000.0
width_m = 50.0
[[layer]]
base_m = {:?}
top_m = {:?}
extinction_per_m = 2e-4
single_scattering_albedo = 0.9
phase = {{ kind = "henyey_greenstein", g = 0.7 }}
"#,
        layer.0, layer.1
    );
    if surface {
        t += "[surface]\naltitude_m = 0.0\nalbedo = 0.3\n";
    }
    scene_text(&t)
}

/// A horizontal beam at ground level in a homogeneous layer: the half of the beam below the
/// horizon leaves the atmosphere at once, so the single scattering is exactly half that of the
/// same beam inside an unbounded medium, E = E₀ η A O ∫ β e^{−2σr}/r² dr (a midpoint rule of
/// 20 000 steps per gate here), while no ray of the upper half reaches the layer's top before
/// the last gate (3000 m × 1 mrad = 3 m). Before 28 Nov 2026 the analytic equation took every
/// ray at the axis' altitude and returned twice this, and the Monte Carlo, right, 0.49× it.
#[test]
fn horizontal_beam_at_ground_level_returns_half() {
    let scene = near_horizontal(0.0, 90.0, (0.0, 1000.0), false);
    let an = analytic(&scene);
    let (sigma, albedo, g) = (2e-4, 0.9, 0.7);
    let beta = sigma * albedo * (1.0 - g) / ((1.0 + g) * (1.0 + g)) / (4.0 * std::f64::consts::PI);
    let area = std::f64::consts::PI * 0.25 * 0.3 * 0.3;
    let mut worst = 0.0f64;
    for gate in 0..an.range_m.len() {
        let ra = 100.0 + 50.0 * gate as f64;
        let n = 20_000;
        let h = 50.0 / n as f64;
        let integral: f64 = (0..n)
            .map(|i| {
                let r = ra + (i as f64 + 0.5) * h;
                (-2.0 * sigma * r).exp() / (r * r)
            })
            .sum::<f64>()
            * h;
        for (f, overlap) in [(0, 0.25), (1, 1.0)] {
            // The uniform beam's overlap with the 1 mrad field of view, exactly.
            let o = if f == 0 {
                (0.25e-3f64).sin().powi(2) / (0.5e-3f64).sin().powi(2)
            } else {
                overlap
            };
            let truth = 0.5 * area * o * beta * integral;
            let a = an.energy(0, f, gate, Order::Exactly(1)).unwrap();
            worst = worst.max((a / truth - 1.0).abs());
        }
    }
    assert!(
        worst < 1e-6,
        "analytic against half the unbounded medium: {worst:e}"
    );
    let mc = run(&scene, 200_000, |o| o.sim.seed = 51);
    let (judged, with_signal) = check_order1("horizontal at ground level", &mc.returns, &an);
    assert!(judged >= 60, "{judged} of {with_signal}");
}

/// Beams at and near the horizontal (zenith 85–90.1°) from 0, 1 and 10 m, with a wide beam
/// and two fields of view, over no ground, a ground of albedo 0.3, and inside a layer only
/// 10 m thick (5–15 m, which the beam overfills beyond 1 km): Monte Carlo single scattering
/// equals the analytic equation gate by gate (the rule of `check_order1`), wherever the beam
/// meets the ground, leaves through a layer edge or stays inside. The analytic follows each ray
/// of the beam's cross-section here (`lidar_eq`, rays); along the axis alone it differed by up to
/// a factor 2.
#[test]
fn near_horizontal_beams_near_the_ground_and_layer_edges() {
    let mut cases = Vec::new();
    for altitude in [0.0, 1.0, 10.0] {
        for zenith in [85.0, 89.0, 89.9, 90.0, 90.1] {
            cases.push((altitude, zenith, (0.0, 1000.0), false));
        }
        for zenith in [89.9, 90.0, 90.1] {
            if altitude > 0.0 {
                cases.push((altitude, zenith, (0.0, 1000.0), true));
            }
        }
    }
    cases.push((10.0, 90.0, (5.0, 15.0), false));
    cases.push((10.0, 89.9, (5.0, 15.0), false));
    let mut summary = Vec::new();
    for (i, (altitude, zenith, layer, surface)) in cases.into_iter().enumerate() {
        // From 0 m below the horizon the whole beam leaves the atmosphere; with a surface,
        // a lidar on the ground pointing below the horizon is refused (no gate before it).
        let name = format!("{altitude} m, zenith {zenith}°, layer {layer:?}, surface {surface}");
        let scene = near_horizontal(altitude, zenith, layer, surface);
        let an = analytic(&scene);
        let mc = run(&scene, 100_000, |o| o.sim.seed = 60 + i as u64);
        assert!(
            mc.returns
                .energy_j
                .iter()
                .chain(&mc.returns.stderr_j)
                .all(|v| v.is_finite() && *v >= 0.0),
            "{name}: non-finite or negative returns"
        );
        let (judged, with_signal) = check_order1(&name, &mc.returns, &an);
        if altitude == 0.0 && zenith > 90.0 {
            // Every ray goes below the ground: nothing anywhere.
            assert!(an.energy_j.iter().all(|e| *e == 0.0), "{name}");
            assert!(mc.returns.energy_j.iter().all(|e| *e == 0.0), "{name}");
        } else {
            assert!(judged > 0, "{name}: nothing judged of {with_signal}");
        }
        summary.push(format!("{name}: {judged} of {with_signal} judged"));
    }
    eprintln!("{}", summary.join("\n"));
}
