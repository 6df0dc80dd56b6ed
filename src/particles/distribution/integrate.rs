//! Integration of one mode over size parameter: composite trapezoid sums on panels refined
//! where the integrals still change, with the angular (matrix) integrals accumulated on the fly
//! from the same Mie coefficients ([`super`] module docs).

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

/// The result of one mode's integration.
pub(super) struct ModeGrid {
    /// The integrals (see [`Sums`]).
    pub(super) sums: Sums,
    /// Per angle of the tables, ∫ n(r) S_ij/k² dr (None without angle tables).
    pub(super) matrix: Option<MatrixSums>,
}

/// Panels of a mode's size-parameter range, equal in ln x: the log-normal and gamma modes are
/// smooth in ln r, so equal panels in ln x hold comparable shares of the integrals near the
/// mode and small ones in the tails, where a coarse step then suffices.
pub(super) const PANELS: usize = 16;

/// Intervals of a panel before any halving (16 × 8 = 128, the old uniform grid's start).
const PANEL_START_INTERVALS: usize = 8;

/// Most radii per Mie block: the block's amplitudes come from two matrix products over its
/// radii. 128 (not 32): the products repack the angle tables on every call, which then costs a
/// fraction of the arithmetic (9 % of the OPAC maritime-clean run at 532 nm, from 22 %).
const R: usize = 128;

/// Bytes of one thread's product matrices (coefficients and amplitudes, 32 × radii ×
/// (terms + angles)) above which a block takes fewer radii ([`block_radii`]).
const SCRATCH_BYTES: usize = 32 << 20;

/// Radii per block for `n_max` terms and `angles` angles: [`R`], or fewer (at least 4) where
/// the product matrices would exceed [`SCRATCH_BYTES`] (size parameters of several 10⁴), so
/// memory stays bounded. It depends on the inputs only: the blocks, and so the order of the
/// sums, are the same at any thread count.
fn block_radii(n_max: usize, angles: usize) -> usize {
    (SCRATCH_BYTES / (32 * (n_max + angles).max(1))).clamp(4, R)
}

/// Blocks evaluated between two reductions: the blocks' partial sums are held this many at a
/// time (16 × 4 × angles × 8 bytes: 0.7 MB with the default 1391 angles), so memory does not
/// grow with the number of radii.
const BLOCKS_PER_BATCH: usize = 16;

/// The panels of `[x_lo, x_hi]` (see [`PANELS`]); the last ends exactly at `x_hi`.
pub(super) fn panels(x_lo: f64, x_hi: f64) -> Vec<(f64, f64)> {
    let (l0, l1) = (x_lo.ln(), x_hi.ln());
    let edge = |i: usize| match i {
        0 => x_lo,
        i if i == PANELS => x_hi,
        i => (l0 + (l1 - l0) * i as f64 / PANELS as f64).exp(),
    };
    (0..PANELS).map(|i| (edge(i), edge(i + 1))).collect()
}

/// Whether a panel of `intervals` intervals of width `dx` may be halved: not below
/// `min_step_x`, and not beyond its share (1/[`PANELS`]) of `max_points`.
fn may_halve(dx: f64, intervals: usize, opts: &BulkOptions) -> bool {
    !(dx * 0.5 < opts.min_step_x || 2 * intervals > (opts.max_points - 1) / PANELS)
}

