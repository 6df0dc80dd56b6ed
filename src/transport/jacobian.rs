//! Jacobians from the same photons: the derivatives of every Monte Carlo return with respect to
//! each layer's absorption coefficient, molecular and particle scattering coefficients and
//! particle extinction (at a fixed single-scattering albedo), tallied along the paths that make
//! the returns (`docs/transport.md`, "Jacobians").
//!
//! A return is E = ∫ f(x̄) dx̄ over photon paths x̄; every estimator of the walk, whatever it
//! samples (free paths on the scattering coefficient, DDIS, the cone and crossing estimates,
//! splitting, roulette), scores f(x̄)/p(x̄) with multiple-importance weights that sum to one.
//! The sampling densities do not depend on the layer property θ that is differentiated, or
//! their dependence is immaterial: ∂E/∂θ = ∫ ∂f/∂θ dx̄ is estimated without bias by scoring
//! f/p · ∂ln f/∂θ with the same weights (the "differential" or "perturbation" Monte Carlo of
//! Marchuk et al. 1980, *The Monte Carlo Methods in Atmospheric Optics*, ch. 4). For a path
//! with legs of length ℓ_L inside layer L and scatterings e in L,
//!
//! * absorption:  ∂ln f/∂k_L = −ℓ_L
//! * scattering of species i: ∂ln f/∂σ_i,L = Σ_e P_i(Θ_e)/Σ_j σ_j P_j(Θ_e) − ℓ_L
//!
//! (the collision factor of f is Σ_j σ_j P_j(Θ)/4π, its transmission e^{−∫(k+σ)}).
//!
//! **Lengths in O(1) per leg.** With ov_L(z) = clamp(z − b_L, 0, h_L) (the part of layer L
//! below z), a leg from z_a to z_b with direction cosine μ has ℓ_L = (ov_L(z_b) − ov_L(z_a))/μ,
//! so a path's ℓ_L is Σ_p a_p ov_L(z_p) over its points, a_p = 1/μ_in − 1/μ_out. A photon
//! therefore carries, per layer holding a point, Σ a_p and Σ a_p (z_p − b_L); an estimate adds
//! its score times these into per-layer tallies G and H, and the fold recovers
//! ℓ-weighted sums for every layer as h_L Σ_{λ>L} G_λ + H_L. An order-1 estimate touches two
//! layers however many it crosses.
//!
//! **Shares.** Per layer the photon also carries its number of scatterings n_L and, per
//! channel, the molecular share u = σ_mol P_mol(Θ)/Σ_j σ_j P_j(Θ) summed over them; the
//! particle share is 1 − u. Then ∂ln f/∂σ_mol = U/σ_mol − ℓ, ∂ln f/∂σ_part = (n − U)/σ_part − ℓ
//! and, at a fixed albedo ω = σ_part/ε_part, ∂ln f/∂ε_part = (n − U)/ε_part − ℓ.

use super::tally::TallyShape;
pub use crate::jacobians::{JacobianQuantity, Jacobians};
use crate::optics::OpticalAtmosphere;
use crate::returns::Order;
use crate::stats;

/// Tally quantities per (layer, channel): Σ s·a, Σ s·(a·offset + direct length), Σ s·n, Σ s·U.
const Q: usize = 4;
/// Reported quantities per (layer, channel): [`JacobianQuantity::ALL`].
const QR: usize = crate::jacobians::QUANTITIES;
/// Order groups of the tally: single scattering and orders ≥ 2.
const JORDERS: usize = 2;

/// The layers' geometry and scatterers as the Jacobian tally needs them.
#[derive(Debug, Clone)]
pub(crate) struct JacSetup {
    /// The window of layers a path can reach within the last gate's time: the first (index
    /// into the optical atmosphere) and how many.
    pub first: usize,
    pub n_layers: usize,
    nch: usize,
    edges_m: Vec<f64>,
    /// Index of the molecular component of each layer, if it has one.
    pub molecular: Vec<Option<usize>>,
}

