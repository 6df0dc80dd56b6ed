//! An upper bound on the multiple-scattering share of every return, for any scatterers
//! (molecules, particle layers, a Lambertian surface): what [`crate::skip`] decides with.
//! Derivation: `docs/transport.md`, "When the Monte Carlo is skipped", Eqs. S1–S10.
//!
//! Order 2, per unit range of the farther of the two scatterings and relative to that point's
//! single scattering, is integrated over the angle γ of the leg between the two scatterings to
//! the beam, in bins [γ_j, γ_{j+1}], with each bin's worst case: the phase functions at their
//! largest over the bin and over the field of view's angular uncertainty, the scatterers of the
//! leg's reach (the layers' optical depth within it, not a maximum coefficient times a range),
//! no attenuation credit beyond what the single-scatter path has. A gate's bound then takes
//! the single scattering of every gate-wide window that the returns' delay (at most half the
//! footprint) can shift into it, against its own; orders ≥ 3 follow as a geometric series over
//! every farther point their longer paths can have.

use std::f64::consts::{FRAC_PI_2, PI};

use super::{GL_W, GL_X, overlap};
use crate::optics::OpticalAtmosphere;
use crate::particles::phase::{Cosine, PhaseFunction};
use crate::scene::{BeamProfile, Scene};

/// Smallest nonzero edge of the bins in γ \[rad\] (larger where the geometry allows it without
/// loss: `Geometry::gamma_min`); the first bin takes the leg as long as the path allows.
const GAMMA_MIN_RAD: f64 = 1e-8;
/// Ratio of consecutive bin edges in γ; each bin takes its worst end, so a phase function's
/// value or a leg's reach is overstated by at most about this factor.
const GAMMA_RATIO: f64 = 1.08;
/// Grid steps per gate for the single scattering of shifted windows: a window rounded outward
/// to the grid is at most 2/`GRID_PER_GATE` of a gate wider.
const GRID_PER_GATE: usize = 32;
/// Orders summed one by one in the bound on orders ≥ 3 (each over its own window of farther
/// points); beyond, a closed-form tail.
const ORDERS_WINDOWED: usize = 30;
/// A Gaussian beam is followed to this many 1/e² half-angles: the Monte Carlo draws none
/// beyond 4.29 (the largest radius its 53-bit uniform numbers give), the physical tail beyond
/// is e^{−40} of the energy.
const GAUSS_EXTENT: f64 = 4.5;
/// A surface met so obliquely that the field of view's footprint on it stretches by more than
/// this (tan α tan θ) is not bounded (the bound is ∞).
const MAX_FOOTPRINT_STRETCH: f64 = 0.5;

/// Upper bound on the multiple-scattering share of a scene's returns, per channel, field of
/// view and range gate (`docs/transport.md`, "When the Monte Carlo is skipped"): order-2 energy
/// ≤ K × the single-scatter energy (`ratio`), all orders ≥ 2 with the higher orders of Eq. S10
/// (`all_orders_by_channel`). ∞ where no bound is given (a gate with no single scattering that
/// multiply scattered light can reach, a scatterer with no backscatter, a grazing surface, k̂ ≥ 1).
#[derive(Debug, Clone, PartialEq)]
pub struct MultipleScatteringBound {
    /// Fields of view, full angles \[mrad\], as in the scene.
    pub fov_full_angle_mrad: Vec<f64>,
    /// Gate centres \[m\].
    pub range_m: Vec<f64>,
    /// Bound K on E₂/E₁, index `fov * range_m.len() + gate`, the largest over the channels.
    pub ratio: Vec<f64>,
    /// Channel names, in scene order.
    pub channels: Vec<String>,
    /// The bound on all orders ≥ 2 over single scattering, index
    /// `(channel * n_fov + fov) * n_gates + gate`.
    pub all_orders_by_channel: Vec<f64>,
}

impl MultipleScatteringBound {
    /// The largest bound K over every field of view and gate, and the field of view it belongs
    /// to (the first such, on a tie); (0, the first field of view) when every bound is 0.
    pub fn worst(&self) -> (f64, f64) {
        let n = self.range_m.len().max(1);
        let first = self.fov_full_angle_mrad.first().copied().unwrap_or(0.0);
        self.ratio
            .iter()
            .enumerate()
            .fold((0.0, first), |(k, f), (i, r)| {
                if *r > k {
                    (*r, self.fov_full_angle_mrad[i / n])
                } else {
                    (k, f)
                }
            })
    }

    /// The geometric series K/(1 − K) over orders ≥ 2 of one factor K per order (∞ for K ≥ 1):
    /// the earlier bound's rule for all orders, kept for callers that have one factor.
    pub fn all_orders(k: f64) -> f64 {
        if k < 1.0 {
            k / (1.0 - k)
        } else {
            f64::INFINITY
        }
    }

    /// The bound on all orders ≥ 2 of channel `channel`, field of view `fov`, gate `gate`.
    pub fn all_orders_at(&self, channel: usize, fov: usize, gate: usize) -> f64 {
        let (nf, ng) = (self.fov_full_angle_mrad.len(), self.range_m.len());
        self.all_orders_by_channel[(channel * nf + fov) * ng + gate]
    }

    /// The largest bound on all orders ≥ 2 and where: (value, channel, field of view, gate),
    /// the first on a tie (an infinite bound counts as largest); `None` without bins.
    pub fn worst_all_orders(&self) -> Option<(f64, usize, usize, usize)> {
        let (nf, ng) = (self.fov_full_angle_mrad.len(), self.range_m.len());
        let mut best: Option<(f64, usize)> = None;
        for (i, &v) in self.all_orders_by_channel.iter().enumerate() {
            let v = if v.is_nan() { f64::INFINITY } else { v };
            if best.is_none_or(|(b, _)| v > b) {
                best = Some((v, i));
            }
        }
        best.map(|(v, i)| (v, i / (nf * ng), (i / ng) % nf, i % ng))
    }
}

