//! Geometry and densities of the cone estimate (`photon::Tracer::score_cone`): a virtual last
//! scattering at a point y drawn inside a field-of-view annulus, on the ray y = rx + r ω from the
//! receiver, combined with the ordinary local estimate at the walk's own collisions by multiple
//! importance sampling (balance heuristic; Veach 1997, ch. 9, as next-event estimation is
//! combined with BSDF sampling in a path tracer).
//!
//! Along the ray, in t = r − r∥ (r∥ the foot of the collision x on the ray, ρ its distance from
//! the ray), y is drawn from the mixture ½ p_A + ½ p_B of two Cauchy densities: p_A ∝ 1/(t² + ρ²)
//! = 1/|x − y|², the flight's own fall-off, and p_B ∝ 1/(t² + b²), b = CONE_WIDE_SCALE·max(ρ, ℓ),
//! for far points where the leg x → y turns into a forward peak. Legs shorter than ℓ
//! (CONE_MIN_LEG_M) are excluded: there the ordinary local estimate alone scores.

use glam::DVec3;

use super::Setup;

/// The last atmospheric collision x of a photon, as the cone estimate and its MIS weights need
/// it: where, the direction the photon arrived with, its path there, the DDIS probability used
/// for the scattering at x (0 without DDIS) and its layer.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Prev {
    pub pos: DVec3,
    pub dir_in: DVec3,
    pub path: f64,
    pub eps: f64,
    pub layer: usize,
    /// Probability with which the cone estimate is made from here (`Setup::cone_rate`).
    pub cone_rate: f64,
}

/// One ray of an annulus as seen from a collision: the allowed part of t and the two densities'
/// normalisers.
pub(crate) struct ConeRay {
    /// r∥: distance along the ray to the foot of x.
    pub along: f64,
    rho: f64,
    b: f64,
    pieces: [(f64, f64); 2],
    ma: [f64; 2],
    mb: [f64; 2],
    za: f64,
    zb: f64,
}

/// atan(b/c) − atan(a/c), without cancellation when c ≪ |a|, |b|.
#[inline]
fn arc(a: f64, b: f64, c: f64) -> f64 {
    if b > a {
        ((b - a) * c).atan2(c * c + a * b)
    } else {
        0.0
    }
}

impl ConeRay {
    /// Draw t from ½ p_A + ½ p_B with two uniform numbers.
    #[inline]
    pub fn sample(&self, u1: f64, u2: f64) -> f64 {
        let (m, c, mut u) = if u1 < 0.5 {
            (self.ma, self.rho, u2 * (self.ma[0] + self.ma[1]))
        } else {
            (self.mb, self.b, u2 * (self.mb[0] + self.mb[1]))
        };
        let ta = if u < m[0] {
            self.pieces[0].0
        } else {
            u -= m[0];
            self.pieces[1].0
        };
        // t = c tan(atan(t_a/c) + u), as (t_a + c tan u)/(1 − t_a tan u/c).
        let tu = u.tan();
        (ta + c * tu) / (1.0 - ta * tu / c)
    }

    /// ½ p_A(t) + ½ p_B(t) (0 outside the allowed part).
    #[inline]
    pub fn density(&self, t: f64) -> f64 {
        let inside = self.pieces.iter().any(|(a, b)| t >= *a && t <= *b && b > a);
        if !inside {
            return 0.0;
        }
        0.5 / (self.za * (t * t + self.rho * self.rho))
            + 0.5 / (self.zb * (t * t + self.b * self.b))
    }

    /// |x − y|² at t.
    #[inline]
    pub fn leg2(&self, t: f64) -> f64 {
        t * t + self.rho * self.rho
    }
}