impl JacSetup {
    /// The layers of `atm` within `reach_m` of the receiver's altitude `z_rx`: a path to the
    /// last gate (range r_end) is 2 r_end long, so it never gets further than r_end from the
    /// receiver, and the derivatives of every layer beyond are exactly 0 (an airborne lidar at
    /// 8 km then leaves out the 500 layers up to 60 km).
    pub fn new(atm: &OpticalAtmosphere, z_rx: f64, reach_m: f64) -> Self {
        let n = atm.n_layers();
        let e = &atm.edges_m;
        let first = (0..n).find(|&l| e[l + 1] > z_rx - reach_m).unwrap_or(n);
        let end = (first..n).find(|&l| e[l] >= z_rx + reach_m).unwrap_or(n);
        JacSetup {
            first,
            n_layers: end - first,
            nch: atm.n_channels,
            edges_m: e[first..=end.max(first)].to_vec(),
            molecular: atm.components[first..end]
                .iter()
                .map(|c| c.iter().position(|x| x.molecular))
                .collect(),
        }
    }

    /// The window's index of a layer of the optical atmosphere, if it is in the window.
    #[inline]
    pub fn local(&self, layer: usize) -> Option<usize> {
        layer.checked_sub(self.first).filter(|l| *l < self.n_layers)
    }

    /// Values per (gate, order group, annulus): (layers + the region above them) × Q × channels.
    #[inline]
    fn block(&self) -> usize {
        (self.n_layers + 1) * Q * self.nch
    }

    /// Length of a batch's Jacobian tally.
    pub fn len(&self, shape: &TallyShape) -> usize {
        shape.n_gates * JORDERS * shape.n_fov * self.block()
    }

    /// Start of the block of (gate, order, annulus).
    #[inline]
    pub fn base(&self, shape: &TallyShape, gate: usize, order: u32, annulus: usize) -> usize {
        let jo = usize::from(order >= 2);
        ((gate * JORDERS + jo) * shape.n_fov + annulus) * self.block()
    }

    /// Where altitude z is: its layer (n_layers above the top) and its height above the
    /// layer's bottom; None below the bottom (where ov_L(z) = 0 for every layer).
    #[inline]
    pub fn locate(&self, atm: &OpticalAtmosphere, z: f64) -> Option<(usize, f64)> {
        let (bottom, top) = (self.edges_m[0], self.edges_m[self.n_layers]);
        if !(z > bottom) {
            return None;
        }
        if z >= top {
            return Some((self.n_layers, 0.0));
        }
        let l = (atm.layer_of(z).saturating_sub(self.first)).min(self.n_layers - 1);
        Some((l, z - self.edges_m[l]))
    }
}

/// One layer's entry of a photon's Jacobian state.
#[derive(Debug, Clone, Copy)]
struct Entry {
    layer: usize,
    /// Σ a_p over the photon's points in the layer.
    a: f64,
    /// Σ a_p (z_p − b_L), plus the lengths of horizontal legs in the layer.
    b: f64,
    /// Scatterings in the layer.
    n: f64,
}

/// What a photon carries for the Jacobians: per layer holding one of its points (sparse).
#[derive(Debug, Clone, Default)]
pub(crate) struct JacState {
    entries: Vec<Entry>,
    /// Molecular share summed over the layer's scatterings, per channel (entry-major).
    u: Vec<f64>,
    /// Entry of each layer (n_layers + 1 slots), u32::MAX where none.
    slot: Vec<u32>,
    nch: usize,
}

impl JacState {
    pub fn new(js: &JacSetup) -> Self {
        JacState {
            entries: Vec::new(),
            u: Vec::new(),
            slot: vec![u32::MAX; js.n_layers + 1],
            nch: js.nch,
        }
    }

    pub fn clear(&mut self) {
        for e in &self.entries {
            self.slot[e.layer] = u32::MAX;
        }
        self.entries.clear();
        self.u.clear();
    }

    /// Become a copy of `other` (a state of the same run).
    pub fn copy_from(&mut self, other: &JacState) {
        self.clear();
        self.entries.extend_from_slice(&other.entries);
        self.u.extend_from_slice(&other.u);
        for (i, e) in self.entries.iter().enumerate() {
            self.slot[e.layer] = i as u32;
        }
    }

    /// A copy without the slot table (what a stacked photon keeps).
    pub fn snapshot(&self) -> JacState {
        JacState {
            entries: self.entries.clone(),
            u: self.u.clone(),
            slot: Vec::new(),
            nch: self.nch,
        }
    }

