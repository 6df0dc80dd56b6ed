//! Integration of one mode over size parameter: trapezoid sums on halved grids until they
//! converge, then the angular (matrix) integrals on the final grid ([`super`] module docs).

use std::f64::consts::PI;

use nalgebra::DMatrix;
use num_complex::Complex64;
use rayon::prelude::*;

use super::options::{BulkOptions, ModeConvergence};
use super::{SizeDistribution, param};
use crate::particles::mie::{MieCoefficients, MieError, four_s_from_s_pm};

/// Integrals over one mode: ∫ n(r) {Cext, Csca, Cback, g·Csca, r²·π, r³·π} dr [cm⁻³ µm²(µm)].
#[derive(Clone, Copy, Default, Debug)]
pub(super) struct Sums(pub(super) [f64; 6]);

impl Sums {
    fn add(&mut self, o: &Sums, w: f64) {
        for i in 0..6 {
            self.0[i] += w * o.0[i];
        }
    }
}

pub(super) struct ModeGrid {
    m: Complex64,
    mode: SizeDistribution,
    k_per_um: f64,
    pub(super) x_lo: f64,
    pub(super) dx: f64,
    pub(super) points: usize, // intervals M (points = M + 1)
    pub(super) sums: Sums,
}

const BLOCK: usize = 64;

fn integrand(mode: &SizeDistribution, m: Complex64, k: f64, x: f64) -> Result<Sums, MieError> {
    let r = x / k;
    let n = mode.density(r);
    if n == 0.0 {
        return Ok(Sums::default());
    }
    let e = MieCoefficients::compute(m, x)?.efficiencies();
    let area = PI * r * r;
    Ok(Sums([
        n * e.qext * area,
        n * e.qsca * area,
        n * e.qback * area,
        n * e.g * e.qsca * area,
        n * area,
        n * area * r,
    ]))
}

/// Sum of the integrand over the points x0 + i·h, i in 0..count (parallel, fixed block order).
fn sum_points(
    mode: &SizeDistribution,
    m: Complex64,
    k: f64,
    x0: f64,
    h: f64,
    count: usize,
) -> Result<Sums, MieError> {
    let blocks: Vec<Result<Sums, MieError>> = (0..count.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let mut s = Sums::default();
            for i in b * BLOCK..((b + 1) * BLOCK).min(count) {
                s.add(&integrand(mode, m, k, x0 + i as f64 * h)?, 1.0);
            }
            Ok(s)
        })
        .collect();
    let mut total = Sums::default();
    for b in blocks {
        total.add(&b?, 1.0);
    }
    Ok(total)
}

/// The radius range \[µm\] a mode is integrated over (all but `tail_fraction` of its geometric
/// cross-section, within its truncation), for wavenumber `k` \[1/µm\].
pub(super) fn mode_range_um(
    mode: &SizeDistribution,
    k: f64,
    opts: &BulkOptions,
) -> Result<(f64, f64), MieError> {
    let (tr_lo, tr_hi) = mode.range_um();
    let r_lo = mode.area_quantile(0.5 * opts.tail_fraction).max(tr_lo);
    let r_hi = mode
        .area_quantile(1.0 - 0.5 * opts.tail_fraction)
        .min(tr_hi);
    if !(r_hi > r_lo) {
        return Err(param(
            "r_max_um",
            r_hi,
            "the truncation range holds none of the distribution",
        ));
    }
    if k * r_hi > crate::particles::mie::MAX_SIZE_PARAMETER {
        return Err(MieError::SizeParameter(k * r_hi));
    }
    Ok((r_lo, r_hi))
}

/// Intervals of the finest grid the step halving of [`integrate_mode`] can reach over
/// `[x_lo, x_hi]` (it stops there if it has not converged before): 128 · 2^j, the same
/// arithmetic as the halving itself.
pub(super) fn max_intervals(x_lo: f64, x_hi: f64, opts: &BulkOptions) -> usize {
    let mut intervals = 128usize;
    let mut dx = (x_hi - x_lo) / intervals as f64;
    while !(dx * 0.5 < opts.min_step_x || 2 * intervals + 1 > opts.max_points) {
        dx *= 0.5;
        intervals *= 2;
    }
    intervals
}

/// Efficiency below which the size integration's convergence is absolute (see
/// [`integrate_mode`]): 10⁻¹² is far below any efficiency that matters next to the geometric
/// cross-section, and far above the rounding noise of the Mie sums (~10⁻¹⁶).
const CONVERGENCE_FLOOR: f64 = 1e-12;

