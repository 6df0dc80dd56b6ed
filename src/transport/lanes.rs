//! Kernels over per-channel arrays. The photon carries one weight, one pair of cumulative
//! optical depths and so on per channel, each quantity a contiguous array; a scattering event
//! updates or scores every channel with the same few operations. Written branch-free, those
//! loops compile to SIMD instructions (two channels an instruction on the baseline x86-64
//! target; from `WIDE_FROM` channels on, the kernels with an exponential or a division run a
//! second, AVX2 copy where the processor has it: [`wide_fn!`]), so that a 16-channel DIAL scene
//! costs little more per event than a one-channel one (the idea of pbrt-v4's
//! `SampledSpectrum`). The one operation per channel that a library call would keep scalar is
//! the exponential: [`exp`] is an inline, branch-free one, used where there are several
//! channels (`per_channel!`).

use crate::simd::{WIDE_FROM, wide_fn};

/// Run `$body` for every channel k < n with `$e` the exponential: [`exp_one`] (the library's,
/// with a series just below 0) for a single channel (faster alone than [`exp`], and the
/// one-channel tracer keeps its numbers whichever tracer runs it), [`exp`] for several, where
/// the loop is vectorised.
macro_rules! per_channel {
    ($n:expr, |$k:ident, $e:ident| $body:block) => {
        if $n == 1 {
            let $k = 0;
            let $e = exp_one;
            $body
        } else {
            let $e = exp;
            for $k in 0..$n $body
        }
    };
}

/// e^{−x} for x ≥ 0. Below 1e-3 (the absorption of a flight through a nearly conservative
/// cloud, once per collision) by its Taylor series to x⁴, whose remainder x⁵/120 < 1e-17 is
/// below the last bit: the same number, within rounding, at a fraction of a library call's cost.
#[inline(always)]
pub(super) fn exp_neg(x: f64) -> f64 {
    if x < 1e-3 {
        1.0 - x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0))))
    } else {
        (-x).exp()
    }
}

/// e^x for a single channel ([`per_channel!`]): glibc's, except just below 0, where it is
/// [`exp_neg`]'s series. A one-channel walk through a droplet cloud takes e^{−τ_a} of a tiny
/// absorption at every collision; the library call there cost C.1's plain walk 5 %.
#[inline(always)]
fn exp_one(x: f64) -> f64 {
    if x <= 0.0 { exp_neg(-x) } else { x.exp() }
}

/// ln 2 split into a part with trailing zero bits (so that n·LN2_HI is exact for |n| < 2²⁰)
/// and the rest (fdlibm's e_exp.c values).
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// 1.5·2⁵²: added to a number below 2⁵¹ in magnitude, it rounds it to the nearest integer and
/// leaves that integer (plus 2⁵¹) in the low bits of the sum's mantissa.
const ROUND: f64 = 6_755_399_441_055_744.0;
/// Below this the result would be subnormal: e^x is taken as 0 (it is below 3.3e-308).
const UNDERFLOW: f64 = -708.0;
/// Above this 2^n would overflow the exponent field: the argument is clamped.
const OVERFLOW: f64 = 709.0;

/// e^x for x ≤ 709, to about 1 ulp; 0 below −708 (where the true value is below 3.3e-308) and
/// NaN for NaN. Branch-free (Cody & Waite 1980, "Software Manual for the Elementary
/// Functions": x = n ln 2 + r with |r| ≤ ln 2/2, e^x = 2ⁿ e^r), so that a loop over channels
/// calling it is vectorised; glibc's `exp` is a call per channel and was a quarter of a
/// 16-channel scene's time. The one-channel tracer keeps the library's (`Tracer::exp`). e^r by its Taylor series to r¹³: the remainder, below
/// (ln 2/2)¹⁴/14! = 4.4e-18, is under the last bit.
#[inline(always)]
pub(crate) fn exp(x: f64) -> f64 {
    let xc = x.clamp(UNDERFLOW, OVERFLOW);
    let t = xc * std::f64::consts::LOG2_E + ROUND;
    let n = t - ROUND;
    let r = (xc - n * LN2_HI) - n * LN2_LO;
    // Estrin's scheme: the same polynomial in a tree of depth 4 instead of a chain of 13
    // multiply-adds, which a lone call (no neighbouring channel to interleave with) waits on.
    let c = |n: f64| 1.0 / n;
    let r2 = r * r;
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    let q0 = 1.0 + r;
    let q1 = 0.5 + c(6.0) * r;
    let q2 = c(24.0) + c(120.0) * r;
    let q3 = c(720.0) + c(5_040.0) * r;
    let q4 = c(40_320.0) + c(362_880.0) * r;
    let q5 = c(3_628_800.0) + c(39_916_800.0) * r;
    let q6 = c(479_001_600.0) + c(6_227_020_800.0) * r;
    let t0 = (q0 + q1 * r2) + (q2 + q3 * r2) * r4;
    let t1 = (q4 + q5 * r2) + q6 * r4;
    let p = t0 + t1 * r8;
    // 2ⁿ: the low bits of t hold n + 2⁵¹; adding the exponent bias and shifting moves n + 1023
    // into the exponent field (the 2⁵¹ falls off the top).
    let scale = f64::from_bits(t.to_bits().wrapping_add(1023) << 52);
    if x < UNDERFLOW { 0.0 } else { p * scale }
}

