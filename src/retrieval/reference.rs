//! The state a retrieval assumes, and the truth it is compared with.
//!
//! Both live on the scene's molecular grid (Curtis-Godson layers, [`crate::spectroscopy::layers`]),
//! the grid on which the truth's gas optical depths were computed: a path that ends inside a
//! layer takes the share of that layer's column or optical depth proportional to the share of
//! its thickness, as the optical atmosphere does.
//!
//! The forward model of the retrieval (Ehret et al. 2008, Appl. Phys. B 90, 593, Eqs. 1–4, in
//! the form of docs/design.md §3) is the one-way differential absorption optical depth from the lidar to
//! altitude z for a reference profile whose target gas is scaled by s,
//!
//! ```text
//! D(z; s) = ½ ln( T̄²_off(z; s) / T̄²_on(z; s) ),   T̄²_ℓ = Σᵢ wᵢ exp(−2 (s τ_t,ℓ,i + τ_o,ℓ,i)/|μ|)
//! ```
//!
//! with τ_t and τ_o the vertical optical depths of the target gas and of the other gases between
//! the lidar and z, at the nominal quadrature nodes νᵢ of each line (the retrieval assumes the
//! nominal laser: no frequency offset, no jitter, full spectral purity). For a monochromatic
//! laser D is linear in s and the IPDA retrieval below is the weighting-function form
//! X = DAOD/IWF; for a finite line width it is solved for s exactly.

use super::RetrievalError;
use crate::atmosphere::Profile;
use crate::instrument::laser::{Filter, Laser, Line};
use crate::instrument::line_shape::MHZ_PER_CM1;
use crate::spectroscopy::{
    CgLayer, LayerDepthMemo, LblOptions, LineFilter, LineList, isotopologues, layers,
};

/// Dry-air and gas columns of a profile on a layer grid.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerColumns {
    /// Layer edges \[m\], strictly increasing.
    pub edges_m: Vec<f64>,
    /// Dry-air column of each layer [molecules/m²].
    pub dry_air_per_m2: Vec<f64>,
    /// Target-gas column of each layer [molecules/m²].
    pub gas_per_m2: Vec<f64>,
}

impl LayerColumns {
    /// Columns of `gas` in `profile` on `edges_m` (Curtis-Godson integration).
    pub fn new(profile: &Profile, edges_m: &[f64], gas: &str) -> Result<Self, RetrievalError> {
        Self::of_layers(
            profile,
            edges_m,
            &layers::curtis_godson_layers(profile, edges_m)?,
            gas,
        )
    }

    /// [`Self::new`] from the Curtis-Godson layers `cg` of `profile` on `edges_m`, computed
    /// before (with `gas` and water vapour at least, [`LayerDepthMemo::layers`]).
    pub fn of_layers(
        profile: &Profile,
        edges_m: &[f64],
        cg: &[CgLayer],
        gas: &str,
    ) -> Result<Self, RetrievalError> {
        let names = cg.first().map_or(&[][..], |l| &l.gas_names[..]);
        let index = |name: &str| names.iter().position(|g| g == name);
        let gi = index(gas).ok_or_else(|| {
            RetrievalError::Gas(format!("the profile `{}` has no {gas}", profile.name))
        })?;
        let h2o = index("H2O");
        let mut dry = Vec::with_capacity(cg.len());
        let mut g = Vec::with_capacity(cg.len());
        for l in cg {
            let w = h2o.map(|i| l.gas_columns_per_cm2[i]).unwrap_or(0.0);
            dry.push((l.air_column_per_cm2 - w) * 1e4);
            g.push(l.gas_columns_per_cm2[gi] * 1e4);
        }
        Ok(LayerColumns {
            edges_m: edges_m.to_vec(),
            dry_air_per_m2: dry,
            gas_per_m2: g,
        })
    }

    /// Vertical gas and dry-air columns between two altitudes (either order) [molecules/m²].
    pub fn between(&self, z_a: f64, z_b: f64) -> (f64, f64) {
        let mut gas = 0.0;
        let mut dry = 0.0;
        for (l, f) in layer_fractions(&self.edges_m, z_a, z_b) {
            gas += f * self.gas_per_m2[l];
            dry += f * self.dry_air_per_m2[l];
        }
        (gas, dry)
    }
}

