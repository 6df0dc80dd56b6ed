//! The analytic single-scatter lidar equation for any scene, in the layout of the Monte Carlo
//! returns (order 1).
//!
//! Energy received from gate [r₁, r₂] for pulse energy E₀ (docs/design.md §3; Measures 1984, Eq. 7.7):
//!
//! E = E₀ η A_tel O ∫_{r₁}^{r₂} β(r) e^{−2τ(r)} / r² dr,
//! β = Σᵢ σ_s,i Pᵢ(180°)/(4π),
//!
//! integrated exactly over the gate (Gauss–Legendre on pieces of homogeneous layer, each fine
//! enough that the integral is converged to ~1e-12), not with the gate-centre approximation. The
//! hard-target return of a Lambertian surface of albedo ρ at range R, incidence θ:
//! E = E₀ η A_tel O/R² · ρ cos θ/π · e^{−2τ(R)}.
//!
//! O is the geometric overlap of the beam with a field of view for a coaxial lidar in the far
//! field: 1 for a pencil beam; (1 − cos α)/(1 − cos β) for a beam uniform inside the half-angle
//! β and a field of view of half-angle α < β; 1 − exp(−2α²/β²) for a Gaussian beam of 1/e²
//! half-angle β.

use crate::aperture::{self, Aperture};
use crate::optics::OpticalAtmosphere;
use crate::particles::matrix::MatrixElements;
use crate::returns::{Order, Returns, Source};
use crate::scene::{BeamProfile, Lidar, Polarisation, Scene};

mod bound;

pub use bound::{MultipleScatteringBound, multiple_scattering_bound};

/// Geometric overlap of the beam with a field of view (full angles in mrad).
pub fn overlap(lidar: &Lidar, fov_full_angle_mrad: f64) -> f64 {
    let alpha = 0.5e-3 * fov_full_angle_mrad;
    let beta = 0.5e-3 * lidar.beam_divergence_full_angle_mrad;
    if beta == 0.0 {
        return 1.0;
    }
    match lidar.beam_profile {
        BeamProfile::Uniform => {
            if alpha >= beta {
                1.0
            } else {
                // 1 − cos x = 2 sin²(x/2), stable for small angles.
                (0.5 * alpha).sin().powi(2) / (0.5 * beta).sin().powi(2)
            }
        }
        BeamProfile::Gaussian => -(-2.0 * alpha * alpha / (beta * beta)).exp_m1(),
    }
}