wide_fn! {
    /// A local estimate per channel: le = w·g·e^{−τ}.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn estimate<'a>(le: &'a mut [f64], w: &'a [f64], tau: &'a [f64], g: f64)
    where
        wide(le.len() >= WIDE_FROM)
    {
        let n = le.len();
        let (w, tau) = (&w[..n], &tau[..n]);
        per_channel!(n, |k, e| {
            le[k] = w[k] * g * e(-tau[k]);
        });
    }
}

wide_fn! {
    /// A local estimate per channel with its own phase function: le = w·g·e^{−τ}·P.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn estimate_phase<'a>(
        le: &'a mut [f64],
        w: &'a [f64],
        tau: &'a [f64],
        phase: &'a [f64],
        g: f64,
    )
    where
        wide(le.len() >= WIDE_FROM)
    {
        let n = le.len();
        let (w, tau, phase) = (&w[..n], &tau[..n], &phase[..n]);
        per_channel!(n, |k, e| {
            le[k] = w[k] * g * e(-tau[k]) * phase[k];
        });
    }
}

/// Add the estimates to the tally: bins += le.
#[inline]
pub(super) fn accumulate(bins: &mut [f64], le: &[f64]) {
    let n = bins.len();
    let le = &le[..n];
    for k in 0..n {
        bins[k] += le[k];
    }
}

wide_fn! {
    /// The optical depth of a leg per channel from the cumulative vertical optical depths at its
    /// ends, (ts, ta) and (ts_y, ta_y), and its slant factor |μ|: out = |(ts_y + ta_y) − (ts +
    /// ta)|/|μ|.
    pub(super) fn slant<'a>(
        out: &'a mut [f64],
        ts_y: &'a [f64],
        ta_y: &'a [f64],
        ts: &'a [f64],
        ta: &'a [f64],
        mu: f64,
    )
    where
        wide(out.len() >= WIDE_FROM)
    {
        let n = out.len();
        let (ts_y, ta_y, ts, ta) = (&ts_y[..n], &ta_y[..n], &ts[..n], &ta[..n]);
        for k in 0..n {
            out[k] = ((ts_y[k] + ta_y[k]) - (ts[k] + ta[k])).abs() / mu;
        }
    }
}

wide_fn! {
    /// The optical depth to the receiver per channel: out = |ts + ta − τ_rx|/|μ|.
    pub(super) fn to_receiver<'a>(
        out: &'a mut [f64],
        ts: &'a [f64],
        ta: &'a [f64],
        tau_rx: &'a [f64],
        mu: f64,
    )
    where
        wide(out.len() >= WIDE_FROM)
    {
        let n = out.len();
        let (ts, ta, tau_rx) = (&ts[..n], &ta[..n], &tau_rx[..n]);
        for k in 0..n {
            out[k] = (ts[k] + ta[k] - tau_rx[k]).abs() / mu;
        }
    }
}

wide_fn! {
    /// The crossing estimate per channel with one phase function for all (grey scattering):
    /// le = w·e^{−(τ_a + τ)}·g, τ_a = |ta_y − ta|/|μ| the absorption along the flight to y.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn crossing_grey<'a>(
        le: &'a mut [f64],
        w: &'a [f64],
        ta_y: &'a [f64],
        ta: &'a [f64],
        tau: &'a [f64],
        inv_mu: f64,
        g: f64,
    )
    where
        wide(le.len() >= WIDE_FROM)
    {
        let n = le.len();
        let (w, ta_y, ta, tau) = (&w[..n], &ta_y[..n], &ta[..n], &tau[..n]);
        per_channel!(n, |k, e| {
            let dta = (ta_y[k] - ta[k]).abs() * inv_mu;
            le[k] = w[k] * e(-(dta + tau[k])) * g;
        });
    }
}

