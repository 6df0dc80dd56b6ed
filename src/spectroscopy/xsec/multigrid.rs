//! The multigrid sum of a cross-section on a uniform grid (`docs/spectroscopy.md`
//! §"Multigrid"; module docs of [`super`]).

use rayon::prelude::*;

use super::line::Prepared;
use super::{LblOptions, VoigtMethod, WavenumberGrid};

/// Step ratio between levels (a power of two, so coarse nodes coincide with fine ones exactly).
const RATIO: i64 = 4;
/// Level-k interpolation is used only at distances ≥ D_k = max(MG_M h_k, MG_KAPPA γ_D) from
/// the centre: there the 6-point interpolation error of a Lorentzian wing is ≲ 25 (h/Δ)⁶ ≈ 1e-6
/// and the Gaussian core (∝ e^{−ln2 Δ²/γ_D²} < 1e-19) is gone.
const MG_M: f64 = 16.0;
const MG_KAPPA: f64 = 8.0;
/// Extra nodes kept on each side of every level (≥ what the 6-point stencils reach).
const MARGIN: i64 = 6;
/// The lines are split into at most MAX_CHUNKS chunks of at least MIN_CHUNK lines; the split
/// depends on the number of lines only, so the summation order does not depend on threads.
const MAX_CHUNKS: usize = 8;
const MIN_CHUNK: usize = 64;

/// Weights of 6-point Lagrange interpolation at t = p/RATIO between nodes −2..3.
fn lagrange6_weights() -> [[f64; 6]; RATIO as usize] {
    let mut w = [[0.0; 6]; RATIO as usize];
    for (p, wp) in w.iter_mut().enumerate() {
        let t = p as f64 / RATIO as f64;
        for (s, ws) in wp.iter_mut().enumerate() {
            let xs = s as f64 - 2.0;
            let mut v = 1.0;
            for o in 0..6 {
                if o != s {
                    let xo = o as f64 - 2.0;
                    v *= (t - xo) / (xs - xo);
                }
            }
            *ws = v;
        }
    }
    w
}

struct Levels {
    start: f64,
    h0: f64,
    /// stride[k] = RATIO^k (fine points per level-k step).
    stride: Vec<i64>,
    /// Highest regular node index of each level (nodes run from −MARGIN to top + MARGIN).
    top: Vec<i64>,
    weights: [[f64; 6]; RATIO as usize],
}

impl Levels {
    fn new(grid: &WavenumberGrid, wing: f64) -> Self {
        let h0 = grid.step_cm1;
        let n1 = (grid.len - 1) as i64;
        let mut stride = vec![1i64];
        // Add levels while a coarser level can still hold a line's wing.
        while stride.len() < 14 {
            let s = *stride.last().unwrap_or(&1) * RATIO;
            if (MG_M + 8.0) * h0 * s as f64 >= wing {
                break;
            }
            stride.push(s);
        }
        let top = stride.iter().map(|&s| (n1 + s - 1) / s).collect();
        Levels {
            start: grid.start_cm1,
            h0,
            stride,
            top,
            weights: lagrange6_weights(),
        }
    }
    fn n(&self) -> usize {
        self.stride.len()
    }
    #[inline]
    fn nu(&self, k: usize, j: i64) -> f64 {
        self.start + (j * self.stride[k]) as f64 * self.h0
    }
    fn h(&self, k: usize) -> f64 {
        self.h0 * self.stride[k] as f64
    }
    fn len(&self, k: usize) -> usize {
        (self.top[k] + 2 * MARGIN + 1) as usize
    }
    /// Node range [a, b] of level k covering the wavenumber interval [lo, hi], clipped.
    fn range(&self, k: usize, lo: f64, hi: f64) -> Option<(i64, i64)> {
        let h = self.h(k);
        let a = (((lo - self.start) / h).floor() as i64).max(-MARGIN);
        let b = (((hi - self.start) / h).ceil() as i64).min(self.top[k] + MARGIN);
        (a <= b).then_some((a, b))
    }
}

pub(super) fn multigrid_sum(
    prepared: &[Prepared],
    grid: &WavenumberGrid,
    opts: &LblOptions,
) -> Vec<f64> {
    let w = opts.wing_cm1;
    let lv = Levels::new(grid, w);
    let reach = 8.0 * lv.h(lv.n() - 1);
    let (lo, hi) = (grid.start_cm1 - w - reach, grid.end_cm1() + w + reach);
    let active: Vec<&Prepared> = prepared
        .iter()
        .filter(|p| p.nu_w >= lo && p.nu_w <= hi)
        .collect();
    let zero = || {
        (0..lv.n())
            .map(|k| vec![0.0; lv.len(k)])
            .collect::<Vec<_>>()
    };
    // Chunks in parallel, each chunk sequential; the parts are added in chunk order.
    let chunk = active.len().div_ceil(MAX_CHUNKS).max(MIN_CHUNK);
    let chunks: Vec<&[&Prepared]> = active.chunks(chunk).collect();
    let parts: Vec<Vec<Vec<f64>>> = chunks
        .par_iter()
        .map(|chunk| {
            let mut a = zero();
            let mut buf = Vec::new();
            for p in chunk.iter() {
                add_line(&lv, &mut a, &mut buf, p, opts);
            }
            a
        })
        .collect();
    const BLOCK: usize = 8192;
    let mut acc: Vec<Vec<f64>> = (0..lv.n())
        .map(|k| {
            let mut v = vec![0.0; lv.len(k)];
            v.par_chunks_mut(BLOCK).enumerate().for_each(|(b, out)| {
                let (off, len) = (b * BLOCK, out.len());
                for part in &parts {
                    for (o, x) in out.iter_mut().zip(&part[k][off..off + len]) {
                        *o += x;
                    }
                }
            });
            v
        })
        .collect();
    // Interpolate coarse to fine: R_k = A_k + I(R_{k+1}) (each fine node independent).
    for k in (0..lv.n() - 1).rev() {
        let (fine, coarse) = acc.split_at_mut(k + 1);
        let (fine, coarse) = (&mut fine[k], &coarse[0]);
        fine.par_chunks_mut(BLOCK).enumerate().for_each(|(b, out)| {
            for (idx, o) in out.iter_mut().enumerate() {
                let j = (b * BLOCK + idx) as i64 - MARGIN;
                let q = j.div_euclid(RATIO);
                let p = j.rem_euclid(RATIO) as usize;
                *o += if p == 0 {
                    coarse[(q + MARGIN) as usize]
                } else {
                    let base = (q - 2 + MARGIN) as usize;
                    dot6(&lv.weights[p], &coarse[base..base + 6])
                };
            }
        });
    }
    acc.swap_remove(0)[MARGIN as usize..MARGIN as usize + grid.len].to_vec()
}