pub(super) fn integrate_mode(
    name: &str,
    mode: &SizeDistribution,
    m: Complex64,
    wavelength_um: f64,
    opts: &BulkOptions,
) -> Result<(ModeGrid, ModeConvergence), MieError> {
    let k = 2.0 * PI / wavelength_um;
    let (r_lo, r_hi) = mode_range_um(mode, k, opts)?;
    let (x_lo, x_hi) = (k * r_lo, k * r_hi);
    // Level 0: 128 intervals.
    let mut intervals = 128usize;
    let mut dx = (x_hi - x_lo) / intervals as f64;
    let ends = {
        let mut e = integrand(mode, m, k, x_lo)?;
        e.add(&integrand(mode, m, k, x_hi)?, 1.0);
        e
    };
    // Sum over all points, ends with weight 1/2.
    let mut total = ends;
    for v in total.0.iter_mut() {
        *v *= 0.5;
    }
    total.add(&sum_points(mode, m, k, x_lo + dx, dx, intervals - 1)?, 1.0);
    let integral = |t: &Sums, dx: f64| -> [f64; 6] {
        let mut o = t.0;
        o.iter_mut().for_each(|v| *v *= dx / k);
        o
    };
    let mut prev = integral(&total, dx);
    let mut passes = 0;
    let mut last_change = f64::INFINITY;
    let mut converged = false;
    loop {
        if dx * 0.5 < opts.min_step_x || 2 * intervals + 1 > opts.max_points {
            break;
        }
        let h = dx * 0.5;
        total.add(&sum_points(mode, m, k, x_lo + h, dx, intervals)?, 1.0);
        intervals *= 2;
        dx = h;
        let cur = integral(&total, dx);
        // Each change relative to the integral, or to CONVERGENCE_FLOOR × the geometric
        // cross-section (cur[4] > 0) where the integral is smaller: an integral that is
        // rounding noise (no index contrast, m ≈ 1) has no relative convergence and would
        // refine to the finest grid.
        let floor = CONVERGENCE_FLOOR * cur[4];
        last_change = (0..4)
            .map(|i| {
                let scale = cur[i].abs().max(floor);
                if scale == 0.0 {
                    0.0
                } else {
                    ((cur[i] - prev[i]) / scale).abs()
                }
            })
            .fold(0.0, f64::max);
        prev = cur;
        if last_change <= opts.rel_tol {
            passes += 1;
            if passes >= 2 {
                converged = true;
                break;
            }
        } else {
            passes = 0;
        }
    }
    let sums = Sums(prev);
    Ok((
        ModeGrid {
            m,
            mode: mode.clone(),
            k_per_um: k,
            x_lo,
            dx,
            points: intervals,
            sums,
        },
        ModeConvergence {
            component: name.to_string(),
            r_range_um: (r_lo, r_hi),
            step_x: dx,
            points: intervals + 1,
            last_rel_change: last_change,
            converged,
        },
    ))
}

/// Angle tables for the phase function: c_n (π_n ± τ_n)(cos θ_k), K × N_max, column-major.
pub(super) struct AngleTables {
    plus: DMatrix<f64>,
    minus: DMatrix<f64>,
}

pub(super) fn angle_tables(theta_deg: &[f64], n_max: usize) -> AngleTables {
    let kk = theta_deg.len();
    let mut plus = DMatrix::<f64>::zeros(kk, n_max);
    let mut minus = DMatrix::<f64>::zeros(kk, n_max);
    for (row, t) in theta_deg.iter().enumerate() {
        let mu = t.to_radians().cos();
        let mut pi_prev = 0.0;
        let mut pi = 1.0;
        for col in 0..n_max {
            let n = (col + 1) as f64;
            let tau = n * mu * pi - (n + 1.0) * pi_prev;
            let c = (2.0 * n + 1.0) / (n * (n + 1.0));
            plus[(row, col)] = c * (pi + tau);
            minus[(row, col)] = c * (pi - tau);
            let pi_next = ((2.0 * n + 1.0) * mu * pi - (n + 1.0) * pi_prev) / n;
            pi_prev = pi;
            pi = pi_next;
        }
    }
    AngleTables { plus, minus }
}

/// Per angle, ∫ n(r) S_ij/k² dr over a mode's final grid for S11, S12, S33, S34 [cm⁻³ µm² sr⁻¹]
/// (Bohren & Huffman 1983, eq. 4.77; S11/k² = (|S1|²+|S2|²)/(2k²) = dCsca/dΩ).
#[derive(Debug, Clone, Default)]
pub(super) struct MatrixSums {
    pub(super) s11: Vec<f64>,
    pub(super) s12: Vec<f64>,
    pub(super) s33: Vec<f64>,
    pub(super) s34: Vec<f64>,
}

