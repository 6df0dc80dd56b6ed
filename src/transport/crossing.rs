//! Geometry of the crossing estimate (`photon::Tracer::score_crossing`, `docs/transport.md`
//! step 6b): the part of a flight's ray inside the fields of view it serves, where the walk's
//! next collision would be seen by the receiver.
//!
//! A field of view is the forward nappe of a cone with its apex at the receiver, around the
//! telescope axis. Along a line x + s ω, with u = x − rx split into its parts along the axis
//! (u_a) and across it (u_⊥), and ω likewise, a point is inside the cone of half-angle α when
//!
//!   f(s) = |u_⊥ + s ω_⊥|² − tan²α (u_a + s ω_a)² ≤ 0   and   u_a + s ω_a ≥ 0,
//!
//! a quadratic written with the perpendicular parts themselves, not 1 − cos², so that it keeps
//! its digits for rays nearly along a narrow cone. The nappe is convex, so the set is one
//! interval (possibly unbounded).

use glam::DVec3;

use super::Setup;

/// An interval [a, b] of the flight's distance s; empty when b ≤ a.
pub(crate) type Span = (f64, f64);

const EMPTY: Span = (0.0, 0.0);

/// A line u + s ω relative to the apex, 0 ≤ s ≤ s_max, in the parts along the axis and across it that every cone
/// around the same axis shares: the quadratic of each cone then costs a few products.
struct Line {
    ua: f64,
    wa: f64,
    /// |u_⊥|², u_⊥·ω_⊥, |ω_⊥|².
    uu: f64,
    uw: f64,
    ww: f64,
    /// The forward half-space u_a + s ω_a ≥ 0, clipped to [0, s_max] (empty: hi ≤ lo).
    lo: f64,
    hi: f64,
}

impl Line {
    #[inline]
    fn new(u: DVec3, omega: DVec3, axis: DVec3, s_max: f64) -> Self {
        let ua = u.dot(axis);
        let wa = omega.dot(axis);
        let up = u - axis * ua;
        let wp = omega - axis * wa;
        let (mut lo, mut hi) = (0.0f64, s_max);
        if wa > 0.0 {
            lo = lo.max(-ua / wa);
        } else if wa < 0.0 {
            hi = hi.min(-ua / wa);
        } else if ua < 0.0 {
            hi = lo;
        }
        Line {
            ua,
            wa,
            uu: up.length_squared(),
            uw: up.dot(wp),
            ww: wp.length_squared(),
            lo,
            hi,
        }
    }

    /// The interval of the line inside the forward nappe of the cone with tan² of its
    /// half-angle `t2`.
    #[inline]
    fn span(&self, t2: f64) -> Span {
        if !(self.hi > self.lo) {
            return EMPTY;
        }
        let (ua, wa) = (self.ua, self.wa);
        let a = self.ww - t2 * wa * wa;
        let b = self.uw - t2 * ua * wa;
        let c = self.uu - t2 * ua * ua;
        // {f ≤ 0}: between the roots (a > 0), outside them (a < 0), a half-line (a = 0).
        let disc = b * b - a * c;
        let (p, q) = if a > 0.0 {
            if disc < 0.0 {
                return EMPTY;
            }
            roots(a, b, c, disc)
        } else if a < 0.0 {
            if disc < 0.0 {
                (f64::NEG_INFINITY, f64::INFINITY)
            } else {
                // Two half-lines on the two nappes; the forward one is where the line goes
                // along the axis (ω_a ≠ 0 when a < 0).
                let (r1, r2) = roots(a, b, c, disc);
                if wa > 0.0 {
                    (r2, f64::INFINITY)
                } else {
                    (f64::NEG_INFINITY, r1)
                }
            }
        } else if b > 0.0 {
            (f64::NEG_INFINITY, -c / (2.0 * b))
        } else if b < 0.0 {
            (-c / (2.0 * b), f64::INFINITY)
        } else if c <= 0.0 {
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            return EMPTY;
        };
        let (lo, hi) = (self.lo.max(p), self.hi.min(q));
        if hi > lo { (lo, hi) } else { EMPTY }
    }
}

/// The roots r1 ≤ r2 of a s² + 2 b s + c (a ≠ 0, discriminant b² − ac ≥ 0), without
/// cancellation (the larger one in magnitude first, the other from their product c/a).
#[inline]
fn roots(a: f64, b: f64, c: f64, disc: f64) -> (f64, f64) {
    let q = -(b + b.signum() * disc.sqrt());
    let (r1, r2) = if q != 0.0 { (q / a, c / q) } else { (0.0, 0.0) };
    if r1 <= r2 { (r1, r2) } else { (r2, r1) }
}