/// The bound of [`MultipleScatteringBound`] (derivation: `docs/transport.md`, "When the Monte
/// Carlo is skipped", Eqs. S1–S10). For each channel, field of view and gate [a, b]:
///
/// ```text
/// E₂(gate) ≤ Σ_ψ w_ψ [ k_vol · max_{0≤d≤δ} E₁,vol([a − d, b − d]) + K_S · E₁,surface ]
/// K = E₂(gate) / E₁(gate)
/// ```
///
/// over the beam's rays (weight w_ψ at angle ψ to the axis: the field of view seen from the ray
/// widens to α + ψ), with δ = ½ r tan α (1 + ½ tan α) the largest delay of an order-2 return
/// behind its farther point, k_vol the volume bound per unit single scattering for farther
/// points in [a − δ, b] (Eqs. S3–S6: forward-then-back and back-then-forward paths, binned in the
/// leg's angle) and K_S the surface's (Eqs. S7–S8, when the gate can receive its light); all
/// orders add E_{≥3} ≤ O Σ_{n≥3} k̂^{n−1} E₁([a/n, b]) (Eq. S10).
pub fn multiple_scattering_bound(
    scene: &Scene,
    atm: &OpticalAtmosphere,
) -> MultipleScatteringBound {
    let lidar = &scene.lidar;
    let gates = &scene.gates;
    let nch = atm.n_channels;
    let nf = lidar.fov_full_angle_mrad.len();
    let ng = gates.count;
    let range_m: Vec<f64> = (0..ng).map(|i| gates.centre_m(i)).collect();
    let channels: Vec<String> = scene.channels.iter().map(|c| c.name.clone()).collect();
    let mut k2 = vec![0.0; nch * nf * ng];
    let mut all = vec![0.0; nch * nf * ng];
    let geo = Geometry::new(scene, atm);
    let bins = Bins::new(gamma_edges(geo.gamma_min(scene, atm)));
    let rays = beam_rays(scene);
    let grid = geo.grid(scene, &rays);
    let nr = rays.len();
    for class in channel_classes(atm) {
        let groups = geo.groups(atm, &class, &bins.edges);
        // k_vol and K_S per field of view, ray bin and gate: shared by the class's channels.
        let mut k_vol = vec![0.0; nf * nr * ng];
        let mut k_surf = vec![0.0; nf * nr];
        // k_vol for farther points nearer than the first gate's window: with the gates' own,
        // the factor of each further order for paths within a gate's reach.
        let mut k_before = vec![0.0; nf * nr];
        for (f, fov) in lidar.fov_full_angle_mrad.iter().enumerate() {
            for (b, &(psi, _)) in rays.iter().enumerate() {
                let tan_a = (0.5e-3 * fov + psi).tan();
                let ray = RayTables::new(&groups, &bins, tan_a, 0..geo.n_seg());
                for g in 0..ng {
                    let (lo, hi) = geo.window(g, tan_a);
                    k_vol[(f * nr + b) * ng + g] = geo.k_window(&groups, &bins, &ray, lo, hi);
                }
                k_surf[f * nr + b] = geo.k_surface(&groups, &bins, &ray, psi);
                let (first_lo, _) = geo.window(0, tan_a);
                k_before[f * nr + b] = geo.k_window(&groups, &bins, &ray, 0.0, first_lo);
            }
        }
        for &k in &class {
            let ch = geo.channel(atm, k);
            let single = geo.cumulative_single(&ch, &grid);
            let echo = geo.surface_echo(scene, &ch, k);
            let f_surf = geo.slant_factor_surface(atm, &ch, k);
            let beta_max = ch.beta.iter().fold(0.0f64, |m, b| m.max(*b));
            // Further scatterings anywhere on the path: the slant credit of the whole path.
            let path_slant = geo.slant_factor(atm, &ch, k, 0.0, geo.r_end(), 0.0);
            for (f, fov) in lidar.fov_full_angle_mrad.iter().enumerate() {
                let o = overlap(lidar, *fov);
                let (mut e1s, mut e2s) = (vec![0.0; ng], vec![0.0; ng]);
                for g in 0..ng {
                    let a = gates.start_m + g as f64 * gates.width_m;
                    let b_end = a + gates.width_m;
                    let mut e2 = 0.0;
                    for (b, &(psi, w)) in rays.iter().enumerate() {
                        let tan_a = (0.5e-3 * fov + psi).tan();
                        let kv = k_vol[(f * nr + b) * ng + g];
                        if kv > 0.0 {
                            let (lo, hi) = geo.window(g, tan_a);
                            let shifted = grid.largest_shifted(&single, a, b_end, a - lo);
                            let slant = geo.slant_factor(atm, &ch, k, lo, hi, tan_a);
                            e2 += w * times(kv * slant, shifted);
                        }
                        if let Some((_, energy, _)) = echo {
                            let tan_fov = (0.5e-3 * fov).tan();
                            let (r_min, r_max) = geo.surface_arrivals(tan_fov, tan_a, psi);
                            if r_min < b_end && r_max >= a {
                                e2 += w * times(k_surf[f * nr + b] * f_surf, energy);
                            }
                        }
                    }
                    let mut e1 = single.between(&grid, a, b_end);
                    if let Some((Some(sg), energy, _)) = echo
                        && sg == g
                    {
                        e1 += energy;
                    }
                    e1s[g] = e1 * o;
                    e2s[g] = e2;
                }
                // Orders ≥ 3 (S10): an order-n return arriving in a gate [a, b] has every
                // point within b of the lidar and its farthest beyond a/n; each further order
                // at most k̂ times the last, k̂ the largest order-2 factor of the points within
                // b (the volume's up to the gate, the surface's once it is nearer than b).
                let mut running: Vec<f64> = (0..nr).map(|b| k_before[f * nr + b]).collect();
                let surface_factor: f64 = rays
                    .iter()
                    .enumerate()
                    .map(|(b, &(_, w))| w * times(k_surf[f * nr + b], f_surf))
                    .sum();
                for g in 0..ng {
                    let a = gates.start_m + g as f64 * gates.width_m;
                    let b_end = a + gates.width_m;
                    let mut volume_factor = 0.0;
                    for (b, &(_, w)) in rays.iter().enumerate() {
                        running[b] = running[b].max(k_vol[(f * nr + b) * ng + g]);
                        volume_factor += w * times(running[b], path_slant);
                    }
                    let surface_near = echo.is_some_and(|(_, _, rs)| rs < b_end);
                    let khat = if surface_near {
                        volume_factor.max(surface_factor)
                    } else {
                        volume_factor
                    } / o;
                    let echo_within = |x: f64| match echo {
                        Some((_, energy, rs)) if rs >= x && rs < b_end => energy,
                        _ => 0.0,
                    };
                    let higher = higher_orders(
                        khat,
                        a,
                        |x| grid.energy_from_node_before(&single, x, b_end) + echo_within(x),
                        beta_max,
                    );
                    let (e1, e2) = (e1s[g], e2s[g] + o * higher);
                    let i = (k * nf + f) * ng + g;
                    k2[i] = ratio_of(e2s[g], e1);
                    all[i] = ratio_of(e2, e1);
                }
            }
        }
    }
    let mut ratio = vec![0.0f64; nf * ng];
    for k in 0..nch {
        for i in 0..nf * ng {
            ratio[i] = ratio[i].max(k2[k * nf * ng + i]);
        }
    }
    MultipleScatteringBound {
        fov_full_angle_mrad: lidar.fov_full_angle_mrad.clone(),
        range_m,
        ratio,
        channels,
        all_orders_by_channel: all,
    }
}

/// a · b with 0 · ∞ = 0 (no scatterer, or no energy, means no contribution).
fn times(a: f64, b: f64) -> f64 {
    if a == 0.0 || b == 0.0 { 0.0 } else { a * b }
}

/// A share: 0 where nothing arrives, ∞ where something may arrive and no single scattering does.
fn ratio_of(e2: f64, e1: f64) -> f64 {
    if e2 == 0.0 {
        0.0
    } else if e1 > 0.0 {
        e2 / e1
    } else {
        f64::INFINITY
    }
}