impl Setup<'_> {
    /// The ray rx + r ω seen from a collision at x after a path `path_x`: its part inside the
    /// layers, reachable before the last gate and at least ℓ from x. `None` if empty.
    pub(crate) fn cone_ray(&self, x: DVec3, path_x: f64, omega: DVec3) -> Option<ConeRay> {
        if omega.z.abs() < 1e-12 {
            return None;
        }
        let budget = 2.0 * self.r_end_m - path_x;
        let v = x - self.receiver;
        let v2 = v.length_squared();
        if budget * budget <= v2 {
            return None;
        }
        let r1 = (self.bottom_m - self.receiver.z) / omega.z;
        let r2 = (self.top_m - self.receiver.z) / omega.z;
        let along = v.dot(omega);
        // Ellipsoid with foci x and rx: |x − y| + r = budget.
        let r_budget = (budget * budget - v2) / (2.0 * (budget - along));
        let r_lo = r1.min(r2).max(0.0);
        let r_hi = r1.max(r2).min(r_budget);
        if !(r_hi > r_lo) {
            return None;
        }
        let lmin = super::CONE_MIN_LEG_M;
        let rho = (v2 - along * along).max(0.0).sqrt().max(1e-9);
        let (t_lo, t_hi) = (r_lo - along, r_hi - along);
        let h = (lmin * lmin - rho * rho).max(0.0).sqrt();
        let pieces = if h > 0.0 {
            [(t_lo, t_hi.min(-h)), (t_lo.max(h), t_hi)]
        } else {
            [(t_lo, t_hi), (0.0, 0.0)]
        };
        let b = super::CONE_WIDE_SCALE * rho.max(lmin);
        let ma = [
            arc(pieces[0].0, pieces[0].1, rho),
            arc(pieces[1].0, pieces[1].1, rho),
        ];
        let mb = [
            arc(pieces[0].0, pieces[0].1, b),
            arc(pieces[1].0, pieces[1].1, b),
        ];
        let (za, zb) = ((ma[0] + ma[1]) / rho, (mb[0] + mb[1]) / b);
        if !(za > 0.0 && zb > 0.0) {
            return None;
        }
        Some(ConeRay {
            along,
            rho,
            b,
            pieces,
            ma,
            mb,
            za,
            zb,
        })
    }

    /// Density (per volume) with which the cone estimate from `p` draws the point y in
    /// annulus `a` (one of the cone's annuli, chosen uniformly, then a point in it).
    pub(crate) fn cone_density(&self, p: &Prev, y: DVec3, a: usize) -> f64 {
        let d_omega = self.annulus_sr[a];
        if !(d_omega > 0.0) || !self.cone_annuli.contains(&a) {
            return 0.0;
        }
        let v = y - self.receiver;
        let r = v.length();
        let omega = v / r;
        match self.cone_ray(p.pos, p.path, omega) {
            Some(ray) => {
                p.cone_rate * ray.density(r - ray.along)
                    / (d_omega * r * r * self.cone_annuli.len() as f64)
            }
            None => 0.0,
        }
    }

    /// Probability that the cone estimate is made from a collision at x: 1 within
    /// [`super::CONE_RATE_FOOTPRINTS`] footprints of the widest annulus it serves from the axis,
    /// falling as 1/ρ beyond, where its contributions are small (Russian roulette on the
    /// estimate, unbiased: its density carries the rate in both MIS weights).
    pub(crate) fn cone_rate(&self, x: DVec3) -> f64 {
        let v = x - self.receiver;
        let along = v.dot(self.axis);
        let rho = (v.length_squared() - along * along).max(0.0).sqrt();
        let reach = super::CONE_RATE_FOOTPRINTS * along.abs() * self.cone_tan;
        if rho <= reach { 1.0 } else { reach / rho }
    }

    /// Density (per volume) of the walk's next collision at y after the scattering at `p`, in
    /// scattering class 0 and without the flight's truncation: the phase function (mixed with
    /// DDIS's receiver-centred one where that was used) times σ_s e^{−τ_s}/|x − y|². Only the
    /// MIS weights use it, and any positive function computed alike on both sides keeps them
    /// summing to one.
    pub(crate) fn walk_density(&self, p: &Prev, y: DVec3, layer_y: usize) -> f64 {
        let cls = &self.classes[0];
        let sigma = cls.sigma[layer_y];
        if !(sigma > 0.0) {
            return 0.0;
        }
        let leg = y - p.pos;
        let l2 = leg.length_squared();
        let l = l2.sqrt();
        let e = leg / l;
        let k = cls.channel;
        let mut phase = self.mixture_phase(p.layer, k, p.dir_in.dot(e));
        if p.eps > 0.0 {
            let to_rx = (self.receiver - p.pos).normalize();
            phase = (1.0 - p.eps) * phase + p.eps * self.mixture_phase(p.layer, k, to_rx.dot(e));
        }
        let tau = if e.z.abs() < 1e-12 {
            cls.sigma[p.layer] * l
        } else {
            (self.class_tau_in(0, layer_y, y.z) - self.class_tau_in(0, p.layer, p.pos.z)).abs()
                / e.z.abs()
        };
        phase * (0.25 / std::f64::consts::PI) * sigma * (-tau).exp() / l2
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::OpticalAtmosphere;
    use crate::transport::testing::{CLOUD, edited, with_setup};

    /// The allowed part of t as one list of intervals.
    fn allowed(ray: &ConeRay) -> Vec<(f64, f64)> {
        ray.pieces.iter().copied().filter(|(a, b)| b > a).collect()
    }

    /// The probability with which the cone estimate is made from a collision is one within a
    /// footprint of the widest field of view it serves (1 mrad: 0.5 mrad half-angle) and falls
    /// beyond, never above one (the estimate cannot be made more than once, so a rate above one
    /// would bias it), from 100 m to 100 km along the axis and 0 to 1 km off it.
    #[test]
    fn cone_rate_is_one_inside_the_footprint_and_a_probability_beyond() {
        with_setup(CLOUD, |s, _| {
            let half_angle = 0.5e-3f64;
            for along in [100.0, 1e3, 1e4, 1e5] {
                let footprint = along * half_angle.tan();
                let mut last = 1.0;
                for rho in [0.0, 0.01, 0.1, 1.0, 10.0, 100.0, 1000.0] {
                    let x = s.receiver + s.axis * along + s.axis_e1 * rho;
                    let rate = s.cone_rate(x);
                    let what = format!("{along} m along, {rho} m off the axis: rate {rate}");
                    assert!(rate > 0.0 && rate <= 1.0, "{what}");
                    assert!(rate <= last, "{what}, after {last}");
                    if rho <= 0.999 * footprint {
                        assert_eq!(rate, 1.0, "{what}");
                    } else if rho >= 1.001 * footprint {
                        assert!(rate < 1.0, "{what}");
                    }
                    last = rate;
                }
            }
        });
    }

    /// CLOUD's layer from the ground to 10 km at 4 km⁻¹.
    fn deep_layer() -> String {
        edited(
            CLOUD,
            &[
                (
                    "base_m = 500.0\ntop_m = 700.0",
                    "base_m = 0.0\ntop_m = 10000.0",
                ),
                ("extinction_per_km = 10.0", "extinction_per_km = 4.0"),
            ],
        )
    }

    /// A scattering in the middle of the deep layer, on the axis, the photon leaving along
    /// `dir_in`, with DDIS's share `eps`.
    fn at_5_km(dir_in: DVec3, eps: f64, atm: &OpticalAtmosphere) -> Prev {
        let pos = DVec3::new(0.0, 0.0, 5000.0);
        Prev {
            pos,
            dir_in,
            path: 5000.0,
            eps,
            layer: atm.layer_of(pos.z),
            cone_rate: 1.0,
        }
    }

    /// The walk's next-collision density after a scattering at x, p(y) = P(Θ)/4π σ e^{−τ}/|x − y|²
    /// (the phase function mixed with DDIS's receiver-centred one), is a probability density: in
    /// a layer 10 km deep at 4 km⁻¹ (optical depth 20 from x at its middle to either side, so
    /// all but e⁻²⁰ of the photons collide in it) it integrates to one over the layer, without
    /// DDIS and with ε = 0.3. Quadrature: Simpson's rule in μ (4000 steps for the forward and
    /// the receiver-centred peaks, both on the vertical), 8 azimuths, and along each direction
    /// 32-point Gauss–Legendre in u = 1 − e^{−σl}, where the exact integrand is constant.
    #[test]
    fn walk_density_integrates_to_one_in_an_optically_deep_layer() {
        with_setup(&deep_layer(), |s, atm| {
            let sigma = 4e-3;
            let gl = crate::instrument::line_shape::gauss_legendre(32);
            for eps in [0.0, 0.3] {
                let p = at_5_km(DVec3::Z, eps, atm);
                let x = p.pos;
                let along = |e: DVec3| -> f64 {
                    // ∫₀^{l_exit} l² p(x + l e) dl, with u = 1 − e^{−σl}: dl = du/(σ(1 − u)).
                    let l_exit = if e.z > 0.0 {
                        (10000.0 - x.z) / e.z
                    } else {
                        -x.z / e.z
                    };
                    let u_exit = -(-sigma * l_exit).exp_m1();
                    gl.iter()
                        .map(|q| {
                            let u = 0.5 * u_exit * (1.0 + q.offset_mhz);
                            let l = -(-u).ln_1p() / sigma;
                            let y = x + e * l;
                            let w = 0.5 * u_exit * q.weight;
                            w * l * l * s.walk_density(&p, y, atm.layer_of(y.z))
                                / (sigma * (1.0 - u))
                        })
                        .sum()
                };
                let (n_mu, n_phi) = (4000, 8);
                let h = 2.0 / n_mu as f64;
                let mut total = 0.0;
                for i in 0..=n_mu {
                    // Not exactly ±1 or 0 (vertical or horizontal): the layer's ends and the poles.
                    let mu = (-1.0 + i as f64 * h).clamp(-1.0 + 1e-12, 1.0 - 1e-12);
                    let mu = if mu == 0.0 { 1e-12 } else { mu };
                    let simpson = if i == 0 || i == n_mu {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    let st = (1.0 - mu * mu).sqrt();
                    let ring: f64 = (0..n_phi)
                        .map(|j| {
                            let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / n_phi as f64;
                            along(DVec3::new(st * phi.cos(), st * phi.sin(), mu))
                        })
                        .sum::<f64>()
                        * (2.0 * std::f64::consts::PI / n_phi as f64);
                    total += simpson * h / 3.0 * ring;
                }
                assert!((total - 1.0).abs() < 1e-6, "ε = {eps}: ∫ p dV = {total}");
            }
        });
    }

    /// Rays 0°, 30°, 60° and 85° from the zenith, seen from collisions off the ray (ρ from
    /// 0.3 m, where legs shorter than ℓ = 1 m are cut out, to 200 m). The allowed part of t runs
    /// from the layers' bottom to their top (y = rx + (r∥ + t) ω at 500 and 700 m), less the
    /// points within ℓ of x (|x − y| = ℓ at the cut's ends), and ½ p_A + ½ p_B integrates to 1
    /// over it (Simpson's rule on each interval after t = ρ tan φ, 10⁵ steps: fine enough for
    /// p_B's peak, ρ/b wide in φ). When the way back through y would arrive after the last gate,
    /// the ray ends earlier, on the ellipsoid of that path length.
    ///
    /// (The transport stays unbiased with a wrong ray or density as long as the cone estimate
    /// and its MIS partner compute them alike: only the variance would show it.)
    #[test]
    fn cone_ray_spans_the_layers_and_its_density_is_normalised() {
        with_setup(CLOUD, |s, _| {
            let lmin = crate::transport::CONE_MIN_LEG_M;
            for zenith_deg in [0.0f64, 30.0, 60.0, 85.0] {
                let th = zenith_deg.to_radians();
                let omega = DVec3::new(th.sin(), 0.0, th.cos());
                let e_perp = DVec3::new(th.cos(), 0.0, -th.sin())
                    .cross(omega)
                    .normalize();
                for (r_foot, rho) in [(550.0, 0.3), (650.0, 0.9), (600.0, 5.0), (400.0, 200.0)] {
                    let r_foot = r_foot / th.cos();
                    let x = s.receiver + omega * r_foot + e_perp * rho;
                    let ray = s.cone_ray(x, (x - s.receiver).length(), omega).unwrap();
                    let what = format!("zenith {zenith_deg}°, ρ {rho} m");
                    assert!((ray.along - r_foot).abs() < 1e-9 * r_foot, "{what}");
                    let parts = allowed(&ray);
                    let z_at = |t: f64| s.receiver.z + (ray.along + t) * omega.z;
                    let (first, last) = (parts[0].0, parts[parts.len() - 1].1);
                    assert!(
                        (z_at(first) - 500.0).abs() < 1e-9,
                        "{what}: {}",
                        z_at(first)
                    );
                    assert!((z_at(last) - 700.0).abs() < 1e-9, "{what}: {}", z_at(last));
                    if rho < lmin {
                        assert_eq!(parts.len(), 2, "{what}");
                        for t in [parts[0].1, parts[1].0] {
                            assert!((ray.leg2(t).sqrt() - lmin).abs() < 1e-9, "{what}");
                        }
                    } else {
                        assert_eq!(parts.len(), 1, "{what}");
                    }
                    // ∫ density dt, with t = ρ tan φ taking out the 1/(t² + ρ²) peak.
                    let mut total = 0.0;
                    for (a, b) in parts {
                        let (pa, pb) = ((a / rho).atan(), (b / rho).atan());
                        let n = 100_000;
                        let h = (pb - pa) / n as f64;
                        // Inside the interval's ends: density() is 0 a rounding outside them.
                        let f = |phi: f64| {
                            let t = (rho * phi.tan()).clamp(a, b);
                            ray.density(t) * rho / phi.cos().powi(2)
                        };
                        let mut sum = f(pa) + f(pb);
                        for i in 1..n {
                            sum += f(pa + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
                        }
                        total += sum * h / 3.0;
                    }
                    assert!((total - 1.0).abs() < 1e-9, "{what}: ∫ density = {total}");
                }
                // After a path that leaves a budget to the last gate's end (twice 10 km) of 150 m
                // more than the way straight back from x: the ray stops where the way back through
                // y would overrun it, on the ellipsoid |x − y| + r = budget with foci x and the
                // receiver, inside the cloud.
                let x = s.receiver + omega * (600.0 / th.cos()) + e_perp * 5.0;
                let budget = (x - s.receiver).length() + 150.0;
                let ray = s.cone_ray(x, 2.0 * 10_000.0 - budget, omega).unwrap();
                let last = allowed(&ray).last().unwrap().1;
                let y = s.receiver + omega * (ray.along + last);
                assert!(y.z > 600.0 && y.z < 700.0, "zenith {zenith_deg}°: {}", y.z);
                let back = (y - x).length() + (y - s.receiver).length();
                assert!(
                    (back - budget).abs() < 1e-9 * budget,
                    "zenith {zenith_deg}°: {back} against {budget}"
                );
            }
        });
    }

    /// The receiver-centred part of the walk's density points at the receiver, as DDIS draws
    /// it (`photon.rs`: towards rx − x). In the deep layer, after a scattering at 5 km with the
    /// photon going horizontally, the points 100 m straight down (towards the receiver) and up
    /// are 90° from its direction and equally deep: their densities differ only by the
    /// receiver-centred part, P(0°) below and P(180°) above. HG, g = 0.8:
    /// P(μ) = (1 − g²)/(1 + g² − 2gμ)^{3/2}.
    #[test]
    fn walk_density_s_receiver_centred_part_points_at_the_receiver() {
        let hg = |mu: f64| (1.0 - 0.64) / (1.64 - 1.6 * mu).powf(1.5);
        with_setup(&deep_layer(), |s, atm| {
            let eps = 0.3;
            let p = at_5_km(DVec3::X, eps, atm);
            let x = p.pos;
            let at = |y: DVec3| s.walk_density(&p, y, atm.layer_of(y.z));
            let (down, up) = (x - DVec3::Z * 100.0, x + DVec3::Z * 100.0);
            let want =
                ((1.0 - eps) * hg(0.0) + eps * hg(1.0)) / ((1.0 - eps) * hg(0.0) + eps * hg(-1.0));
            let got = at(down) / at(up);
            assert!((got / want - 1.0).abs() < 1e-9, "down/up {got}, not {want}");
        });
    }
}
