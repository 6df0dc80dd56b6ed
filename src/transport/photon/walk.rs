//! The walk of one photon: flights, collisions and scatterings (`follow`).

use glam::DVec3;
use rand::RngExt;

use super::*;

impl<'a, const ONE_CHANNEL: bool> Tracer<'a, ONE_CHANNEL> {
    /// Follow a photon (weights in `self.w`) from `pos` along `dir` after a path `path` and
    /// `order` scatterings, the last of them in the atmosphere at `prev` (`None` after emission
    /// or a surface reflection), to its end.
    pub(super) fn follow(
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

    /// Several scattering classes: the weights of a collision at `pos` (in `layer`, reached
    /// after `s_coll` along a flight with slant factor `inv_mu` = 1/|μ|), w_k ← w_k f_k/g, where
    /// f_k = σ_s,k e^{−τ_s,k − τ_a,k} is channel k's own collision density and g the density
    /// the collision was drawn from: `a_phys` Σ_c σ_c e^{−τ_c}/ΣP_c + `a_unif` (the branch and
    /// range-stratification shares; `p_any` = ΣP_c). Both are scaled by e^{τ_min}, τ_min the
    /// least class optical depth among the classes scattering here, so that neither underflows
    /// in optically thick channels. No class scattering here: false (zero weight).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn mixture_weights(
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
    pub(super) fn channel_step(
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
}
