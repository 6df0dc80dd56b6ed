//! One photon packet's life, read from top to bottom:
//! emit → (range check → flight → surface or collision → local estimate → roulette → scatter)*.
//!
//! Method (docs/design.md §2; `docs/transport.md` has the derivations, by step):
//! * Free paths are sampled on the scattering coefficient of channel 0 when all channels
//!   scatter alike (one scattering class, `super::scatter_classes`); all absorption, and any
//!   small difference in scattering between channels, rides in per-channel weights (ALIS,
//!   Emde et al. 2011, JQSRT 112, 1622): per segment w_k ← w_k · e^{−τ_a,k} · (σ_s,k/σ_s,0) ·
//!   e^{−(τ_s,k − τ_s,0)}, and after a scattering w_k ← w_k · P_k(Θ)/P_0(Θ). Hence the local
//!   estimate carries no single-scattering albedo. With several classes (scattering that
//!   differs by orders of magnitude), each collision and each scattering angle is drawn from
//!   the mixture of the classes' densities and every channel weighted by its own density over
//!   the mixture's (one-sample MIS, balance heuristic; `docs/transport.md`, step 5).
//! * Every flight is cut to the part of its path from which the photon could still reach a gate
//!   (an ellipsoid with the receiver as one focus: total path + return leg ≤ 2 r_end). A collision
//!   is forced inside that part with weight factor 1 − e^{−τ}, the uncollided remainder being
//!   scored to the flux tally as escaped (Cashwell & Everett 1959; Marchuk et al. 1980). A flight
//!   that ends on the surface instead either collides (probability q = max(1 − e^{−τ}, ½)) or
//!   reaches the surface (1 − q), each branch weighted by true/chosen probability, so that thin
//!   atmospheres over a bright surface still get scattering events.
//! * The surface contribution to the signal is scored at every flight that heads for the surface,
//!   as an expected value (the uncollided weight e^{−τ} reaching it), not when the photon happens
//!   to arrive; the reflected branch then continues without scoring again.
//! * Local (peel-off) estimate at every collision for every field of view at once:
//!   ΔE_k = w_k · P(Θ_r)/(4π) · cos θ_r/d² · e^{−τ_k(x→receiver)}, and at the surface
//!   ΔE_k = w_k e^{−τ_k} · ρ_k cos θ_s/π · cos θ_r/d² · e^{−τ_k(S→receiver)}; the telescope area,
//!   optical efficiency and pulse energy per photon multiply in once, when a batch is folded.
//! * Cone estimate for the narrow fields of view (`super::cone`, `docs/transport.md` step 6a):
//!   at a collision (always near the axis, with probability falling as 1/ρ farther out) one more
//!   flight and scattering drawn into a FOV annulus, scored as the next order and combined with
//!   the walk's own local estimates there by the balance heuristic.
//! * Crossing estimate for the wider ones (`super::crossing`, step 6b): at every flight from a
//!   scattering, the local estimate of the collision that ends it, in expectation over where
//!   along the flight it falls inside them; and at every DDIS scattering the same along one more
//!   direction drawn about the receiver's (step 6c), the two combined by the balance heuristic.
//! * Russian roulette below a weight of 1e-2 (survivors continue at 5e-2), on the weight times
//!   the photon's alignment importance max(1, P(Θ_rx)/10) where DDIS applies: photons heading
//!   for the receiver, which DDIS gives small weights, are spared (`docs/transport.md` step 7).

use glam::DVec3;
use rand::RngExt;

mod estimate;
mod sampling;
mod surface;
#[cfg(test)]
mod tests;
mod walk;

use super::cone::Prev;
use super::jacobian::{JacState, Virtual};
use super::lanes;
use super::stokes::{self, Reduced, Turn};
use super::tally::{Flux, TallyShape};
use super::{RunStats, Setup};
use crate::aperture;
use crate::rng::Rng;
use lanes::exp_neg;
use sampling::{lambertian, one_minus_exp_neg, pick_component, rotate, unit_azimuth};