/// (layer, fraction of its thickness) for every layer overlapping [min(z_a, z_b), max(z_a, z_b)].
pub fn layer_fractions(edges_m: &[f64], z_a: f64, z_b: f64) -> Vec<(usize, f64)> {
    let (lo, hi) = (z_a.min(z_b), z_a.max(z_b));
    let mut out = Vec::new();
    for l in 0..edges_m.len().saturating_sub(1) {
        let (a, b) = (edges_m[l], edges_m[l + 1]);
        let overlap = hi.min(b) - lo.max(a);
        if overlap > 0.0 {
            out.push((l, overlap / (b - a)));
        }
    }
    out
}

/// The reference state: columns and layer optical depths at the nominal quadrature nodes of
/// each line, split into the target gas and the others.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceState {
    /// Columns of the reference profile.
    pub columns: LayerColumns,
    /// Quadrature weights of each line's nominal line shape (sum 1).
    pub weights: Vec<Vec<f64>>,
    /// Vertical optical depth of the target gas, layer by layer, line by line, node by node:
    /// index [`Self::tau_index`] (one array: a study makes several reference states a profile).
    pub target_tau: Vec<f64>,
    /// Vertical optical depth of every other gas with lines, the same index.
    pub other_tau: Vec<f64>,
}

/// Slant optical depths from the lidar to one altitude, line by line, node by node (index
/// `line · nodes + node`): the target gas in a part held at the reference and a part scaled by
/// s, and the other gases.
#[derive(Debug, Clone, PartialEq)]
pub struct PathDepths {
    /// Quadrature nodes per line.
    pub nodes: usize,
    /// Target gas, held fixed.
    pub target_fixed: Vec<f64>,
    /// Target gas, scaled by s.
    pub target_scaled: Vec<f64>,
    /// Other gases.
    pub other: Vec<f64>,
}

impl PathDepths {
    /// The path to `far` with only the part beyond `near` scaled: a DIAL range cell.
    pub fn cell(near: &PathDepths, far: &PathDepths) -> PathDepths {
        let diff =
            |a: &[f64], b: &[f64]| -> Vec<f64> { a.iter().zip(b).map(|(u, v)| v - u).collect() };
        PathDepths {
            nodes: near.nodes,
            target_fixed: near.target_scaled.clone(),
            target_scaled: diff(&near.target_scaled, &far.target_scaled),
            other: far.other.clone(),
        }
    }
}

/// The instrument as a retrieval assumes it: the laser's lines, its line shape and the
/// receiver's filter, without the laser's imperfections (frequency offset, jitter, spectral
/// impurity).
#[derive(Debug, Clone, Copy)]
pub struct AssumedInstrument<'a> {
    /// The laser (its line shape and quadrature; its imperfections are ignored).
    pub laser: &'a Laser,
    /// Its lines.
    pub lines: &'a [Line],
    /// The receiver's filter.
    pub filter: &'a Filter,
}

impl ReferenceState {
    /// Line by line for `profile` on `edges_m` with `lines` and `options`, at the nominal nodes
    /// of the instrument's line shape around each of its lines.
    pub fn new(
        profile: &Profile,
        edges_m: &[f64],
        gas: &str,
        lines: &LineList,
        options: &LblOptions,
        instrument: AssumedInstrument,
    ) -> Result<Self, RetrievalError> {
        let mut memo = LayerDepthMemo::new();
        Self::new_with(profile, edges_m, gas, lines, options, instrument, &mut memo)
    }