    #[inline]
    fn entry(&mut self, layer: usize) -> usize {
        let s = self.slot[layer];
        if s != u32::MAX {
            return s as usize;
        }
        self.entries.push(Entry {
            layer,
            a: 0.0,
            b: 0.0,
            n: 0.0,
        });
        self.u.extend(std::iter::repeat_n(0.0, self.nch));
        let i = self.entries.len() - 1;
        self.slot[layer] = i as u32;
        i
    }

    /// A point of the path at altitude z with coefficient `coef` (±1/μ of the legs it joins).
    #[inline]
    pub fn point(&mut self, js: &JacSetup, atm: &OpticalAtmosphere, z: f64, coef: f64) {
        if let Some((l, off)) = js.locate(atm, z) {
            let i = self.entry(l);
            self.entries[i].a += coef;
            self.entries[i].b += coef * off;
        }
    }

    /// A horizontal leg of `length` inside `layer`.
    #[inline]
    pub fn direct(&mut self, layer: usize, length: f64) {
        let i = self.entry(layer);
        self.entries[i].b += length;
    }

    /// A scattering in `layer` with molecular shares `u` (one per channel).
    #[inline]
    pub fn event(&mut self, layer: usize, u: &[f64]) {
        let i = self.entry(layer);
        self.entries[i].n += 1.0;
        let nch = self.nch;
        for (d, s) in self.u[i * nch..(i + 1) * nch].iter_mut().zip(u) {
            *d += s;
        }
    }

    /// Add `score[k]` times the state to the tally block at `base`.
    #[inline]
    pub fn score(&self, jbins: &mut [f64], base: usize, score: &[f64]) {
        let nch = self.nch;
        for (i, e) in self.entries.iter().enumerate() {
            let o = base + e.layer * Q * nch;
            let u = &self.u[i * nch..(i + 1) * nch];
            for (k, s) in score.iter().enumerate().take(nch) {
                if *s == 0.0 {
                    continue;
                }
                jbins[o + k] += s * e.a;
                jbins[o + nch + k] += s * e.b;
                jbins[o + 2 * nch + k] += s * e.n;
                jbins[o + 3 * nch + k] += s * u[k];
            }
        }
    }
}

/// An estimate's own part of the path, which the photon does not carry: its last legs to the
/// receiver and the scatterings that turn it there.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Virtual {
    points: [(f64, f64); 6],
    np: usize,
    direct: [(usize, f64); 2],
    nd: usize,
    events: [(usize, f64); 2],
    ne: usize,
}

impl Virtual {
    /// A leg from altitude `z_from` to `z_to` with direction cosine `mu` and `length`, in
    /// `layer` if it is horizontal.
    #[inline]
    pub fn leg(&mut self, z_from: f64, z_to: f64, mu: f64, length: f64, layer: usize) {
        if mu.abs() <= super::photon::HORIZONTAL_MU {
            self.direct[self.nd] = (layer, length);
            self.nd += 1;
        } else {
            self.point(z_from, -1.0 / mu);
            self.point(z_to, 1.0 / mu);
        }
    }

    /// One point with its coefficient.
    #[inline]
    pub fn point(&mut self, z: f64, coef: f64) {
        self.points[self.np] = (z, coef);
        self.np += 1;
    }

    /// A scattering in `layer` through the angle whose cosine is `mu`.
    #[inline]
    pub fn event(&mut self, layer: usize, mu: f64) {
        self.events[self.ne] = (layer, mu);
        self.ne += 1;
    }

    /// Add `score[k]` times these terms to the tally block at `base`; `share(layer, k, mu)`
    /// gives a scattering's molecular share.
    #[inline]
    pub fn score(
        &self,
        js: &JacSetup,
        atm: &OpticalAtmosphere,
        jbins: &mut [f64],
        base: usize,
        score: &[f64],
        share: impl Fn(usize, usize, f64) -> f64,
    ) {
        let nch = js.nch;
        for &(z, coef) in &self.points[..self.np] {
            let Some((l, off)) = js.locate(atm, z) else {
                continue;
            };
            let o = base + l * Q * nch;
            for (k, s) in score.iter().enumerate().take(nch) {
                jbins[o + k] += s * coef;
                jbins[o + nch + k] += s * coef * off;
            }
        }
        for &(l, length) in &self.direct[..self.nd] {
            let Some(l) = js.local(l) else { continue };
            let o = base + l * Q * nch;
            for (k, s) in score.iter().enumerate().take(nch) {
                jbins[o + nch + k] += s * length;
            }
        }
        for &(l_atm, mu) in &self.events[..self.ne] {
            let Some(l) = js.local(l_atm) else { continue };
            let o = base + l * Q * nch;
            for (k, s) in score.iter().enumerate().take(nch) {
                if *s == 0.0 {
                    continue;
                }
                jbins[o + 2 * nch + k] += s;
                jbins[o + 3 * nch + k] += s * share(l_atm, k, mu);
            }
        }
    }
}

