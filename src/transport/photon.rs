//! One photon packet's life, read from top to bottom:
//! emit → (range check → flight → surface or collision → local estimate → roulette → scatter)*.
//!
//! Method (DESIGN §2; `docs/transport.md` has the derivations, by step):
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

use std::f64::consts::PI;

use glam::DVec3;
use rand::RngExt;

use super::cone::Prev;
use super::stokes::{self, Reduced, Turn};
use super::tally::{Flux, TallyShape};
use super::{RunStats, Setup};
use crate::aperture;
use crate::rng::Rng;
use crate::scene::BeamProfile;

/// Weight below which Russian roulette is played, and the weight survivors continue with.
const ROULETTE_BELOW: f64 = 1e-2;
const ROULETTE_SURVIVOR: f64 = 5e-2;
/// Smallest probability of colliding before the surface on a flight that ends there.
const MIN_COLLISION_PROBABILITY: f64 = 0.5;
/// Direction cosines below this are treated as horizontal (the flight stays in its layer).
const HORIZONTAL: f64 = 1e-12;

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
    /// Scratch: a local estimate's factor per channel, without the scattering matrix.
    le: Vec<f64>,
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

    /// Update the cumulative optical depths for altitude z.
    #[inline]
    fn set_altitude(&mut self, z: f64) {
        for k in 0..self.nch() {
            let (s, a) = self.s.atm.cumulative_tau(z, k);
            self.ts[k] = s;
            self.ta[k] = a;
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
        self.follow(self.s.receiver, dir, 0.0, 0, None, rng);
        while let Some(copy) = self.split.pop() {
            self.w[..nch].copy_from_slice(&copy.w);
            self.cross_mis = copy.cross_mis;
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

    /// Polarised local estimate: every channel's light arriving along `dir` (the photon's
    /// reference axis and Stokes vectors) scattered in `layer` toward `omega`, split by the
    /// analyser and scored into co (`base + k`) and cross (`base + n + k`, n channels), each
    /// times `self.le[k]`, the estimate's factor without the scattering matrix.
    fn score_polarised(&mut self, layer: usize, dir: DVec3, omega: DVec3, base: usize) {
        let s = self.s;
        let Some(an) = &s.analyser else { return };
        let turn = Turn::new(dir, self.e1, omega);
        let analysis = an.toward(omega, turn.e1);
        let mu = dir.dot(omega);
        let grey = s
            .atm
            .grey_scattering
            .then(|| s.mixture_matrix(layer, 0, mu));
        let n = self.nch();
        for k in 0..n {
            if self.le[k] == 0.0 {
                continue;
            }
            let m = grey.unwrap_or_else(|| s.mixture_matrix(layer, k, mu));
            let (co, cross) = analysis.split(turn.apply(self.pol[k], &m));
            self.bins[base + k] += self.le[k] * co;
            self.bins[base + n + k] += self.le[k] * cross;
        }
    }

    /// Largest channel weight.
    #[inline]
    fn w_max(&self) -> f64 {
        self.w[..self.nch()].iter().fold(0.0f64, |m, w| m.max(*w))
    }

    /// Follow a photon (weights in `self.w`) from `pos` along `dir` after a path `path` and
    /// `order` scatterings, the last of them in the atmosphere at `prev` (`None` after emission
    /// or a surface reflection), to its end.
    fn follow(
        &mut self,
        mut pos: DVec3,
        mut dir: DVec3,
        mut path: f64,
        mut order: u32,
        mut prev: Option<Prev>,
        rng: &mut Rng,
    ) {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let ncls = self.ncls();
        self.set_altitude(pos.z);
        let mut carried: Option<(DVec3, f64)> = None;
        // The layer the photon is in (where the next flight starts): the first guess of the
        // searches for its collision's layer.
        let mut at_layer = if s.has_layers { atm.layer_of(pos.z) } else { 0 };

        loop {
            // Range check: even a straight return from here arrives after the last gate.
            // The geometry to the receiver, carried over from the collision that ends the last
            // flight (where the local estimate needed it) or computed here.
            let (to_rx, d0) = match carried.take() {
                Some(g) => g,
                None => {
                    let v = s.receiver - pos;
                    (v, v.length())
                }
            };
            let budget = 2.0 * s.r_end_m - path;
            if d0 >= budget {
                self.stats.cut += 1;
                if s.flux_tally {
                    for k in 0..nch {
                        self.flux.cut[k] += self.w[k];
                    }
                }
                return;
            }

            // Flight: the useful part of the path and where it ends.
            let mu = dir.z;
            let horizontal = mu.abs() <= HORIZONTAL;
            // Slant factor 1/|μ| (unused, infinite, when horizontal): one division per flight.
            let inv_mu = 1.0 / mu.abs();
            let (s_end, end) = s.useful_length(pos, dir, budget, (to_rx, d0));

            // Crossing estimate: from a scattering, the next collision's local estimate in the
            // fields of view it serves, in expectation over where along this flight the
            // collision falls inside them; the walk's own collision then does not score there.
            let crossing =
                prev.is_some() && !horizontal && ncls == 1 && s.crossing_from < self.shape.n_fov;
            if crossing {
                let scale = self.cross_mis;
                self.score_crossing(
                    pos,
                    dir,
                    inv_mu,
                    path,
                    order + 1,
                    s_end,
                    scale,
                    at_layer,
                    rng,
                );
            }

            // Scattering optical depth of the flight for each class (class 0: channel 0's).
            let inside = pos.z >= s.bottom_m && pos.z <= s.top_m && s.has_layers;
            let layer0 = if horizontal && inside {
                atm.layer_of(pos.z)
            } else {
                0
            };
            for c in 0..ncls {
                self.cls_tau[c] = if horizontal {
                    if inside {
                        s.classes[c].sigma[layer0] * s_end
                    } else {
                        0.0
                    }
                } else {
                    let t0 = self.ts[s.classes[c].channel];
                    (s.class_tau_at_end(c, end, pos.z + mu * s_end) - t0).abs() * inv_mu
                };
                self.cls_p[c] = one_minus_exp_neg(self.cls_tau[c]);
            }
            let p_collide = self.cls_p[0];
            // ΣP_c over the classes (one class: its own P); its mean decides the surface branch.
            let p_any: f64 = self.cls_p[..ncls].iter().sum();
            let scatters = self.cls_tau[..ncls].iter().any(|t| *t > 0.0);
            // Per-channel extinction to the end of the flight (into tmp), only where needed.
            let need_end_tau = end == End::Surface || s.flux_tally;
            if need_end_tau {
                let z_end = pos.z + mu * s_end;
                for k in 0..nch {
                    self.tmp[k] = if horizontal {
                        if inside {
                            let i = layer0 * nch + k;
                            (atm.sigma_s_per_m[i] + atm.sigma_a_per_m[i]) * s_end
                        } else {
                            0.0
                        }
                    } else {
                        let (ts1, ta1) = atm.cumulative_tau(z_end, k);
                        ((ts1 - self.ts[k]) + (ta1 - self.ta[k])).abs() * inv_mu
                    };
                }
            }
            if s.flux_tally {
                self.score_absorption(pos.z, mu, s_end);
            }

            // `branch`: probability of the collide branch (the surface branch takes the rest).
            let branch;
            if end == End::Surface {
                let hit = pos + dir * s_end;
                self.score_surface(hit, path + s_end, order + 1);
                let q = if scatters {
                    (p_any / ncls as f64).max(MIN_COLLISION_PROBABILITY)
                } else {
                    0.0
                };
                let albedo = s.surface.as_deref().unwrap_or(&[]);
                if rng.random::<f64>() >= q {
                    // Reach the surface and reflect (its signal was scored above).
                    for k in 0..nch {
                        let arriving = self.w[k] * (-self.tmp[k]).exp();
                        self.flux.down[k] += arriving * (1.0 - albedo[k]);
                        self.w[k] = arriving / (1.0 - q) * albedo[k];
                    }
                    pos = hit;
                    pos.z = s.bottom_m;
                    at_layer = 0;
                    path += s_end;
                    order += 1;
                    self.stats.surface_reflections += 1;
                    prev = None;
                    self.cross_mis = 1.0;
                    self.set_altitude(pos.z);
                    dir = lambertian(rng.random(), rng.random());
                    // A Lambertian surface reflects unpolarised light.
                    if s.analyser.is_some() {
                        self.e1 = dir.any_orthonormal_vector();
                        self.pol.iter_mut().for_each(|p| *p = [0.0; 3]);
                    }
                    if !self.roulette(1.0, rng) {
                        return;
                    }
                    continue;
                }
                // Collide before the surface; the surface absorbs its share in expectation.
                for k in 0..nch {
                    self.flux.down[k] += self.w[k] * (-self.tmp[k]).exp() * (1.0 - albedo[k]);
                }
                branch = q;
            } else {
                // Escape or cut: the uncollided part leaves; a collision is forced in the rest.
                if s.flux_tally {
                    let out = match end {
                        End::Top => &mut self.flux.up,
                        End::Bottom => &mut self.flux.down,
                        _ => &mut self.flux.cut,
                    };
                    for k in 0..nch {
                        out[k] += self.w[k] * (-self.tmp[k]).exp();
                    }
                }
                if !scatters {
                    self.stats.escaped += 1;
                    return;
                }
                branch = 1.0;
            }

            // Sample the collision: a class with probability P_c/ΣP (one class: always class 0),
            // then τ* from its exponential truncated to [0, τ_c). The collision density is then
            // Σ_c σ_c e^{−τ_c(s)}/ΣP_c: the mixture of the classes' truncated densities. On the
            // first flight, whose distances are ranges, the collision is instead drawn uniformly
            // in range over the gated window with probability β (range stratification), the two
            // densities combined by the balance heuristic: every gate then gets first
            // collisions, however thin its air compared with, say, a boundary layer below.
            let window = if order == 0 && s.stratify > 0.0 {
                let (a, b) = (s.gate_start_m, s.r_end_m.min(s_end));
                if b > a { Some((a, b)) } else { None }
            } else {
                None
            };
            let uniform = window.is_some() && rng.random::<f64>() < s.stratify;
            let (s_coll, layer, tau_star) = if let (true, Some((a, b))) = (uniform, window) {
                let s_u = a + rng.random::<f64>() * (b - a);
                let z = pos.z + mu * s_u;
                let tau = if horizontal {
                    s.classes[0].sigma[layer0] * s_u
                } else {
                    (s.class_tau_at(0, z) - self.ts[0]).abs() * inv_mu
                };
                (s_u, if horizontal { layer0 } else { atm.layer_of(z) }, tau)
            } else {
                let c = if ncls == 1 {
                    0
                } else {
                    let mut x = rng.random::<f64>() * p_any;
                    (0..ncls)
                        .find(|&c| {
                            x -= self.cls_p[c];
                            x < 0.0 && self.cls_p[c] > 0.0
                        })
                        .unwrap_or_else(|| {
                            (0..ncls).rev().find(|&c| self.cls_p[c] > 0.0).unwrap_or(0)
                        })
                };
                // −ln(1 − uP): u·P < 1, and the absolute error of τ* (what places the
                // collision) is a few ulps of 1 however small uP is; ln_1p would cost 2× more.
                let tau_star = -(1.0 - rng.random::<f64>() * self.cls_p[c]).ln();
                if horizontal {
                    (tau_star / s.classes[c].sigma[layer0], layer0, tau_star)
                } else {
                    let t0 = self.ts[s.classes[c].channel];
                    let (z, l) = s.altitude_at_tau(c, t0, mu, tau_star, at_layer);
                    (((z - pos.z).abs() * inv_mu).min(s_end), l, tau_star)
                }
            };
            let p_unif = |s_c: f64| match window {
                Some((a, b)) if s_c >= a && s_c <= b => 1.0 / (b - a),
                _ => 0.0,
            };
            let beta = if window.is_some() { s.stratify } else { 0.0 };
            let in_layers = s.has_layers && {
                let z = pos.z + mu * s_coll;
                z >= s.bottom_m && z <= s.top_m
            };
            pos += dir * s_coll;
            path += s_coll;
            order += 1;
            at_layer = layer;
            self.stats.collisions += 1;

            if ncls == 1 {
                // One class: the collision is drawn from channel 0's own density, so every
                // channel's weight loses its absorption, e^{−τ_a}, times the collision factor
                // P/branch (and the range-stratification ratio), and where a channel scatters a
                // little differently, (σ_s,k/σ_s,0) e^{−(τ_s,k − τ_s,0)} (ALIS).
                let mut collide_factor = p_collide / branch;
                if window.is_some() {
                    // Physical density of the truncated exponential at s, and the mixture density.
                    let sigma = if in_layers {
                        s.classes[0].sigma[layer]
                    } else {
                        0.0
                    };
                    let p_phys = sigma * (-tau_star).exp() / p_collide;
                    let g = (1.0 - beta) * p_phys + beta * p_unif(s_coll);
                    if !(p_phys > 0.0) || !(g > 0.0) {
                        // A range-stratified collision in air that cannot scatter has zero weight.
                        self.stats.zero_weight += 1;
                        return;
                    }
                    collide_factor *= p_phys / g;
                }
                let i = layer * nch;
                // Channel 0's scattering optical depth of the flight, which the others' is
                // compared with (grey scattering: all equal, not needed).
                let dts_ref = if atm.grey_scattering {
                    0.0
                } else if horizontal {
                    s.classes[0].sigma[layer] * s_coll
                } else {
                    (s.class_tau_at(0, pos.z) - self.ts[0]).abs() * inv_mu
                };
                let known = in_layers.then_some(layer);
                for k in 0..nch {
                    let (ts_new, ta_new, dts, dta) =
                        self.channel_step(k, pos.z, known, inv_mu, horizontal, s_coll, i + k);
                    let mut f = collide_factor;
                    if dta > 0.0 {
                        f *= exp_neg(dta);
                    }
                    if !atm.grey_scattering {
                        f *= atm.sigma_s_per_m[i + k] / atm.sigma_s_per_m[i]
                            * (-(dts - dts_ref)).exp();
                    }
                    self.w[k] *= f;
                    self.ts[k] = ts_new;
                    self.ta[k] = ta_new;
                }
            } else if !self.mixture_weights(
                pos,
                inv_mu,
                horizontal,
                s_coll,
                layer,
                in_layers,
                p_any,
                branch * (1.0 - beta),
                branch * beta * p_unif(s_coll),
            ) {
                self.stats.zero_weight += 1;
                return;
            }

            // Whether the scattering here will use DDIS (decided now: the cone estimate's MIS
            // weights need it). The direction to the receiver only where DDIS can apply (not in
            // Rayleigh air). Only where a local estimate could still matter (in some class):
            // through more than DDIS_MAX_TAU to the receiver it is below e⁻³⁰ of its
            // unattenuated size, and DDIS factors multiplied over the hundreds of scatterings
            // deep in a thick cloud would only widen the weights' spread.
            let ddis_layer = s.ddis_epsilon > 0.0 && s.forward_peaked[layer];
            let to_rx = s.receiver - pos;
            let d_here = to_rx.length();
            carried = Some((to_rx, d_here));
            // Seen from the receiver within the DDIS cone: −(rx − x)·axis ≥ cos α · d.
            let (omega_rx, d_rx) = if ddis_layer && -to_rx.dot(s.axis) >= s.ddis_cos[layer] * d_here
            {
                (to_rx * (1.0 / d_here), d_here)
            } else {
                (DVec3::ZERO, 0.0)
            };
            let ddis = d_rx > 0.0
                && s.classes[..ncls].iter().any(|c| {
                    let k = c.channel;
                    s.tau_to_receiver(pos.z, omega_rx.z, d_rx, layer, k, self.ts[k] + self.ta[k])
                        < super::DDIS_MAX_TAU
                });
            let here = Prev {
                pos,
                dir_in: dir,
                path,
                eps: if ddis { s.ddis_epsilon } else { 0.0 },
                layer,
                cone_rate: if s.cone { s.cone_rate(pos) } else { 0.0 },
            };

            // Local estimate toward the receiver, every field of view; with the cone estimate,
            // weighted against the cone estimate from the previous collision, which is made
            // here for the next order.
            self.score_collision(
                pos,
                (to_rx, d_here),
                dir,
                path,
                order,
                layer,
                if s.cone { prev.as_ref() } else { None },
                if crossing {
                    s.crossing_from
                } else {
                    self.shape.n_fov
                },
            );
            if s.cone {
                self.score_cone(&here, order, rng);
            }

            // The phase function toward the receiver for the direction the photon arrives with,
            // P(Θ_rx): where DDIS applies, the chance that the scattering here sends it into the
            // fields of view is in proportion to it. Russian roulette weighs the photon by it
            // (a photon heading for the receiver is worth P(Θ_rx)/ROULETTE_ALIGNMENT others),
            // and alignment splitting splits by it.
            let mu_rx = dir.dot(omega_rx);
            // A photon travelling away from the receiver (μ ≤ 0) has P(Θ_rx) at most the
            // backward hemisphere's largest value; where that can neither raise its roulette
            // importance above 1 nor split it, the value is not needed (the same outcome; a
            // bound too low would change only which photons are spared or split, unbiased
            // either way).
            // Only in layers without a backward peak (`ALIGNMENT_BACKWARD_MAX`).
            let needed = ddis
                && (s.roulette_align > 0.0 || s.align_split > 0.0)
                && s.backward_max[layer] <= ALIGNMENT_BACKWARD_MAX
                && (mu_rx > 0.0 || {
                    let bound = s.backward_max[layer];
                    (s.roulette_align > 0.0 && bound > s.roulette_align)
                        || (s.align_split > 0.0 && self.w_max() * bound > 2.0 * s.align_split)
                });
            let p_align = if needed {
                s.mean_phase(layer, mu_rx).min(ALIGNMENT_MAX)
            } else {
                0.0
            };
            let importance = if s.roulette_align > 0.0 {
                (p_align / s.roulette_align).max(1.0)
            } else {
                1.0
            };
            if !self.roulette(importance, rng) {
                return;
            }

            // Scatter: a scatterer by its share of the scattering, Θ from its phase function, a
            // uniform azimuth; with several classes, first a class among those that scatter
            // here, uniformly, and every channel then weighted by P_k(Θ)/P̄(Θ), P̄ the classes'
            // mean phase function (the density actually sampled). Near the receiver's line of
            // sight and in forward-peaked media, detector-directed importance sampling (DDIS;
            // Buras & Mayer 2011, JQSRT 112, 434) draws the new direction, with probability ε,
            // from the same phase function centred on the direction to the receiver instead;
            // every channel is then weighted by P_k(Θ)/[(1 − ε) P̄(Θ) + ε P̄(Θ_rx)] (balance
            // heuristic), which is unbiased and caps the local-estimate spikes of the forward
            // peak. A collision can only land in a layer with scatterers; rounding at a layer
            // edge must not make it pick from none.
            if atm.components[layer].is_empty() {
                self.stats.zero_weight += 1;
                return;
            }
            let n_here = (0..ncls)
                .filter(|&c| s.classes[c].sigma[layer] > 0.0)
                .count();
            if n_here == 0 {
                self.stats.zero_weight += 1;
                return;
            }
            let mean_phase = |mu: f64| s.mean_phase(layer, mu);
            // Alignment splitting: the photon's direction makes the receiver's direction
            // likely for the next one in proportion to P(Θ_rx), and a photon that turns into
            // the forward peak toward the receiver with a weight near 1 is the rare event
            // behind what is left of the local estimate's spikes (validation/ms_efficiency).
            // Such a photon is split *before* it scatters, so that the copies draw their
            // directions independently; after the scattering they would share one.
            let n_split = if ddis && s.align_split > 0.0 {
                let importance = self.w_max() * p_align / s.align_split;
                self.copies(importance, 2.0, super::ALIGNMENT_MAX_COPIES)
            } else {
                1
            };
            if n_split > 1 {
                let f = 1.0 / n_split as f64;
                self.w[..nch].iter_mut().for_each(|w| *w *= f);
                self.pre[..nch].copy_from_slice(&self.w[..nch]);
                self.stats.splits += (n_split - 1) as u64;
                if s.analyser.is_some() {
                    self.e1_pre = self.e1;
                    self.pol_pre.copy_from_slice(&self.pol);
                }
            }
            // DDIS crossing: one more direction drawn about the receiver's, as DDIS draws it,
            // and the crossing estimate along it, combined with the walk's own crossing estimate
            // on its next flight by the balance heuristic over their direction densities.
            // Each copy of alignment splitting makes its own, with its own weight.
            let ddis_crossing =
                ddis && s.ddis_crossing && ncls == 1 && s.crossing_from < self.shape.n_fov;
            self.cross_mis = 1.0;
            for j in 0..n_split {
                if j > 0 {
                    self.w[..nch].copy_from_slice(&self.pre[..nch]);
                    if s.analyser.is_some() {
                        self.e1 = self.e1_pre;
                        self.pol.copy_from_slice(&self.pol_pre);
                    }
                }
                let virtual_done = ddis_crossing
                    && self.score_ddis_crossing(pos, dir, omega_rx, path, order, layer, rng);
                let cls = if ncls == 1 {
                    0
                } else {
                    let pick = ((rng.random::<f64>() * n_here as f64) as usize).min(n_here - 1);
                    (0..ncls)
                        .filter(|&c| s.classes[c].sigma[layer] > 0.0)
                        .nth(pick)
                        .unwrap_or(0)
                };
                let towards_rx = ddis && rng.random::<f64>() < s.ddis_epsilon;
                let rep = s.classes[cls].channel;
                let c = pick_component(
                    &atm.components[layer],
                    rep,
                    s.classes[cls].sigma[layer],
                    rng,
                );
                let (mu_sampled, p_sampled) = atm.phases
                    [atm.components[layer][c].phase[rep] as usize]
                    .sample_with_value(rng.random());
                let centre = if towards_rx { omega_rx } else { dir };
                let new_dir = rotate(centre, mu_sampled, unit_azimuth(rng));
                if ddis {
                    let mu_s = dir.dot(new_dir);
                    // One scatterer in one class: the density sampled is the mean phase function,
                    // and its value at the sampled angle came with the sample.
                    let sampled_is_mean = ncls == 1 && atm.components[layer].len() == 1;
                    let (p0, p_rx) = match (sampled_is_mean, towards_rx) {
                        (true, false) => (p_sampled, mean_phase(omega_rx.dot(new_dir))),
                        (true, true) => (mean_phase(mu_s), p_sampled),
                        _ => (mean_phase(mu_s), mean_phase(omega_rx.dot(new_dir))),
                    };
                    let q = (1.0 - s.ddis_epsilon) * p0 + s.ddis_epsilon * p_rx;
                    for k in 0..nch {
                        let pk = if atm.grey_scattering {
                            p0
                        } else {
                            s.mixture_phase(layer, k, mu_s)
                        };
                        self.w[k] *= pk / q;
                    }
                    // Against the DDIS crossing made here, whose direction density is P(Θ_rx).
                    self.cross_mis = if virtual_done { q / (q + p_rx) } else { 1.0 };
                } else if !atm.grey_scattering {
                    let p_mean = mean_phase(mu_sampled);
                    for k in 0..nch {
                        self.w[k] *= s.mixture_phase(layer, k, mu_sampled) / p_mean;
                    }
                }
                if s.analyser.is_some() {
                    self.polarise(layer, dir, new_dir);
                }
                if j + 1 < n_split {
                    self.push_copy(pos, new_dir, path, order, here);
                } else {
                    dir = new_dir;
                }
            }
            prev = Some(here);
            self.split_heavy(pos, dir, path, order, here);
        }
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
        });
    }

    /// Several scattering classes: the weights of a collision at `pos` (in `layer`, reached
    /// after `s_coll` along a flight with slant factor `inv_mu` = 1/|μ|), w_k ← w_k f_k/g, where
    /// f_k = σ_s,k e^{−τ_s,k − τ_a,k} is channel k's own collision density and g the density
    /// the collision was drawn from: `a_phys` Σ_c σ_c e^{−τ_c}/ΣP_c + `a_unif` (the branch and
    /// range-stratification shares; `p_any` = ΣP_c). Both are scaled by e^{τ_min}, τ_min the
    /// least class optical depth among the classes scattering here, so that neither underflows
    /// in optically thick channels. No class scattering here: false (zero weight).
    #[allow(clippy::too_many_arguments)]
    fn mixture_weights(
        &mut self,
        pos: DVec3,
        inv_mu: f64,
        horizontal: bool,
        s_coll: f64,
        layer: usize,
        in_layers: bool,
        p_any: f64,
        a_phys: f64,
        a_unif: f64,
    ) -> bool {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let mut tau_min = f64::INFINITY;
        for (c, cls) in s.classes.iter().enumerate() {
            let tau = if horizontal {
                cls.sigma[layer] * s_coll
            } else {
                (s.class_tau_at(c, pos.z) - self.ts[cls.channel]).abs() * inv_mu
            };
            self.cls_tau[c] = tau;
            if in_layers && cls.sigma[layer] > 0.0 {
                tau_min = tau_min.min(tau);
            }
        }
        if tau_min == f64::INFINITY {
            return false;
        }
        let mut dens = 0.0;
        for (c, cls) in s.classes.iter().enumerate() {
            if cls.sigma[layer] > 0.0 {
                dens += cls.sigma[layer] * (-(self.cls_tau[c] - tau_min)).exp();
            }
        }
        let g = a_phys * dens / p_any
            + if a_unif > 0.0 {
                a_unif * tau_min.exp()
            } else {
                0.0
            };
        if !(g > 0.0 && g.is_finite()) {
            return false;
        }
        let known = in_layers.then_some(layer);
        for k in 0..nch {
            let i = layer * nch + k;
            let (ts_new, ta_new, dts, dta) =
                self.channel_step(k, pos.z, known, inv_mu, horizontal, s_coll, i);
            let sigma_k = atm.sigma_s_per_m[i];
            // σ_k = 0: this channel cannot scatter here (and e^{τ_min − τ_k} may be huge).
            self.w[k] *= if sigma_k > 0.0 && in_layers {
                sigma_k * (-(dts - tau_min) - dta).exp() / g
            } else {
                0.0
            };
            self.ts[k] = ts_new;
            self.ta[k] = ta_new;
        }
        true
    }

    /// Channel k over a flight of length `s_coll` (slant factor `inv_mu` = 1/|μ|) ending at
    /// altitude z, in layer `layer` if known (index `i` of its layer and channel): the
    /// cumulative scattering and absorption optical depths there, and the flight's scattering
    /// and absorption optical depths.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn channel_step(
        &self,
        k: usize,
        z: f64,
        layer: Option<usize>,
        inv_mu: f64,
        horizontal: bool,
        s_coll: f64,
        i: usize,
    ) -> (f64, f64, f64, f64) {
        let atm = self.s.atm;
        let (ts_new, ta_new) = match layer {
            Some(l) => atm.cumulative_tau_in(l, z, k),
            None => atm.cumulative_tau(z, k),
        };
        let (dts, dta) = if horizontal {
            (atm.sigma_s_per_m[i] * s_coll, atm.sigma_a_per_m[i] * s_coll)
        } else {
            (
                (ts_new - self.ts[k]).abs() * inv_mu,
                (ta_new - self.ta[k]).abs() * inv_mu,
            )
        };
        (ts_new, ta_new, dts, dta)
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

    /// Local estimate from a collision at `x` in `layer` of a photon travelling along `dir`;
    /// `(v, d)`: rx − x and its length. Annuli from `skip_from` on are left out (the crossing
    /// estimate of the flight that ends here scored them).
    #[allow(clippy::too_many_arguments)]
    fn score_collision(
        &mut self,
        x: DVec3,
        (v, d): (DVec3, f64),
        dir: DVec3,
        path: f64,
        order: u32,
        layer: usize,
        mis: Option<&Prev>,
        skip_from: usize,
    ) {
        let s = self.s;
        // Outside the widest field of view: (x − rx)·axis < cos α_max · d.
        let along = -v.dot(s.axis);
        if along <= 0.0 || along < s.fov_cos_widest * d {
            return;
        }
        let d2 = d * d;
        let omega = v * (1.0 / d);
        let cos_axis = along / d;
        let Some(annulus) = self.annulus(cos_axis).filter(|a| *a < skip_from) else {
            return;
        };
        let Some(gate) = self.gate(path + d) else {
            return;
        };
        self.stats.local_estimates += 1;
        let mu_s = dir.dot(omega);
        // Close to the receiver, the energy the aperture collects instead of the point value
        // (`crate::aperture`): the phase function's mean over the band it spans, and its solid
        // angle.
        let band = (d2 < s.aperture.near_d2[layer])
            .then(|| aperture::band(dir, omega, s.aperture.half_angle(d)));
        // Grey scattering: one phase function for every channel (polarised: a matrix, below).
        let grey = s.atm.grey_scattering;
        let p_ref = if grey && s.analyser.is_none() {
            s.receiver_phase(layer, 0, mu_s, band)
        } else {
            1.0
        };
        let mut geometric = match band {
            None => p_ref * (0.25 / PI) * cos_axis / d2,
            Some(_) => p_ref * (0.25 / PI) * cos_axis * s.aperture.solid_angle_per_area(d),
        };
        // Against the cone estimate from the previous collision (balance heuristic).
        if let Some(p) = mis {
            let p_cone = s.cone_density(p, x, annulus);
            if p_cone > 0.0 {
                let p_walk = s.walk_density(p, x, layer);
                geometric *= p_walk / (p_walk + p_cone);
            }
        }
        let base = self.shape.base(gate, s.order_bin(order), annulus);
        let nch = self.nch();
        if s.analyser.is_some() {
            // The scattering matrix instead of the phase function.
            for k in 0..nch {
                let tau = s.tau_to_receiver(x.z, omega.z, d, layer, k, self.ts[k] + self.ta[k]);
                self.le[k] = self.w[k] * geometric * (-tau).exp();
                if band.is_some() {
                    self.le[k] *= s.band_over_point(layer, k, mu_s, band);
                }
            }
            self.score_polarised(layer, dir, omega, base);
            return;
        }
        for k in 0..nch {
            if self.w[k] == 0.0 {
                continue;
            }
            let tau = s.tau_to_receiver(x.z, omega.z, d, layer, k, self.ts[k] + self.ta[k]);
            let mut e = self.w[k] * geometric * (-tau).exp();
            if !grey {
                e *= s.receiver_phase(layer, k, mu_s, band);
            }
            self.bins[base + k] += e;
        }
    }

    /// Crossing estimate (`docs/transport.md` step 6b): the local estimate of the collision
    /// that ends the flight from `pos` along `dir` (slant factor `inv_mu`, useful length
    /// `s_end`, after a path `path`; the collision's order `order`), in the annuli the
    /// crossing estimate serves, as its expected value over where along the flight the
    /// collision falls inside them. The walk's collision density along the flight is
    /// w σ_s e^{−τ(s)} whatever the forced-collision and surface branches made of it; over the
    /// parts [a, b] of the flight inside the annuli its mass is P = Σ e^{−τ(a)} − e^{−τ(b)}
    /// (class 0), so one point y drawn from the exponential truncated to them, scored with
    /// weight w_k P e^{−τ_a,k} (and ALIS's scattering ratio), has the walk's local estimate
    /// there as its expectation. Every flight that crosses a field of view thus scores, not
    /// only the fraction P of them that collide inside it; the walk's own collision then leaves
    /// these annuli out.
    #[allow(clippy::too_many_arguments)]
    // Out of line, as are the DDIS crossing and the cone estimate: `follow` stays small enough
    // for its hot helpers to be inlined (3 % fewer instructions on the plain walk, callgrind).
    #[inline(never)]
    fn score_crossing(
        &mut self,
        pos: DVec3,
        dir: DVec3,
        inv_mu: f64,
        path: f64,
        order: u32,
        s_end: f64,
        scale: f64,
        at_layer: usize,
        rng: &mut Rng,
    ) {
        let s = self.s;
        let atm = s.atm;
        let mu = dir.z;
        let spans = s.crossing_spans(pos, dir, s_end);
        let t0 = self.ts[s.classes[0].channel];
        let tau_at = |sv: f64| (s.class_tau_at(0, pos.z + mu * sv) - t0).abs() * inv_mu;
        // Per span: τ at its start, 1 − e^{−Δτ} across it, and its mass e^{−τ_a}(1 − e^{−Δτ}).
        let mut parts = [(0.0, 0.0, 0.0); 2];
        let mut total = 0.0;
        for (part, (a, b)) in parts.iter_mut().zip(spans) {
            if b > a {
                let ta = tau_at(a);
                let p_span = one_minus_exp_neg((tau_at(b) - ta).max(0.0));
                let mass = (-ta).exp() * p_span;
                *part = (ta, p_span, mass);
                total += mass;
            }
        }
        if !(total > 0.0) {
            // Nothing scatters inside: the walk's collision cannot land there either.
            return;
        }
        let i = usize::from(parts[0].2 < rng.random::<f64>() * total);
        let (ta, p_span, _) = parts[i];
        let (a, b) = spans[i];
        let tau_star = ta - (1.0 - rng.random::<f64>() * p_span).ln();
        let (z, layer) = s.altitude_at_tau(0, t0, mu, tau_star, at_layer);
        let s_y = ((z - pos.z).abs() * inv_mu).clamp(a, b);
        let y = pos + dir * s_y;
        // The receiver as seen from y.
        let v = s.receiver - y;
        let d = v.length();
        let along = -v.dot(s.axis);
        if along <= 0.0 || along < s.fov_cos_widest * d {
            return;
        }
        let cos_axis = along / d;
        let Some(annulus) = self.annulus(cos_axis).filter(|a| *a >= s.crossing_from) else {
            return;
        };
        let Some(gate) = self.gate(path + s_y + d) else {
            return;
        };
        let omega = v * (1.0 / d);
        let mu_s = dir.dot(omega);
        let grey = atm.grey_scattering;
        let polarised = s.analyser.is_some();
        let nch = self.nch();
        let i0 = layer * nch;
        // Close to the receiver, the aperture's band and solid angle (`crate::aperture`).
        let band = (d * d < s.aperture.near_d2[layer])
            .then(|| aperture::band(dir, omega, s.aperture.half_angle(d)));
        // The phase function per channel below, or (polarised) the scattering matrix.
        let p_ref = if grey && !polarised {
            s.receiver_phase(layer, 0, mu_s, band)
        } else {
            1.0
        };
        let geometric = match band {
            None => scale * total * p_ref * (0.25 / PI) * cos_axis / (d * d),
            Some(_) => {
                scale * total * p_ref * (0.25 / PI) * cos_axis * s.aperture.solid_angle_per_area(d)
            }
        };
        let base = self.shape.base(gate, s.order_bin(order), annulus);
        for k in 0..nch {
            if self.w[k] == 0.0 {
                self.le[k] = 0.0;
                continue;
            }
            let (ts_y, ta_y) = atm.cumulative_tau_in(layer, y.z, k);
            let mut f = exp_neg((ta_y - self.ta[k]).abs() * inv_mu);
            if !grey {
                let dts = (ts_y - self.ts[k]).abs() * inv_mu;
                let ratio = atm.sigma_s_per_m[i0 + k] / atm.sigma_s_per_m[i0];
                f *= if polarised {
                    ratio * (-(dts - tau_star)).exp()
                } else {
                    ratio * (-(dts - tau_star)).exp() * s.receiver_phase(layer, k, mu_s, band)
                };
            }
            let tau = s.tau_to_receiver(y.z, omega.z, d, layer, k, ts_y + ta_y);
            let e = self.w[k] * f * geometric * (-tau).exp();
            if polarised {
                self.le[k] = e;
                if band.is_some() {
                    self.le[k] *= s.band_over_point(layer, k, mu_s, band);
                }
            } else {
                self.bins[base + k] += e;
            }
        }
        if polarised {
            self.score_polarised(layer, dir, omega, base);
        }
    }

    /// DDIS crossing (`docs/transport.md` step 6c): at a collision at `pos` (photon arriving
    /// along `dir`, receiver direction `omega_rx`, after `path` and `order` scatterings, in
    /// `layer`), a direction ω drawn from the phase function centred on the receiver's
    /// direction, density P(ω_rx·ω) per 4π, and the crossing estimate of the flight along it,
    /// weighted w_k P_k(Θ)/(q + P(ω_rx·ω)) with q the walk's own direction density (DDIS's
    /// mixture): the balance heuristic, whose partner is the walk's crossing estimate on its
    /// next flight, weighted q/(q + P(ω_rx·ω')) at its direction ω' ([`Tracer::cross_mis`]).
    /// The walk turns toward the receiver at a fraction ε of its DDIS scatterings; this estimate
    /// does at every one, without changing the walk. False if the flight would end at once.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn score_ddis_crossing(
        &mut self,
        pos: DVec3,
        dir: DVec3,
        omega_rx: DVec3,
        path: f64,
        order: u32,
        layer: usize,
        rng: &mut Rng,
    ) -> bool {
        let s = self.s;
        let atm = s.atm;
        let to_rx = s.receiver - pos;
        let d0 = to_rx.length();
        let budget = 2.0 * s.r_end_m - path;
        if d0 >= budget {
            return false;
        }
        let rep = s.classes[0].channel;
        let c = pick_component(&atm.components[layer], rep, s.classes[0].sigma[layer], rng);
        let (mu_sampled, p_sampled) = atm.phases[atm.components[layer][c].phase[rep] as usize]
            .sample_with_value(rng.random());
        let omega = rotate(omega_rx, mu_sampled, unit_azimuth(rng));
        if omega.z.abs() <= HORIZONTAL {
            return true;
        }
        let single = atm.components[layer].len() == 1;
        let mu_in = dir.dot(omega);
        let p_b = if single {
            p_sampled
        } else {
            s.mixture_phase(layer, 0, omega_rx.dot(omega))
        };
        let p0 = s.mixture_phase(layer, 0, mu_in);
        let q = (1.0 - s.ddis_epsilon) * p0 + s.ddis_epsilon * p_b;
        let norm = 1.0 / (q + p_b);
        for k in 0..self.nch() {
            let pk = if atm.grey_scattering {
                p0
            } else {
                s.mixture_phase(layer, k, mu_in)
            };
            self.virt[k] = self.w[k] * pk * norm;
        }
        let polarised = s.analyser.is_some();
        if polarised {
            // The virtual scattering acts on the Stokes vectors as the walk's would.
            let turn = Turn::new(dir, self.e1, omega);
            let grey = atm
                .grey_scattering
                .then(|| s.mixture_matrix(layer, 0, mu_in));
            for k in 0..self.nch() {
                let m = grey.unwrap_or_else(|| s.mixture_matrix(layer, k, mu_in));
                let (r, p) = stokes::reduce(turn.apply(self.pol[k], &m), m.f11);
                self.virt[k] *= r;
                self.pol_virt[k] = p;
            }
            self.e1_virt = turn.e1;
            std::mem::swap(&mut self.pol, &mut self.pol_virt);
            std::mem::swap(&mut self.e1, &mut self.e1_virt);
        }
        let (s_end, _) = s.useful_length(pos, omega, budget, (to_rx, d0));
        std::mem::swap(&mut self.w, &mut self.virt);
        self.score_crossing(
            pos,
            omega,
            1.0 / omega.z.abs(),
            path,
            order + 1,
            s_end,
            1.0,
            layer,
            rng,
        );
        std::mem::swap(&mut self.w, &mut self.virt);
        if polarised {
            std::mem::swap(&mut self.pol, &mut self.pol_virt);
            std::mem::swap(&mut self.e1, &mut self.e1_virt);
        }
        true
    }

    /// Cone estimate (a double local estimate, Marchuk et al. 1980, with the last point drawn
    /// inside the fields of view; `cone` module): the order-(n + 1) return of a photon that has
    /// just collided for the n-th time at x (`p`), as the expected value over one more flight
    /// and a scattering at a point y drawn in each FOV annulus: y = rx + r ω, ω uniform in the
    /// annulus's solid angle ΔΩ, r from the `cone::ConeRay` densities. Its value
    ///   f_k = w_k σ_s,k(y) P_x(Θ_xy)/4π e^{−τ_k(x→y)}/|x − y|² · P_y(Θ_y,rx)/4π cos θ e^{−τ_k(y→rx)}/r²
    /// is weighted against the walk's own collisions by the balance heuristic: f_k/(p_cone +
    /// p_walk) with p_cone = p_t/(ΔΩ r²). Every collision thus contributes to every field of
    /// view, however narrow, instead of only the rare ones that land inside it.
    #[inline(never)]
    fn score_cone(&mut self, p: &Prev, order: u32, rng: &mut Rng) {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let x = p.pos;
        // Through more than DDIS_MAX_TAU of vertical optical depth to the receiver's altitude
        // (in every channel) both legs together attenuate by more than e⁻³⁰.
        if !s.has_layers
            || (0..nch).all(|k| (self.ts[k] + self.ta[k] - s.tau_rx[k]).abs() > super::DDIS_MAX_TAU)
        {
            return;
        }
        // Russian roulette on the estimate far from the axis (its rate is in p_cone).
        if p.cone_rate < 1.0 && rng.random::<f64>() >= p.cone_rate {
            return;
        }
        let grey = atm.grey_scattering;
        let order_bin = s.order_bin(order + 1);
        // One of the cone's annuli, chosen uniformly (its probability is in p_cone).
        let n_cone = s.cone_annuli.len();
        let pick = ((rng.random::<f64>() * n_cone as f64) as usize).min(n_cone - 1);
        let a = s.cone_annuli[pick];
        let d_omega = s.annulus_sr[a];
        let inner = if a == 0 { 1.0 } else { s.fov_cos[a - 1] };
        let ct = s.fov_cos[a] + rng.random::<f64>() * (inner - s.fov_cos[a]);
        let st = (1.0 - ct * ct).max(0.0).sqrt();
        let (cp, sp) = unit_azimuth(rng);
        let omega = s.axis * ct + (s.axis_e1 * cp + s.axis_e2 * sp) * st;
        let Some(ray) = s.cone_ray(x, p.path, omega) else {
            return;
        };
        let t = ray.sample(rng.random(), rng.random());
        let r = ray.along + t;
        if !(r > 0.0) {
            return;
        }
        let y = s.receiver + omega * r;
        let l2 = ray.leg2(t);
        let l = l2.sqrt();
        let Some(gate) = self.gate(p.path + l + r) else {
            return;
        };
        if !(l > 0.0) {
            return;
        }
        let e_xy = (y - x) / l;
        let layer_y = atm.layer_of(y.z);
        if atm.components[layer_y].is_empty() {
            return;
        }
        let p_cone = p.cone_rate * ray.density(t) / (d_omega * r * r * n_cone as f64);
        let p_walk = s.walk_density(p, y, layer_y);
        // Close to the receiver, the last leg's aperture band and solid angle
        // (`crate::aperture`) instead of the point value.
        let band = (r * r < s.aperture.near_d2[layer_y])
            .then(|| aperture::band(e_xy, -omega, s.aperture.half_angle(r)));
        // f_k/(p_cone + p_walk), the geometric part of f_k: cos θ/(l² r²) and the 1/4π².
        let factor = match band {
            None => ct / (l2 * r * r) * (0.25 / PI) * (0.25 / PI) / (p_cone + p_walk),
            Some(_) => {
                ct * s.aperture.solid_angle_per_area(r) / l2 * (0.25 / PI) * (0.25 / PI)
                    / (p_cone + p_walk)
            }
        };
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        let mu_x = p.dir_in.dot(e_xy);
        let mu_y = -e_xy.dot(omega);
        let (px0, py0) = if grey {
            (
                s.mixture_phase(p.layer, 0, mu_x),
                s.receiver_phase(layer_y, 0, mu_y, band),
            )
        } else {
            (1.0, 1.0)
        };
        let base = self.shape.base(gate, order_bin, a);
        let horizontal = e_xy.z.abs() < HORIZONTAL;
        // Polarised: the two scatterings' geometry, and the analyser for the beam from y.
        let polarised = s.analyser.map(|an| {
            let t1 = Turn::new(p.dir_in, self.e1, e_xy);
            let t2 = Turn::new(e_xy, t1.e1, -omega);
            (t1, t2, an.toward(-omega, t2.e1))
        });
        for k in 0..nch {
            if self.w[k] == 0.0 {
                continue;
            }
            let iy = layer_y * nch + k;
            let sigma_y = atm.sigma_s_per_m[iy];
            if !(sigma_y > 0.0) {
                continue;
            }
            let (tsy, tay) = atm.cumulative_tau(y.z, k);
            let tau_xy = if horizontal {
                let ix = p.layer * nch + k;
                (atm.sigma_s_per_m[ix] + atm.sigma_a_per_m[ix]) * l
            } else {
                ((tsy + tay) - (self.ts[k] + self.ta[k])).abs() / e_xy.z.abs()
            };
            let tau_back = s.tau_to_receiver(y.z, -omega.z, r, layer_y, k, tsy + tay);
            if let Some((t1, t2, analysis)) = &polarised {
                // The phase functions' product becomes I after x times co (cross) after y.
                let mut e = self.w[k] * sigma_y * factor * (-(tau_xy + tau_back)).exp();
                if band.is_some() {
                    e *= s.band_over_point(layer_y, k, mu_y, band);
                }
                let s1 = t1.apply(self.pol[k], &s.mixture_matrix(p.layer, k, mu_x));
                let (i1, p1) = stokes::reduce(s1, 1.0);
                let s2 = t2.apply(p1, &s.mixture_matrix(layer_y, k, mu_y));
                let (co, cross) = analysis.split(s2);
                self.bins[base + k] += e * i1 * co;
                self.bins[base + nch + k] += e * i1 * cross;
                continue;
            }
            let (px, py) = if grey {
                (px0, py0)
            } else {
                (
                    s.mixture_phase(p.layer, k, mu_x),
                    s.receiver_phase(layer_y, k, mu_y, band),
                )
            };
            self.bins[base + k] +=
                self.w[k] * sigma_y * px * py * factor * (-(tau_xy + tau_back)).exp();
        }
    }

    /// Expected surface contribution of a flight that heads for the surface point `hit`; the
    /// uncollided weights are w_k e^{−tmp_k}.
    fn score_surface(&mut self, hit: DVec3, path: f64, order: u32) {
        let s = self.s;
        let Some(albedo) = &s.surface else { return };
        let v = s.receiver - hit;
        let d2 = v.length_squared();
        let d = d2.sqrt();
        let omega = v * (1.0 / d);
        if omega.z <= 0.0 {
            return;
        }
        let cos_axis = -omega.dot(s.axis);
        let Some(annulus) = self.annulus(cos_axis) else {
            return;
        };
        let Some(gate) = self.gate(path + d) else {
            return;
        };
        self.stats.local_estimates += 1;
        // Close by, the cosine-weighted solid angle of the aperture: a surface never returns
        // more than its albedo times what reaches it (`crate::aperture`).
        let geometric = if d2 < s.aperture.surface_near_d2 {
            omega.z / PI * cos_axis * s.aperture.lambertian_per_area(d)
        } else {
            omega.z / PI * cos_axis / d2
        };
        let base = self.shape.base(gate, s.order_bin(order), annulus);
        let layer = 0;
        let n = self.nch();
        for k in 0..n {
            let (ts, ta) = s.atm.cumulative_tau(hit.z, k);
            let tau_back = s.tau_to_receiver(hit.z, omega.z, d, layer, k, ts + ta);
            let e = self.w[k] * (-self.tmp[k]).exp() * albedo[k] * geometric * (-tau_back).exp();
            if s.analyser.is_some() {
                // A Lambertian surface reflects unpolarised light: half of it each way.
                self.bins[base + k] += 0.5 * e;
                self.bins[base + n + k] += 0.5 * e;
            } else {
                self.bins[base + k] += e;
            }
        }
    }

    /// Expected absorption in the atmosphere along a flight, per channel (flux tally only):
    /// w_k ∫ σ_a e^{−τ_ext(s)} ds, layer by layer.
    fn score_absorption(&mut self, z0: f64, mu: f64, s_end: f64) {
        let atm = self.s.atm;
        let nch = self.nch();
        for k in 0..nch {
            self.flux.absorbed[k] += self.w[k] * atm.absorbed_fraction(z0, mu, s_end, k);
        }
    }
}