impl MatrixSums {
    pub(super) fn zeros(n: usize) -> Self {
        MatrixSums {
            s11: vec![0.0; n],
            s12: vec![0.0; n],
            s33: vec![0.0; n],
            s34: vec![0.0; n],
        }
    }

    pub(super) fn add(&mut self, o: &MatrixSums) {
        for (a, b) in [
            (&mut self.s11, &o.s11),
            (&mut self.s12, &o.s12),
            (&mut self.s33, &o.s33),
            (&mut self.s34, &o.s34),
        ] {
            for (t, v) in a.iter_mut().zip(b) {
                *t += v;
            }
        }
    }
}

/// The matrix products give S± = S1 ± S2 (the angle tables hold c_n(π_n ± τ_n), the
/// coefficients a_n ± b_n); the elements are products of S+ and S−
/// ([`crate::particles::mie::four_s_from_s_pm`]). The coefficients are stored in Bohren & Huffman's
/// convention, so these S± are BH's amplitudes — not the conjugates that
/// [`MieCoefficients::amplitudes`] returns — and S34 = ½ Im(S+ S−*) has BH's sign.
pub(super) fn matrix_integral(g: &ModeGrid, tables: &AngleTables) -> Result<MatrixSums, MieError> {
    const R: usize = 32;
    let kk = tables.plus.nrows();
    let npts = g.points + 1;
    let k = g.k_per_um;
    let n_max = tables.plus.ncols();
    // Per-thread scratch matrices (reused: large fresh allocations cost page faults); they hold
    // no state between blocks, so results do not depend on the thread count.
    let scratch = || {
        (
            DMatrix::<f64>::zeros(n_max, 2 * R),
            DMatrix::<f64>::zeros(n_max, 2 * R),
            DMatrix::<f64>::zeros(kk, 2 * R),
            DMatrix::<f64>::zeros(kk, 2 * R),
        )
    };
    let blocks: Vec<Result<MatrixSums, MieError>> = (0..npts.div_ceil(R))
        .into_par_iter()
        .map_init(scratch, |(bp, bm, cp, cm), b| {
            let idx: Vec<usize> = (b * R..((b + 1) * R).min(npts)).collect();
            let mut coeffs = Vec::with_capacity(idx.len());
            let mut weights = Vec::with_capacity(idx.len());
            for &i in &idx {
                let x = g.x_lo + i as f64 * g.dx;
                let r = x / k;
                let mut w = g.mode.density(r) * g.dx / k;
                if i == 0 || i == npts - 1 {
                    w *= 0.5;
                }
                weights.push(w);
                coeffs.push(if w > 0.0 {
                    Some(MieCoefficients::compute(g.m, x)?)
                } else {
                    None
                });
            }
            let nb = coeffs
                .iter()
                .map(|c| c.as_ref().map_or(0, |c| c.len()))
                .max()
                .unwrap_or(0)
                .min(n_max);
            let mut acc = MatrixSums::zeros(kk);
            if nb == 0 {
                return Ok(acc);
            }
            bp.fill(0.0);
            bm.fill(0.0);
            for (j, c) in coeffs.iter().enumerate() {
                if let Some(c) = c {
                    for n in 0..c.len().min(nb) {
                        let p = c.a[n] + c.b[n];
                        let q = c.a[n] - c.b[n];
                        bp[(n, j)] = p.re;
                        bp[(n, R + j)] = p.im;
                        bm[(n, j)] = q.re;
                        bm[(n, R + j)] = q.im;
                    }
                }
            }
            cp.gemm(1.0, &tables.plus.columns(0, nb), &bp.rows(0, nb), 0.0);
            cm.gemm(1.0, &tables.minus.columns(0, nb), &bm.rows(0, nb), 0.0);
            for (j, w) in weights.iter().enumerate() {
                if *w == 0.0 {
                    continue;
                }
                // 4 S_ij from S± (four_s_from_s_pm); S_ij/k² = f · 4 S_ij with f = w/(4k²).
                let f = w / (4.0 * k * k);
                let (p_re, p_im) = (cp.column(j), cp.column(R + j));
                let (m_re, m_im) = (cm.column(j), cm.column(R + j));
                for a in 0..kk {
                    let [s11, s12, s33, s34] = four_s_from_s_pm(
                        Complex64::new(p_re[a], p_im[a]),
                        Complex64::new(m_re[a], m_im[a]),
                    );
                    acc.s11[a] += f * s11;
                    acc.s12[a] += f * s12;
                    acc.s33[a] += f * s33;
                    acc.s34[a] += f * s34;
                }
            }
            Ok(acc)
        })
        .collect();
    let mut total = MatrixSums::zeros(kk);
    for b in blocks {
        total.add(&b?);
    }
    Ok(total)
}