/// 8-point Gauss–Legendre nodes and weights on [−1, 1].
const GL_X: [f64; 4] = [
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
const GL_W: [f64; 4] = [
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// Single-scatter returns of a scene (analytic; `stderr_j` = 0).
pub fn single_scatter(scene: &Scene, atm: &OpticalAtmosphere) -> Returns {
    single_scatter_of(scene, atm, backscatter_phase, 1.0)
}

/// The co- and cross-polarised parts of the single-scatter returns of a scene whose lidar
/// emits polarised light (`None` for unpolarised light). From the scattering matrices at 180°,
/// σ-weighted over a layer's scatterers (`docs/transport.md`, "Polarisation"): for linearly
/// polarised light co = (F₁₁ + 2F₁₂ + F₂₂)/2 and cross = (F₁₁ − F₂₂)/2, for circular light
/// co = (F₁₁ − F₄₄)/2 and cross = (F₁₁ + F₄₄)/2, in place of the phase function F₁₁(180°);
/// a Lambertian surface returns half of its echo each way.
pub fn single_scatter_polarised(
    scene: &Scene,
    atm: &OpticalAtmosphere,
) -> Option<(Returns, Returns)> {
    let circular = match scene.lidar.polarisation {
        Polarisation::None => return None,
        Polarisation::Linear => false,
        Polarisation::Circular => true,
    };
    let part = |cross: bool| {
        move |atm: &OpticalAtmosphere, layer: usize, k: usize, cap: Option<f64>| -> f64 {
            let total = atm.sigma_s_per_m[layer * atm.n_channels + k];
            // Close to the receiver: the matrix scaled by the mean of F₁₁ over the aperture's
            // cap over its value at 180° (`crate::aperture`).
            let scale = cap.map_or(1.0, |alpha| {
                let point = backscatter_phase(atm, layer, k, None);
                if point > 0.0 {
                    backscatter_phase(atm, layer, k, Some(alpha)) / point
                } else {
                    0.0
                }
            });
            scale
                * atm.components[layer]
                    .iter()
                    .map(|c| {
                        let m = backscatter_matrix(atm, c.phase[k] as usize);
                        let (co, x) = if circular {
                            (0.5 * (m.f11 - m.f44), 0.5 * (m.f11 + m.f44))
                        } else {
                            (0.5 * (m.f11 + 2.0 * m.f12 + m.f22), 0.5 * (m.f11 - m.f22))
                        };
                        c.sigma_s_per_m[k] * if cross { x } else { co }
                    })
                    .sum::<f64>()
                / total
        }
    };
    Some((
        single_scatter_of(scene, atm, part(false), 0.5),
        single_scatter_of(scene, atm, part(true), 0.5),
    ))
}

/// The scattering matrix at 180° of the atmosphere's scatterer `i` (its phase function's).
fn backscatter_matrix(atm: &OpticalAtmosphere, i: usize) -> MatrixElements {
    atm.matrices[i].eval(-1.0)
}

/// Single-scatter returns with the backscatter phase function of a layer and channel given by
/// `back` (per 4π) and the surface's echo times `surface_share`.
///
/// The beam is one ray along the axis, with the overlap of each field of view, unless the
/// beam's cross-section spans altitudes that matter: where the spread of its rays in altitude
/// at the last gate, r_end m sin θ (m the half-angle of the part of the beam inside a field of
/// view, θ the zenith angle), exceeds [`RAY_SPREAD`] of a gate's vertical extent w |cos θ|
/// (near-horizontal and slant beams with wide divergence; a horizontal beam at ground level,
/// half of which is below the ground). The return is then the overlap-weighted mean over the
/// rays of the beam's cross-section, each followed through the layers (and to the surface) on
/// its own: E = E₀ η A ∫ w_f(ψ) E_ray(θ − ψ) dψ, ψ the ray's angle to the axis in the vertical
/// plane and w_f the beam's irradiance inside field of view f integrated across that plane
/// (`beam_rays`). Close to the receiver each ray's scatterers use the aperture's collected
/// energy instead of the point value, as the Monte Carlo does (`crate::aperture`).
fn single_scatter_of(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    back: impl Fn(&OpticalAtmosphere, usize, usize, Option<f64>) -> f64,
    surface_share: f64,
) -> Returns {
    let lidar = &scene.lidar;
    let gates = &scene.gates;
    let range_m: Vec<f64> = (0..gates.count).map(|i| gates.centre_m(i)).collect();
    let mut out = Returns::zeros(
        Source::Analytic,
        scene.channels.iter().map(|c| c.name.clone()).collect(),
        lidar.fov_full_angle_mrad.clone(),
        range_m,
        vec![Order::Exactly(1)],
    );
    let e0 = lidar.pulse_energy_j * lidar.optical_efficiency * lidar.telescope_area_m2();
    let ap = Aperture::new(lidar.telescope_diameter_m, atm);
    let ray = |mu: f64| RayReturns::of(scene, atm, &ap, &back, e0, mu);
    let nch = scene.channels.len();
    match beam_rays(scene) {
        None => {
            // One ray along the axis; the overlap of each field of view.
            let r = ray(lidar.axis().z);
            let overlaps: Vec<f64> = lidar
                .fov_full_angle_mrad
                .iter()
                .map(|f| overlap(lidar, *f))
                .collect();
            for g in 0..gates.count {
                for k in 0..nch {
                    for (f, o) in overlaps.iter().enumerate() {
                        let idx = out.index(k, f, g, 0);
                        out.energy_j[idx] += e0 * o * r.volume[g * nch + k];
                    }
                }
            }
            if let Some((g, echo)) = r.surface(surface_share) {
                for k in 0..nch {
                    for (f, o) in overlaps.iter().enumerate() {
                        let idx = out.index(k, f, g, 0);
                        out.energy_j[idx] += echo[k] * o;
                    }
                }
            }
        }
        Some(rays) => {
            for (mu, f, w) in rays {
                let r = ray(mu);
                for g in 0..gates.count {
                    for k in 0..nch {
                        let idx = out.index(k, f, g, 0);
                        out.energy_j[idx] += e0 * w * r.volume[g * nch + k];
                    }
                }
                if let Some((g, echo)) = r.surface(surface_share) {
                    for k in 0..nch {
                        let idx = out.index(k, f, g, 0);
                        out.energy_j[idx] += echo[k] * w;
                    }
                }
            }
        }
    }
    out
}

/// Fraction of a gate's vertical extent that the spread of the beam's rays in altitude at the
/// last gate may reach before the analytic equation follows the rays one by one.
const RAY_SPREAD: f64 = 1e-3;
/// Rays per field of view when the beam's cross-section is followed.
const RAYS_PER_FOV: usize = 96;

/// The rays of the beam's cross-section, `None` where the axis alone is right (see
/// [`single_scatter_of`]): (vertical direction cosine, field of view, weight) with the weights
/// of each field of view summing to its overlap.
///
/// In the far field the beam's irradiance at angle ψ⃗ from the axis is p(ψ⃗) (uniform inside the
/// half-angle b, 1/(πb²); Gaussian, 2/(πb²) e^{−2ψ²/b²}), and a field of view of half-angle α
/// accepts |ψ⃗| ≤ α. Only the component ψ in the vertical plane of the axis changes a ray's
/// altitude (the other changes its zenith angle at second order), so the cross-section reduces
/// to w(ψ) = ∫ p dψ⊥ over |ψ⃗| ≤ min(α, support): for the uniform beam 2√(m² − ψ²)/(πb²) with
/// m = min(α, b); for the Gaussian (2/(πb²)) e^{−2ψ²/b²} · b √(π/2) erf(√2 √(α² − ψ²)/b). Each
/// is integrated over ψ = m cos t, t ∈ [0, π], by the midpoint rule in t (the square-root edges
/// become smooth), and scaled so its sum is the exact overlap.
fn beam_rays(scene: &Scene) -> Option<Vec<(f64, usize, f64)>> {
    let lidar = &scene.lidar;
    let b = 0.5e-3 * lidar.beam_divergence_full_angle_mrad;
    if b <= 0.0 {
        return None;
    }
    let theta = lidar.zenith_angle_deg.to_radians();
    let half = |fov: f64| {
        let alpha = 0.5e-3 * fov;
        match lidar.beam_profile {
            BeamProfile::Uniform => alpha.min(b),
            BeamProfile::Gaussian => alpha,
        }
    };
    let m_max = lidar
        .fov_full_angle_mrad
        .iter()
        .map(|f| half(*f))
        .fold(0.0f64, f64::max);
    let spread = scene.gates.end_m() * m_max * theta.sin().abs();
    if !(spread > RAY_SPREAD * scene.gates.width_m * theta.cos().abs()) {
        return None;
    }
    let mut rays = Vec::with_capacity(RAYS_PER_FOV * lidar.fov_full_angle_mrad.len());
    for (f, fov) in lidar.fov_full_angle_mrad.iter().enumerate() {
        let alpha = 0.5e-3 * fov;
        let m = half(*fov);
        let first = rays.len();
        let mut sum = 0.0;
        for j in 0..RAYS_PER_FOV {
            let t = std::f64::consts::PI * (j as f64 + 0.5) / RAYS_PER_FOV as f64;
            let psi = m * t.cos();
            // w(ψ) dψ with dψ = m sin t dt (dt common to all nodes: cancels in the scaling).
            let w = match lidar.beam_profile {
                BeamProfile::Uniform => 2.0 * m * t.sin() / (std::f64::consts::PI * b * b),
                BeamProfile::Gaussian => {
                    let chord = (alpha * alpha - psi * psi).max(0.0).sqrt();
                    (-2.0 * psi * psi / (b * b)).exp()
                        * statrs::function::erf::erf(2f64.sqrt() * chord / b)
                }
            } * m
                * t.sin();
            sum += w;
            rays.push(((theta - psi).cos(), f, w));
        }
        let o = overlap(lidar, *fov);
        for r in &mut rays[first..] {
            r.2 *= if sum > 0.0 { o / sum } else { 0.0 };
        }
    }
    Some(rays)
}

/// The single-scatter returns of one ray from the lidar with vertical direction cosine μ: the
/// volume integral of every gate and channel (index g · channels + k; times E₀ η A and the
/// overlap, an energy), and where the ray meets the surface its echo \[J per unit overlap\].
struct RayReturns {
    volume: Vec<f64>,
    /// The gate of the surface echo and per channel its energy before the share: E₀ η A ρ_k
    /// |μ|/π · T_k² times 1/R² (or, close by, 1/(R² + a²)).
    echo: Option<(usize, Vec<f64>)>,
}

impl RayReturns {
    /// [`Self::traced`] with the widest vector instructions the processor has
    /// ([`crate::simd`]: the same numbers).
    fn of<B: Fn(&OpticalAtmosphere, usize, usize, Option<f64>) -> f64>(
        scene: &Scene,
        atm: &OpticalAtmosphere,
        ap: &Aperture,
        back: &B,
        e0: f64,
        mu: f64,
    ) -> Self {
        struct Op<'a, B> {
            scene: &'a Scene,
            atm: &'a OpticalAtmosphere,
            ap: &'a Aperture,
            back: &'a B,
            e0: f64,
            mu: f64,
        }
        impl<B: Fn(&OpticalAtmosphere, usize, usize, Option<f64>) -> f64> crate::simd::WithSimd
            for Op<'_, B>
        {
            type Output = RayReturns;
            #[inline(always)]
            fn with_simd<S: crate::simd::Simd>(self, _: S) -> RayReturns {
                RayReturns::traced(self.scene, self.atm, self.ap, self.back, self.e0, self.mu)
            }
        }
        crate::simd::dispatch(Op {
            scene,
            atm,
            ap,
            back,
            e0,
            mu,
        })
    }

    /// The volume returns of every gate and channel and the surface echo along the ray of
    /// direction cosine `mu`.
    #[inline(always)]
    fn traced(
        scene: &Scene,
        atm: &OpticalAtmosphere,
        ap: &Aperture,
        back: &impl Fn(&OpticalAtmosphere, usize, usize, Option<f64>) -> f64,
        e0: f64,
        mu: f64,
    ) -> Self {
        let lidar = &scene.lidar;
        let nch = scene.channels.len();
        let gates = &scene.gates;
        let z0 = lidar.altitude_m;
        let horizontal = mu.abs() < 1e-12;
        // The ray ends at the surface when it points down at one.
        let surface_range = match &scene.surface {
            Some(s) if mu < -1e-12 => Some((z0 - s.altitude_m) / -mu),
            _ => None,
        };
        let r_max = surface_range.unwrap_or(f64::INFINITY);

        // Ranges where the ray crosses layer edges.
        let mut crossings: Vec<f64> = if horizontal {
            Vec::new()
        } else {
            atm.edges_m
                .iter()
                .map(|e| (e - z0) / mu)
                .filter(|r| *r > 0.0)
                .collect()
        };
        crossings.sort_by(f64::total_cmp);

        let t_rx: Vec<f64> = (0..nch)
            .map(|k| {
                let (s, a) = atm.cumulative_tau(z0, k);
                s + a
            })
            .collect();
        // One-way extinction optical depth from the lidar to range r along the ray.
        let tau_at = |r: f64, k: usize| -> f64 {
            if horizontal {
                return atm.segment_tau_ext(z0, 0.0, r, k);
            }
            let (s, a) = atm.cumulative_tau(z0 + mu * r, k);
            (s + a - t_rx[k]).abs() / mu.abs()
        };
        let inside = |z: f64| atm.n_layers() > 0 && z >= atm.bottom_m() && z <= atm.top_m();

        let mut volume = vec![0.0; gates.count * nch];
        let mut lanes = (!horizontal).then(|| Lanes::new(atm, &t_rx, mu));
        for g in 0..gates.count {
            let ra = gates.start_m + g as f64 * gates.width_m;
            let rb = (ra + gates.width_m).min(r_max);
            if rb <= ra {
                continue;
            }
            let mut breaks = vec![ra];
            breaks.extend(crossings.iter().copied().filter(|r| *r > ra && *r < rb));
            breaks.push(rb);
            let row = &mut volume[g * nch..(g + 1) * nch];
            for w in breaks.windows(2) {
                let (a, b) = (w[0], w[1]);
                let zm = z0 + mu * 0.5 * (a + b);
                if !inside(zm) {
                    continue;
                }
                let l = atm.layer_of(zm);
                // Far from the receiver every channel's piece at once (the same operations per
                // channel as below, in the same order); close to it, and along a horizontal
                // ray, one channel at a time.
                let vectorised = match lanes.as_mut() {
                    Some(lanes) if a * a >= ap.near_d2[l] => {
                        lanes.add_piece(atm, back, z0, l, a, b, row);
                        true
                    }
                    _ => false,
                };
                for k in 0..nch {
                    if vectorised && !lanes.as_ref().is_some_and(|v| v.rest[k]) {
                        continue;
                    }
                    let i = l * nch + k;
                    let sigma_s = atm.sigma_s_per_m[i];
                    if sigma_s <= 0.0 {
                        continue;
                    }
                    let beta = sigma_s * back(atm, l, k, None) / (4.0 * std::f64::consts::PI);
                    // Close to the receiver (from the piece's start on), per node: the
                    // aperture's collected energy, σ_s P̄(cap of α(r))/(4π) · Ω(r)/A.
                    let near = a * a < ap.near_d2[l];
                    let beta_near = |r: f64| {
                        sigma_s * back(atm, l, k, Some(ap.half_angle(r)))
                            / (4.0 * std::f64::consts::PI)
                            * ap.solid_angle_per_area(r)
                    };
                    let sigma_e = sigma_s + atm.sigma_a_per_m[i];
                    let tau_a = tau_at(a, k);
                    let n = subintervals(sigma_e, a, b);
                    let h = (b - a) / n as f64;
                    let mut integral = row[k];
                    for j in 0..n {
                        let c = a + (j as f64 + 0.5) * h;
                        for (x, wgt) in GL_X.iter().zip(GL_W) {
                            for r in [c - 0.5 * h * x, c + 0.5 * h * x] {
                                let tau = tau_a + sigma_e * (r - a);
                                integral += if near {
                                    0.5 * h * wgt * beta_near(r) * (-2.0 * tau).exp()
                                } else {
                                    0.5 * h * wgt * beta * (-2.0 * tau).exp() / (r * r)
                                };
                            }
                        }
                    }
                    row[k] = integral;
                }
            }
        }

        // Hard target.
        let mut echo = None;
        if let (Some(rs), Some(surface)) = (surface_range, &scene.surface) {
            let x = (rs - gates.start_m) / gates.width_m;
            if x >= 0.0 && (x as usize) < gates.count {
                let near = rs * rs < ap.surface_near_d2;
                let e: Vec<f64> = (0..nch)
                    .map(|k| {
                        let t2 = (-2.0 * tau_at(rs, k)).exp();
                        if near {
                            e0 * ap.lambertian_per_area(rs) * surface.albedo[k] * mu.abs()
                                / std::f64::consts::PI
                                * t2
                        } else {
                            e0 / (rs * rs) * surface.albedo[k] * mu.abs() / std::f64::consts::PI
                                * t2
                        }
                    })
                    .collect();
                echo = Some((x as usize, e));
            }
        }
        RayReturns { volume, echo }
    }

    /// The surface echo's gate and per channel factor, times `share`.
    fn surface(&self, share: f64) -> Option<(usize, Vec<f64>)> {
        self.echo
            .as_ref()
            .map(|(g, e)| (*g, e.iter().map(|v| v * share).collect()))
    }
}

/// Sub-intervals of a piece [a, b] of a layer with extinction σ_e: two-way optical depth
/// ≤ 0.25 and width ≤ 5 % of the range.
fn subintervals(sigma_e: f64, a: f64, b: f64) -> usize {
    ((2.0 * sigma_e * (b - a) / 0.25).ceil())
        .max(((b - a) / (0.05 * a)).ceil())
        .clamp(1.0, 1e6) as usize
}

/// The volume returns of a ray's pieces away from the receiver for every channel at once: per
/// channel the operations of the one-channel loop of [`RayReturns::of`] in the same order, so
/// the same sums, with the layer found and the optical depths at the piece's start read once
/// for all channels (`OpticalAtmosphere::cumulative_taus_in`), each layer's backscatter phase
/// evaluated once, and the exponentials in a loop the compiler vectorises
/// (`transport::lanes::exp`, within 2 ulps of the library's, for several channels).
struct Lanes {
    mu: f64,
    t_rx: Vec<f64>,
    ts: Vec<f64>,
    ta: Vec<f64>,
    tau_a: Vec<f64>,
    sigma_e: Vec<f64>,
    /// β of the channels done here; 0 for those left to the one-channel loop.
    beta: Vec<f64>,
    /// P(180°) of each layer's mixture per channel, once the layer is reached.
    back: Vec<Option<Vec<f64>>>,
    /// The channels with scatterers whose piece needs more sub-intervals than the others (an
    /// optically thick piece): left to the one-channel loop.
    rest: Vec<bool>,
}

impl Lanes {
    fn new(atm: &OpticalAtmosphere, t_rx: &[f64], mu: f64) -> Self {
        let nch = t_rx.len();
        Lanes {
            mu,
            t_rx: t_rx.to_vec(),
            ts: vec![0.0; nch],
            ta: vec![0.0; nch],
            tau_a: vec![0.0; nch],
            sigma_e: vec![0.0; nch],
            beta: vec![0.0; nch],
            back: vec![None; atm.n_layers()],
            rest: vec![false; nch],
        }
    }

    /// Add the piece [a, b] of layer l to `row` (the gate's energies per channel) for every
    /// channel not marked in `self.rest`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn add_piece(
        &mut self,
        atm: &OpticalAtmosphere,
        back: &impl Fn(&OpticalAtmosphere, usize, usize, Option<f64>) -> f64,
        z0: f64,
        l: usize,
        a: f64,
        b: f64,
        row: &mut [f64],
    ) {
        let nch = self.t_rx.len();
        let range = nch * l..nch * (l + 1);
        let (ss, sa) = (&atm.sigma_s_per_m[range.clone()], &atm.sigma_a_per_m[range]);
        let back_l = self.back[l].get_or_insert_with(|| {
            (0..nch)
                .map(|k| {
                    if ss[k] > 0.0 {
                        back(atm, l, k, None)
                    } else {
                        0.0
                    }
                })
                .collect()
        });
        // τ from the lidar to the piece's start, as `tau_at(a, k)`.
        let z = (z0 + self.mu * a).clamp(atm.bottom_m(), atm.top_m());
        atm.cumulative_taus_in(atm.layer_near(z, l), z, &mut self.ts, &mut self.ta);
        let n = subintervals(0.0, a, b);
        for k in 0..nch {
            self.tau_a[k] = (self.ts[k] + self.ta[k] - self.t_rx[k]).abs() / self.mu.abs();
            self.sigma_e[k] = ss[k] + sa[k];
            let here = ss[k] > 0.0 && subintervals(self.sigma_e[k], a, b) == n;
            self.rest[k] = ss[k] > 0.0 && !here;
            self.beta[k] = if here {
                ss[k] * back_l[k] / (4.0 * std::f64::consts::PI)
            } else {
                0.0
            };
        }
        let h = (b - a) / n as f64;
        let (tau_a, sigma_e, beta) = (&self.tau_a[..], &self.sigma_e[..], &self.beta[..]);
        if nch == 1 {
            add_nodes(n, a, h, tau_a, sigma_e, beta, row, f64::exp);
        } else {
            add_nodes(
                n,
                a,
                h,
                tau_a,
                sigma_e,
                beta,
                row,
                crate::transport::lanes::exp,
            );
        }
    }
}