/// e^{−x} for x ≥ 0. Below 1e-3 (the absorption of a flight through a nearly conservative
/// cloud, once per flight) by its Taylor series to x⁴, whose remainder x⁵/120 < 1e-17 is below
/// the last bit: the same number at a fraction of a library call's cost.
#[inline]
fn exp_neg(x: f64) -> f64 {
    if x < 1e-3 {
        1.0 - x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0))))
    } else {
        (-x).exp()
    }
}

/// 1 − e^{−τ} for τ ≥ 0, to a few ulps relative: expm1 only where the difference would cancel
/// (it costs about 3× exp in glibc, and this runs once per flight); exactly 1 beyond τ ≈ 37.
#[inline]
fn one_minus_exp_neg(tau: f64) -> f64 {
    if tau > 40.0 {
        1.0
    } else if tau > 0.5 {
        1.0 - (-tau).exp()
    } else {
        -(-tau).exp_m1()
    }
}

/// A scatterer of the layer, chosen with probability σ_c/σ in channel `k` (σ: the layer's total
/// in that channel, > 0).
#[inline]
fn pick_component(
    comps: &[crate::optics::Component],
    k: usize,
    sigma: f64,
    rng: &mut Rng,
) -> usize {
    if comps.len() == 1 {
        return 0;
    }
    // x starts ≥ 0 and only a scatterer with σ_c > 0 can take it below 0, so the one returned
    // scatters in this channel.
    let mut x = rng.random::<f64>() * sigma;
    for (j, comp) in comps.iter().enumerate() {
        x -= comp.sigma_s_per_m[k];
        if x < 0.0 {
            return j;
        }
    }
    // Rounding left x ≥ 0: the last scatterer that scatters in this channel.
    comps
        .iter()
        .rposition(|c| c.sigma_s_per_m[k] > 0.0)
        .unwrap_or(comps.len() - 1)
}

