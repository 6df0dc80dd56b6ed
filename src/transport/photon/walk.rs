//! The walk of one photon: flights, collisions and scatterings (`follow`).

use glam::DVec3;
use rand::RngExt;

use super::*;

mod collision;

/// The photon a walk follows, as its steps share it.
struct Walk {
    pos: DVec3,
    dir: DVec3,
    /// Path travelled since emission [m].
    path: f64,
    /// Scatterings so far.
    order: u32,
    /// The last scattering, in the atmosphere (`None` after emission or a surface reflection).
    prev: Option<Prev>,
    /// The geometry to the receiver, rx − pos and its length, carried over from the collision
    /// that ends the last flight (where the local estimate needed it).
    carried: Option<(DVec3, f64)>,
    /// The layer the photon is in (where the next flight starts): the first guess of the
    /// searches for its collision's layer.
    at_layer: usize,
}

/// One flight; the scattering classes' optical depths along it are in `Tracer::cls_tau` and
/// `cls_p`, the channels' extinction to its end (where needed) in `Tracer::tmp`.
struct Flight {
    mu: f64,
    horizontal: bool,
    /// Slant factor 1/|μ| (infinite when horizontal).
    inv_mu: f64,
    /// Useful length [m] and where it ends.
    s_end: f64,
    end: End,
    /// The crossing estimate was made along it.
    crossing: bool,
    /// A horizontal flight's layer (0 otherwise).
    layer0: usize,
    /// Class 0's probability of colliding on it, the sum over the classes, and whether any
    /// class scatters on it.
    p_collide: f64,
    p_any: f64,
    scatters: bool,
}

/// How a flight ends.
enum FlightEnd {
    /// In a collision, of the branch taken with this probability (the surface's takes the rest).
    Collide(f64),
    /// Reflected by the surface: a new flight starts.
    Reflected,
    /// The walk is over.
    Over,
}

/// A collision drawn on a flight.
struct Collision {
    /// Distance along the flight [m], the layer, and the class optical depth drawn.
    s_coll: f64,
    layer: usize,
    tau_star: f64,
    /// The gated window of range stratification (first flight only).
    window: Option<(f64, f64)>,
    /// The collision is inside the layers.
    in_layers: bool,
}

/// What the scattering at a collision needs of its local estimates.
struct Site {
    layer: usize,
    /// The scattering uses DDIS, toward `omega_rx` (zero where DDIS cannot apply).
    ddis: bool,
    omega_rx: DVec3,
    /// The collision as the next flight's estimates see it.
    here: Prev,
}

impl<'a, const ONE_CHANNEL: bool> Tracer<'a, ONE_CHANNEL> {
    /// Follow a photon (weights in `self.w`) from `pos` along `dir` after a path `path` and
    /// `order` scatterings, the last of them in the atmosphere at `prev` (`None` after emission
    /// or a surface reflection), to its end: flight after flight, each ended by the surface or
    /// a collision, which is scored, played at roulette, scattered and split (module docs).
    pub(super) fn follow(
        &mut self,
        pos: DVec3,
        dir: DVec3,
        path: f64,
        order: u32,
        prev: Option<Prev>,
        rng: &mut Rng,
    ) {
        let s = self.s;
        let at_layer = match prev {
            Some(p) if s.has_layers => s.layer_near(pos.z, p.layer),
            _ if s.has_layers => s.layer_of(pos.z),
            _ => 0,
        };
        self.set_altitude_in(at_layer, pos.z);
        let mut walk = Walk {
            pos,
            dir,
            path,
            order,
            prev,
            carried: None,
            at_layer,
        };
        loop {
            let Some(flight) = self.fly(&mut walk, rng) else {
                return;
            };
            let branch = match self.end_flight(&mut walk, &flight, rng) {
                FlightEnd::Collide(branch) => branch,
                FlightEnd::Reflected => continue,
                FlightEnd::Over => return,
            };
            let collision = self.sample_collision(&walk, &flight, rng);
            self.advance(&mut walk, &collision);
            self.jac_arrive(walk.pos.z, flight.mu, collision.layer, collision.s_coll);
            if !self.collision_weights(&walk, &flight, &collision, branch) {
                self.stats.zero_weight += 1;
                return;
            }
            let site = self.score_site(&mut walk, &flight, collision.layer, rng);
            let Some(p_align) = self.roulette_aligned(walk.dir, &site, rng) else {
                return;
            };
            if !self.scatter(&mut walk, &site, p_align, rng) {
                return;
            }
            walk.prev = Some(site.here);
            self.split_heavy(walk.pos, walk.dir, walk.path, walk.order, site.here);
        }
    }