/// The bound on orders ≥ 3 arriving in a gate starting at `a` (per unit E₀ η A O, pencil
/// beam): Σ_{n≥3} k̂^{n−1} E₁([a/n, b]), `window(x)` the single scattering of farther points in
/// [x, b] (rounded outward); for n > `ORDERS_WINDOWED` E₁([a/n, b]) ≤ window(a/N) + β_max n/a.
/// ∞ for k̂ ≥ 1 where anything scatters before the gate's end.
fn higher_orders(khat: f64, a: f64, window: impl Fn(f64) -> f64, beta_max: f64) -> f64 {
    if khat == 0.0 {
        return 0.0;
    }
    let n_max = ORDERS_WINDOWED;
    let near = window(a / n_max as f64);
    if !(khat < 1.0) {
        return if near > 0.0 || beta_max > 0.0 {
            f64::INFINITY
        } else {
            0.0
        };
    }
    let mut sum = 0.0;
    for n in 3..=n_max {
        sum += khat.powi(n as i32 - 1) * window(a / n as f64);
    }
    // Σ_{n>N} k^{n−1} = k^N/(1 − k); Σ_{n>N} n k^{n−1} = ((N + 1) k^N (1 − k) + k^{N+1})/(1 − k)².
    let kn = khat.powi(n_max as i32);
    let one = 1.0 - khat;
    sum += kn / one * near;
    sum += beta_max / a * ((n_max as f64 + 1.0) * kn * one + kn * khat) / (one * one);
    sum
}

/// Bin edges in γ: 0, `first`, then geometric by `GAMMA_RATIO` to π/2.
fn gamma_edges(first: f64) -> Vec<f64> {
    let mut e = vec![0.0];
    let mut g = first;
    while g < FRAC_PI_2 {
        e.push(g);
        g *= GAMMA_RATIO;
    }
    e.push(FRAC_PI_2);
    e
}

/// ∫_a^b tan γ dγ = ln cos a − ln cos b (∞ to π/2), accurate for small angles.
fn tan_integral(a: f64, b: f64) -> f64 {
    if b >= FRAC_PI_2 {
        return f64::INFINITY;
    }
    let ln_cos = |x: f64| (-2.0 * (0.5 * x).sin().powi(2)).ln_1p();
    ln_cos(a) - ln_cos(b)
}

/// The largest value of a phase function over the scattering angles [lo, hi] ⊂ [0, π]: at an
/// end for the monotone (Henyey-Greenstein) and convex-in-μ (Rayleigh) ones, each lobe's
/// largest for two lobes, the ends and the nodes inside for a table (linear in μ).
fn phase_max(p: &PhaseFunction, lo: f64, hi: f64) -> f64 {
    let (lo, hi) = (lo.clamp(0.0, PI), hi.clamp(0.0, PI));
    let (mu_top, mu_bottom) = (lo.cos(), hi.cos());
    match p {
        PhaseFunction::Isotropic => 1.0,
        PhaseFunction::Rayleigh(r) => r.eval(mu_top).max(r.eval(mu_bottom)),
        PhaseFunction::HenyeyGreenstein(h) => h.eval(mu_top).max(h.eval(mu_bottom)),
        PhaseFunction::DoubleHenyeyGreenstein { f, hg1, hg2 } => {
            f * hg1.eval(mu_top).max(hg1.eval(mu_bottom))
                + (1.0 - f) * hg2.eval(mu_top).max(hg2.eval(mu_bottom))
        }
        PhaseFunction::Tabulated(t) => {
            let (mu, v) = t.nodes();
            let from = mu.partition_point(|m| *m <= mu_bottom);
            let to = mu.partition_point(|m| *m < mu_top);
            let inside = v[from..to.max(from)].iter().fold(0.0f64, |m, x| m.max(*x));
            inside.max(t.eval(mu_top)).max(t.eval(mu_bottom))
        }
    }
}

/// The beam's rays in bins of their angle ψ to the axis: (the bin's largest ψ, its share of
/// the pulse energy); one bin at ψ = 0 for a pencil beam.
fn beam_rays(scene: &Scene) -> Vec<(f64, f64)> {
    let b = 0.5e-3 * scene.lidar.beam_divergence_full_angle_mrad;
    if !(b > 0.0) {
        return vec![(0.0, 1.0)];
    }
    let (edges, cdf): (Vec<f64>, Box<dyn Fn(f64) -> f64>) = match scene.lidar.beam_profile {
        BeamProfile::Uniform => (
            (1..=8).map(|i| b * i as f64 / 8.0).collect(),
            Box::new(move |x: f64| ((0.5 * x).sin() / (0.5 * b).sin()).powi(2)),
        ),
        BeamProfile::Gaussian => (
            [0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, GAUSS_EXTENT]
                .iter()
                .map(|x| x * b)
                .collect(),
            Box::new(move |x: f64| -(-2.0 * x * x / (b * b)).exp_m1()),
        ),
    };
    let mut prev = 0.0;
    edges
        .into_iter()
        .map(|psi| {
            let c = cdf(psi);
            let w = (c - prev).max(0.0);
            prev = c;
            (psi, w)
        })
        .collect()
}

/// Channels that share every component's phase function: one computation of k_vol and K_S
/// serves them all (their coefficients taken at their largest, their backscatter at its
/// least).
fn channel_classes(atm: &OpticalAtmosphere) -> Vec<Vec<usize>> {
    let key = |k: usize| -> Vec<u32> {
        atm.components
            .iter()
            .flat_map(|cs| cs.iter().map(move |c| c.phase[k]))
            .collect()
    };
    let mut classes: Vec<(Vec<u32>, Vec<usize>)> = Vec::new();
    for k in 0..atm.n_channels {
        let kk = key(k);
        match classes.iter_mut().find(|(x, _)| *x == kk) {
            Some((_, v)) => v.push(k),
            None => classes.push((kk, vec![k])),
        }
    }
    classes.into_iter().map(|(_, v)| v).collect()
}

/// Largest value over index ranges, O(1) per query (a sparse table).
struct RangeMax {
    levels: Vec<Vec<f64>>,
}

impl RangeMax {
    fn new(v: &[f64]) -> Self {
        let mut levels = vec![v.to_vec()];
        let mut width = 1;
        while 2 * width <= v.len() {
            let prev = levels.last().expect("a level");
            let next: Vec<f64> = (0..=v.len() - 2 * width)
                .map(|i| prev[i].max(prev[i + width]))
                .collect();
            levels.push(next);
            width *= 2;
        }
        RangeMax { levels }
    }

    /// max v[i..=j] (i ≤ j).
    fn max(&self, i: usize, j: usize) -> f64 {
        let len = j - i + 1;
        let l = (usize::BITS - 1 - len.leading_zeros()) as usize;
        self.levels[l][i].max(self.levels[l][j + 1 - (1 << l)])
    }
}