/// Weight below which Russian roulette is played, and the weight survivors continue with.
const ROULETTE_BELOW: f64 = 1e-2;
const ROULETTE_SURVIVOR: f64 = 5e-2;
/// Smallest probability of colliding before the surface on a flight that ends there.
const MIN_COLLISION_PROBABILITY: f64 = 0.5;
/// Direction cosines below this are treated as horizontal (the flight stays in its layer).
const HORIZONTAL: f64 = 1e-12;
/// The same, for the Jacobian tally's legs.
pub(super) const HORIZONTAL_MU: f64 = HORIZONTAL;

/// Alignment splitting and the roulette's alignment importance weigh a photon by the phase
/// function toward the receiver, P(Θ_rx), because a photon turned into a forward peak toward the
/// receiver is rare and its next local estimate a spike. Two bounds keep their work bounded:
/// * P(Θ_rx) counts at most `ALIGNMENT_MAX`. Splitting until w·P(Θ_rx) ≤ 2 makes about
///   w·P/2 copies of a photon in all; the cap is above C.1's forward peak (760 at 1064 nm: its
///   runs are unchanged) and keeps one of g = 0.99999999 (2e16) from splitting without end.
/// * Neither is used in a layer whose phase function has a backward peak, above
///   `ALIGNMENT_BACKWARD_MAX` anywhere in the backward hemisphere (C.1's droplets stay below
///   1). There a photon heading away is sent back toward the receiver as often as it
///   backscatters, and one sent back along the line of sight is aligned with the forward peak:
///   alignment is common, not rare. A double Henyey-Greenstein of g = 0.99 and −0.99 made
///   every such photon hundreds of copies (2700 scatterings per photon instead of 8.5, for no
///   smaller error; `tests/stress.rs`).
const ALIGNMENT_MAX: f64 = 1e3;
const ALIGNMENT_BACKWARD_MAX: f64 = 10.0;

/// Weight above which a photon is split ([`Tracer::split_heavy`]).
const SPLIT_ABOVE: f64 = 8.0;
/// Most copies waiting at once (a bound on memory; beyond it no more splitting, still unbiased).
const MAX_SPLIT_STACK: usize = 256;

/// A copy made by splitting, waiting to be followed.
struct PhotonCopy {
    pos: DVec3,
    dir: DVec3,
    path: f64,
    order: u32,
    w: Vec<f64>,
    /// The scattering that made it (at `pos`).
    prev: Prev,
    /// Its crossing estimate's MIS factor ([`Tracer::cross_mis`]).
    cross_mis: f64,
    /// Polarised runs: its reference axis and reduced Stokes vectors ([`Tracer::e1`]).
    e1: DVec3,
    pol: Vec<Reduced>,
    /// Jacobian runs: its path's points and scatterings.
    jac: JacState,
}

/// Per-batch state: buffers reused by every photon of the batch.
pub(crate) struct Tracer<'a, const ONE_CHANNEL: bool> {
    s: &'a Setup<'a>,
    /// Weights per channel.
    w: Vec<f64>,
    /// Cumulative vertical scattering / absorption optical depth at the photon's altitude.
    ts: Vec<f64>,
    ta: Vec<f64>,
    /// Scratch per channel.
    tmp: Vec<f64>,
    /// Scratch per channel: the cumulative optical depths at a second point (scattering,
    /// absorption), and phase-function values at two scatterings.
    ts_y: Vec<f64>,
    ta_y: Vec<f64>,
    phase: Vec<f64>,
    phase_y: Vec<f64>,
    /// Scratch per channel: optical depths of an estimate's legs.
    tau: Vec<f64>,
    tau2: Vec<f64>,
    /// Per scattering class: scattering optical depth of the flight and 1 − e^{−τ} (collision
    /// probability), then scratch for the optical depth to the collision.
    cls_tau: Vec<f64>,
    cls_p: Vec<f64>,
    /// Copies made by splitting, not yet followed.
    split: Vec<PhotonCopy>,
    /// The weights before the scattering of a photon that alignment splitting copies.
    pre: Vec<f64>,
    pub bins: Vec<f64>,
    /// Factor of the next flight's crossing estimate: its MIS weight against the DDIS crossing
    /// made at the scattering that started it (1 where there was none).
    cross_mis: f64,
    /// Scratch: the weights of a DDIS crossing.
    virt: Vec<f64>,
    /// Polarised runs (`super::stokes`): the photon's reference axis ⊥ its direction and, per
    /// channel, its reduced Stokes vector (Q, U, V)/I (I is the weight); their values before a
    /// scattering that alignment splitting repeats, and those of a DDIS crossing.
    e1: DVec3,
    pol: Vec<Reduced>,
    e1_pre: DVec3,
    pol_pre: Vec<Reduced>,
    e1_virt: DVec3,
    pol_virt: Vec<Reduced>,
    /// Scratch: a local estimate's factor per channel, without the scattering matrix; in
    /// Jacobian runs, every estimate's score per channel.
    le: Vec<f64>,
    /// Jacobian runs (`super::jacobian`): the photon's path so far, the batch's tally, the
    /// state before a scattering that alignment splitting repeats, scratch for molecular
    /// shares, and the virtual scattering of a DDIS crossing (altitude, layer, cosine of its
    /// angle).
    jac: JacState,
    pub jbins: Vec<f64>,
    jac_pre: JacState,
    jac_u: Vec<f64>,
    jac_extra: Option<(f64, usize, f64)>,
    pub flux: Flux,
    pub stats: RunStats,
    shape: TallyShape,
}

