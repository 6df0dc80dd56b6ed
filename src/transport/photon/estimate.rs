//! Local estimates toward the receiver: at a collision, along a flight (crossing), along a
//! DDIS direction, and the cone estimate; polarised scoring.

use std::f64::consts::PI;

use glam::DVec3;
use rand::RngExt;

use super::*;

impl<'a, const ONE_CHANNEL: bool> Tracer<'a, ONE_CHANNEL> {
    /// Polarised local estimate: every channel's light arriving along `dir` (the photon's
    /// reference axis and Stokes vectors) scattered in `layer` toward `omega`, split by the
    /// analyser and scored into co (`base + k`) and cross (`base + n + k`, n channels), each
    /// times `self.le[k]`, the estimate's factor without the scattering matrix.
    pub(super) fn score_polarised(&mut self, layer: usize, dir: DVec3, omega: DVec3, base: usize) {
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

    /// Local estimate from a collision at `x` in `layer` of a photon travelling along `dir`;
    /// `(v, d)`: rx − x and its length. Annuli from `skip_from` on are left out (the crossing
    /// estimate of the flight that ends here scored them).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn score_collision(
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
        let jac = s.jac.is_some();
        // Every channel in one branch-free pass (`lanes`): a channel of zero weight scores 0.
        let (ts, ta) = (&self.ts[..nch], &self.ta[..nch]);
        s.taus_to_receiver(x.z, omega.z, d, layer, ts, ta, &mut self.tau[..nch]);
        let (w, tau, le) = (&self.w[..nch], &self.tau[..nch], &mut self.le[..nch]);
        if grey {
            lanes::estimate(le, w, tau, geometric);
        } else {
            s.receiver_phases(layer, mu_s, band, &mut self.phase[..nch]);
            lanes::estimate_phase(le, w, tau, &self.phase, geometric);
        }
        lanes::accumulate(&mut self.bins[base..base + nch], le);
        if jac {
            // The path's own end: the scattering toward the receiver and the leg to it.
            let mut v = Virtual::default();
            v.event(layer, mu_s);
            v.leg(x.z, s.receiver.z, omega.z, d, layer);
            self.jac_score(gate, order, annulus, &v);
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
    pub(super) fn score_crossing(
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
        let tau_at = |sv: f64| (s.class_tau_near(0, pos.z + mu * sv, at_layer) - t0).abs() * inv_mu;
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
        let jac = s.jac.is_some();
        if !polarised {
            // Every channel in one branch-free pass (`lanes`): the absorption along the flight
            // to y, ALIS's scattering ratio there, and the leg to the receiver in one exponent.
            let (ts_y, ta_y) = (&mut self.ts_y[..nch], &mut self.ta_y[..nch]);
            atm.cumulative_taus_in(layer, y.z, ts_y, ta_y);
            s.taus_to_receiver(y.z, omega.z, d, layer, ts_y, ta_y, &mut self.tau[..nch]);
            let (ts, ta) = (&self.ts[..nch], &self.ta[..nch]);
            let (w, tau, le) = (&self.w[..nch], &self.tau[..nch], &mut self.le[..nch]);
            if grey {
                lanes::crossing_grey(le, w, ta_y, ta, tau, inv_mu, geometric);
            } else {
                s.receiver_phases(layer, mu_s, band, &mut self.phase[..nch]);
                let ss = &atm.sigma_s_per_m[i0..i0 + nch];
                let phase = &self.phase[..nch];
                #[rustfmt::skip]
                lanes::crossing(le, w, ts_y, ta_y, ts, ta, tau, ss, phase, inv_mu, tau_star, geometric);
            }
            lanes::accumulate(&mut self.bins[base..base + nch], le);
        }
        if polarised {
            // The scattering matrix instead of the phase function: per channel.
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
                    f *= ratio * (-(dts - tau_star)).exp();
                }
                let tau = s.tau_to_receiver(y.z, omega.z, d, layer, k, ts_y + ta_y);
                self.le[k] = self.w[k] * f * geometric * (-tau).exp();
                if band.is_some() {
                    self.le[k] *= s.band_over_point(layer, k, mu_s, band);
                }
            }
            self.score_polarised(layer, dir, omega, base);
        } else if jac {
            // The flight's collision at y, its scattering toward the receiver and the leg to
            // it; after a DDIS crossing also the virtual scattering that started the flight.
            let mut v = Virtual::default();
            if let Some((z0, l0, mu0)) = self.jac_extra {
                v.point(z0, -1.0 / mu);
                v.event(l0, mu0);
            }
            v.point(y.z, 1.0 / mu);
            v.event(layer, mu_s);
            v.leg(y.z, s.receiver.z, omega.z, d, layer);
            self.jac_score(gate, order, annulus, &v);
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
    pub(super) fn score_ddis_crossing(
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
        let nch = self.nch();
        // Channel 0's phase function is the first of the channels' (the same arithmetic).
        let p0 = if atm.grey_scattering {
            let p0 = s.mixture_phase(layer, 0, mu_in);
            self.phase[..nch].fill(p0);
            p0
        } else {
            s.mixture_phases(layer, mu_in, &mut self.phase[..nch]);
            self.phase[0]
        };
        let q = (1.0 - s.ddis_epsilon) * p0 + s.ddis_epsilon * p_b;
        let norm = 1.0 / (q + p_b);
        for k in 0..nch {
            self.virt[k] = self.w[k] * self.phase[k] * norm;
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
        if s.jac.is_some() {
            self.jac_extra = Some((pos.z, layer, mu_in));
        }
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
        self.jac_extra = None;
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
    pub(super) fn score_cone(&mut self, p: &Prev, order: u32, rng: &mut Rng) {
        let s = self.s;
        let atm = s.atm;
        let nch = self.nch();
        let x = p.pos;
        // Through more than DDIS_MAX_TAU of vertical optical depth to the receiver's altitude
        // (in every channel) both legs together attenuate by more than e⁻³⁰.
        if !s.has_layers
            || (0..nch).all(|k| {
                (self.ts[k] + self.ta[k] - s.tau_rx[k]).abs() > crate::transport::DDIS_MAX_TAU
            })
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
        let layer_y = s.layer_near(y.z, p.layer);
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
        let jac = s.jac.is_some();
        // Every channel's optical depths at y at once.
        atm.cumulative_taus_in(layer_y, y.z, &mut self.ts_y[..nch], &mut self.ta_y[..nch]);
        if let Some((t1, t2, analysis)) = &polarised {
            // The scattering matrices instead of the phase functions: per channel.
            for k in 0..nch {
                if self.w[k] == 0.0 {
                    continue;
                }
                let iy = layer_y * nch + k;
                let sigma_y = atm.sigma_s_per_m[iy];
                if !(sigma_y > 0.0) {
                    continue;
                }
                let (tsy, tay) = (self.ts_y[k], self.ta_y[k]);
                let tau_xy = if horizontal {
                    let ix = p.layer * nch + k;
                    (atm.sigma_s_per_m[ix] + atm.sigma_a_per_m[ix]) * l
                } else {
                    ((tsy + tay) - (self.ts[k] + self.ta[k])).abs() / e_xy.z.abs()
                };
                let tau_back = s.tau_to_receiver(y.z, -omega.z, r, layer_y, k, tsy + tay);
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
            }
            return;
        }
        // Every channel in one branch-free pass (`lanes`): both legs' optical depths, then the
        // estimate (0 for a channel of zero weight or that does not scatter at y).
        let (ts, ta) = (&self.ts[..nch], &self.ta[..nch]);
        let (ts_y, ta_y) = (&self.ts_y[..nch], &self.ta_y[..nch]);
        let tau_xy = &mut self.tau[..nch];
        if horizontal {
            let row = p.layer * nch..(p.layer + 1) * nch;
            let (ss, sa) = (&atm.sigma_s_per_m[row.clone()], &atm.sigma_a_per_m[row]);
            for k in 0..nch {
                tau_xy[k] = (ss[k] + sa[k]) * l;
            }
        } else {
            lanes::slant(tau_xy, ts_y, ta_y, ts, ta, e_xy.z.abs());
        }
        s.taus_to_receiver(y.z, -omega.z, r, layer_y, ts_y, ta_y, &mut self.tau2[..nch]);
        let (w, tau_xy, tau_back) = (&self.w[..nch], &self.tau[..nch], &self.tau2[..nch]);
        let sigma_y = &atm.sigma_s_per_m[layer_y * nch..(layer_y + 1) * nch];
        let le = &mut self.le[..nch];
        if grey {
            lanes::cone_grey(le, w, sigma_y, px0, py0, factor, tau_xy, tau_back);
        } else {
            s.mixture_phases(p.layer, mu_x, &mut self.phase[..nch]);
            s.receiver_phases(layer_y, mu_y, band, &mut self.phase_y[..nch]);
            let (px, py) = (&self.phase[..nch], &self.phase_y[..nch]);
            lanes::cone(le, w, sigma_y, px, py, factor, tau_xy, tau_back);
        }
        lanes::accumulate(&mut self.bins[base..base + nch], le);
        if jac {
            // Both of the estimate's scatterings and its two legs.
            let mut v = Virtual::default();
            v.leg(x.z, y.z, e_xy.z, l, p.layer);
            v.event(p.layer, mu_x);
            v.event(layer_y, mu_y);
            v.leg(y.z, s.receiver.z, -omega.z, r, layer_y);
            self.jac_score(gate, order + 1, a, &v);
        }
    }
}