    // The steps below are called once each from `follow`'s loop and inlined into it, so that
    // the loop compiles as the single function it was written as before (the same
    // instructions, callgrind); the state they share travels in `Walk`, `Flight` and `Site`.

    /// Range check and flight: None if even a straight return from here arrives after the last
    /// gate (the photon is cut); otherwise the useful part of the flight, where it ends and the
    /// scattering classes' optical depths along it, after the crossing estimate along it and
    /// the flux tally's absorption.
    #[inline(always)]
    fn fly(&mut self, walk: &mut Walk, rng: &mut Rng) -> Option<Flight> {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let ncls = self.ncls();
        let (pos, dir) = (walk.pos, walk.dir);
        // Range check: even a straight return from here arrives after the last gate.
        // The geometry to the receiver, carried over from the collision that ends the last
        // flight (where the local estimate needed it) or computed here.
        let (to_rx, d0) = match walk.carried.take() {
            Some(g) => g,
            None => {
                let v = s.receiver - pos;
                (v, v.length())
            }
        };
        let budget = 2.0 * s.r_end_m - walk.path;
        if d0 >= budget {
            self.stats.cut += 1;
            if s.flux_tally {
                for k in 0..nch {
                    self.flux.cut[k] += self.w[k];
                }
            }
            return None;
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
            walk.prev.is_some() && !horizontal && ncls == 1 && s.crossing_from < self.shape.n_fov;
        if crossing {
            let scale = self.cross_mis;
            self.score_crossing(
                pos,
                dir,
                inv_mu,
                walk.path,
                walk.order + 1,
                s_end,
                scale,
                walk.at_layer,
                rng,
            );
        }

        // Scattering optical depth of the flight for each class (class 0: channel 0's).
        let inside = pos.z >= s.bottom_m && pos.z <= s.top_m && s.has_layers;
        let layer0 = if horizontal && inside {
            s.layer_near(pos.z, walk.at_layer)
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
            let tmp = &mut self.tmp[..nch];
            if horizontal {
                if inside {
                    let row = layer0 * nch..(layer0 + 1) * nch;
                    let (ss, sa) = (&atm.sigma_s_per_m[row.clone()], &atm.sigma_a_per_m[row]);
                    for k in 0..nch {
                        tmp[k] = (ss[k] + sa[k]) * s_end;
                    }
                } else {
                    tmp.fill(0.0);
                }
            } else {
                // The end's layer: the bottom one at the surface, found once for all channels.
                let z_end = pos.z + mu * s_end;
                if s.has_layers {
                    let hint = match end {
                        End::Top => atm.n_layers() - 1,
                        End::Bottom | End::Surface => 0,
                        End::Cut => walk.at_layer,
                    };
                    let z = z_end.clamp(s.bottom_m, s.top_m);
                    let l = s.layer_near(z, hint);
                    atm.cumulative_taus_in(l, z, &mut self.ts_y[..nch], &mut self.ta_y[..nch]);
                } else {
                    self.ts_y[..nch].fill(0.0);
                    self.ta_y[..nch].fill(0.0);
                }
                let (ts, ta) = (&self.ts[..nch], &self.ta[..nch]);
                let (ts1, ta1) = (&self.ts_y[..nch], &self.ta_y[..nch]);
                for k in 0..nch {
                    tmp[k] = ((ts1[k] - ts[k]) + (ta1[k] - ta[k])).abs() * inv_mu;
                }
            }
        }
        if s.flux_tally {
            self.score_absorption(pos.z, mu, s_end);
        }
        Some(Flight {
            mu,
            horizontal,
            inv_mu,
            s_end,
            end,
            crossing,
            layer0,
            p_collide,
            p_any,
            scatters,
        })
    }

    /// The end of a flight: one that heads for the surface scores the surface's signal and
    /// either reflects there or collides before it; any other escapes (or is cut) with its
    /// uncollided part and collides in the rest.
    #[inline(always)]
    fn end_flight(&mut self, walk: &mut Walk, f: &Flight, rng: &mut Rng) -> FlightEnd {
        let s = self.s;
        let nch = self.nch();
        let ncls = self.ncls();
        if f.end == End::Surface {
            let hit = walk.pos + walk.dir * f.s_end;
            self.score_surface(hit, f.mu, walk.path + f.s_end, walk.order + 1);
            let q = if f.scatters {
                (f.p_any / ncls as f64).max(MIN_COLLISION_PROBABILITY)
            } else {
                0.0
            };
            let albedo = s.surface.as_deref().unwrap_or(&[]);
            if rng.random::<f64>() >= q {
                // Reach the surface and reflect (its signal was scored above).
                if s.flux_tally {
                    // The surface absorbs what arrives and does not reflect.
                    for k in 0..nch {
                        let arriving = self.w[k] * (-self.tmp[k]).exp();
                        self.flux.down[k] += arriving * (1.0 - albedo[k]);
                    }
                }
                // The weights by one kernel whether or not the flux is tallied, so that the
                // flux tally never changes the returns.
                lanes::reflect(&mut self.w[..nch], &self.tmp, albedo, 1.0 - q);
                walk.pos = hit;
                walk.pos.z = s.bottom_m;
                walk.at_layer = 0;
                walk.path += f.s_end;
                walk.order += 1;
                self.stats.surface_reflections += 1;
                walk.prev = None;
                self.cross_mis = 1.0;
                self.set_altitude_in(0, walk.pos.z);
                walk.dir = lambertian(rng.random(), rng.random());
                self.jac_arrive(walk.pos.z, f.mu, 0, f.s_end);
                self.jac_depart(walk.pos.z, walk.dir.z);
                // A Lambertian surface reflects unpolarised light.
                if s.analyser.is_some() {
                    self.e1 = walk.dir.any_orthonormal_vector();
                    self.pol.iter_mut().for_each(|p| *p = [0.0; 3]);
                }
                if !self.roulette(1.0, rng) {
                    return FlightEnd::Over;
                }
                return FlightEnd::Reflected;
            }
            // Collide before the surface; the surface absorbs its share in expectation.
            if s.flux_tally {
                for k in 0..nch {
                    self.flux.down[k] += self.w[k] * (-self.tmp[k]).exp() * (1.0 - albedo[k]);
                }
            }
            FlightEnd::Collide(q)
        } else {
            // Escape or cut: the uncollided part leaves; a collision is forced in the rest.
            if s.flux_tally {
                let out = match f.end {
                    End::Top => &mut self.flux.up,
                    End::Bottom => &mut self.flux.down,
                    _ => &mut self.flux.cut,
                };
                for k in 0..nch {
                    out[k] += self.w[k] * (-self.tmp[k]).exp();
                }
            }
            if !f.scatters {
                self.stats.escaped += 1;
                return FlightEnd::Over;
            }
            FlightEnd::Collide(1.0)
        }
    }

    /// The collision's local estimates: decides whether its scattering will use DDIS, then
    /// scores the local estimate toward the receiver and the cone estimate.
    #[inline(always)]
    fn score_site(&mut self, walk: &mut Walk, f: &Flight, layer: usize, rng: &mut Rng) -> Site {
        let s = self.s;
        let ncls = self.ncls();
        let (pos, dir, path, order) = (walk.pos, walk.dir, walk.path, walk.order);
        // Whether the scattering here will use DDIS (decided now: the cone estimate's MIS
        // weights need it). The direction to the receiver only where DDIS can apply (not in
        // Rayleigh air). Only where a local estimate could still matter (in some class):
        // through more than DDIS_MAX_TAU to the receiver it is below e⁻³⁰ of its
        // unattenuated size, and DDIS factors multiplied over the hundreds of scatterings
        // deep in a thick cloud would only widen the weights' spread.
        let ddis_layer = s.ddis_epsilon > 0.0 && s.forward_peaked[layer];
        let to_rx = s.receiver - pos;
        let d_here = to_rx.length();
        walk.carried = Some((to_rx, d_here));
        // Seen from the receiver within the DDIS cone: −(rx − x)·axis ≥ cos α · d.
        let (omega_rx, d_rx) = if ddis_layer && -to_rx.dot(s.axis) >= s.ddis_cos[layer] * d_here {
            (to_rx * (1.0 / d_here), d_here)
        } else {
            (DVec3::ZERO, 0.0)
        };
        let ddis = d_rx > 0.0
            && s.classes[..ncls].iter().any(|c| {
                let k = c.channel;
                s.tau_to_receiver(pos.z, omega_rx.z, d_rx, layer, k, self.ts[k] + self.ta[k])
                    < crate::transport::DDIS_MAX_TAU
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
            if s.cone { walk.prev.as_ref() } else { None },
            if f.crossing {
                s.crossing_from
            } else {
                self.shape.n_fov
            },
        );
        if s.cone {
            self.score_cone(&here, order, rng);
        }
        Site {
            layer,
            ddis,
            omega_rx,
            here,
        }
    }

    /// Russian roulette at the collision, on the weight times the photon's alignment
    /// importance. None if the photon dies; otherwise P(Θ_rx), which alignment splitting uses.
    #[inline(always)]
    fn roulette_aligned(&mut self, dir: DVec3, site: &Site, rng: &mut Rng) -> Option<f64> {
        let s = self.s;
        let layer = site.layer;
        // The phase function toward the receiver for the direction the photon arrives with,
        // P(Θ_rx): where DDIS applies, the chance that the scattering here sends it into the
        // fields of view is in proportion to it. Russian roulette weighs the photon by it
        // (a photon heading for the receiver is worth P(Θ_rx)/ROULETTE_ALIGNMENT others),
        // and alignment splitting splits by it.
        let mu_rx = dir.dot(site.omega_rx);
        // A photon travelling away from the receiver (μ ≤ 0) has P(Θ_rx) at most the
        // backward hemisphere's largest value; where that can neither raise its roulette
        // importance above 1 nor split it, the value is not needed (the same outcome; a
        // bound too low would change only which photons are spared or split, unbiased
        // either way).
        // Only in layers without a backward peak (`ALIGNMENT_BACKWARD_MAX`).
        let needed = site.ddis
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
            return None;
        }
        Some(p_align)
    }

    /// Scatter at the collision, after splitting the photon by its alignment `p_align`
    /// (P(Θ_rx)): every copy but the last stacked, the last continuing in `walk`. False: zero
    /// weight (nothing scatters here).
    #[inline(always)]
    fn scatter(&mut self, walk: &mut Walk, site: &Site, p_align: f64, rng: &mut Rng) -> bool {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let ncls = self.ncls();
        let (layer, ddis) = (site.layer, site.ddis);
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
            return false;
        }
        let n_here = (0..ncls)
            .filter(|&c| s.classes[c].sigma[layer] > 0.0)
            .count();
        if n_here == 0 {
            self.stats.zero_weight += 1;
            return false;
        }
        // Alignment splitting: the photon's direction makes the receiver's direction
        // likely for the next one in proportion to P(Θ_rx), and a photon that turns into
        // the forward peak toward the receiver with a weight near 1 is the rare event
        // behind what is left of the local estimate's spikes (validation/ms_efficiency).
        // Such a photon is split *before* it scatters, so that the copies draw their
        // directions independently; after the scattering they would share one.
        let n_split = if ddis && s.align_split > 0.0 {
            let importance = self.w_max() * p_align / s.align_split;
            self.copies(importance, 2.0, crate::transport::ALIGNMENT_MAX_COPIES)
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
            if s.jac.is_some() {
                self.jac_pre.copy_from(&self.jac);
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
                if s.jac.is_some() {
                    self.jac.copy_from(&self.jac_pre);
                }
            }
            let new_dir = self.scatter_once(walk, site, n_here, ddis_crossing, rng);
            self.jac_event(layer, walk.dir.dot(new_dir));
            self.jac_depart(walk.pos.z, new_dir.z);
            if j + 1 < n_split {
                self.push_copy(walk.pos, new_dir, walk.path, walk.order, site.here);
            } else {
                walk.dir = new_dir;
            }
        }
        true
    }