wide_fn! {
    /// The crossing estimate per channel (ALIS): le = w·(σ_k/σ_0)·e^{−(τ_a + τ_s − τ* + τ)}·P·g,
    /// τ_s − τ* the channel's scattering optical depth to y beyond class 0's.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn crossing<'a>(
        le: &'a mut [f64],
        w: &'a [f64],
        ts_y: &'a [f64],
        ta_y: &'a [f64],
        ts: &'a [f64],
        ta: &'a [f64],
        tau: &'a [f64],
        sigma: &'a [f64],
        phase: &'a [f64],
        inv_mu: f64,
        tau_star: f64,
        g: f64,
    )
    where
        wide(le.len() >= WIDE_FROM)
    {
        let n = le.len();
        let (w, ts_y, ta_y, ts, ta) = (&w[..n], &ts_y[..n], &ta_y[..n], &ts[..n], &ta[..n]);
        let (tau, sigma, phase) = (&tau[..n], &sigma[..n], &phase[..n]);
        per_channel!(n, |k, e| {
            let dta = (ta_y[k] - ta[k]).abs() * inv_mu;
            let dts = (ts_y[k] - ts[k]).abs() * inv_mu;
            let ratio = sigma[k] / sigma[0];
            let f = ratio * e(-(dta + (dts - tau_star) + tau[k])) * phase[k];
            le[k] = w[k] * f * g;
        });
    }
}

wide_fn! {
    /// The cone estimate per channel with one phase function for all: le = w·σ_y·P_x·P_y·f·
    /// e^{−(τ_xy + τ_back)}.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn cone_grey<'a>(
        le: &'a mut [f64],
        w: &'a [f64],
        sigma_y: &'a [f64],
        px: f64,
        py: f64,
        factor: f64,
        tau_xy: &'a [f64],
        tau_back: &'a [f64],
    )
    where
        wide(le.len() >= WIDE_FROM)
    {
        let n = le.len();
        let (w, sigma_y, tau_xy, tau_back) = (&w[..n], &sigma_y[..n], &tau_xy[..n], &tau_back[..n]);
        per_channel!(n, |k, e| {
            let t = e(-(tau_xy[k] + tau_back[k]));
            le[k] = w[k] * sigma_y[k] * px * py * factor * t;
        });
    }
}

wide_fn! {
    /// The cone estimate per channel, each with its phase functions at x and y.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn cone<'a>(
        le: &'a mut [f64],
        w: &'a [f64],
        sigma_y: &'a [f64],
        px: &'a [f64],
        py: &'a [f64],
        factor: f64,
        tau_xy: &'a [f64],
        tau_back: &'a [f64],
    )
    where
        wide(le.len() >= WIDE_FROM)
    {
        let n = le.len();
        let (w, sigma_y, px, py) = (&w[..n], &sigma_y[..n], &px[..n], &py[..n]);
        let (tau_xy, tau_back) = (&tau_xy[..n], &tau_back[..n]);
        per_channel!(n, |k, e| {
            let t = e(-(tau_xy[k] + tau_back[k]));
            le[k] = w[k] * sigma_y[k] * px[k] * py[k] * factor * t;
        });
    }
}

wide_fn! {
    /// The surface's expected signal per channel: le = w·e^{−(τ_in + τ_back)}·ρ·g, τ_in the
    /// flight's optical depth to the surface, τ_back the leg to the receiver, ρ the albedo.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn surface<'a>(
        le: &'a mut [f64],
        w: &'a [f64],
        tau_in: &'a [f64],
        tau_back: &'a [f64],
        albedo: &'a [f64],
        g: f64,
    )
    where
        wide(le.len() >= WIDE_FROM)
    {
        let n = le.len();
        let (w, tau_in, tau_back, albedo) = (&w[..n], &tau_in[..n], &tau_back[..n], &albedo[..n]);
        per_channel!(n, |k, e| {
            le[k] = w[k] * e(-(tau_in[k] + tau_back[k])) * albedo[k] * g;
        });
    }
}

wide_fn! {
    /// The weights of a photon reflected by the surface, of the branch taken with probability
    /// `branch`: w = w·e^{−τ}/branch·ρ, τ the flight's optical depth, ρ the albedo.
    pub(super) fn reflect<'a>(w: &'a mut [f64], tau: &'a [f64], albedo: &'a [f64], branch: f64)
    where
        wide(w.len() >= WIDE_FROM)
    {
        let n = w.len();
        let (tau, albedo) = (&tau[..n], &albedo[..n]);
        per_channel!(n, |k, e| {
            w[k] = w[k] * e(-tau[k]) / branch * albedo[k];
        });
    }
}