/// Σ w_s v_s over the 6-point stencil (written out: this is the inner loop).
#[inline]
fn dot6(w: &[f64; 6], v: &[f64]) -> f64 {
    let v: &[f64; 6] = v.try_into().unwrap_or(&[0.0; 6]);
    (w[0] * v[0] + w[1] * v[1]) + (w[2] * v[2] + w[3] * v[3]) + (w[4] * v[4] + w[5] * v[5])
}

/// Add one line's contributions A_k to every level (module docs; `docs/spectroscopy.md`).
fn add_line(lv: &Levels, a: &mut [Vec<f64>], buf: &mut Vec<f64>, p: &Prepared, opts: &LblOptions) {
    let w = opts.wing_cm1;
    let exact = opts.voigt == VoigtMethod::Exact;
    // Inner boundaries D_k (D_0 = 0) and the top level K of this line.
    let d = |k: usize| -> f64 {
        if k == 0 {
            0.0
        } else {
            (MG_M * lv.h(k)).max(MG_KAPPA * p.gamma_d) + p.spread
        }
    };
    let mut top = 0;
    while top + 1 < lv.n() && d(top + 1) + 8.0 * lv.h(top + 1) < w {
        top += 1;
    }
    // Targets of level k at nodes lo..=hi into `out`: the line where |Δ| ≥ D_k inside the
    // window, 0 elsewhere and at nodes beyond the level's ends. Nodes are evaluated in pairs
    // (the same numbers as one by one; faster for beyond-Voigt lines).
    let targets = |k: usize, lo: i64, hi: i64, out: &mut Vec<f64>| {
        out.clear();
        out.resize((hi - lo + 1) as usize, 0.0);
        let dk = d(k);
        let mut pending: Option<(usize, f64)> = None;
        for j in lo.max(-MARGIN)..=hi.min(lv.top[k] + MARGIN) {
            let nu = lv.nu(k, j);
            if (nu - p.nu_c).abs() >= dk && p.in_window(nu, w) {
                let idx = (j - lo) as usize;
                match pending.take() {
                    Some((i0, nu0)) => {
                        let (x, y) = p.eval_pair(nu0, nu, exact);
                        out[i0] = x;
                        out[idx] = y;
                    }
                    None => pending = Some((idx, nu)),
                }
            }
        }
        if let Some((i0, nu0)) = pending {
            out[i0] = p.eval(nu0, exact);
        }
    };
    let mut fine = Vec::new();
    // Top level: everything in the window beyond D_top.
    if let Some((ja, jb)) = lv.range(top, p.nu_w - w, p.nu_w + w) {
        let dk = d(top);
        let ak = &mut a[top];
        for j in ja..=jb {
            let nu = lv.nu(top, j);
            if (nu - p.nu_c).abs() >= dk && p.in_window(nu, w) {
                ak[(j + MARGIN) as usize] += p.eval(nu, exact);
            }
        }
    }
    // Lower levels: exact T_k − I[T_{k+1}] in the zones where interpolation of T_{k+1} is not
    // accurate (around the joint at D_{k+1} and around both window edges); zero elsewhere.
    for k in (0..top).rev() {
        let hc = lv.h(k + 1);
        let reach = 3.0 * hc + lv.h(k);
        let dn = d(k + 1);
        let mut zones: Vec<(i64, i64)> = [
            (p.nu_c - dn - reach, p.nu_c + dn + reach),
            (p.nu_w - w - reach, p.nu_w - w + reach),
            (p.nu_w + w - reach, p.nu_w + w + reach),
        ]
        .iter()
        .filter_map(|&(lo, hi)| lv.range(k, lo, hi))
        .collect();
        zones.sort_unstable();
        let mut merged: Vec<(i64, i64)> = Vec::with_capacity(3);
        for z in zones {
            match merged.last_mut() {
                Some(m) if z.0 <= m.1 + 1 => m.1 = m.1.max(z.1),
                _ => merged.push(z),
            }
        }
        for (ja, jb) in merged {
            // Level k+1 nodes the stencils of ja..=jb use.
            let qa = ja.div_euclid(RATIO) - 2;
            let qb = jb.div_euclid(RATIO) + 3;
            targets(k + 1, qa, qb, buf);
            targets(k, ja, jb, &mut fine);
            let ak = &mut a[k];
            for j in ja..=jb {
                let q = j.div_euclid(RATIO);
                let ph = j.rem_euclid(RATIO) as usize;
                let interp = if ph == 0 {
                    buf[(q - qa) as usize]
                } else {
                    let base = (q - 2 - qa) as usize;
                    dot6(&lv.weights[ph], &buf[base..base + 6])
                };
                ak[(j + MARGIN) as usize] += fine[(j - ja) as usize] - interp;
            }
        }
    }
}