/// The Gauss–Legendre nodes of a piece's `n` sub-intervals of width h from a, added to each
/// channel's sum in [`RayReturns::of`]'s order; `e` the exponential. A channel left out has
/// β = 0: it adds +0 to its sum, which leaves it as it is.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn add_nodes(
    n: usize,
    a: f64,
    h: f64,
    tau_a: &[f64],
    sigma_e: &[f64],
    beta: &[f64],
    row: &mut [f64],
    e: impl Fn(f64) -> f64,
) {
    let nch = row
        .len()
        .min(tau_a.len())
        .min(sigma_e.len())
        .min(beta.len());
    for j in 0..n {
        let c = a + (j as f64 + 0.5) * h;
        for (x, wgt) in GL_X.iter().zip(GL_W) {
            for r in [c - 0.5 * h * x, c + 0.5 * h * x] {
                let (f, d, r2) = (0.5 * h * wgt, r - a, r * r);
                for k in 0..nch {
                    let tau = tau_a[k] + sigma_e[k] * d;
                    row[k] += f * beta[k] * e(-2.0 * tau) / r2;
                }
            }
        }
    }
}

/// P(180°) of the scatterer mixture of a layer for channel k; with `cap` = α, its mean over
/// the cap of half-angle α about 180° (what an aperture of half-angle α collects,
/// `crate::aperture`).
fn backscatter_phase(atm: &OpticalAtmosphere, layer: usize, k: usize, cap: Option<f64>) -> f64 {
    let total = atm.sigma_s_per_m[layer * atm.n_channels + k];
    let comps = atm.components[layer].iter();
    match cap {
        None => {
            comps
                .map(|c| c.sigma_s_per_m[k] * atm.phases[c.phase[k] as usize].backscatter())
                .sum::<f64>()
                / total
        }
        Some(alpha) => aperture::mixture_band_mean(
            comps.map(|c| (c.sigma_s_per_m[k], &*atm.phases[c.phase[k] as usize])),
            total,
            (std::f64::consts::PI - alpha, std::f64::consts::PI),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn scene(text: &str) -> Scene {
        Scene::from_toml(Path::new("t.toml"), text).unwrap()
    }

    const HOMOGENEOUS: &str = r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 30.0
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
end_m = 2100.0
width_m = 500.0
[[layer]]
base_m = 0.0
top_m = 5000.0
extinction_per_m = 1e-3
single_scattering_albedo = 0.8
phase = { kind = "isotropic" }
"#;

    #[test]
    fn homogeneous_medium_matches_closed_form() {
        // β = ϖσ/(4π), α = σ: ∫ β e^{−2σr}/r² dr has no elementary form, so compare with an
        // independent fine midpoint rule on the closed-form integrand.
        // Looking up, at 30° and horizontally (where the optical depth is taken along the
        // level path, not from the layer edges), from 1 km inside the 5 km medium.
        for zenith in [0.0, 30.0, 90.0] {
            let mut s = scene(HOMOGENEOUS);
            s.lidar.altitude_m = 1000.0;
            s.lidar.zenith_angle_deg = zenith;
            homogeneous_gates_match_closed_form(&s);
        }
    }

    fn homogeneous_gates_match_closed_form(s: &Scene) {
        let atm = OpticalAtmosphere::build(s).unwrap();
        let r = single_scatter(s, &atm);
        let area = std::f64::consts::PI * 0.25;
        let beta = 0.8e-3 / (4.0 * std::f64::consts::PI);
        for g in 0..4 {
            let (a, b) = (100.0 + 500.0 * g as f64, 600.0 + 500.0 * g as f64);
            let n = 200_000;
            let h = (b - a) / n as f64;
            let exact: f64 = (0..n)
                .map(|i| {
                    let x = a + (i as f64 + 0.5) * h;
                    beta * (-2e-3 * x).exp() / (x * x) * h
                })
                .sum::<f64>()
                * area;
            let got = r.energy(0, 0, g, Order::Exactly(1)).unwrap();
            assert!(
                (got / exact - 1.0).abs() < 1e-8,
                "zenith {}°, gate {g}: {got} vs {exact}",
                s.lidar.zenith_angle_deg
            );
        }
    }

    /// Every channel of a many-channel scene (the pieces away from the receiver done for all
    /// channels at once, `Lanes`) gets what the same channel gets alone (one channel: the
    /// library's exponential, one channel at a time), including a channel so thick that its
    /// pieces need more sub-intervals than the others' (left to the one-channel loop, so
    /// bit for bit).
    #[test]
    fn many_channels_at_once_are_each_channel_alone() {
        let extinction = [1e-3, 2e-3, 0.2, 1e-4, 5e-3];
        let many = HOMOGENEOUS
            .replace(
                "[[channel]]\nname = \"a\"\nwavelength_nm = 1064.0\n",
                &(0..extinction.len())
                    .map(|k| format!("[[channel]]\nname = \"c{k}\"\nwavelength_nm = 1064.0\n"))
                    .collect::<String>(),
            )
            .replace(
                "extinction_per_m = 1e-3",
                &format!("extinction_per_m = {extinction:?}"),
            );
        for zenith in [0.0, 30.0, 150.0] {
            let mut s = scene(&many);
            s.lidar.altitude_m = 1000.0;
            s.lidar.zenith_angle_deg = zenith;
            let all = single_scatter(&s, &OpticalAtmosphere::build(&s).unwrap());
            for (k, e) in extinction.iter().enumerate() {
                let mut one = scene(&HOMOGENEOUS.replace(
                    "extinction_per_m = 1e-3",
                    &format!("extinction_per_m = {e:?}"),
                ));
                one.lidar.altitude_m = 1000.0;
                one.lidar.zenith_angle_deg = zenith;
                let alone = single_scatter(&one, &OpticalAtmosphere::build(&one).unwrap());
                for g in 0..4 {
                    let (a, b) = (
                        all.energy(k, 0, g, Order::Exactly(1)).unwrap(),
                        alone.energy(0, 0, g, Order::Exactly(1)).unwrap(),
                    );
                    // Looking down from 1 km, the last gates lie below the medium.
                    assert!(
                        a > 0.0 || (zenith > 90.0 && g >= 2),
                        "zenith {zenith}°, channel {k}, gate {g}: {a}"
                    );
                    if k == 2 || a == 0.0 {
                        assert_eq!(a.to_bits(), b.to_bits(), "thick channel, gate {g}");
                    } else {
                        assert!(
                            (a / b - 1.0).abs() < 1e-14,
                            "zenith {zenith}°, channel {k}, gate {g}: {a} vs {b}"
                        );
                    }
                }
            }
        }
    }

    /// All orders ≥ 2 bounded by the geometric series Σₙ≥₁ Kⁿ = K/(1 − K); the largest bound
    /// and its field of view, the first on a tie; the largest all-orders bound and where.
    #[test]
    fn bound_on_all_orders_and_the_worst_field_of_view() {
        assert_eq!(MultipleScatteringBound::all_orders(0.5), 1.0);
        assert_eq!(MultipleScatteringBound::all_orders(0.2), 0.25);
        assert_eq!(MultipleScatteringBound::all_orders(0.0), 0.0);
        assert_eq!(MultipleScatteringBound::all_orders(1.0), f64::INFINITY);
        let b = MultipleScatteringBound {
            fov_full_angle_mrad: vec![1.0, 2.0, 3.0],
            range_m: vec![100.0, 200.0],
            ratio: vec![0.1, 0.2, 0.3, 0.05, 0.3, 0.0],
            channels: vec!["a".into(), "b".into()],
            all_orders_by_channel: vec![
                0.1, 0.2, 0.3, 0.05, 0.3, 0.0, // channel a
                0.0, 0.0, 0.0, 0.4, 0.0, 0.4, // channel b
            ],
        };
        assert_eq!(b.worst(), (0.3, 2.0));
        assert_eq!(b.worst_all_orders(), Some((0.4, 1, 1, 1)));
        assert_eq!(b.all_orders_at(1, 2, 1), 0.4);
        let zero = MultipleScatteringBound {
            ratio: vec![0.0; 6],
            ..b
        };
        assert_eq!(zero.worst(), (0.0, 1.0));
    }

    /// A pencil-beam lidar at the ground looking up at one isotropic layer (no air), one gate
    /// around it: the bound's ratio in that gate.
    fn isotropic_layer_bound(base_m: f64, top_m: f64, sigma_per_m: f64, fov_mrad: f64) -> f64 {
        let text = format!(
            r#"
[lidar]
altitude_m = 0.0
zenith_angle_deg = 0.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 0.1
optical_efficiency = 1.0
fov_full_angle_mrad = {fov_mrad}
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = {}
end_m = {}
width_m = {}
[[layer]]
base_m = {base_m}
top_m = {top_m}
extinction_per_m = {sigma_per_m}
single_scattering_albedo = 1.0
phase = {{ kind = "isotropic" }}
"#,
            base_m - 5.0,
            top_m + 5.0,
            top_m - base_m + 10.0
        );
        let s = scene(&text);
        let atm = OpticalAtmosphere::build(&s).unwrap();
        let b = multiple_scattering_bound(&s, &atm);
        assert_eq!(b.ratio.len(), 1);
        b.ratio[0]
    }

    /// Isotropic scatterers make the order-2 kernel's bound a closed form (docs/transport.md,
    /// S5): with the farther point at depth H into a layer, each ordering gives
    /// ½ ∫₀^{π/2} tan γ σ min(ρ cot γ, H) dγ = (σ/4)[H ln(1 + ρ²/H²) + 2ρ atan(H/ρ)], ρ the
    /// footprint radius: (π/2)σρ for a thick layer, about σH ln(ρ/H) for a thin one. The bound
    /// lies between that at the layer's top (ρ there) and 1.25 times it (ρ at the gate's end;
    /// bins of 8 % in γ).
    #[test]
    fn an_isotropic_layer_is_bounded_by_its_optical_depth_within_the_footprint() {
        let closed = |sigma: f64, h: f64, rho: f64| {
            0.5 * sigma * (h * (1.0 + (rho / h).powi(2)).ln() + 2.0 * rho * (h / rho).atan())
        };
        // (layer thickness, FOV): thin under a wide footprint, and thick under a narrow one.
        for (h, fov_mrad) in [(10.0, 200.0), (1.0, 20.0), (2000.0, 1.0)] {
            let (base, sigma) = (1000.0, 1e-4);
            let top = base + h;
            let k = isotropic_layer_bound(base, top, sigma, fov_mrad);
            let tan_a = (0.5e-3 * fov_mrad).tan();
            let low = closed(sigma, h, top * tan_a);
            let high = closed(sigma, h, (top + 5.0) * tan_a);
            assert!(
                k >= low && k <= 1.25 * high,
                "H = {h} m, FOV {fov_mrad} mrad: bound {k:.4e}, closed form {low:.4e}–{high:.4e}"
            );
            // A layer thinner than the footprint: far below the thick-medium value πσρ/2.
            if h < 0.1 * top * tan_a {
                assert!(k < 0.5 * 0.5 * std::f64::consts::PI * sigma * top * tan_a);
            }
        }
    }

    /// The surface gate of a nadir lidar over a Lambertian surface under an isotropic layer of
    /// thickness H (docs/transport.md, S7–S8): light scattered into the footprint by the layer
    /// and light the surface returns that the layer scatters into the field of view each give
    /// ½σ[H + ρ − √(H² + ρ²)], together σ[H + ρ − √(H² + ρ²)], the layer's optical depth
    /// within the footprint's reach. The bound lies between 1 and 1.25 times that (plus the
    /// layer's own order-2 light delayed into the gate, small against the echo here).
    #[test]
    fn a_surface_under_a_layer_is_bounded_by_the_optical_depth_within_reach() {
        let text = r#"
[lidar]
altitude_m = 20000.0
zenith_angle_deg = 180.0
pulse_energy_j = 1.0
beam_divergence_full_angle_mrad = 0.0
telescope_diameter_m = 0.1
optical_efficiency = 1.0
fov_full_angle_mrad = [1.0, 10.0]
[[channel]]
name = "a"
wavelength_nm = 1064.0
[gates]
start_m = 20000.0
end_m = 20010.0
width_m = 10.0
[[layer]]
base_m = 0.0
top_m = 50.0
extinction_per_m = 1e-5
single_scattering_albedo = 1.0
phase = { kind = "isotropic" }
[surface]
altitude_m = 0.0
albedo = 1.0
"#;
        let s = scene(text);
        let atm = OpticalAtmosphere::build(&s).unwrap();
        let b = multiple_scattering_bound(&s, &atm);
        let (sigma, h): (f64, f64) = (1e-5, 50.0);
        for (f, fov) in [1.0f64, 10.0].iter().enumerate() {
            let rho = 20000.0 * (0.5e-3 * fov).tan();
            let closed = sigma * (h + rho - (h * h + rho * rho).sqrt());
            let k = b.ratio[f];
            assert!(
                k >= closed && k <= 1.25 * closed,
                "FOV {fov} mrad: bound {k:.4e}, closed form {closed:.4e}"
            );
        }
        // Looking up, the surface is never met: the same bound as without it.
        let mut up = s.clone();
        up.lidar.altitude_m = 0.0;
        up.lidar.zenith_angle_deg = 0.0;
        up.gates.start_m = 10.0;
        let mut clear = up.clone();
        clear.surface = None;
        let atm_up = OpticalAtmosphere::build(&up).unwrap();
        assert_eq!(
            multiple_scattering_bound(&up, &atm_up).ratio,
            multiple_scattering_bound(&clear, &atm_up).ratio
        );
    }

    #[test]
    fn overlap_of_uniform_and_gaussian_beams() {
        let mut s = scene(HOMOGENEOUS);
        s.lidar.beam_divergence_full_angle_mrad = 2.0;
        assert_eq!(overlap(&s.lidar, 4.0), 1.0);
        assert!((overlap(&s.lidar, 1.0) - 0.25).abs() < 1e-6);
        s.lidar.beam_profile = BeamProfile::Gaussian;
        assert!((overlap(&s.lidar, 2.0) - (1.0 - (-2.0f64).exp())).abs() < 1e-12);
    }
}