/// Intervals of the finest grid the refinement of [`integrate_mode`] can reach over
/// `[x_lo, x_hi]` (every panel halved until [`may_halve`] refuses: the grid when it never
/// converges), per panel.
pub(super) fn max_intervals(x_lo: f64, x_hi: f64, opts: &BulkOptions) -> Vec<(f64, f64, usize)> {
    panels(x_lo, x_hi)
        .into_iter()
        .map(|(a, b)| {
            let mut intervals = PANEL_START_INTERVALS;
            let mut dx = (b - a) / intervals as f64;
            while may_halve(dx, intervals, opts) {
                dx *= 0.5;
                intervals *= 2;
            }
            (a, b, intervals)
        })
        .collect()
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

/// Efficiency below which the size integration's convergence is absolute (see
/// [`integrate_mode`]): 10⁻¹² is far below any efficiency that matters next to the geometric
/// cross-section, and far above the rounding noise of the Mie sums (~10⁻¹⁶).
const CONVERGENCE_FLOOR: f64 = 1e-12;

/// Share of `rel_tol` that the panels stopped early (in the tails) may take: the sum of their
/// last changes stays below it.
const FROZEN_SHARE: f64 = 0.1;

/// The sum of the panels' latest integrals.
fn sum_last(panels: &[Panel]) -> [f64; 6] {
    let all: Vec<usize> = (0..panels.len()).collect();
    sum_of(panels, &all)
}

/// The sum of the latest integrals of the panels `which`.
fn sum_of(panels: &[Panel], which: &[usize]) -> [f64; 6] {
    let mut t = [0.0; 6];
    for &i in which {
        for (t, v) in t.iter_mut().zip(panels[i].history.last().unwrap()) {
            *t += v;
        }
    }
    t
}

/// One panel's state: its grid, the raw sums over its points (ends weighted ½) and its
/// integrals at the last three levels.
struct Panel {
    a: f64,
    intervals: usize,
    dx: f64,
    raw: Sums,
    raw_matrix: Option<MatrixSums>,
    /// Integrals at the levels reached, newest last (at most three kept).
    history: Vec<[f64; 6]>,
    frozen: bool,
}

impl Panel {
    fn integral(&self, k: f64) -> [f64; 6] {
        let mut o = self.raw.0;
        o.iter_mut().for_each(|v| *v *= self.dx / k);
        o
    }

    /// The largest change of quantity `q` over the last two halvings (0 with none).
    fn change(&self, q: usize) -> f64 {
        self.history
            .windows(2)
            .map(|w| (w[1][q] - w[0][q]).abs())
            .fold(0.0, f64::max)
    }
}

/// A run of equally spaced points of one panel: `x0 + i h`, i in 0..count, the first and the
/// last weighted ½ when `ends` (a panel's first level).
#[derive(Clone, Copy)]
struct Run {
    panel: usize,
    x0: f64,
    h: f64,
    count: usize,
    ends: bool,
}

/// What the evaluation of a mode needs besides its points.
struct Integrand<'a> {
    mode: &'a SizeDistribution,
    m: Complex64,
    k: f64,
    tables: Option<&'a AngleTables>,
    /// Radii per block ([`block_radii`]).
    radii: usize,
}

/// Per-thread scratch matrices of the block products (reused: large fresh allocations cost
/// page faults); they hold no state between blocks, so results do not depend on the thread
/// count.
type Scratch = Option<(DMatrix<f64>, DMatrix<f64>, DMatrix<f64>, DMatrix<f64>)>;