wide_fn! {
    /// A collision's weights with one scattering class and grey scattering: w ·= f·e^{−τ_a},
    /// τ_a the flight's absorption optical depth per channel.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn collide_grey<'a>(w: &'a mut [f64], dta: &'a [f64], f: f64)
    where
        wide(w.len() >= WIDE_FROM)
    {
        let n = w.len();
        let dta = &dta[..n];
        if n == 1 && dta[0] == 0.0 {
            // One channel through a conservative medium (a cloud): e^0 = 1 without the call, which
            // was 1.5 % of C.1's time.
            w[0] *= f;
            return;
        }
        per_channel!(n, |k, e| {
            w[k] *= f * e(-dta[k]);
        });
    }
}

wide_fn! {
    /// A collision's weights with one scattering class (ALIS): w ·= f·(σ_k/σ_0)·
    /// e^{−(τ_a + τ_s − τ_s,0)}, τ_s,0 class 0's scattering optical depth of the flight.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn collide<'a>(
        w: &'a mut [f64],
        dts: &'a [f64],
        dta: &'a [f64],
        sigma: &'a [f64],
        f: f64,
        dts_ref: f64,
    )
    where
        wide(w.len() >= WIDE_FROM)
    {
        let n = w.len();
        let (dts, dta, sigma) = (&dts[..n], &dta[..n], &sigma[..n]);
        per_channel!(n, |k, e| {
            w[k] *= f * (sigma[k] / sigma[0] * e(-(dta[k] + (dts[k] - dts_ref))));
        });
    }
}

wide_fn! {
    /// A scattering's weights, each channel by its phase function against the density
    /// sampled: w ·= P_k/q.
    pub(super) fn reweight<'a>(w: &'a mut [f64], phase: &'a [f64], q: f64)
    where
        wide(w.len() >= WIDE_FROM)
    {
        let n = w.len();
        let phase = &phase[..n];
        for k in 0..n {
            w[k] *= phase[k] / q;
        }
    }
}

/// Per channel, the difference of the cumulative optical depths at a flight's ends times its
/// slant factor: out = |c1 − c0|·inv_μ.
#[inline]
pub(super) fn step(out: &mut [f64], c1: &[f64], c0: &[f64], inv_mu: f64) {
    let n = out.len();
    let (c1, c0) = (&c1[..n], &c0[..n]);
    for k in 0..n {
        out[k] = (c1[k] - c0[k]).abs() * inv_mu;
    }
}

/// out = σ·s: a horizontal flight's optical depth per channel.
#[inline]
pub(super) fn scale(out: &mut [f64], sigma: &[f64], s: f64) {
    let n = out.len();
    let sigma = &sigma[..n];
    for k in 0..n {
        out[k] = sigma[k] * s;
    }
}

#[cfg(test)]
mod tests {
    use super::exp;

    /// Distance in units in the last place between two positive finite numbers.
    fn ulps(a: f64, b: f64) -> u64 {
        a.to_bits().abs_diff(b.to_bits())
    }

    /// Against the C library's exp (correctly rounded to within 0.502 ulp) over the whole range
    /// the transport uses, on a dense grid and at the reduction's edges (r = ±ln 2/2): at most
    /// 2 ulps, and exactly 1 at 0.
    #[test]
    fn exp_is_within_two_ulps_of_the_library() {
        let mut worst = (0, 0.0);
        let mut xs: Vec<f64> = (0..=2_000_000)
            .map(|i| -708.0 + 1417.0 * i as f64 / 2e6)
            .collect();
        for n in -1021..=1022 {
            let edge = (n as f64 + 0.5) * std::f64::consts::LN_2;
            xs.extend([edge, edge.next_up(), edge.next_down()]);
        }
        xs.extend([0.0, -0.0, 1e-300, -1e-300, 1e-9, -1e-9, 709.0, -708.0]);
        for x in xs.into_iter().filter(|x| (-708.0..=709.0).contains(x)) {
            let u = ulps(exp(x), x.exp());
            if u > worst.0 {
                worst = (u, x);
            }
        }
        assert!(worst.0 <= 2, "{} ulps at x = {}", worst.0, worst.1);
        assert_eq!(exp(0.0), 1.0);
    }