/// The scatterers of one phase function along the axis, over a class of channels, and the
/// phase function's angular tables.
struct Group {
    phase: std::sync::Arc<PhaseFunction>,
    /// Largest scattering coefficient of the class's channels per segment \[1/m\].
    sig_max: Vec<f64>,
    /// Least, per segment \[1/m\].
    sig_min: Vec<f64>,
    /// ∫₀^{r_i} σ_max dr at the breakpoints.
    cum: Vec<f64>,
    /// ∫_{r_i}^{r_end} σ_max/r² dr at the breakpoints \[1/m\] (∞ at r = 0 inside scatterers).
    qc: Vec<f64>,
    sup: RangeMax,
    /// P(π).
    back: f64,
    /// max P over all angles.
    p_max: f64,
    /// Per bin j: the probability of scattering into γ ∈ [γ_j, γ_{j+1}].
    mass: Vec<f64>,
    /// Per bin: max P over [γ_j, γ_{j+1}].
    fwd: Vec<f64>,
    /// Per bin: max P over [π − γ_{j+1}, π − γ_j].
    bwd: Vec<f64>,
}

/// The bins in γ and what each needs that depends on nothing else.
struct Bins {
    edges: Vec<f64>,
    /// tan γ_j.
    tan0: Vec<f64>,
    /// 1/cos γ_{j+1}.
    inv_cos1: Vec<f64>,
    /// ∫ tan γ dγ over the bin.
    tan_int: Vec<f64>,
    /// γ_{j+1} − γ_j.
    width: Vec<f64>,
}

impl Bins {
    fn new(edges: Vec<f64>) -> Self {
        let n = edges.len() - 1;
        Bins {
            tan0: (0..n).map(|j| edges[j].tan()).collect(),
            inv_cos1: (0..n).map(|j| 1.0 / edges[j + 1].cos()).collect(),
            tan_int: (0..n)
                .map(|j| tan_integral(edges[j], edges[j + 1]))
                .collect(),
            width: (0..n).map(|j| edges[j + 1] - edges[j]).collect(),
            edges,
        }
    }

    fn len(&self) -> usize {
        self.edges.len() - 1
    }
}

/// Per group, the phase function's largest values over bins widened by the field of view's
/// half-angle α′ (the second scattering's angle is known to within it).
struct WideTables {
    /// max P over [γ_j, γ_{j+1} + α′]: the second scattering of a back-then-forward path.
    fwd: Vec<Vec<f64>>,
    /// max P over [π − γ_{j+1}, π − γ_j + min(γ_{j+1}, α′)]: the second scattering of a
    /// forward-then-back path.
    bwd: Vec<Vec<f64>>,
}

impl WideTables {
    fn new(groups: &[Group], edges: &[f64], alpha: f64) -> Self {
        let n = edges.len() - 1;
        let fwd = groups
            .iter()
            .map(|g| {
                (0..n)
                    .map(|j| phase_max(&g.phase, edges[j], edges[j + 1] + alpha))
                    .collect()
            })
            .collect();
        let bwd = groups
            .iter()
            .map(|g| {
                (0..n)
                    .map(|j| {
                        phase_max(
                            &g.phase,
                            PI - edges[j + 1],
                            PI - edges[j] + edges[j + 1].min(alpha),
                        )
                    })
                    .collect()
            })
            .collect();
        WideTables { fwd, bwd }
    }
}

/// A segment's scatterers as the farther point of a path.
enum SegRatio {
    /// None.
    Clear,
    /// Scatterers with no backscatter: no single scattering to compare with.
    NoBackscatter,
    /// Per bin, the largest P(Θ)/P(π) over the class's channels for Θ near π − γ
    /// (forward-then-back, widened by α′) and at π − γ (back-then-forward).
    Ratios(Vec<f64>, Vec<f64>),
}

/// What a ray bin (a field of view widened by ψ) needs: tan α′, the widened tables, the
/// back-then-forward reach s_j = tan γ_j/(tan γ_j + tan α′) and each segment's backscatter
/// ratios (those the gates' windows can meet).
struct RayTables {
    tan_a: f64,
    wide: WideTables,
    s: Vec<f64>,
    first_seg: usize,
    ratios: Vec<SegRatio>,
}

impl RayTables {
    fn new(groups: &[Group], bins: &Bins, tan_a: f64, segs: std::ops::Range<usize>) -> Self {
        let wide = WideTables::new(groups, &bins.edges, tan_a.atan());
        let nb = bins.len();
        let ratios = segs
            .clone()
            .map(|s| {
                let total: f64 = groups.iter().map(|g| g.sig_max[s]).sum();
                if total == 0.0 {
                    return SegRatio::Clear;
                }
                let den: f64 = groups.iter().map(|g| g.sig_min[s] * g.back).sum();
                if !(den > 0.0) {
                    return SegRatio::NoBackscatter;
                }
                let (mut b, mut a) = (vec![0.0; nb], vec![0.0; nb]);
                for (i, g) in groups.iter().enumerate() {
                    if g.sig_max[s] == 0.0 {
                        continue;
                    }
                    for j in 0..nb {
                        b[j] += g.sig_max[s] * wide.bwd[i][j];
                        a[j] += g.sig_max[s] * g.bwd[j];
                    }
                }
                b.iter_mut().chain(a.iter_mut()).for_each(|v| *v /= den);
                SegRatio::Ratios(b, a)
            })
            .collect();
        RayTables {
            s: bins.tan0.iter().map(|t| t / (t + tan_a)).collect(),
            tan_a,
            wide,
            first_seg: segs.start,
            ratios,
        }
    }

    fn ratio(&self, s: usize) -> &SegRatio {
        match s.checked_sub(self.first_seg) {
            Some(i) => &self.ratios[i],
            None => &SegRatio::Clear,
        }
    }
}

/// The surface as the bound sees it.
#[derive(Debug, Clone, Copy)]
struct SurfaceGeometry {
    /// Range along the axis \[m\].
    range_m: f64,
    /// Altitude \[m\].
    altitude_m: f64,
    /// Angle of incidence of the axis \[rad\].
    incidence: f64,
}

/// The axis through the optical atmosphere: homogeneous segments between the layer edges it
/// crosses, to the surface (downward, with one) or the last gate's end.
struct Geometry {
    z0: f64,
    mu: f64,
    /// Breakpoints along the axis \[m\]: 0, the edges crossed, r_end.
    r: Vec<f64>,
    /// Layer of each segment (`None` outside the atmosphere).
    layer: Vec<Option<usize>>,
    surface: Option<SurfaceGeometry>,
    gate_start_m: f64,
    gate_width_m: f64,
}