impl Integrand<'_> {
    /// The raw sums over points `idx` of `run` (at most [`block_radii`]): Σ w n(r) {Q π r², …} and, with
    /// angle tables, Σ w n(r) S_ij/k², w = ½ at a first level's ends and 1 elsewhere.
    fn block(
        &self,
        run: &Run,
        idx: std::ops::Range<usize>,
        scratch: &mut Scratch,
    ) -> Result<(Sums, Option<MatrixSums>), MieError> {
        let k = self.k;
        let mut sums = Sums::default();
        let mut coeffs = Vec::with_capacity(idx.len());
        let mut weights = Vec::with_capacity(idx.len());
        for i in idx {
            let x = run.x0 + i as f64 * run.h;
            let r = x / k;
            let mut w = self.mode.density(r);
            if run.ends && (i == 0 || i == run.count - 1) {
                w *= 0.5;
            }
            if w == 0.0 {
                continue;
            }
            let c = MieCoefficients::compute(self.m, x)?;
            let e = c.efficiencies();
            let area = PI * r * r;
            sums.add(
                &Sums([
                    e.qext * area,
                    e.qsca * area,
                    e.qback * area,
                    e.g * e.qsca * area,
                    area,
                    area * r,
                ]),
                w,
            );
            if self.tables.is_some() {
                weights.push(w);
                coeffs.push(c);
            }
        }
        let Some(tables) = self.tables else {
            return Ok((sums, None));
        };
        let kk = tables.plus.nrows();
        let n_max = tables.plus.ncols();
        let mut acc = MatrixSums::zeros(kk);
        let nb = coeffs.iter().map(|c| c.len()).max().unwrap_or(0).min(n_max);
        if nb == 0 {
            return Ok((sums, Some(acc)));
        }
        // Only the columns of the radii evaluated take part in the products: the real parts
        // of the coefficients in columns 0..len, the imaginary parts in len..2 len.
        let len = coeffs.len();
        let (bp, bm, cp, cm) = scratch.get_or_insert_with(|| {
            (
                DMatrix::<f64>::zeros(n_max, 2 * self.radii),
                DMatrix::<f64>::zeros(n_max, 2 * self.radii),
                DMatrix::<f64>::zeros(kk, 2 * self.radii),
                DMatrix::<f64>::zeros(kk, 2 * self.radii),
            )
        });
        // Zero only what the products read (shorter series of the block leave zeros).
        bp.view_mut((0, 0), (nb, 2 * len)).fill(0.0);
        bm.view_mut((0, 0), (nb, 2 * len)).fill(0.0);
        for (j, c) in coeffs.iter().enumerate() {
            for n in 0..c.len().min(nb) {
                let p = c.a[n] + c.b[n];
                let q = c.a[n] - c.b[n];
                bp[(n, j)] = p.re;
                bp[(n, len + j)] = p.im;
                bm[(n, j)] = q.re;
                bm[(n, len + j)] = q.im;
            }
        }
        let mut cp = cp.columns_mut(0, 2 * len);
        let mut cm = cm.columns_mut(0, 2 * len);
        cp.gemm(
            1.0,
            &tables.plus.columns(0, nb),
            &bp.view((0, 0), (nb, 2 * len)),
            0.0,
        );
        cm.gemm(
            1.0,
            &tables.minus.columns(0, nb),
            &bm.view((0, 0), (nb, 2 * len)),
            0.0,
        );
        for (j, w) in weights.iter().enumerate() {
            // 4 S_ij from S± (four_s_from_s_pm); S_ij/k² = f · 4 S_ij with f = w/(4k²).
            let f = w / (4.0 * k * k);
            let (p_re, p_im) = (cp.column(j), cp.column(len + j));
            let (m_re, m_im) = (cm.column(j), cm.column(len + j));
            let (p_re, p_im) = (p_re.as_slice(), p_im.as_slice());
            let (m_re, m_im) = (m_re.as_slice(), m_im.as_slice());
            let (s11, s12) = (&mut acc.s11[..kk], &mut acc.s12[..kk]);
            let (s33, s34) = (&mut acc.s33[..kk], &mut acc.s34[..kk]);
            for a in 0..kk {
                let [v11, v12, v33, v34] = four_s_from_s_pm(
                    Complex64::new(p_re[a], p_im[a]),
                    Complex64::new(m_re[a], m_im[a]),
                );
                s11[a] += f * v11;
                s12[a] += f * v12;
                s33[a] += f * v33;
                s34[a] += f * v34;
            }
        }
        Ok((sums, Some(acc)))
    }

    /// Evaluate `runs` and add each run's raw sums to its panel. Blocks of [`block_radii`] radii run in
    /// parallel, [`BLOCKS_PER_BATCH`] at a time; their sums are added in block order, so the
    /// numbers do not depend on the thread count. `progress` hears the radii of each batch.
    fn evaluate(
        &self,
        runs: &[Run],
        panels: &mut [Panel],
        progress: &dyn Fn(u64),
    ) -> Result<(), MieError> {
        let r = self.radii;
        let blocks: Vec<(usize, std::ops::Range<usize>)> = runs
            .iter()
            .enumerate()
            .flat_map(|(j, run)| {
                (0..run.count.div_ceil(r)).map(move |b| (j, b * r..((b + 1) * r).min(run.count)))
            })
            .collect();
        for batch in blocks.chunks(BLOCKS_PER_BATCH) {
            let results: Vec<Result<(Sums, Option<MatrixSums>), MieError>> = batch
                .par_iter()
                .map_init(
                    || None,
                    |scratch, (j, idx)| self.block(&runs[*j], idx.clone(), scratch),
                )
                .collect();
            let mut radii = 0;
            for ((j, idx), r) in batch.iter().zip(results) {
                let (s, m) = r?;
                let p = &mut panels[runs[*j].panel];
                p.raw.add(&s, 1.0);
                if let (Some(acc), Some(m)) = (p.raw_matrix.as_mut(), m) {
                    acc.add(&m);
                }
                radii += idx.len() as u64;
            }
            progress(radii);
        }
        Ok(())
    }
}