    /// [`Self::new`], the same numbers, with the layers and cross-sections `memo` holds reused
    /// and what it computes added to it (an ensemble member's states, [`LayerDepthMemo`]).
    pub fn new_with(
        profile: &Profile,
        edges_m: &[f64],
        gas: &str,
        lines: &LineList,
        options: &LblOptions,
        instrument: AssumedInstrument,
        memo: &mut LayerDepthMemo,
    ) -> Result<Self, RetrievalError> {
        let AssumedInstrument {
            laser,
            lines: laser_lines,
            filter,
        } = instrument;
        let id = isotopologues::molecule_id(gas)
            .ok_or_else(|| RetrievalError::Gas(format!("`{gas}` is not a HITRAN molecule")))?;
        let others: Vec<u8> = lines.molecules().into_iter().filter(|m| *m != id).collect();
        let pick = |ms: Vec<u8>| {
            lines.filtered(&LineFilter {
                molecules: Some(ms),
                ..Default::default()
            })
        };
        let target_lines = pick(vec![id]);
        if target_lines.is_empty() {
            return Err(RetrievalError::Gas(format!(
                "no {gas} lines near the laser lines"
            )));
        }
        // The nodes of a line at its nominal centre through the filter, weights normalised (a
        // constant share of energy cancels in the on/off ratio).
        let nodes = filter.line_nodes(laser, 0.0);
        let total: f64 = nodes.iter().map(|q| q.weight).sum();
        if !(total > 0.0) {
            return Err(RetrievalError::Gas(
                "the filter blocks the whole laser line".into(),
            ));
        }
        let nus: Vec<f64> = laser_lines
            .iter()
            .flat_map(|l| {
                nodes
                    .iter()
                    .map(move |q| l.wavenumber_cm1 + q.offset_mhz / MHZ_PER_CM1)
            })
            .collect();
        let columns = LayerColumns::of_layers(
            profile,
            edges_m,
            &memo.layers(profile, edges_m, &[gas])?,
            gas,
        )?;
        // Each layer's row holds its lines' nodes in order: the rows one after another are
        // the index of `tau_index`.
        let mut per_layer = |ls: &LineList| -> Result<Vec<f64>, RetrievalError> {
            Ok(if ls.is_empty() {
                vec![0.0; nus.len() * (edges_m.len() - 1)]
            } else {
                memo.layer_optical_depths_at(profile, ls, edges_m, &nus, options)?
                    .concat()
            })
        };
        Ok(ReferenceState {
            columns,
            weights: vec![nodes.iter().map(|q| q.weight / total).collect(); laser_lines.len()],
            target_tau: per_layer(&target_lines)?,
            other_tau: per_layer(&pick(others))?,
        })
    }

    /// Lines of the laser.
    pub fn lines(&self) -> usize {
        self.weights.len()
    }

    /// Quadrature nodes of each line.
    pub fn nodes(&self) -> usize {
        self.weights.first().map_or(0, Vec::len)
    }

    /// Index of (layer, line, node) in [`Self::target_tau`] and [`Self::other_tau`].
    pub fn tau_index(&self, layer: usize, line: usize, node: usize) -> usize {
        (layer * self.lines() + line) * self.nodes() + node
    }