impl Geometry {
    fn new(scene: &Scene, atm: &OpticalAtmosphere) -> Self {
        let lidar = &scene.lidar;
        let z0 = lidar.altitude_m;
        let mu = lidar.axis().z;
        let surface = match &scene.surface {
            Some(s) if mu < -1e-12 && z0 > s.altitude_m => Some(SurfaceGeometry {
                range_m: (z0 - s.altitude_m) / -mu,
                altitude_m: s.altitude_m,
                incidence: (-mu).min(1.0).acos(),
            }),
            _ => None,
        };
        let r_end = surface.map_or(scene.gates.end_m(), |s| s.range_m);
        let mut r = vec![0.0, r_end];
        if mu.abs() > 1e-12 {
            r.extend(
                atm.edges_m
                    .iter()
                    .map(|e| (e - z0) / mu)
                    .filter(|x| *x > 0.0 && *x < r_end),
            );
        }
        r.sort_by(f64::total_cmp);
        r.dedup();
        let inside = |z: f64| atm.n_layers() > 0 && z >= atm.bottom_m() && z < atm.top_m();
        let layer = r
            .windows(2)
            .map(|w| {
                let z = z0 + mu * 0.5 * (w[0] + w[1]);
                inside(z).then(|| atm.layer_of(z))
            })
            .collect();
        Geometry {
            z0,
            mu,
            r,
            layer,
            surface,
            gate_start_m: scene.gates.start_m,
            gate_width_m: scene.gates.width_m,
        }
    }

    fn r_end(&self) -> f64 {
        *self.r.last().expect("two breakpoints")
    }

    fn n_seg(&self) -> usize {
        self.r.len() - 1
    }

    /// The segment holding x: r_s ≤ x < r_{s+1} (clamped to the path).
    fn seg(&self, x: f64) -> usize {
        self.r
            .partition_point(|r| *r <= x)
            .saturating_sub(1)
            .min(self.n_seg() - 1)
    }

    /// The segment ending at or after x from the left: r_s < x ≤ r_{s+1} (clamped).
    fn seg_left(&self, x: f64) -> usize {
        self.r
            .partition_point(|r| *r < x)
            .saturating_sub(1)
            .min(self.n_seg() - 1)
    }

    /// The scatterers of a class of channels by phase function.
    fn groups(&self, atm: &OpticalAtmosphere, class: &[usize], edges: &[f64]) -> Vec<Group> {
        let k0 = class[0];
        let mut phases: Vec<usize> = Vec::new();
        for comps in &atm.components {
            for c in comps {
                let p = c.phase[k0] as usize;
                if class.iter().any(|&k| c.sigma_s_per_m[k] > 0.0) && !phases.contains(&p) {
                    phases.push(p);
                }
            }
        }
        let n = self.n_seg();
        let nb = edges.len() - 1;
        phases
            .into_iter()
            .map(|p| {
                let (mut sig_max, mut sig_min) = (vec![0.0; n], vec![0.0; n]);
                for s in 0..n {
                    let Some(l) = self.layer[s] else { continue };
                    let per_channel = class.iter().map(|&k| {
                        atm.components[l]
                            .iter()
                            .filter(|c| c.phase[k0] as usize == p)
                            .map(|c| c.sigma_s_per_m[k])
                            .sum::<f64>()
                    });
                    let (lo, hi) =
                        per_channel.fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
                    sig_max[s] = hi;
                    sig_min[s] = lo.min(hi);
                }
                let mut cum = vec![0.0; n + 1];
                for s in 0..n {
                    cum[s + 1] = cum[s] + sig_max[s] * (self.r[s + 1] - self.r[s]);
                }
                let mut qc = vec![0.0; n + 1];
                for s in (0..n).rev() {
                    let part = if sig_max[s] > 0.0 {
                        sig_max[s] * (1.0 / self.r[s] - 1.0 / self.r[s + 1])
                    } else {
                        0.0
                    };
                    qc[s] = qc[s + 1] + part;
                }
                let phase = atm.phases[p].clone();
                let up = |e: f64| phase.tails(Cosine::of_angle(e)).1;
                let mass = (0..nb)
                    .map(|j| (up(edges[j + 1]) - up(edges[j])).max(0.0))
                    .collect();
                let fwd = (0..nb)
                    .map(|j| phase_max(&phase, edges[j], edges[j + 1]))
                    .collect();
                let bwd = (0..nb)
                    .map(|j| phase_max(&phase, PI - edges[j + 1], PI - edges[j]))
                    .collect();
                Group {
                    back: phase.backscatter(),
                    p_max: phase_max(&phase, 0.0, PI),
                    phase,
                    sup: RangeMax::new(&sig_max),
                    sig_max,
                    sig_min,
                    cum,
                    qc,
                    mass,
                    fwd,
                    bwd,
                }
            })
            .collect()
    }

    /// ∫₀^x σ_max dr of a group, x in segment s.
    fn t_in(&self, g: &Group, x: f64, s: usize) -> f64 {
        if x <= 0.0 {
            0.0
        } else if x >= self.r_end() {
            g.cum[self.n_seg()]
        } else {
            g.cum[s] + g.sig_max[s] * (x - self.r[s])
        }
    }

    /// ∫_x^{r_end} σ_max/r² dr of a group, x in segment s.
    fn q_in(&self, g: &Group, x: f64, s: usize) -> f64 {
        if x >= self.r_end() {
            0.0
        } else if x <= 0.0 {
            g.qc[0]
        } else if g.sig_max[s] > 0.0 {
            g.sig_max[s] * (1.0 / x - 1.0 / self.r[s + 1]) + g.qc[s + 1]
        } else {
            g.qc[s + 1]
        }
    }

    /// The largest σ_max of a group on [x, y], x in segment sx, y in segment sy (from the left).
    fn sup_in(&self, g: &Group, x: f64, sx: usize, y: f64, sy: usize) -> f64 {
        if y <= 0.0 || x >= self.r_end() {
            return 0.0;
        }
        let a = if x <= 0.0 { 0 } else { sx };
        g.sup.max(a.min(sy), sy)
    }

    /// The farther points [lo, hi] whose order-2 returns can arrive in gate `g`: the gate
    /// extended toward the lidar by the largest delay, ½ r tan α′ (1 + ½ tan α′) at its end,
    /// and cut at the surface.
    fn window(&self, g: usize, tan_a: f64) -> (f64, f64) {
        let a = self.gate_start_m + g as f64 * self.gate_width_m;
        let b = a + self.gate_width_m;
        let delay = 0.5 * b * tan_a * (1.0 + 0.5 * tan_a);
        ((a - delay).max(0.0), b.min(self.r_end()))
    }