/// Where a flight ends if nothing happens on the way.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum End {
    Top,
    Bottom,
    Surface,
    Cut,
}

impl<'a, const ONE_CHANNEL: bool> Tracer<'a, ONE_CHANNEL> {
    pub fn new(s: &'a Setup<'a>) -> Self {
        let nch = s.atm.n_channels;
        debug_assert!(!ONE_CHANNEL || nch == 1);
        Tracer {
            s,
            w: vec![0.0; nch],
            ts: vec![0.0; nch],
            ta: vec![0.0; nch],
            tmp: vec![0.0; nch],
            ts_y: vec![0.0; nch],
            ta_y: vec![0.0; nch],
            phase: vec![0.0; nch],
            phase_y: vec![0.0; nch],
            tau: vec![0.0; nch],
            tau2: vec![0.0; nch],
            cls_tau: vec![0.0; s.classes.len()],
            cls_p: vec![0.0; s.classes.len()],
            split: Vec::new(),
            pre: vec![0.0; nch],
            bins: vec![0.0; s.shape.len()],
            cross_mis: 1.0,
            virt: vec![0.0; nch],
            e1: DVec3::X,
            pol: vec![[0.0; 3]; nch],
            e1_pre: DVec3::X,
            pol_pre: vec![[0.0; 3]; nch],
            e1_virt: DVec3::X,
            pol_virt: vec![[0.0; 3]; nch],
            le: vec![0.0; nch],
            jac: s.jac.as_ref().map(JacState::new).unwrap_or_default(),
            jbins: s
                .jac
                .as_ref()
                .map(|j| vec![0.0; j.len(&s.shape)])
                .unwrap_or_default(),
            jac_pre: s.jac.as_ref().map(JacState::new).unwrap_or_default(),
            jac_u: vec![0.0; nch],
            jac_extra: None,
            flux: Flux::zeros(nch),
            stats: RunStats::default(),
            shape: s.shape,
        }
    }

    /// Channels traced: a compile-time 1 in the one-channel tracer, whose per-channel loops
    /// then compile to straight-line code (12 % fewer instructions a scattering event on C.1,
    /// callgrind).
    #[inline(always)]
    fn nch(&self) -> usize {
        if ONE_CHANNEL { 1 } else { self.w.len() }
    }

    /// Scattering classes (`super::scatter_classes`): one channel has one.
    #[inline(always)]
    fn ncls(&self) -> usize {
        if ONE_CHANNEL { 1 } else { self.s.classes.len() }
    }

    /// Update the cumulative optical depths for altitude z in layer l (`Walk::at_layer`):
    /// every channel in one pass over the layer's row.
    #[inline]
    fn set_altitude_in(&mut self, l: usize, z: f64) {
        let nch = self.nch();
        if self.s.has_layers {
            self.s
                .atm
                .cumulative_taus_in(l, z, &mut self.ts[..nch], &mut self.ta[..nch]);
        } else {
            self.ts[..nch].fill(0.0);
            self.ta[..nch].fill(0.0);
        }
    }