    /// Each kernel gives, to the bit, the per-channel expression it vectorises, with [`exp`]
    /// (19 channels: the dispatched copy, AVX2 where the processor has it, vector bodies and a
    /// remainder; 5: the baseline copy below `WIDE_FROM`), and with the library's for one
    /// channel.
    #[test]
    fn kernels_are_their_per_channel_expressions() {
        use super::*;
        const { assert!(5 < WIDE_FROM && WIDE_FROM <= 19) };
        for n in [19, 5, 1] {
            let lib = n == 1;
            let ex = |x: f64| if lib { x.exp() } else { exp(x) };
            let v = |seed: f64| -> Vec<f64> {
                (0..n)
                    .map(|k| (seed * (k as f64 + 1.3)).sin().abs() * 3.0)
                    .collect()
            };
            let (w, a, b, c, d, g, f) = (v(1.1), v(2.3), v(3.7), v(4.1), v(5.9), v(6.3), v(7.7));
            let mut out = vec![vec![0.0; n]; 16];
            estimate_phase(&mut out[0], &w, &a, &b, 0.7);
            crossing(&mut out[1], &w, &a, &b, &c, &d, &g, &f, &a, 1.3, 0.2, 0.9);
            cone(&mut out[2], &w, &a, &b, &c, 0.4, &d, &g);
            out[3].copy_from_slice(&w);
            collide(&mut out[3], &a, &b, &c, 0.8, 0.1);
            slant(&mut out[4], &a, &b, &c, &d, 0.3);
            crossing_grey(&mut out[5], &w, &a, &b, &c, 1.7, 0.6);
            out[6].copy_from_slice(&c);
            accumulate(&mut out[6], &a);
            surface(&mut out[7], &w, &a, &b, &c, 0.7);
            to_receiver(&mut out[8], &a, &b, &c, 0.3);
            out[9].copy_from_slice(&w);
            reflect(&mut out[9], &a, &b, 0.6);
            estimate(&mut out[10], &w, &a, 0.7);
            cone_grey(&mut out[11], &w, &a, 0.3, 0.5, 0.4, &b, &c);
            out[12].copy_from_slice(&w);
            collide_grey(&mut out[12], &a, 0.8);
            step(&mut out[13], &a, &b, 1.3);
            scale(&mut out[14], &a, 0.9);
            out[15].copy_from_slice(&w);
            reweight(&mut out[15], &a, 0.7);
            let mut clear = w.clone();
            collide_grey(&mut clear, &vec![0.0; n], 0.8);
            for k in 0..n {
                let same = |i: usize, x: f64| {
                    assert_eq!(
                        out[i][k].to_bits(),
                        x.to_bits(),
                        "kernel {i}, channel {k} of {n}"
                    )
                };
                same(0, w[k] * 0.7 * ex(-a[k]) * b[k]);
                let dta = (b[k] - d[k]).abs() * 1.3;
                let dts = (a[k] - c[k]).abs() * 1.3;
                let ratio = f[k] / f[0];
                same(
                    1,
                    w[k] * (ratio * ex(-(dta + (dts - 0.2) + g[k])) * a[k]) * 0.9,
                );
                same(2, w[k] * a[k] * b[k] * c[k] * 0.4 * ex(-(d[k] + g[k])));
                same(3, w[k] * (0.8 * (c[k] / c[0] * ex(-(b[k] + (a[k] - 0.1))))));
                same(4, ((a[k] + b[k]) - (c[k] + d[k])).abs() / 0.3);
                same(5, w[k] * ex(-((a[k] - b[k]).abs() * 1.7 + c[k])) * 0.6);
                same(6, c[k] + a[k]);
                same(7, w[k] * ex(-(a[k] + b[k])) * c[k] * 0.7);
                same(8, (a[k] + b[k] - c[k]).abs() / 0.3);
                same(9, w[k] * ex(-a[k]) / 0.6 * b[k]);
                same(10, w[k] * 0.7 * ex(-a[k]));
                same(11, w[k] * a[k] * 0.3 * 0.5 * 0.4 * ex(-(b[k] + c[k])));
                same(12, w[k] * (0.8 * ex(-a[k])));
                same(13, (a[k] - b[k]).abs() * 1.3);
                same(14, a[k] * 0.9);
                same(15, w[k] * (a[k] / 0.7));
                assert_eq!(clear[k].to_bits(), (w[k] * 0.8).to_bits());
            }
        }
    }

    /// Below −708 it is 0, NaN stays NaN, and the result never exceeds the largest finite number.
    #[test]
    fn exp_ends_of_the_range() {
        for x in [-708.5, -745.2, -1e6, f64::NEG_INFINITY] {
            assert_eq!(exp(x), 0.0, "{x}");
        }
        assert!(exp(f64::NAN).is_nan());
        assert!(exp(1e6).is_finite() && exp(1e6) > 8e307);
    }
}