    /// k_vol: order 2 per unit single scattering of farther points in [lo, hi], both
    /// orderings (docs/transport.md, S3–S6), for the ray bin's field of view.
    fn k_window(&self, groups: &[Group], bins: &Bins, ray: &RayTables, lo: f64, hi: f64) -> f64 {
        if !(lo < hi) || groups.is_empty() {
            return 0.0;
        }
        let nb = bins.len();
        // The farther point's backscatter ratio P(Θ)/P(π), the worst of the segments in the
        // window.
        let (mut rb, mut ra) = (vec![0.0f64; nb], vec![0.0f64; nb]);
        let mut any = false;
        for s in self.seg(lo)..=self.seg_left(hi) {
            match ray.ratio(s) {
                SegRatio::Clear => {}
                SegRatio::NoBackscatter => return f64::INFINITY,
                SegRatio::Ratios(b, a) => {
                    any = true;
                    for j in 0..nb {
                        rb[j] = rb[j].max(b[j]);
                        ra[j] = ra[j].max(a[j]);
                    }
                }
            }
        }
        if !any {
            return 0.0;
        }
        let rho = hi * ray.tan_a;
        let s_hi = self.seg_left(hi);
        let t_hi: Vec<f64> = groups.iter().map(|g| self.t_in(g, hi, s_hi)).collect();
        let q_hi: Vec<f64> = groups.iter().map(|g| self.q_in(g, hi, s_hi)).collect();
        let (mut k_fwd, mut k_back) = (0.0, 0.0);
        // Segment pointers for lo − L_j and lo·s_j, both increasing with j.
        let (mut sf, mut sb) = (0usize, 0usize);
        for j in 0..nb {
            let width = bins.width[j];
            // Forward-then-back: the nearer point A within L = ρ cot γ of the farther point.
            let xf = if bins.tan0[j] > 0.0 {
                lo - rho / bins.tan0[j]
            } else {
                f64::NEG_INFINITY
            };
            while sf + 1 < self.n_seg() && self.r[sf + 1] <= xf {
                sf += 1;
            }
            // Back-then-forward: the nearer point B within [r s_j, r].
            let xb = lo * ray.s[j];
            while sb + 1 < self.n_seg() && self.r[sb + 1] <= xb {
                sb += 1;
            }
            for (i, g) in groups.iter().enumerate() {
                if t_hi[i] == 0.0 {
                    continue;
                }
                if g.mass[j] > 0.0 && rb[j] > 0.0 {
                    let reach = t_hi[i] - self.t_in(g, xf, sf);
                    let first = times(2.0 * g.mass[j] * bins.inv_cos1[j], reach);
                    let cap = self.sup_in(g, xf, sf, hi, s_hi) * rho * g.fwd[j] * width;
                    k_fwd += rb[j] * first.min(cap);
                }
                let p = ray.wide.fwd[i][j];
                if ra[j] > 0.0 && p > 0.0 {
                    let q = self.q_in(g, xb, sb) - q_hi[i];
                    let first = times(bins.tan_int[j], hi * hi * q);
                    let cap = self.sup_in(g, xb, sb, hi, s_hi) * rho * width;
                    k_back += ra[j] * p * first.min(cap);
                }
            }
        }
        0.5 * (k_fwd + k_back)
    }

    /// The smallest nonzero bin edge that loses nothing: below it a forward leg reaches past
    /// every scatterer (ρ cot γ beyond their extent, ρ the narrowest footprint) and a backward
    /// leg's reach [r s, r] starts before the first scatterer.
    fn gamma_min(&self, scene: &Scene, atm: &OpticalAtmosphere) -> f64 {
        let scatters = |s: usize| {
            self.layer[s].is_some_and(|l| {
                (0..atm.n_channels).any(|k| atm.sigma_s_per_m[l * atm.n_channels + k] > 0.0)
            })
        };
        let Some(first) = (0..self.n_seg()).find(|s| scatters(*s)) else {
            return FRAC_PI_2;
        };
        let r_first = self.r[first];
        let extent = (self.r_end() - r_first).max(f64::MIN_POSITIVE);
        let tan_fov = scene
            .lidar
            .fov_full_angle_mrad
            .iter()
            .fold(f64::INFINITY, |m, f| m.min((0.5e-3 * f).tan()));
        let forward = scene.gates.start_m * tan_fov / extent;
        let backward = tan_fov * r_first / self.r_end();
        forward.min(backward).clamp(GAMMA_MIN_RAD, 1e-2)
    }

    /// The range of incidence angles of the beam's rays at ψ from the axis on the surface.
    fn ray_incidence(&self, psi: f64) -> (f64, f64) {
        let th = self.surface.map_or(0.0, |s| s.incidence);
        ((th - psi).max(0.0), th + psi)
    }

    /// The footprint on the surface of the cone of half-angle atan(tan_a) about a ray at ψ:
    /// its nearest and farthest axial distances and its radius, or `None` when too oblique.
    fn footprint(&self, tan_a: f64, psi: f64) -> Option<(f64, f64, f64)> {
        let s = self.surface?;
        let (_, th) = self.ray_incidence(psi);
        let t = tan_a * th.tan();
        if !(th < FRAC_PI_2 && t < MAX_FOOTPRINT_STRETCH) {
            return None;
        }
        let (near, far) = (s.range_m / (1.0 + t), s.range_m / (1.0 - t));
        Some((near, far, far * tan_a))
    }

    /// K_S: order 2 through the surface per unit surface echo (docs/transport.md, S7–S8).
    fn k_surface(&self, groups: &[Group], bins: &Bins, ray: &RayTables, psi: f64) -> f64 {
        let (tan_a, wide, edges) = (ray.tan_a, &ray.wide, &bins.edges);
        let Some(surf) = self.surface else {
            return 0.0;
        };
        let Some((near, far, rho)) = self.footprint(tan_a, psi) else {
            return f64::INFINITY;
        };
        let rs = surf.range_m;
        let (th_lo, th_hi) = self.ray_incidence(psi);
        let cos_a = 1.0 / (1.0 + tan_a * tan_a).sqrt();
        let nb = edges.len() - 1;
        let (s_near, s_rs) = (self.seg_left(near), self.seg_left(rs));
        // Forward, then the surface (S7): the light scattered by A into the footprint's cone.
        let mut ka = 0.0;
        for g in groups {
            let t_near = self.t_in(g, near, s_near);
            let mut s = 0usize;
            for j in 0..nb {
                if g.mass[j] == 0.0 {
                    continue;
                }
                let x = if edges[j] > 0.0 {
                    near - rho / edges[j].tan()
                } else {
                    f64::NEG_INFINITY
                };
                while s + 1 < self.n_seg() && self.r[s + 1] <= x {
                    s += 1;
                }
                ka += g.mass[j] * (t_near - self.t_in(g, x, s));
            }
            // Scatterers beside the footprint (oblique incidence): all they scatter.
            ka += self.t_in(g, rs, s_rs) - t_near;
        }
        ka *= (rs / (near * cos_a)).powi(2) / th_hi.cos();
        // The surface, then B back toward the lidar (S8).
        let mut kb = 0.0;
        for (i, g) in groups.iter().enumerate() {
            let q_rs = self.q_in(g, rs, s_rs);
            let mut s = 0usize;
            for j in 0..nb {
                let (e0, e1) = (edges[j], edges[j + 1]);
                // cos θ_out ≤ cos of the least angle between γ and the incidence.
                let gap = (e0 - th_hi).max(th_lo - e1).max(0.0);
                let c = gap.min(FRAC_PI_2).cos();
                let sj = e0.tan() / (e0.tan() + tan_a);
                let x = rs * sj;
                while s + 1 < self.n_seg() && self.r[s + 1] <= x {
                    s += 1;
                }
                let q = self.q_in(g, x, s) - q_rs;
                let first = times(tan_integral(e0, e1), rs * rs * q);
                let cap = self.sup_in(g, x, s, rs, s_rs) * rs * tan_a * (e1 - e0);
                kb += c * wide.fwd[i][j] * first.min(cap);
            }
            // B beyond S₀ along the axis but above the oblique surface: a slab of half-thickness
            // H about S₀, ∫ dV/|S₀B|² ≤ 2π [H ln(1 + ρ²/H²) + 2ρ atan(H/ρ)].
            let h = far - rs;
            if h > 0.0 {
                let slab = h * (1.0 + (rho / h).powi(2)).ln() + 2.0 * rho * (h / rho).atan();
                let sig = self.sup_in(g, near, self.seg(near), rs, s_rs);
                kb += sig * g.p_max * slab * (rs / near).powi(2);
            }
        }
        kb *= 0.5 / th_hi.cos();
        ka + kb
    }