/// Integrate one mode over `[x_lo, x_hi]` (from [`mode_range_um`]).
///
/// The range is cut into [`PANELS`] panels equal in ln x, each a trapezoid rule that starts
/// with 8 intervals and is halved (reusing its points), all panels together, until two
/// successive halvings change the extinction, scattering, backscatter and g·Csca integrals of
/// the mode by less than `rel_tol` of themselves — the criterion of the uniform grid this
/// replaces. But a panel that has been halved twice may stop: the panels whose largest
/// relative change at their last two halvings is smallest per unit cost of their next halving
/// stop first, each as long as the changes of all stopped panels sum to at most
/// [`FROZEN_SHARE`] × `rel_tol`. These are the panels in
/// the mode's tails, which hold little of the integrals: they stay at a coarse step while the
/// panels near the mode are refined (the coarse sea-salt mode at 532 nm, x = 2.5…709: a fifth
/// of the radii of the uniform grid). A panel also stops at `min_step_x` or at its share of
/// `max_points` ([`may_halve`]); `converged` is false when such a panel last changed by more
/// than `rel_tol`, or when the tolerance was not met.
///
/// With `tables`, the angular integrals ∫ n S_ij/k² dr are summed from the same Mie
/// coefficients as the efficiencies, on the same points: on the final grid, so that P(180°) is
/// exactly the backscatter integral.
pub(super) fn integrate_mode(
    name: &str,
    mode: &SizeDistribution,
    m: Complex64,
    wavelength_um: f64,
    opts: &BulkOptions,
    tables: Option<&AngleTables>,
    progress: &dyn Fn(u64),
) -> Result<(ModeGrid, ModeConvergence), MieError> {
    let k = 2.0 * PI / wavelength_um;
    let (r_lo, r_hi) = mode_range_um(mode, k, opts)?;
    let (x_lo, x_hi) = (k * r_lo, k * r_hi);
    let radii = tables.map_or(R, |t| block_radii(t.plus.ncols(), t.plus.nrows()));
    let f = Integrand {
        mode,
        m,
        k,
        tables,
        radii,
    };
    let kk = tables.map_or(0, |t| t.plus.nrows());
    let mut panels: Vec<Panel> = panels(x_lo, x_hi)
        .into_iter()
        .map(|(a, b)| Panel {
            a,
            intervals: PANEL_START_INTERVALS,
            dx: (b - a) / PANEL_START_INTERVALS as f64,
            raw: Sums::default(),
            raw_matrix: tables.map(|_| MatrixSums::zeros(kk)),
            history: Vec::new(),
            frozen: false,
        })
        .collect();
    // Level 0 of every panel.
    let runs: Vec<Run> = panels
        .iter()
        .enumerate()
        .map(|(i, p)| Run {
            panel: i,
            x0: p.a,
            h: p.dx,
            count: p.intervals + 1,
            ends: true,
        })
        .collect();
    f.evaluate(&runs, &mut panels, progress)?;
    for p in panels.iter_mut() {
        let i = p.integral(k);
        p.history.push(i);
    }
    // Halve the panels in `which` (their new midpoints), then record the new integrals.
    let halve = |panels: &mut Vec<Panel>, which: &[usize]| -> Result<(), MieError> {
        let runs: Vec<Run> = which
            .iter()
            .map(|&i| {
                let p = &panels[i];
                Run {
                    panel: i,
                    x0: p.a + 0.5 * p.dx,
                    h: p.dx,
                    count: p.intervals,
                    ends: false,
                }
            })
            .collect();
        f.evaluate(&runs, panels, progress)?;
        for &i in which {
            let p = &mut panels[i];
            p.intervals *= 2;
            p.dx *= 0.5;
            let cur = p.integral(k);
            p.history.push(cur);
            if p.history.len() > 3 {
                p.history.remove(0);
            }
        }
        Ok(())
    };
    let mut passes = 0;
    let mut budget_used = 0.0;
    let (last_change, converged) = loop {
        let total = sum_last(&panels);
        // Each change relative to the integral, or to CONVERGENCE_FLOOR × the geometric
        // cross-section (total[4] > 0) where the integral is smaller: an integral that is
        // rounding noise (no index contrast, m ≈ 1) has no relative convergence and would
        // refine to the finest grid.
        let floor = CONVERGENCE_FLOOR * total[4];
        let relative = |q: usize, d: f64| {
            let scale = total[q].abs().max(floor);
            if scale == 0.0 { 0.0 } else { d / scale }
        };
        // A panel that has been halved twice may stop (the order below), while the changes of
        // the stopped panels sum to at most FROZEN_SHARE × rel_tol.
        // Each panel's largest relative change at its last (up to two) halvings: 0 for a
        // panel that could not be halved at all (its start is finer than min_step_x).
        let errors: Vec<f64> = panels
            .iter()
            .map(|p| (0..4).map(|q| relative(q, p.change(q))).fold(0.0, f64::max))
            .collect();
        // A panel that cannot be halved further and changed by more than rel_tol at its last
        // halvings has not converged, whatever the others do.
        let capped = (0..panels.len()).any(|i| {
            !panels[i].frozen
                && !may_halve(panels[i].dx, panels[i].intervals, opts)
                && errors[i] > opts.rel_tol
        });
        // The budget goes where it saves the most work: the panels are taken by their change
        // per unit cost of their next halving (its new radii times the Mie terms at the
        // panel's middle, which the series and the angular products both scale with), so an
        // expensive panel of large size parameters that has settled stops before cheap ones
        // (the coarse sea salt's last panel at 532 nm, x = 497…709, was a third of the work);
        // each that fits is stopped.
        let mut candidates: Vec<(f64, f64, usize)> = (0..panels.len())
            .filter(|&i| !panels[i].frozen && panels[i].history.len() >= 3)
            .map(|i| {
                let p = &panels[i];
                let mid = p.a + 0.5 * p.dx * p.intervals as f64;
                let cost = p.intervals as f64 * (mid + 4.05 * mid.cbrt() + 2.0);
                (errors[i] / cost, errors[i], i)
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
        for (_, e, i) in candidates {
            if budget_used + e <= FROZEN_SHARE * opts.rel_tol {
                budget_used += e;
                panels[i].frozen = true;
            }
        }
        let which: Vec<usize> = (0..panels.len())
            .filter(|&i| !panels[i].frozen && may_halve(panels[i].dx, panels[i].intervals, opts))
            .collect();
        if which.is_empty() {
            break (budget_used, !capped);
        }
        let before: [f64; 6] = sum_of(&panels, &which);
        halve(&mut panels, &which)?;
        let after: [f64; 6] = sum_of(&panels, &which);
        let change = (0..4)
            .map(|q| relative(q, (after[q] - before[q]).abs()))
            .fold(0.0, f64::max);
        if change <= opts.rel_tol {
            passes += 1;
            if passes >= 2 {
                break (change, !capped);
            }
        } else {
            passes = 0;
        }
    };
    let mut sums = Sums::default();
    for p in &panels {
        sums.add(&Sums(*p.history.last().unwrap()), 1.0);
    }
    let matrix = tables.map(|_| {
        let mut total = MatrixSums::zeros(kk);
        for p in &panels {
            if let Some(m) = &p.raw_matrix {
                total.add_scaled(m, p.dx / k);
            }
        }
        total
    });
    let step_x = panels.iter().map(|p| p.dx).fold(f64::INFINITY, f64::min);
    let intervals: usize = panels.iter().map(|p| p.intervals).sum();
    Ok((
        ModeGrid { sums, matrix },
        ModeConvergence {
            component: name.to_string(),
            r_range_um: (r_lo, r_hi),
            step_x,
            // Panels share their ends.
            points: intervals + 1,
            panels: panels.iter().map(|p| (p.a, p.dx, p.intervals)).collect(),
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

/// Per angle, ∫ n(r) S_ij/k² dr over a mode for S11, S12, S33, S34 [cm⁻³ µm² sr⁻¹]
/// (Bohren & Huffman 1983, eq. 4.77; S11/k² = (|S1|²+|S2|²)/(2k²) = dCsca/dΩ).
///
/// The matrix products give S± = S1 ± S2 (the angle tables hold c_n(π_n ± τ_n), the
/// coefficients a_n ± b_n); the elements are products of S+ and S−
/// ([`crate::particles::mie::four_s_from_s_pm`]). The coefficients are stored in Bohren &
/// Huffman's convention, so these S± are BH's amplitudes — not the conjugates that
/// [`MieCoefficients::amplitudes`] returns — and S34 = ½ Im(S+ S−*) has BH's sign.
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
        self.add_scaled(o, 1.0);
    }

    pub(super) fn add_scaled(&mut self, o: &MatrixSums, w: f64) {
        for (a, b) in [
            (&mut self.s11, &o.s11),
            (&mut self.s12, &o.s12),
            (&mut self.s33, &o.s33),
            (&mut self.s34, &o.s34),
        ] {
            for (t, v) in a.iter_mut().zip(b) {
                *t += w * v;
            }
        }
    }
}