/// Running means and M2 over batches of the Jacobians (reported layout: channel, FOV, gate,
/// order total/1/2+, layer, quantity).
pub(crate) struct JacFold {
    js: JacSetup,
    shape: TallyShape,
    fov_of_annulus: Vec<usize>,
    thickness_m: Vec<f64>,
    /// Per (layer, channel): 1/σ_mol, 1/σ_part, 1/ε_part (0 where absent).
    inv: Vec<[f64; 3]>,
    /// Per (layer, channel): the line-by-line gases' absorption coefficient [1/m].
    gas: Vec<f64>,
    n_batches: usize,
    mean: Vec<f64>,
    m2: Vec<f64>,
    scale: Vec<f64>,
    scratch: Vec<f64>,
    /// Combinations of channels (laser lines), folded from each batch's channel values; with
    /// them the channels' own are not kept (a run reports its lines, and a line-shape
    /// quadrature's nodes would multiply the memory by their number).
    combos: Vec<crate::returns::Combination>,
    /// Per channel: the combinations it enters, with its coefficient.
    terms_of: Vec<Vec<(usize, f64)>>,
    cmean: Vec<f64>,
    cm2: Vec<f64>,
    cscale: Vec<f64>,
    cvalues: Vec<f64>,
}

impl JacFold {
    /// Also fold these combinations of channels (the laser lines), so that their derivatives
    /// have standard errors of their own.
    pub fn with_combinations(mut self, combos: &[crate::returns::Combination]) -> Self {
        if combos.is_empty() {
            return self;
        }
        let n = combos.len() * self.per_channel();
        self.combos = combos.to_vec();
        self.terms_of = vec![Vec::new(); self.js.nch];
        for (j, c) in combos.iter().enumerate() {
            for &(k, coef) in &c.terms {
                self.terms_of[k].push((j, coef));
            }
        }
        self.mean = Vec::new();
        self.m2 = Vec::new();
        self.scale = Vec::new();
        self.scratch = Vec::new();
        self.cmean = vec![0.0; n];
        self.cm2 = vec![0.0; n];
        self.cscale = vec![0.0; n];
        self.cvalues = vec![0.0; n];
        self
    }

    /// Reported values per channel.
    fn per_channel(&self) -> usize {
        self.shape.n_fov * self.shape.n_gates * 3 * self.js.n_layers * QR
    }

    pub fn new(
        js: &JacSetup,
        atm: &OpticalAtmosphere,
        shape: TallyShape,
        fov_of_annulus: Vec<usize>,
    ) -> Self {
        let (nl, nch) = (js.n_layers, js.nch);
        let mut inv = vec![[0.0; 3]; nl * nch];
        for l in 0..nl {
            for k in 0..nch {
                let (mut mol, mut part, mut ext) = (0.0, 0.0, 0.0);
                for (c, comp) in atm.components[js.first + l].iter().enumerate() {
                    if js.molecular[l] == Some(c) {
                        mol += comp.sigma_s_per_m[k];
                    } else {
                        part += comp.sigma_s_per_m[k];
                        ext += comp.sigma_s_per_m[k] + comp.sigma_a_per_m[k];
                    }
                }
                let r = |x: f64| if x > 0.0 { 1.0 / x } else { 0.0 };
                inv[l * nch + k] = [r(mol), r(part), r(ext)];
            }
        }
        let n = nch * shape.n_fov * shape.n_gates * 3 * nl * QR;
        JacFold {
            gas: atm.gas_sigma_a_per_m[js.first * nch..(js.first + nl) * nch].to_vec(),
            thickness_m: (0..nl).map(|l| js.edges_m[l + 1] - js.edges_m[l]).collect(),
            js: js.clone(),
            shape,
            fov_of_annulus,
            inv,
            n_batches: 0,
            mean: vec![0.0; n],
            m2: vec![0.0; n],
            scale: vec![0.0; n],
            scratch: vec![0.0; n],
            combos: Vec::new(),
            terms_of: Vec::new(),
            cmean: Vec::new(),
            cm2: Vec::new(),
            cscale: Vec::new(),
            cvalues: Vec::new(),
        }
    }