    /// Slant optical depths along a path from altitude `z_lidar` to `z` with direction cosine μ.
    pub fn path(&self, z_lidar: f64, z: f64, mu: f64) -> PathDepths {
        struct Op<'a> {
            state: &'a ReferenceState,
            z_lidar: f64,
            z: f64,
            mu: f64,
        }
        impl crate::simd::WithSimd for Op<'_> {
            type Output = PathDepths;
            #[inline(always)]
            fn with_simd<S: crate::simd::Simd>(self, _: S) -> PathDepths {
                self.state.summed_path(self.z_lidar, self.z, self.mu)
            }
        }
        // The sums over layers vectorised with the widest instructions the processor has
        // ([`crate::simd`]: the same numbers).
        crate::simd::dispatch(Op {
            state: self,
            z_lidar,
            z,
            mu,
        })
    }

    /// The loop of [`Self::path`].
    #[inline(always)]
    fn summed_path(&self, z_lidar: f64, z: f64, mu: f64) -> PathDepths {
        let n = self.lines() * self.nodes();
        let mut t = vec![0.0; n];
        let mut o = vec![0.0; n];
        let m = mu.abs();
        for (l, f) in layer_fractions(&self.columns.edges_m, z_lidar, z) {
            let add = |sum: &mut [f64], tau: &[f64]| {
                for (s, tau) in sum
                    .iter_mut()
                    .zip(tau.get(l * n..(l + 1) * n).unwrap_or(&[]))
                {
                    *s += f * tau / m;
                }
            };
            add(&mut t, &self.target_tau);
            add(&mut o, &self.other_tau);
        }
        PathDepths {
            nodes: self.nodes(),
            target_fixed: vec![0.0; n],
            target_scaled: t,
            other: o,
        }
    }

    /// Two-way transmission T̄²(s) of line `line` over a path, and its derivative in s.
    pub fn transmission2(&self, p: &PathDepths, line: usize, s: f64) -> (f64, f64) {
        let mut t = 0.0;
        let mut dt = 0.0;
        let first = line * p.nodes;
        for (i, w) in self.weights[line].iter().enumerate() {
            let k = first + i;
            let tau = p.target_fixed[k] + s * p.target_scaled[k] + p.other[k];
            let e = w * (-2.0 * tau).exp();
            t += e;
            dt += -2.0 * p.target_scaled[k] * e;
        }
        (t, dt)
    }

    /// D(s) and dD/ds for the on- and off-line over a path (module docs).
    pub fn daod(&self, p: &PathDepths, on: usize, off: usize, s: f64) -> (f64, f64) {
        let (t_on, dt_on) = self.transmission2(p, on, s);
        let (t_off, dt_off) = self.transmission2(p, off, s);
        (
            0.5 * (t_off / t_on).ln(),
            0.5 * (dt_off / t_off - dt_on / t_on),
        )
    }

    /// The scale s of the scaled part of the target gas for which D(s) = `daod` (Newton's
    /// method from the reference, s = 1, D being nearly linear in s); NaN if `daod` is not
    /// finite or D stops growing with s on the way (no unique solution).
    pub fn solve_scale(&self, p: &PathDepths, on: usize, off: usize, daod: f64) -> f64 {
        if !daod.is_finite() {
            return f64::NAN;
        }
        let mut s = 1.0;
        for _ in 0..50 {
            let (d, g) = self.daod(p, on, off, s);
            if !(g > 0.0) {
                return f64::NAN;
            }
            let step = (d - daod) / g;
            s -= step;
            if step.abs() <= 1e-14 * s.abs().max(1.0) {
                return s;
            }
        }
        s
    }

    /// Virtual absorption cross-section of a line over a path (the reference study's
    /// σ = −ln T_gas/(2N)): the target gas's two-way line-shape-averaged transmission and its
    /// slant column N [m²/molecule].
    pub fn virtual_cross_section_m2(
        &self,
        p: &PathDepths,
        line: usize,
        slant_column_per_m2: f64,
    ) -> f64 {
        let mut t = 0.0;
        let first = line * p.nodes;
        for (i, w) in self.weights[line].iter().enumerate() {
            t += w * (-2.0 * (p.target_fixed[first + i] + p.target_scaled[first + i])).exp();
        }
        -t.ln() / (2.0 * slant_column_per_m2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two layers, two lines (on, off) of two quadrature nodes each, every optical depth
    /// different and the off-line absorbing too, so that no term of D or dD/ds cancels.
    fn state() -> ReferenceState {
        ReferenceState {
            columns: LayerColumns {
                edges_m: vec![0.0, 400.0, 1000.0],
                dry_air_per_m2: vec![1e29, 1e29],
                gas_per_m2: vec![4e25, 4e25],
            },
            weights: vec![vec![0.3, 0.7], vec![0.6, 0.4]],
            // [layer][line][node], flattened.
            target_tau: vec![0.4, 0.8, 0.1, 0.25, 0.6, 1.2, 0.15, 0.3],
            other_tau: vec![0.05, 0.1, 0.2, 0.02, 0.02, 0.04, 0.1, 0.01],
        }
    }

    /// D(s) = ½ ln(T̄²_off/T̄²_on) with T̄²_ℓ = Σᵢ wᵢ exp(−2 (s τ_t + τ_o)/|μ|) written out
    /// for the path from 1000 m to 100 m: the whole upper layer and ¾ of the lower.
    fn closed_form_d(s: f64, mu: f64) -> f64 {
        let st = state();
        let t2 = |line: usize| -> f64 {
            (0..2)
                .map(|i| {
                    let col = |tau: &[f64]| {
                        tau[st.tau_index(1, line, i)] + 0.75 * tau[st.tau_index(0, line, i)]
                    };
                    st.weights[line][i]
                        * (-2.0 * (s * col(&st.target_tau) + col(&st.other_tau)) / mu.abs()).exp()
                })
                .sum()
        };
        0.5 * (t2(1) / t2(0)).ln()
    }

    /// The path summed with the processor's widest instructions ([`crate::simd`]) is the same
    /// loop compiled for the baseline, bit for bit, on paths that end inside a layer and
    /// across both layers.
    #[test]
    fn a_vectorised_path_is_the_baseline_loop_bit_for_bit() {
        let st = state();
        for (z_lidar, z, mu) in [
            (1000.0, 100.0, -1.0),
            (1000.0, 0.0, -0.3),
            (0.0, 730.0, 0.8),
        ] {
            let got = st.path(z_lidar, z, mu);
            let want = st.summed_path(z_lidar, z, mu);
            for (g, w) in [
                (&got.target_scaled, &want.target_scaled),
                (&got.other, &want.other),
                (&got.target_fixed, &want.target_fixed),
            ] {
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(g), bits(w));
            }
        }
    }

    /// D against its closed form on a slant path, and dD/ds against a central difference of it.
    #[test]
    fn differential_optical_depth_and_its_slope_follow_the_closed_form() {
        let st = state();
        for mu in [-1.0, -0.5] {
            let p = st.path(1000.0, 100.0, mu);
            for s in [0.0, 1.0, 2.5] {
                let (d, g) = st.daod(&p, 0, 1, s);
                let want = closed_form_d(s, mu);
                assert!((d - want).abs() < 1e-14, "μ {mu}, s {s}: D {d} vs {want}");
                let h = 1e-5;
                let fd = (closed_form_d(s + h, mu) - closed_form_d(s - h, mu)) / (2.0 * h);
                assert!(
                    (g - fd).abs() < 1e-8 * fd,
                    "μ {mu}, s {s}: dD/ds {g} vs {fd}"
                );
            }
        }
    }

    /// `solve_scale` inverts D: from D(s) of the closed form it returns s, also where D is far
    /// from linear and its slope exceeds 2 (so only a method that uses the slope converges); NaN
    /// for a D that is not finite and for one that two scales give.
    #[test]
    fn solve_scale_inverts_the_differential_optical_depth() {
        let st = state();
        let mu = -0.25;
        let p = st.path(1000.0, 100.0, mu);
        let slope = st.daod(&p, 0, 1, 1.0).1;
        assert!(slope > 2.0, "{slope}");
        for s in [0.0, 0.3, 1.0, 4.0] {
            let got = st.solve_scale(&p, 0, 1, closed_form_d(s, mu));
            assert!((got - s).abs() < 1e-12, "s {s}: solved {got}");
        }
        assert!(st.solve_scale(&p, 0, 1, f64::NAN).is_nan());
        assert!(st.solve_scale(&p, 0, 1, f64::INFINITY).is_nan());

        // An on-line half transparent, half opaque (τ 0 and 4 per layer thickness) against an
        // off-line of τ ½: D(s) = −s/2 − ½ ln(½(1 + e^{−8s})) on the vertical path through the
        // upper layer rises to a peak at s = ln 7 / 8 and falls after it, so D(0.1) is reached
        // twice: no unique solution.
        let two_valued = ReferenceState {
            weights: vec![vec![0.5, 0.5], vec![0.5, 0.5]],
            target_tau: vec![0.0, 0.0, 0.0, 0.0, 0.0, 4.0, 0.5, 0.5],
            other_tau: vec![0.0; 8],
            ..state()
        };
        let p = two_valued.path(1000.0, 400.0, -1.0);
        let d = |s: f64| -s / 2.0 - 0.5 * (0.5 * (1.0 + (-8.0 * s).exp())).ln();
        let peak = 7f64.ln() / 8.0;
        assert!(d(0.1) < d(peak) && d(0.1) > d(1.0));
        assert!((two_valued.daod(&p, 0, 1, 0.1).0 - d(0.1)).abs() < 1e-15);
        assert!(two_valued.solve_scale(&p, 0, 1, d(0.1)).is_nan());
    }
}