    /// One scattering of the photon arriving along `walk.dir` (and its DDIS crossing): the
    /// new direction, the weights and Stokes vectors updated.
    #[inline(always)]
    fn scatter_once(
        &mut self,
        walk: &Walk,
        site: &Site,
        n_here: usize,
        ddis_crossing: bool,
        rng: &mut Rng,
    ) -> DVec3 {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let ncls = self.ncls();
        let (pos, dir, path, order) = (walk.pos, walk.dir, walk.path, walk.order);
        let (layer, ddis, omega_rx) = (site.layer, site.ddis, site.omega_rx);
        let mean_phase = |mu: f64| s.mean_phase(layer, mu);
        let virtual_done =
            ddis_crossing && self.score_ddis_crossing(pos, dir, omega_rx, path, order, layer, rng);
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
        let (mu_sampled, p_sampled) = atm.phases[atm.components[layer][c].phase[rep] as usize]
            .sample_with_value(rng.random());
        let centre = if towards_rx { omega_rx } else { dir };
        let new_dir = rotate(centre, mu_sampled, unit_azimuth(rng));
        // With one class the mean phase function is channel 0's, the first of the channels'
        // phase functions (`mixture_phases`, the same arithmetic): not evaluated again.
        let grey = atm.grey_scattering;
        let mean_is_first = ncls == 1 && !grey;
        if ddis {
            let mu_s = dir.dot(new_dir);
            if !grey {
                s.mixture_phases(layer, mu_s, &mut self.phase[..nch]);
            }
            let mean_s = || {
                if mean_is_first {
                    self.phase[0]
                } else {
                    mean_phase(mu_s)
                }
            };
            // One scatterer in one class: the density sampled is the mean phase function,
            // and its value at the sampled angle came with the sample.
            let sampled_is_mean = ncls == 1 && atm.components[layer].len() == 1;
            let (p0, p_rx) = match (sampled_is_mean, towards_rx) {
                (true, false) => (p_sampled, mean_phase(omega_rx.dot(new_dir))),
                (true, true) => (mean_s(), p_sampled),
                _ => (mean_s(), mean_phase(omega_rx.dot(new_dir))),
            };
            let q = (1.0 - s.ddis_epsilon) * p0 + s.ddis_epsilon * p_rx;
            if grey {
                self.w[..nch].iter_mut().for_each(|w| *w *= p0 / q);
            } else {
                lanes::reweight(&mut self.w[..nch], &self.phase, q);
            }
            // Against the DDIS crossing made here, whose direction density is P(Θ_rx).
            self.cross_mis = if virtual_done { q / (q + p_rx) } else { 1.0 };
        } else if !grey {
            s.mixture_phases(layer, mu_sampled, &mut self.phase[..nch]);
            let p_mean = if mean_is_first {
                self.phase[0]
            } else {
                mean_phase(mu_sampled)
            };
            lanes::reweight(&mut self.w[..nch], &self.phase, p_mean);
        }
        if s.analyser.is_some() {
            self.polarise(layer, dir, new_dir);
        }
        new_dir
    }
}