    /// Follow one photon from emission to its end, and every copy splitting made of it.
    pub fn trace(&mut self, rng: &mut Rng) {
        self.stats.photons += 1;
        // Emit: from the receiver position into the divergence cone around the axis.
        let dir = self.s.emit_direction(rng.random(), rng.random());
        let nch = self.nch();
        self.w[..nch].fill(1.0);
        self.cross_mis = 1.0;
        if let Some(an) = &self.s.analyser {
            let (e1, p) = stokes::emitted(
                dir,
                self.s.axis_e1,
                matches!(an, stokes::Analyser::Circular),
            );
            self.e1 = e1;
            self.pol.iter_mut().for_each(|x| *x = p);
        }
        if self.s.jac.is_some() {
            self.jac.clear();
            self.jac_depart(self.s.receiver.z, dir.z);
        }
        self.follow(self.s.receiver, dir, 0.0, 0, None, rng);
        while let Some(copy) = self.split.pop() {
            self.w[..nch].copy_from_slice(&copy.w);
            self.cross_mis = copy.cross_mis;
            if self.s.jac.is_some() {
                self.jac.copy_from(&copy.jac);
            }
            if self.s.analyser.is_some() {
                self.e1 = copy.e1;
                self.pol.copy_from_slice(&copy.pol);
            }
            // Copies are made right after a scattering at their position.
            self.follow(
                copy.pos,
                copy.dir,
                copy.path,
                copy.order,
                Some(copy.prev),
                rng,
            );
        }
    }

    /// Polarised runs: the scattering from `dir` to `new_dir` in `layer` acting on every
    /// channel's Stokes vector; the weights take the factor (F₁₁ + F₁₂ q)/F₁₁ (`super::stokes`).
    fn polarise(&mut self, layer: usize, dir: DVec3, new_dir: DVec3) {
        let s = self.s;
        let turn = Turn::new(dir, self.e1, new_dir);
        let mu = dir.dot(new_dir);
        let grey = s
            .atm
            .grey_scattering
            .then(|| s.mixture_matrix(layer, 0, mu));
        for k in 0..self.nch() {
            let m = grey.unwrap_or_else(|| s.mixture_matrix(layer, k, mu));
            let (r, p) = stokes::reduce(turn.apply(self.pol[k], &m), m.f11);
            self.w[k] *= r;
            self.pol[k] = p;
        }
        self.e1 = turn.e1;
    }

    /// Largest channel weight.
    #[inline]
    fn w_max(&self) -> f64 {
        self.w[..self.nch()].iter().fold(0.0f64, |m, w| m.max(*w))
    }

    /// Splitting, the upper side of the weight window whose lower side is Russian roulette:
    /// a photon whose largest weight exceeds [`SPLIT_ABOVE`] continues as n copies of 1/n its
    /// weight (n = ⌈w_max⌉), the others stacked to be followed after it. Unbiased; it keeps the
    /// weights bounded where the factors of detector-directed sampling (up to 1/(1 − ε) a
    /// scattering) would otherwise multiply, over hundreds of scatterings deep in a thick cloud,
    /// into rare huge weights: a heavy tail whose mean is underestimated, with too small an
    /// error bar, by any practical number of photons.
    #[inline]
    fn split_heavy(&mut self, pos: DVec3, dir: DVec3, path: f64, order: u32, prev: Prev) {
        let w_max = self.w_max();
        let n = self.copies(w_max, SPLIT_ABOVE, usize::MAX);
        if n == 1 {
            return;
        }
        let f = 1.0 / n as f64;
        let nch = self.nch();
        self.w[..nch].iter_mut().for_each(|w| *w *= f);
        for _ in 1..n {
            self.push_copy(pos, dir, path, order, prev);
        }
        self.stats.splits += (n - 1) as u64;
    }

    /// How many a photon continues as when its splitting measure is `x`: ⌈x⌉ above
    /// `threshold`, at most `cap` and as many as the stack has room for; 1 (no splitting)
    /// otherwise or when the stack is full (still unbiased).
    #[inline]
    fn copies(&self, x: f64, threshold: f64, cap: usize) -> usize {
        if !(x > threshold) || self.split.len() >= MAX_SPLIT_STACK {
            return 1;
        }
        (x.ceil() as usize)
            .min(cap)
            .min(MAX_SPLIT_STACK - self.split.len() + 1)
    }