/// (cos φ, sin φ) of a uniform azimuth, by rejection from the unit disc and angle doubling
/// (von Neumann 1951): cheaper than a sine and a cosine.
#[inline]
fn unit_azimuth(rng: &mut Rng) -> (f64, f64) {
    loop {
        let x = 2.0 * rng.random::<f64>() - 1.0;
        let y = 2.0 * rng.random::<f64>() - 1.0;
        let r2 = x * x + y * y;
        if r2 <= 1.0 && r2 > 1e-12 {
            let inv = 1.0 / r2;
            return ((x * x - y * y) * inv, 2.0 * x * y * inv);
        }
    }
}

/// Rotate the unit vector `dir` by a scattering angle with cosine `mu` and azimuth (cos φ, sin φ).
#[inline]
pub(crate) fn rotate(dir: DVec3, mu: f64, (cp, sp): (f64, f64)) -> DVec3 {
    let (e1, e2) = dir.any_orthonormal_pair();
    let sin_t = (1.0 - mu * mu).max(0.0).sqrt();
    let v = dir * mu + (e1 * cp + e2 * sp) * sin_t;
    // |v| = 1 to a few ulps: one Newton step for 1/|v| (1/√a ≈ (3 − a)/2 near a = 1) keeps
    // the length from drifting over thousands of scatterings, without a square root and a
    // division per scattering.
    v * (1.5 - 0.5 * v.length_squared())
}

