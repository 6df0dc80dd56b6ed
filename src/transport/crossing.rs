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
    use std::f64::consts::FRAC_1_SQRT_2;

    use super::*;
    use crate::transport::testing::{CLOUD, edited, with_options, with_setup};

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

    /// Rays parallel to a generator of a 45° cone (tan² α = 1, so a = 0 exactly and the
    /// quadratic is linear), by plane geometry: in the plane y = 0 the cone is |x| ≤ z.
    #[test]
    fn rays_parallel_to_a_generator_of_a_right_angled_cone() {
        let (h, s_max) = (FRAC_1_SQRT_2, 100.0);
        let up = DVec3::new(h, 0.0, h);
        let close = |got: Span, want: Span, what: &str| {
            let ok = |g: f64, w: f64| (g - w).abs() <= 1e-12 * w.abs().max(1.0);
            assert!(
                ok(got.0, want.0) && ok(got.1, want.1),
                "{what}: {got:?}, not {want:?}"
            );
        };
        // From (−1, 0, 0), 1 m beside the apex, along the generator x = z: inside from
        // −1 + s h = −s h, s = 1/(2h), for ever after.
        let from_beside = cone_span(DVec3::new(-1.0, 0.0, 0.0), up, DVec3::Z, 1.0, s_max);
        close(from_beside, (0.5 / h, s_max), "beside the apex, going up");
        // From (1, 0, 10), inside, down and outwards: 1 + s h = 10 − s h, s = 4.5/h.
        let down = DVec3::new(h, 0.0, -h);
        let leaving = cone_span(DVec3::new(1.0, 0.0, 10.0), down, DVec3::Z, 1.0, s_max);
        close(leaving, (0.0, 4.5 / h), "inside, going down and out");
        // Beside the generator, in the plane that touches the cone along it (a = b = 0, c > 0):
        // |(1 + s h, 1)|² > (1 + s h)², never inside.
        let beside = cone_span(DVec3::new(1.0, 1.0, 1.0), up, DVec3::Z, 1.0, s_max);
        assert!(beside.1 <= beside.0, "beside it: {beside:?}, not empty");
        // Along the generator itself: on the boundary, which the (closed) cone includes, from
        // the start up for ever, or down as far as the apex.
        let on = DVec3::new(1.0, 0.0, 1.0);
        close(
            cone_span(on, up, DVec3::Z, 1.0, s_max),
            (0.0, s_max),
            "on it, going up",
        );
        close(
            cone_span(on, -up, DVec3::Z, 1.0, s_max),
            (0.0, 1.0 / h),
            "on it, going down",
        );
    }

    /// A space-borne geometry: a field of view of 2 tan⁻¹ 2⁻¹⁴ (0.12 mrad), a ray 390 km from
    /// the apex and 30 m off the axis, outside the cone, tilted 10⁻¹⁰ and 10⁻¹² rad from a
    /// generator in the plane of the axis. Its a is then 10⁻¹⁴–10⁻¹⁶, and the root that does not
    /// come from the larger |q| would lose about 8 digits to cancellation. The entry point is the
    /// meeting of two lines in that plane, x₀ + s ω_x = −T (z₀ + s ω_z), computed without
    /// cancellation: T = 2⁻¹⁴ makes T z₀ and T ω_z exact, and ω_x + T ω_z has no cancellation.
    #[test]
    fn entry_keeps_its_digits_for_rays_nearly_along_a_generator() {
        let t = 2f64.powi(-14);
        let (x0, z0) = (-30.0, 3.9e5);
        for tilt in [1e-10, 1e-12] {
            let theta = t.atan() + tilt;
            let omega = DVec3::new(theta.sin(), 0.0, theta.cos());
            let (a, _) = cone_span(DVec3::new(x0, 0.0, z0), omega, DVec3::Z, t * t, 1e6);
            let want = (-t * z0 - x0) / (omega.x + t * omega.z);
            assert!(
                (a - want).abs() <= 1e-12 * want,
                "tilt {tilt}: enters at {a} m, not {want} m"
            );
        }
    }

    /// A lidar 300 m up under a cloud, fields of view of 1, 5 and 20 mrad: the cone estimate
    /// serves the two narrow ones there (their footprints on the cloud are optically thin), the
    /// crossing estimate the 20 mrad annulus, from 2.5 to 10 mrad off the axis.
    fn three_fields() -> String {
        edited(
            CLOUD,
            &[
                ("altitude_m = 0.0", "altitude_m = 300.0"),
                (
                    "fov_full_angle_mrad = [1.0]",
                    "fov_full_angle_mrad = [5.0, 20.0, 1.0]",
                ),
            ],
        )
    }

    /// The spans of `crossing_spans` hold exactly the points of the flight whose direction
    /// from the receiver lies in the served annuli (off the axis by more than `inner` and at
    /// most `outer`, half-angles in rad), by a march along rays near the axis, from below,
    /// inside and beyond the cone's apex, in every direction.
    fn spans_match_a_march(s: &Setup<'_>, inner: f64, outer: f64) {
        let served = |p: DVec3| {
            let v = p - s.receiver;
            let off = v.cross(s.axis).length().atan2(v.dot(s.axis));
            v.dot(s.axis) > 0.0 && off > inner && off <= outer
        };
        let (s_max, n) = (2000.0, 20_000);
        let ds = s_max / n as f64;
        let mut met = [0; 2];
        for i in 0..600 {
            let f = |k: f64| ((i as f64) * k).fract() * 2.0 - 1.0;
            let x = s.receiver
                + s.axis * (f(0.732) * 800.0 + 600.0)
                + s.axis_e1 * (f(0.618) * 12.0)
                + s.axis_e2 * (f(0.414) * 12.0);
            let omega = if i % 3 == 0 {
                // Within 20 mrad of the axis, up or down: long stretches in both annuli.
                (s.axis * f(0.5772).signum() + DVec3::new(f(0.271), f(0.577), 0.0) * 0.02)
                    .normalize()
            } else {
                DVec3::new(f(0.271), f(0.577), f(0.173)).normalize()
            };
            let spans = s.crossing_spans(x, omega, s_max);
            assert!(
                spans
                    .iter()
                    .all(|(a, b)| b <= a || (0.0 <= *a && *b <= s_max))
                    && (spans[1].1 <= spans[1].0 || spans[0].1 <= spans[1].0),
                "ray {i}: spans {spans:?} outside [0, {s_max}] or out of order"
            );
            let near_an_end = |t: f64| {
                spans
                    .iter()
                    .filter(|(a, b)| b > a)
                    .any(|(a, b)| (t - a).abs() <= 1.01 * ds || (t - b).abs() <= 1.01 * ds)
            };
            for j in 0..=n {
                let t = j as f64 * ds;
                let want = served(x + omega * t);
                let got = spans.iter().any(|(a, b)| b > a && *a <= t && t <= *b);
                assert!(
                    got == want || near_an_end(t),
                    "ray {i} at {t} m: served {want}, in the spans {got} ({spans:?})"
                );
            }
            // Rays that meet the annuli, and that cross them twice (through the hole).
            let long = spans.iter().filter(|(a, b)| b - a > 10.0 * ds).count();
            met[0] += usize::from(long > 0);
            met[1] += usize::from(long == 2);
        }
        assert!(met[0] > 50, "only {} rays met the annuli", met[0]);
        if inner > 0.0 {
            assert!(met[1] > 25, "only {} rays crossed the annuli twice", met[1]);
        }
    }

    /// With the cone estimate serving the narrow fields of view, the crossing estimate's spans
    /// are the 20 mrad cone less the 5 mrad one: none in the hole, two pieces for a ray through
    /// it. Without the cone estimate they are the whole 20 mrad cone.
    #[test]
    fn crossing_spans_are_the_served_annuli() {
        with_setup(&three_fields(), |s, _| {
            assert_eq!(s.crossing_from, 2, "the cone estimate serves 1 and 5 mrad");
            spans_match_a_march(s, 2.5e-3, 10e-3);
        });
        with_options(
            &three_fields(),
            |s| s.variance_reduction.cone_estimate = false,
            |s, _| {
                assert_eq!(
                    s.crossing_from, 0,
                    "the crossing estimate serves every annulus"
                );
                spans_match_a_march(s, 0.0, 10e-3);
            },
        );
    }
}
