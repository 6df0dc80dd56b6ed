//! A collision on a flight: where it happens, and every channel's weight for it (one
//! scattering class by ALIS's ratios, several by the mixture of their densities).

use super::*;

impl<'a, const ONE_CHANNEL: bool> Tracer<'a, ONE_CHANNEL> {
    /// Where on the flight the photon collides, and in which layer.
    #[inline(always)]
    pub(super) fn sample_collision(&self, walk: &Walk, f: &Flight, rng: &mut Rng) -> Collision {
        let s = self.s;
        let ncls = self.ncls();
        let (pos, mu, horizontal, inv_mu, layer0) =
            (walk.pos, f.mu, f.horizontal, f.inv_mu, f.layer0);
        // Sample the collision: a class with probability P_c/ΣP (one class: always class 0),
        // then τ* from its exponential truncated to [0, τ_c). The collision density is then
        // Σ_c σ_c e^{−τ_c(s)}/ΣP_c: the mixture of the classes' truncated densities. On the
        // first flight, whose distances are ranges, the collision is instead drawn uniformly
        // in range over the gated window with probability β (range stratification), the two
        // densities combined by the balance heuristic: every gate then gets first
        // collisions, however thin its air compared with, say, a boundary layer below.
        let window = if walk.order == 0 && s.stratify > 0.0 {
            let (a, b) = (s.gate_start_m, s.r_end_m.min(f.s_end));
            if b > a { Some((a, b)) } else { None }
        } else {
            None
        };
        let uniform = window.is_some() && rng.random::<f64>() < s.stratify;
        let (s_coll, layer, tau_star) = if let (true, Some((a, b))) = (uniform, window) {
            let s_u = a + rng.random::<f64>() * (b - a);
            let z = pos.z + mu * s_u;
            if horizontal {
                (s_u, layer0, s.classes[0].sigma[layer0] * s_u)
            } else {
                // One search for the layer, which gives the optical depth too.
                let l = s.layer_of(z);
                (
                    s_u,
                    l,
                    (s.class_tau_in(0, l, z) - self.ts[0]).abs() * inv_mu,
                )
            }
        } else {
            let c = if ncls == 1 {
                0
            } else {
                let mut x = rng.random::<f64>() * f.p_any;
                (0..ncls)
                    .find(|&c| {
                        x -= self.cls_p[c];
                        x < 0.0 && self.cls_p[c] > 0.0
                    })
                    .unwrap_or_else(|| (0..ncls).rev().find(|&c| self.cls_p[c] > 0.0).unwrap_or(0))
            };
            // −ln(1 − uP): u·P < 1, and the absolute error of τ* (what places the
            // collision) is a few ulps of 1 however small uP is; ln_1p would cost 2× more.
            let tau_star = -(1.0 - rng.random::<f64>() * self.cls_p[c]).ln();
            if horizontal {
                (tau_star / s.classes[c].sigma[layer0], layer0, tau_star)
            } else {
                let t0 = self.ts[s.classes[c].channel];
                let (z, l) = s.altitude_at_tau(c, t0, mu, tau_star, walk.at_layer);
                (((z - pos.z).abs() * inv_mu).min(f.s_end), l, tau_star)
            }
        };
        let in_layers = s.has_layers && {
            let z = pos.z + mu * s_coll;
            z >= s.bottom_m && z <= s.top_m
        };
        Collision {
            s_coll,
            layer,
            tau_star,
            window,
            in_layers,
        }
    }

    /// Advance the photon to the collision.
    #[inline(always)]
    pub(super) fn advance(&mut self, walk: &mut Walk, c: &Collision) {
        walk.pos += walk.dir * c.s_coll;
        walk.path += c.s_coll;
        walk.order += 1;
        walk.at_layer = c.layer;
        self.stats.collisions += 1;
    }