    #[inline]
    fn reported(&self, k: usize, fov: usize, gate: usize, order: usize, layer: usize) -> usize {
        let s = &self.shape;
        ((((k * s.n_fov + fov) * s.n_gates + gate) * 3 + order) * self.js.n_layers + layer) * QR
    }

    /// Fold one batch's tally (already in energy per pulse).
    pub fn add_batch(&mut self, jbins: &[f64]) {
        let s = self.shape;
        let (nl, nch) = (self.js.n_layers, self.js.nch);
        let block = self.js.block();
        let keep = self.combos.is_empty();
        self.scratch.iter_mut().for_each(|v| *v = 0.0);
        self.cvalues.iter_mut().for_each(|v| *v = 0.0);
        let mut acc = vec![0.0; block];
        for gate in 0..s.n_gates {
            for jo in 0..JORDERS {
                acc.iter_mut().for_each(|v| *v = 0.0);
                for a in 0..s.n_fov {
                    let start = ((gate * JORDERS + jo) * s.n_fov + a) * block;
                    for (d, v) in acc.iter_mut().zip(&jbins[start..start + block]) {
                        *d += v;
                    }
                    let fov = self.fov_of_annulus[a];
                    for k in 0..nch {
                        // Σ over the regions above layer L of G, from the top down.
                        let mut above = acc[nl * Q * nch + k];
                        for l in (0..nl).rev() {
                            let o = l * Q * nch;
                            let (g, h, n, u) = (
                                acc[o + k],
                                acc[o + nch + k],
                                acc[o + 2 * nch + k],
                                acc[o + 3 * nch + k],
                            );
                            let j_abs = -(self.thickness_m[l] * above + h);
                            above += g;
                            let [im, ip, ie] = self.inv[l * nch + k];
                            let vals = [
                                j_abs,
                                u * im + j_abs,
                                (n - u) * ip + j_abs,
                                (n - u) * ie + j_abs,
                                j_abs * self.gas[l * nch + k],
                            ];
                            if keep {
                                let r1 = self.reported(k, fov, gate, 1 + jo, l);
                                let r0 = self.reported(k, fov, gate, 0, l);
                                for (q, v) in vals.iter().enumerate() {
                                    self.scratch[r1 + q] = *v;
                                    self.scratch[r0 + q] += *v;
                                }
                            }
                            for &(j, coef) in self.terms_of.get(k).map_or(&[][..], |v| v.as_slice())
                            {
                                let r1 = self.reported(j, fov, gate, 1 + jo, l);
                                let r0 = self.reported(j, fov, gate, 0, l);
                                for (q, v) in vals.iter().enumerate() {
                                    self.cvalues[r1 + q] += coef * v;
                                    self.cvalues[r0 + q] += coef * v;
                                }
                            }
                        }
                    }
                }
            }
        }
        let n = self.n_batches + 1;
        for (i, v) in self.scratch.iter().enumerate() {
            stats::welford_add_scaled(
                &mut self.mean[i],
                &mut self.m2[i],
                &mut self.scale[i],
                n,
                *v,
            );
        }
        if !self.combos.is_empty() {
            for (i, v) in self.cvalues.iter().enumerate() {
                stats::welford_add_scaled(
                    &mut self.cmean[i],
                    &mut self.cm2[i],
                    &mut self.cscale[i],
                    n,
                    *v,
                );
            }
        }
        self.n_batches = n;
    }

    /// The Jacobians of the combinations (laser lines), if any: a derivative is defined where
    /// it is for every channel of the combination.
    pub fn finish_combined(
        &self,
        fov_full_angle_mrad: Vec<f64>,
        range_m: Vec<f64>,
    ) -> Option<Jacobians> {
        if self.combos.is_empty() {
            return None;
        }
        let channel_defined = self.channel_defined();
        let (nl, nch, m) = (self.js.n_layers, self.js.nch, self.combos.len());
        let mut defined = vec![true; nl * QR * m];
        for (j, c) in self.combos.iter().enumerate() {
            for l in 0..nl {
                for q in 0..QR {
                    defined[(l * QR + q) * m + j] = c
                        .terms
                        .iter()
                        .all(|(k, _)| channel_defined[(l * QR + q) * nch + k]);
                }
            }
        }
        let names = self.combos.iter().map(|c| c.name.clone()).collect();
        let moments = (&self.cmean[..], &self.cm2[..], &self.cscale[..]);
        Some(self.assemble(names, fov_full_angle_mrad, range_m, moments, defined))
    }