    /// The apparent ranges at which order-2 light through the surface can arrive: from the
    /// nearest point of the field of view's own footprint (half-angle atan(tan_fov) about the
    /// axis; a path is at least twice as long as the way to its surface point), to the
    /// farthest the ray's wider cone allows.
    fn surface_arrivals(&self, tan_fov: f64, tan_a: f64, psi: f64) -> (f64, f64) {
        match (self.footprint(tan_fov, 0.0), self.footprint(tan_a, psi)) {
            (Some((near, _, _)), Some((_, far, rho))) => {
                let cos_a = 1.0 / (1.0 + tan_a * tan_a).sqrt();
                (near, far / cos_a + 0.5 * rho)
            }
            _ => (0.0, f64::INFINITY),
        }
    }

    /// One channel's extinction and backscatter along the axis.
    fn channel(&self, atm: &OpticalAtmosphere, k: usize) -> ChannelPath {
        let nch = atm.n_channels;
        let n = self.n_seg();
        let (mut ext, mut beta) = (vec![0.0; n], vec![0.0; n]);
        for s in 0..n {
            let Some(l) = self.layer[s] else { continue };
            ext[s] = atm.sigma_s_per_m[l * nch + k] + atm.sigma_a_per_m[l * nch + k];
            beta[s] = atm.components[l]
                .iter()
                .map(|c| c.sigma_s_per_m[k] * atm.phases[c.phase[k] as usize].backscatter())
                .sum::<f64>()
                / (4.0 * PI);
        }
        let mut cum = vec![0.0; n + 1];
        for s in 0..n {
            cum[s + 1] = cum[s] + ext[s] * (self.r[s + 1] - self.r[s]);
        }
        ChannelPath { ext, beta, cum }
    }

    /// Extinction optical depth along the axis to x.
    fn tau(&self, ch: &ChannelPath, x: f64) -> f64 {
        if x <= 0.0 {
            return 0.0;
        }
        let s = self.seg(x);
        ch.cum[s] + ch.ext[s] * (x.min(self.r_end()) - self.r[s])
    }

    /// The grid of the single scattering of windows: every gate edge, `GRID_PER_GATE` steps per
    /// gate and before the first down to the nearest window start, the breakpoints, and 5 %
    /// steps from there down to start/`ORDERS_WINDOWED` (the windows of orders ≥ 3).
    fn grid(&self, scene: &Scene, rays: &[(f64, f64)]) -> Grid {
        let gates = &scene.gates;
        let widest = scene
            .lidar
            .fov_full_angle_mrad
            .iter()
            .fold(0.0f64, |m, f| m.max(*f));
        let psi = rays.last().map_or(0.0, |r| r.0);
        let tan_a = (0.5e-3 * widest + psi).tan();
        let (first, _) = self.window(0, tan_a);
        let x0 = first.max(0.5 * gates.start_m);
        let h = gates.width_m / GRID_PER_GATE as f64;
        // Down to start/N for the windows [a/n, b] of orders ≥ 3, 5 % apart.
        let lowest = gates.start_m / ORDERS_WINDOWED as f64;
        let mut x = vec![lowest];
        let mut v = lowest;
        while v < x0 {
            x.push(v);
            v *= 1.05;
        }
        x.push(x0);
        let before = ((gates.start_m - x0) / h).ceil().max(0.0) as usize;
        x.extend((0..before).map(|i| gates.start_m - i as f64 * h));
        for g in 0..gates.count {
            let a = gates.start_m + g as f64 * gates.width_m;
            x.extend((0..GRID_PER_GATE).map(|i| a + i as f64 * h));
        }
        x.push(gates.end_m());
        x.extend(
            self.r
                .iter()
                .copied()
                .filter(|r| *r > lowest && *r < gates.end_m()),
        );
        x.retain(|v| *v >= lowest);
        x.sort_by(f64::total_cmp);
        x.dedup();
        Grid { x }
    }

    /// The single-scatter energy of the volume from the first grid node to each node (per unit
    /// E₀ η A, pencil beam, far field), 8-point Gauss–Legendre on pieces of two-way optical
    /// depth ≤ 0.25.
    fn cumulative_single(&self, ch: &ChannelPath, grid: &Grid) -> Cumulative {
        let mut c = vec![0.0; grid.x.len()];
        for i in 0..grid.x.len() - 1 {
            let (a, b) = (grid.x[i], grid.x[i + 1].min(self.r_end()));
            let mut part = 0.0;
            if a < b {
                let s = self.seg(0.5 * (a + b));
                if ch.beta[s] > 0.0 {
                    let n = ((2.0 * ch.ext[s] * (b - a) / 0.25).ceil()).clamp(1.0, 1e6) as usize;
                    let h = (b - a) / n as f64;
                    for m in 0..n {
                        let mid = a + (m as f64 + 0.5) * h;
                        for (x, w) in GL_X.iter().zip(GL_W) {
                            for r in [mid - 0.5 * h * x, mid + 0.5 * h * x] {
                                let tau = ch.cum[s] + ch.ext[s] * (r - self.r[s]);
                                part += 0.5 * h * w * (-2.0 * tau).exp() / (r * r);
                            }
                        }
                    }
                    part *= ch.beta[s];
                }
            }
            c[i + 1] = c[i] + part;
        }
        Cumulative(c)
    }

    /// The surface echo per unit E₀ η A (pencil beam): its gate (if one holds it), energy and
    /// range.
    fn surface_echo(
        &self,
        scene: &Scene,
        ch: &ChannelPath,
        k: usize,
    ) -> Option<(Option<usize>, f64, f64)> {
        let s = self.surface?;
        let albedo = scene.surface.as_ref()?.albedo[k];
        let rs = s.range_m;
        let x = (rs - scene.gates.start_m) / scene.gates.width_m;
        let gate = (x >= 0.0 && (x as usize) < scene.gates.count).then_some(x as usize);
        let energy = albedo * s.incidence.cos() / PI * (-2.0 * self.tau(ch, rs)).exp() / (rs * rs);
        Some((gate, energy, rs))
    }

    /// The vertical extinction optical depth between the lidar and altitude z.
    fn tau_vertical(&self, atm: &OpticalAtmosphere, k: usize, z: f64) -> f64 {
        let t = |z: f64| {
            let (s, a) = atm.cumulative_tau(z, k);
            s + a
        };
        (t(self.z0) - t(z)).abs()
    }

