//! The surface's expected contribution to the signal, and the flux tally's absorption.

use std::f64::consts::PI;

use glam::DVec3;

use super::*;

impl<'a, const ONE_CHANNEL: bool> Tracer<'a, ONE_CHANNEL> {
    /// Expected surface contribution of a flight that heads for the surface point `hit`; the
    /// uncollided weights are w_k e^{−tmp_k}.
    pub(super) fn score_surface(&mut self, hit: DVec3, mu_in: f64, path: f64, order: u32) {
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
        let jac = s.jac.is_some();
        // The surface is the bottom of layer 0: every channel's optical depths there at once.
        if s.has_layers {
            let z = hit.z.clamp(s.bottom_m, s.top_m);
            let l = s.layer_near(z, 0);
            s.atm
                .cumulative_taus_in(l, z, &mut self.ts_y[..n], &mut self.ta_y[..n]);
        } else {
            self.ts_y[..n].fill(0.0);
            self.ta_y[..n].fill(0.0);
        }
        let (ts, ta) = (&self.ts_y[..n], &self.ta_y[..n]);
        s.taus_to_receiver(hit.z, omega.z, d, layer, ts, ta, &mut self.tau[..n]);
        // Every channel in one branch-free pass (`lanes`), both legs' attenuation in one
        // exponent.
        let le = &mut self.le[..n];
        lanes::surface(le, &self.w, &self.tmp, &self.tau, albedo, geometric);
        if s.analyser.is_some() {
            // A Lambertian surface reflects unpolarised light: half of it each way.
            for k in 0..n {
                self.bins[base + k] += 0.5 * le[k];
                self.bins[base + n + k] += 0.5 * le[k];
            }
        } else {
            lanes::accumulate(&mut self.bins[base..base + n], le);
        }
        if jac {
            // The flight's arrival at the surface and the leg from it to the receiver.
            let mut v = Virtual::default();
            v.point(hit.z, 1.0 / mu_in);
            v.leg(hit.z, s.receiver.z, omega.z, d, 0);
            self.jac_score(gate, order, annulus, &v);
        }
    }

    /// Expected absorption in the atmosphere along a flight, per channel (flux tally only):
    /// w_k ∫ σ_a e^{−τ_ext(s)} ds, layer by layer.
    pub(super) fn score_absorption(&mut self, z0: f64, mu: f64, s_end: f64) {
        let atm = self.s.atm;
        let nch = self.nch();
        for k in 0..nch {
            self.flux.absorbed[k] += self.w[k] * atm.absorbed_fraction(z0, mu, s_end, k);
        }
    }
}