impl Setup<'_> {
    /// The parts of the flight x + s ω, 0 ≤ s ≤ `s_max`, inside the annuli the crossing
    /// estimate serves: the widest field of view's cone less the cone of the narrowest
    /// annulus it does not serve (at most two intervals).
    pub(crate) fn crossing_spans(&self, x: DVec3, omega: DVec3, s_max: f64) -> [Span; 2] {
        let line = Line::new(x - self.receiver, omega, self.axis, s_max);
        let outer = line.span(self.crossing_tan2[1]);
        if !(outer.1 > outer.0) {
            return [EMPTY, EMPTY];
        }
        if self.crossing_tan2[0] <= 0.0 {
            return [outer, EMPTY];
        }
        let inner = line.span(self.crossing_tan2[0]);
        if !(inner.1 > inner.0) {
            return [outer, EMPTY];
        }
        [
            (outer.0, inner.0.min(outer.1)),
            (inner.1.max(outer.0), outer.1),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cone_span(u: DVec3, omega: DVec3, axis: DVec3, t2: f64, s_max: f64) -> Span {
        Line::new(u, omega, axis, s_max).span(t2)
    }

    /// Inside the forward nappe, by the angle itself.
    fn inside(p: DVec3, axis: DVec3, half_angle: f64) -> bool {
        let along = p.dot(axis);
        along > 0.0 && along >= half_angle.cos() * p.length()
    }

    /// The interval agrees with a brute-force march along the ray, for rays in every
    /// direction (along the axis, across it, backwards, nearly along a generator), from points
    /// inside, outside and behind the cone, narrow and wide.
    #[test]
    fn cone_span_matches_a_march_along_the_ray() {
        let axis = DVec3::new(0.1, -0.2, 1.0).normalize();
        let mut checked = 0;
        for &half in &[2.5e-4f64, 5e-3, 0.3, 1.2] {
            let t2 = half.tan().powi(2);
            for i in 0..400 {
                // Quasi-random start points and directions.
                let f = |k: f64| ((i as f64) * k).fract() * 2.0 - 1.0;
                let x = DVec3::new(f(0.618) * 30.0, f(0.414) * 30.0, f(0.732) * 1500.0 + 500.0);
                let mut omega = DVec3::new(f(0.271), f(0.577), f(0.173)).normalize();
                if i % 7 == 0 {
                    omega = axis; // along the axis
                } else if i % 11 == 0 {
                    omega = -axis;
                }
                let s_max = 3000.0;
                let (a, b) = cone_span(x, omega, axis, t2, s_max);
                let n = 30_000;
                let ds = s_max / n as f64;
                let (mut first, mut last) = (f64::NAN, f64::NAN);
                for j in 0..=n {
                    let s = j as f64 * ds;
                    if inside(x + omega * s, axis, half) {
                        if first.is_nan() {
                            first = s;
                        }
                        last = s;
                    }
                }
                if first.is_nan() {
                    assert!(
                        b - a <= 2.0 * ds,
                        "ray {i}, α {half}: ({a}, {b}) but none inside"
                    );
                } else {
                    assert!(
                        (a - first).abs() <= 1.01 * ds && (b - last).abs() <= 1.01 * ds,
                        "ray {i}, α {half}: ({a}, {b}) against ({first}, {last})"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 100, "only {checked} rays met a cone");
    }

    /// A ray along the axis from below the apex enters at the apex and stays inside; the
    /// generator itself is on the boundary.
    #[test]
    fn rays_along_the_axis_and_a_generator() {
        let axis = DVec3::Z;
        let (a, b) = cone_span(DVec3::new(0.0, 0.0, -10.0), axis, axis, 1e-6, 100.0);
        assert!((a - 10.0).abs() < 1e-9 && b == 100.0, "({a}, {b})");
        let t = 1e-3f64;
        let g = DVec3::new(t, 0.0, 1.0).normalize();
        let (a, b) = cone_span(DVec3::new(-1.0, 0.0, 0.0), g, axis, t * t, 1e4);
        // Parallel to the generator through the apex, 1 m to its side: |−1 + s g_x| ≤ s g_x
        // from s = 1/(2 g_x) on, for ever after.
        let enter = 0.5 / g.x;
        assert!(
            b == 1e4 && (a - enter).abs() < 1e-6 * enter,
            "({a}, {b}), enter {enter}"
        );
    }
}