    /// Jacobians from running moments (mean, M2, scale) of `channels`.
    fn assemble(
        &self,
        channels: Vec<String>,
        fov_full_angle_mrad: Vec<f64>,
        range_m: Vec<f64>,
        (mean, m2, scale): (&[f64], &[f64], &[f64]),
        defined: Vec<bool>,
    ) -> Jacobians {
        let (nl, n) = (self.js.n_layers, self.n_batches);
        Jacobians {
            channels,
            fov_full_angle_mrad,
            range_m,
            orders: vec![Order::Total, Order::Exactly(1), Order::AtLeast(2)],
            first_layer: self.js.first,
            layer_bottom_m: self.js.edges_m[..nl].to_vec(),
            layer_top_m: self.js.edges_m[1..=nl].to_vec(),
            value: mean.to_vec(),
            stderr: (0..m2.len())
                .map(|i| stats::std_error_scaled(m2[i], scale[i], n))
                .collect(),
            defined,
        }
    }

    /// Which derivatives exist, per channel (layout of [`Jacobians::defined`]).
    fn channel_defined(&self) -> Vec<bool> {
        let (nl, nch) = (self.js.n_layers, self.js.nch);
        let mut defined = vec![false; nl * QR * nch];
        for l in 0..nl {
            for k in 0..nch {
                let [im, ip, ie] = self.inv[l * nch + k];
                let gas = self.gas[l * nch + k] > 0.0;
                for (q, ok) in [true, im > 0.0, ip > 0.0, ie > 0.0, gas]
                    .into_iter()
                    .enumerate()
                {
                    defined[(l * QR + q) * nch + k] = ok;
                }
            }
        }
        defined
    }

    /// The channels' Jacobians with their standard errors; `None` where only the
    /// combinations are kept ([`Self::with_combinations`]).
    pub fn finish(
        &self,
        channels: Vec<String>,
        fov_full_angle_mrad: Vec<f64>,
        range_m: Vec<f64>,
    ) -> Option<Jacobians> {
        if !self.combos.is_empty() {
            return None;
        }
        let moments = (&self.mean[..], &self.m2[..], &self.scale[..]);
        let defined = self.channel_defined();
        Some(self.assemble(channels, fov_full_angle_mrad, range_m, moments, defined))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// A horizontal leg adds its length to its layer directly, and a slanted one its part of
    /// each layer through the ov_L points: a score of 2 on a path of 3 m across layer 0 and
    /// 100 m down from 600 m to its bottom (500 m) puts 2 × 103 m into the layer's lengths.
    #[test]
    fn horizontal_and_slanted_legs_give_the_path_length_in_the_layer() {
        let scene = Scene::from_toml(
            std::path::Path::new("s.toml"),
            crate::transport::testing::CLOUD,
        )
        .unwrap();
        let atm = OpticalAtmosphere::build(&scene).unwrap();
        let js = JacSetup::new(&atm, 0.0, 10_000.0);
        assert_eq!((js.first, js.n_layers), (0, 1));
        let mut v = Virtual::default();
        v.leg(600.0, 600.0, 0.0, 3.0, 0);
        v.leg(600.0, 0.0, -1.0, 600.0, 0);
        let mut jbins = vec![0.0; js.block()];
        v.score(&js, &atm, &mut jbins, 0, &[2.0], |_, _, _| 0.0);
        // Layer 0: G (Σ s a) = 2 × 1 from the point at 600 m; H (Σ s a (z − b) + s ℓ_direct)
        // = 2 × 1 × 100 + 2 × 3; the point at 0 m is below the layers.
        assert_eq!(&jbins[..2], &[2.0, 206.0]);
        // The fold's ℓ_0 = h_0 Σ_{λ>0} G + H_0: nothing above, so H_0 / score = 103 m.
        assert_eq!(jbins[Q], 0.0);
    }
}