/// Cosine-weighted (Lambertian) direction into the upper hemisphere.
#[inline]
fn lambertian(u1: f64, u2: f64) -> DVec3 {
    let mu = u1.sqrt();
    let sin_t = (1.0 - u1).sqrt();
    let (sp, cp) = (2.0 * PI * u2).sin_cos();
    DVec3::new(sin_t * cp, sin_t * sp, mu.max(1e-300))
}

impl Setup<'_> {
    /// The useful part of a flight from `pos` along `dir` with `budget` = 2 r_end − path left,
    /// `(to_rx, d0)` = rx − pos and its length (d0 < budget), and where it ends: at the top of
    /// the atmosphere, its bottom or the surface, or on the ellipsoid with foci at the photon
    /// and the receiver beyond which no gate can receive it (path + s + |rx − x(s)| = 2 r_end).
    #[inline]
    pub(crate) fn useful_length(
        &self,
        pos: DVec3,
        dir: DVec3,
        budget: f64,
        (to_rx, d0): (DVec3, f64),
    ) -> (f64, End) {
        let mu = dir.z;
        let (s_bound, boundary) = if mu > HORIZONTAL {
            ((self.top_m - pos.z).max(0.0) / mu, End::Top)
        } else if mu < -HORIZONTAL {
            let end = if self.surface.is_some() {
                End::Surface
            } else {
                End::Bottom
            };
            ((self.bottom_m - pos.z).min(0.0) / mu, end)
        } else {
            (f64::INFINITY, End::Top)
        };
        // s = (b² − d0²)/(2(b − ω·(rx − x))), the denominator > 0 as b > d0: compared with the
        // boundary's distance before dividing, so that only flights the cut ends divide.
        let range_num = budget * budget - d0 * d0;
        let range_den = 2.0 * (budget - dir.dot(to_rx));
        if range_num < s_bound * range_den {
            (range_num / range_den, End::Cut)
        } else {
            (s_bound, boundary)
        }
    }

    /// A direction inside the beam's divergence around the axis.
    pub(crate) fn emit_direction(&self, u1: f64, u2: f64) -> DVec3 {
        if self.beam_half_angle_rad == 0.0 {
            return self.axis;
        }
        let theta = match self.beam_profile {
            BeamProfile::Uniform => {
                let cos_max = self.beam_half_angle_rad.cos();
                (1.0 - u1 * (1.0 - cos_max)).acos()
            }
            // Intensity ∝ exp(−2θ²/θ_e²) with θ_e the 1/e² half-angle: a 2-D Gaussian with
            // σ = θ_e/2 per axis, whose radial angle is Rayleigh distributed.
            BeamProfile::Gaussian => {
                0.5 * self.beam_half_angle_rad * (-2.0 * (1.0 - u1).ln()).sqrt()
            }
        };
        let (sp, cp) = (2.0 * PI * u2).sin_cos();
        let (st, ct) = theta.sin_cos();
        (self.axis * ct + (self.axis_e1 * cp + self.axis_e2 * sp) * st).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The short forms agree with the library's e^{−x} and expm1 to a couple of ulps over the
    /// whole range, across both switch points.
    #[test]
    fn fast_exponentials_match_the_library() {
        let mut x: f64 = 1e-12;
        while x < 50.0 {
            let e = (-x).exp();
            assert!((exp_neg(x) - e).abs() <= 2.0 * f64::EPSILON * e, "e^-{x}");
            let m = -(-x).exp_m1();
            assert!(
                (one_minus_exp_neg(x) - m).abs() <= 2.0 * f64::EPSILON * m,
                "1 - e^-{x}"
            );
            x *= 1.01;
        }
        assert_eq!(exp_neg(0.0), 1.0);
        assert_eq!(one_minus_exp_neg(0.0), 0.0);
    }

    /// A direction rotated a million times stays a unit vector (no drift from skipping the
    /// normalisation), and each rotation turns it by exactly the angle asked for.
    #[test]
    fn rotations_keep_unit_length_and_angle() {
        let mut d = DVec3::new(0.3, -0.4, 0.5).normalize();
        for i in 0..1_000_000u32 {
            let mu = ((i as f64) * 0.618_033_988_75).fract() * 2.0 - 1.0;
            let phi = (i as f64) * 2.399_963;
            let n = rotate(d, mu, (phi.cos(), phi.sin()));
            assert!((n.dot(d) - mu).abs() < 1e-12, "angle at step {i}");
            d = n;
        }
        assert!((d.length() - 1.0).abs() < 4.0 * f64::EPSILON);
    }

    /// Lambertian directions are cosine-weighted over the upper hemisphere, uniform in azimuth:
    /// over a 400 × 400 midpoint grid of (u1, u2), the mean direction is (0, 0, 2/3) and the
    /// second moments are ⟨μ²⟩ = 1/2, ⟨x²⟩ = ⟨y²⟩ = 1/4, ⟨xy⟩ = 0 (∫ μ^n 2μ dμ over [0, 1]).
    #[test]
    fn lambertian_directions_have_the_cosine_law_moments() {
        let n = 400;
        let (mut m1, mut xx, mut yy, mut xy, mut zz) = (DVec3::ZERO, 0.0, 0.0, 0.0, 0.0);
        for i in 0..n {
            for j in 0..n {
                let u1 = (i as f64 + 0.5) / n as f64;
                let u2 = (j as f64 + 0.5) / n as f64;
                let d = lambertian(u1, u2);
                assert!((d.length() - 1.0).abs() < 1e-12 && d.z > 0.0);
                m1 += d;
                xx += d.x * d.x;
                yy += d.y * d.y;
                xy += d.x * d.y;
                zz += d.z * d.z;
            }
        }
        let k = 1.0 / (n * n) as f64;
        let (m1, xx, yy, xy, zz) = (m1 * k, xx * k, yy * k, xy * k, zz * k);
        // Midpoint rule: errors O(1/n²) for the smooth moments, ~1e-5 at ⟨μ⟩ (√u1 at 0).
        assert!(m1.x.abs() < 1e-9 && m1.y.abs() < 1e-9, "{m1}");
        assert!((m1.z - 2.0 / 3.0).abs() < 1e-4, "{m1}");
        assert!((zz - 0.5).abs() < 1e-9, "⟨μ²⟩ = {zz}");
        assert!(
            (xx - 0.25).abs() < 1e-9 && (yy - 0.25).abs() < 1e-9,
            "{xx} {yy}"
        );
        assert!(xy.abs() < 1e-9, "⟨xy⟩ = {xy}");
    }
}