    /// Every channel's weight for the collision drawn (`branch`: the probability of the
    /// collide branch), and the cumulative optical depths at it. False: zero weight.
    #[inline(always)]
    pub(super) fn collision_weights(
        &mut self,
        walk: &Walk,
        f: &Flight,
        c: &Collision,
        branch: f64,
    ) -> bool {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let ncls = self.ncls();
        let (pos, horizontal, inv_mu) = (walk.pos, f.horizontal, f.inv_mu);
        let (s_coll, layer, in_layers) = (c.s_coll, c.layer, c.in_layers);
        let window = c.window;
        let p_unif = |s_c: f64| match window {
            Some((a, b)) if s_c >= a && s_c <= b => 1.0 / (b - a),
            _ => 0.0,
        };
        let beta = if window.is_some() { s.stratify } else { 0.0 };
        if ncls == 1 {
            // One class: the collision is drawn from channel 0's own density, so every
            // channel's weight loses its absorption, e^{−τ_a}, times the collision factor
            // P/branch (and the range-stratification ratio), and where a channel scatters a
            // little differently, (σ_s,k/σ_s,0) e^{−(τ_s,k − τ_s,0)} (ALIS).
            let mut collide_factor = f.p_collide / branch;
            if window.is_some() {
                // Physical density of the truncated exponential at s, and the mixture density.
                let sigma = if in_layers {
                    s.classes[0].sigma[layer]
                } else {
                    0.0
                };
                let p_phys = sigma * (-c.tau_star).exp() / f.p_collide;
                let g = (1.0 - beta) * p_phys + beta * p_unif(s_coll);
                if !(p_phys > 0.0) || !(g > 0.0) {
                    // A range-stratified collision in air that cannot scatter has zero weight.
                    return false;
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
            } else if in_layers {
                (s.class_tau_in(0, layer, pos.z) - self.ts[0]).abs() * inv_mu
            } else {
                (s.class_tau_at(0, pos.z) - self.ts[0]).abs() * inv_mu
            };
            self.step_to(pos.z, in_layers.then_some(layer));
            let (ss, sa) = (
                &atm.sigma_s_per_m[i..i + nch],
                &atm.sigma_a_per_m[i..i + nch],
            );
            // The flight's scattering and absorption optical depths per channel, then every
            // channel's weight in one branch-free pass (`lanes`), absorption and ALIS's
            // scattering difference in one exponent.
            let (dts, dta) = (&mut self.tau[..nch], &mut self.tau2[..nch]);
            if horizontal {
                lanes::scale(dts, ss, s_coll);
                lanes::scale(dta, sa, s_coll);
            } else {
                lanes::step(dts, &self.ts_y, &self.ts, inv_mu);
                lanes::step(dta, &self.ta_y, &self.ta, inv_mu);
            }
            let w = &mut self.w[..nch];
            if atm.grey_scattering {
                lanes::collide_grey(w, dta, collide_factor);
            } else {
                lanes::collide(w, dts, dta, ss, collide_factor, dts_ref);
            }
            self.arrive();
            true
        } else {
            self.mixture_weights(
                pos,
                inv_mu,
                horizontal,
                s_coll,
                layer,
                in_layers,
                f.p_any,
                branch * (1.0 - beta),
                branch * beta * p_unif(s_coll),
            )
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
        self.step_to(pos.z, in_layers.then_some(layer));
        let i = layer * nch;
        let (ss, sa) = (
            &atm.sigma_s_per_m[i..i + nch],
            &atm.sigma_a_per_m[i..i + nch],
        );
        let (ts0, ta0) = (&self.ts[..nch], &self.ta[..nch]);
        let (ts1, ta1) = (&self.ts_y[..nch], &self.ta_y[..nch]);
        for k in 0..nch {
            let (dts, dta) = if horizontal {
                (ss[k] * s_coll, sa[k] * s_coll)
            } else {
                (
                    (ts1[k] - ts0[k]).abs() * inv_mu,
                    (ta1[k] - ta0[k]).abs() * inv_mu,
                )
            };
            let sigma_k = ss[k];
            // σ_k = 0: this channel cannot scatter here (and e^{τ_min − τ_k} may be huge).
            self.w[k] *= if sigma_k > 0.0 && in_layers {
                sigma_k * (-(dts - tau_min) - dta).exp() / g
            } else {
                0.0
            };
        }
        self.arrive();
        true
    }

    /// Every channel's cumulative optical depths at altitude z, in layer `layer` if known
    /// (otherwise found once for all), into `ts_y`, `ta_y`: where a flight ends.
    #[inline]
    pub(super) fn step_to(&mut self, z: f64, layer: Option<usize>) {
        let s = self.s;
        let nch = self.nch();
        let (ts, ta) = (&mut self.ts_y[..nch], &mut self.ta_y[..nch]);
        if !s.has_layers {
            ts.fill(0.0);
            ta.fill(0.0);
            return;
        }
        match layer {
            Some(l) => s.atm.cumulative_taus_in(l, z, ts, ta),
            None => {
                let z = z.clamp(s.bottom_m, s.top_m);
                s.atm.cumulative_taus_in(s.layer_of(z), z, ts, ta);
            }
        }
    }

    /// The photon has arrived where [`Self::step_to`] looked: its optical depths become the
    /// current ones.
    #[inline]
    pub(super) fn arrive(&mut self) {
        std::mem::swap(&mut self.ts, &mut self.ts_y);
        std::mem::swap(&mut self.ta, &mut self.ta_y);
    }
}