    /// exp(2 (τ_axis(hi) − τ_⊥)): what the multiply scattered light may be attenuated less
    /// than the single scattering of a slant axis (1 for a vertical one), τ_⊥ the vertical
    /// optical depth to the altitude nearest the lidar that the cone reaches at range lo.
    fn slant_factor(
        &self,
        atm: &OpticalAtmosphere,
        ch: &ChannelPath,
        k: usize,
        lo: f64,
        hi: f64,
        tan_a: f64,
    ) -> f64 {
        if self.mu.abs() >= 1.0 - 1e-12 {
            return 1.0;
        }
        let spread = lo * tan_a * (1.0 - self.mu * self.mu).sqrt();
        let z = self.z0 + self.mu * lo;
        let nearest = if (z - spread..=z + spread).contains(&self.z0) {
            self.z0
        } else if z > self.z0 {
            z - spread
        } else {
            z + spread
        };
        let gap = self.tau(ch, hi) - self.tau_vertical(atm, k, nearest);
        (2.0 * gap.max(0.0)).exp()
    }

    /// The same for paths through the surface: both legs cross the whole column.
    fn slant_factor_surface(&self, atm: &OpticalAtmosphere, ch: &ChannelPath, k: usize) -> f64 {
        match self.surface {
            Some(s) if self.mu.abs() < 1.0 - 1e-12 => {
                let gap = self.tau(ch, s.range_m) - self.tau_vertical(atm, k, s.altitude_m);
                (2.0 * gap.max(0.0)).exp()
            }
            _ => 1.0,
        }
    }
}

/// One channel along the axis, per segment.
struct ChannelPath {
    /// Extinction \[1/m\].
    ext: Vec<f64>,
    /// Backscatter σ_s P(π)/(4π) \[1/(m sr)\].
    beta: Vec<f64>,
    /// Extinction optical depth at the breakpoints.
    cum: Vec<f64>,
}

/// Nodes for the single scattering of windows.
struct Grid {
    x: Vec<f64>,
}

/// Single-scatter energy from the first node to each node.
struct Cumulative(Vec<f64>);

impl Cumulative {
    /// The energy between two grid nodes.
    fn between(&self, grid: &Grid, a: f64, b: f64) -> f64 {
        self.0[grid.at_or_after(b)] - self.0[grid.at_or_after(a)]
    }
}

impl Grid {
    /// The energy from the last node ≤ x (the first node if none) to the first node ≥ b.
    fn energy_from_node_before(&self, c: &Cumulative, x: f64, b: f64) -> f64 {
        let i = self.x.partition_point(|v| *v <= x).saturating_sub(1);
        c.0[self.at_or_after(b)] - c.0[i]
    }

    /// The first node ≥ x (the last node if none).
    fn at_or_after(&self, x: f64) -> usize {
        self.x.partition_point(|v| *v < x).min(self.x.len() - 1)
    }

    /// The largest single scattering of a window [a − d, b − d], 0 ≤ d ≤ `delay`: each window
    /// rounded outward to the grid. ∞ when the grid does not reach back so far.
    fn largest_shifted(&self, c: &Cumulative, a: f64, b: f64, delay: f64) -> f64 {
        let width = b - a;
        let ia = self.at_or_after(a);
        let mut best = c.0[self.at_or_after(b)] - c.0[ia];
        if delay <= 0.0 {
            return best;
        }
        let lo = a - delay;
        if lo < self.x[0] {
            return f64::INFINITY;
        }
        let first = self.x.partition_point(|v| *v <= lo).saturating_sub(1);
        let mut end = first;
        for i in first..ia {
            // The first node ≥ x_{i+1} + width: increasing with i.
            let y = self.x[i + 1] + width;
            while end + 1 < self.x.len() && self.x[end] < y {
                end += 1;
            }
            best = best.max(c.0[end] - c.0[i]);
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::phase::{HenyeyGreenstein, TabulatedPhase};

    /// The largest value over an interval against a dense scan (a bound must never fall below
    /// it): a table with a peak between nodes' ends, Rayleigh (largest at the ends), forward
    /// and backward Henyey-Greenstein and two lobes.
    #[test]
    fn phase_maxima_are_never_below_a_dense_scan() {
        let table = TabulatedPhase::from_angles(
            &[0.0, 30.0, 60.0, 90.0, 120.0, 180.0],
            &[5.0, 1.0, 3.0, 0.5, 0.2, 0.4],
        )
        .unwrap();
        let phases = [
            PhaseFunction::Tabulated(Box::new(table)),
            PhaseFunction::Rayleigh(
                crate::particles::phase::RayleighPhase::from_depolarisation(0.03).unwrap(),
            ),
            PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(0.9).unwrap()),
            PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(-0.5).unwrap()),
            PhaseFunction::double_hg(0.7, 0.95, -0.4).unwrap(),
        ];
        let intervals = [
            (0.0, 0.2),
            (0.3, 1.2),
            (0.9, 1.1),
            (1.0, 2.5),
            (2.0, PI),
            (0.0, PI),
        ];
        for p in &phases {
            for &(lo, hi) in &intervals {
                let scan = (0..=2000)
                    .map(|i| p.eval((lo + (hi - lo) * i as f64 / 2000.0).cos()))
                    .fold(0.0f64, f64::max);
                let m = phase_max(p, lo, hi);
                assert!(
                    m >= scan * (1.0 - 1e-12),
                    "{p:?} on [{lo}, {hi}]: {m} < {scan}"
                );
                // Exact where the function is monotone or piecewise linear: no looser than
                // the two lobes' separate maxima.
                assert!(m <= 1.5 * scan, "{p:?} on [{lo}, {hi}]: {m} ≫ {scan}");
            }
        }
        // The table's interior node at 60° is its largest value on [45°, 75°].
        let t = &phases[0];
        let node = t.eval(60f64.to_radians().cos());
        assert_eq!(phase_max(t, 45f64.to_radians(), 75f64.to_radians()), node);
    }

    /// The beam's ray bins carry the pulse: all of it for a uniform beam, all but e^{−2·4.5²}
    /// (what the Monte Carlo's sampler cannot reach) for a Gaussian one; a pencil beam is one
    /// ray along the axis.
    #[test]
    fn beam_ray_bins_carry_the_pulse() {
        let mut s = Scene::from_toml(
            std::path::Path::new("t.toml"),
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
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = 100.0
end_m = 200.0
width_m = 100.0
"#,
        )
        .unwrap();
        assert_eq!(beam_rays(&s), vec![(0.0, 1.0)]);
        s.lidar.beam_divergence_full_angle_mrad = 0.4;
        let sum = |r: Vec<(f64, f64)>| r.iter().map(|x| x.1).sum::<f64>();
        assert!((sum(beam_rays(&s)) - 1.0).abs() < 1e-12);
        assert!((beam_rays(&s).last().unwrap().0 - 0.2e-3).abs() < 1e-15);
        s.lidar.beam_profile = BeamProfile::Gaussian;
        let g = beam_rays(&s);
        assert!((sum(g.clone()) - (1.0 - (-2.0 * 4.5f64 * 4.5).exp())).abs() < 1e-12);
        assert!((g.last().unwrap().0 - 4.5 * 0.2e-3).abs() < 1e-15);
    }
}