    /// Stack a copy of the photon with its current weights, to be followed later.
    #[inline]
    fn push_copy(&mut self, pos: DVec3, dir: DVec3, path: f64, order: u32, prev: Prev) {
        self.split.push(PhotonCopy {
            pos,
            dir,
            path,
            order,
            w: self.w[..self.nch()].to_vec(),
            prev,
            cross_mis: self.cross_mis,
            e1: self.e1,
            pol: if self.s.analyser.is_some() {
                self.pol.clone()
            } else {
                Vec::new()
            },
            jac: if self.s.jac.is_some() {
                self.jac.snapshot()
            } else {
                JacState::default()
            },
        });
    }

    /// Jacobian runs: the photon leaves altitude z with direction cosine μ.
    #[inline]
    fn jac_depart(&mut self, z: f64, mu: f64) {
        if let Some(js) = &self.s.jac
            && mu.abs() > HORIZONTAL
        {
            self.jac.point(js, self.s.atm, z, -1.0 / mu);
        }
    }

    /// Jacobian runs: the photon arrives at altitude z along a leg of direction cosine μ and
    /// `length` (inside `layer` if horizontal).
    #[inline]
    fn jac_arrive(&mut self, z: f64, mu: f64, layer: usize, length: f64) {
        if let Some(js) = &self.s.jac {
            if mu.abs() > HORIZONTAL {
                self.jac.point(js, self.s.atm, z, 1.0 / mu);
            } else if let Some(l) = js.local(layer) {
                self.jac.direct(l, length);
            }
        }
    }

    /// Jacobian runs: the photon scatters in `layer` through the angle of cosine μ.
    #[inline]
    fn jac_event(&mut self, layer: usize, mu: f64) {
        let Some(l) = self.s.jac.as_ref().and_then(|js| js.local(layer)) else {
            return;
        };
        let nch = self.nch();
        if self.s.atm.grey_scattering {
            let u = self.s.molecular_share(layer, 0, mu);
            self.jac_u[..nch].fill(u);
        } else {
            for k in 0..nch {
                self.jac_u[k] = self.s.molecular_share(layer, k, mu);
            }
        }
        self.jac.event(l, &self.jac_u[..nch]);
    }

    /// Jacobian runs: add the estimate whose scores per channel are in `self.le`, of a path of
    /// `order` scatterings reaching `gate` in `annulus`, with its own last legs `v`.
    #[inline]
    fn jac_score(&mut self, gate: usize, order: u32, annulus: usize, v: &Virtual) {
        let Some(js) = &self.s.jac else { return };
        let s = self.s;
        let nch = self.nch();
        let base = js.base(&self.shape, gate, order, annulus);
        let score = &self.le[..nch];
        self.jac.score(&mut self.jbins, base, score);
        let grey = s.atm.grey_scattering;
        v.score(js, s.atm, &mut self.jbins, base, score, |l, k, mu| {
            s.molecular_share(l, if grey { 0 } else { k }, mu)
        });
    }

    /// Russian roulette on the largest channel weight times the photon's `importance` (≥ 1;
    /// step 7): below [`ROULETTE_BELOW`] it survives with probability w·I/[`ROULETTE_SURVIVOR`]
    /// and its weights are divided by that; unbiased for any importance. False if it dies.
    #[inline]
    fn roulette(&mut self, importance: f64, rng: &mut Rng) -> bool {
        let w_max = self.w_max() * importance;
        if w_max >= ROULETTE_BELOW {
            return true;
        }
        let p = w_max / ROULETTE_SURVIVOR;
        if rng.random::<f64>() < p {
            let nch = self.nch();
            self.w[..nch].iter_mut().for_each(|w| *w /= p);
            true
        } else {
            self.stats.roulette_kills += 1;
            false
        }
    }

    /// Gate of a return arriving after a total path of `two_way_m`, if any.
    #[inline]
    fn gate(&self, two_way_m: f64) -> Option<usize> {
        let r = 0.5 * two_way_m;
        let x = (r - self.s.gate_start_m) / self.s.gate_width_m;
        if x >= 0.0 && x < self.shape.n_gates as f64 {
            Some(x as usize)
        } else {
            None
        }
    }

    /// Narrowest field-of-view annulus containing the direction to x, if any.
    #[inline]
    fn annulus(&self, cos_axis: f64) -> Option<usize> {
        self.s.fov_cos.iter().position(|c| cos_axis >= *c)
    }
}
