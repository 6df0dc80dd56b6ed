//! Tallies: one zeroed buffer per batch, folded in batch order into raw moments.
//!
//! A batch scores into FOV *annuli* (each local estimate lands in the narrowest field of view
//! that contains it) and exact-order bins, the cheapest scoring; when the batch ends its buffer
//! is turned into the reported bins — cumulative fields of view, orders 1…N, N+1 and more, and
//! the total — and the running mean and M2 of every reported bin take that batch's values
//! ([`stats::welford_add`]). Only the gates a batch scored into are visited; the zeros a gate
//! is owed are folded at once when a batch next scores into it or at the end
//! ([`stats::welford_add_zeros_scaled`]), so that folding costs what the batch touched.
//! Folding happens in batch order, so results do not depend on the number of threads.

use crate::returns::{Combination, Covariance, Order, Returns, Source};
use crate::stats;

/// Shape of a batch buffer: gate × order bin × FOV annulus × channel (channel fastest, so that
/// one local estimate writes adjacent memory).
#[derive(Debug, Clone, Copy)]
pub(crate) struct TallyShape {
    pub n_gates: usize,
    /// Exact orders 1..=max_order plus one overflow bin.
    pub n_order_bins: usize,
    pub n_fov: usize,
    pub n_channels: usize,
}

impl TallyShape {
    pub fn len(&self) -> usize {
        self.n_gates * self.n_order_bins * self.n_fov * self.n_channels
    }

    /// Start of the channel run for (gate, order bin, annulus).
    #[inline]
    pub fn base(&self, gate: usize, order_bin: usize, annulus: usize) -> usize {
        ((gate * self.n_order_bins + order_bin) * self.n_fov + annulus) * self.n_channels
    }
}

/// Energy leaving the scene by way, per channel, in units of the emitted energy.
#[derive(Debug, Clone, PartialEq)]
pub struct Flux {
    /// Escaped through the top of the atmosphere.
    pub up: Vec<f64>,
    /// Reached the bottom: absorbed by the surface, or left through an open bottom.
    pub down: Vec<f64>,
    /// Absorbed in the atmosphere (gas and particles).
    pub absorbed: Vec<f64>,
    /// Still travelling when it could no longer reach any range gate.
    pub cut: Vec<f64>,
}

impl Flux {
    pub(crate) fn zeros(n: usize) -> Self {
        Flux {
            up: vec![0.0; n],
            down: vec![0.0; n],
            absorbed: vec![0.0; n],
            cut: vec![0.0; n],
        }
    }

    pub(crate) fn parts(&self) -> [&Vec<f64>; 4] {
        [&self.up, &self.down, &self.absorbed, &self.cut]
    }

    pub(crate) fn parts_mut(&mut self) -> [&mut Vec<f64>; 4] {
        [
            &mut self.up,
            &mut self.down,
            &mut self.absorbed,
            &mut self.cut,
        ]
    }
}

/// Running means and M2 over batches for the returns and the flux.
pub(crate) struct Accumulator {
    shape: TallyShape,
    n_batches: usize,
    /// Reported bins: [channel][fov][gate][order: total, 1..=N, N+, then 2+ when N ≥ 2].
    mean: Vec<f64>,
    m2: Vec<f64>,
    /// Per-bin scale of `m2` ([`stats::welford_add_scaled`]).
    m2_scale: Vec<f64>,
    /// Per gate, the batches the moments of its bins hold: a batch that scored nothing into a
    /// gate is folded there only when a later one does, or at the end, all its zeros at once
    /// ([`stats::welford_add_zeros_scaled`]).
    gate_count: Vec<usize>,
    flux_mean: Flux,
    flux_m2: Flux,
    flux_scale: Flux,
    /// Annulus a ↔ scene FOV index.
    fov_of_annulus: Vec<usize>,
    scratch: Vec<f64>,
    /// Combined channels, folded batch by batch so that their errors and covariances are right.
    combined: Option<Combined>,
}

/// Reported order bins per (channel, FOV, gate): the total, the exact orders 1..=N, the
/// overflow N+ and, when N ≥ 2, the multiple scattering 2+ (orders ≥ 2). The 2+ bin is summed
/// batch by batch, so its standard error is its own: `total − 1` from two rows would carry the
/// single-scattering noise, which dominates it (on C.1 the error of `total` is several times
/// the scatter of `total − 1` between seeds).
pub(crate) fn reported_orders(n_order_bins: usize) -> usize {
    n_order_bins + 1 + usize::from(n_order_bins >= 3)
}

/// Running moments of combined channels and of chosen pairs of them.
struct Combined {
    combos: Vec<Combination>,
    /// Bins per channel in the reported layout.
    bins: usize,
    mean: Vec<f64>,
    m2: Vec<f64>,
    /// Scale of `m2` per bin ([`stats::welford_add_scaled`]).
    scale: Vec<f64>,
    /// Pairs (a, b), a < b, and their running co-moments Σ (x_a − x̄_a)(x_b − x̄_b), in units of
    /// the product of the two bins' scales.
    pairs: Vec<(usize, usize)>,
    c2: Vec<f64>,
    /// This batch's values, and their deviations from the old means.
    values: Vec<f64>,
    delta: Vec<f64>,
    /// Scale of `m2` before this batch.
    old_scale: Vec<f64>,
}

impl Accumulator {
    /// `n_flux`: the channels of the flux tally (those of the tally's shape, but in a polarised
    /// run, where the shape counts co- and cross-polarised returns as channels of their own).
    pub fn new(shape: TallyShape, n_flux: usize, fov_of_annulus: Vec<usize>) -> Self {
        let reported =
            shape.n_channels * shape.n_fov * shape.n_gates * reported_orders(shape.n_order_bins);
        Accumulator {
            shape,
            n_batches: 0,
            mean: vec![0.0; reported],
            m2: vec![0.0; reported],
            m2_scale: vec![0.0; reported],
            gate_count: vec![0; shape.n_gates],
            flux_mean: Flux::zeros(n_flux),
            flux_m2: Flux::zeros(n_flux),
            flux_scale: Flux::zeros(n_flux),
            fov_of_annulus,
            scratch: vec![0.0; reported],
            combined: None,
        }
    }

    /// Also fold these combinations of channels (`terms` index the transport's channels), and
    /// the covariances of the pairs (a, b), a < b, of them.
    pub fn with_combinations(
        mut self,
        combos: Vec<Combination>,
        pairs: Vec<(usize, usize)>,
    ) -> Self {
        if combos.is_empty() {
            return self;
        }
        let s = self.shape;
        let bins = s.n_fov * s.n_gates * reported_orders(s.n_order_bins);
        let n = combos.len();
        self.combined = Some(Combined {
            combos,
            bins,
            mean: vec![0.0; n * bins],
            m2: vec![0.0; n * bins],
            scale: vec![0.0; n * bins],
            c2: vec![0.0; pairs.len() * bins],
            pairs,
            values: vec![0.0; n * bins],
            delta: vec![0.0; n * bins],
            old_scale: vec![0.0; n * bins],
        });
        self
    }

    /// Index of the total (order bin 0) of (channel, FOV, gate) in the reported layout; the
    /// exact orders, the overflow and the 2+ bin follow it.
    #[inline]
    fn reported_start(&self, k: usize, fov: usize, gate: usize) -> usize {
        let s = &self.shape;
        ((k * s.n_fov + fov) * s.n_gates + gate) * reported_orders(s.n_order_bins)
    }

    /// Fold one batch (already normalised to energy per pulse) into the running moments. Only
    /// the gates the batch scored into are visited: the work is in proportion to what the
    /// batch touched, not to the whole tally (many gates × channels × FOVs × orders in a short
    /// run). A gate's zeros are folded when a batch next scores into it, or at the end
    /// (`gate_count`); a batch that scores into every gate is folded exactly as Welford's
    /// update bin by bin.
    pub fn add_batch(&mut self, bins: &[f64], flux: &Flux) {
        let s = self.shape;
        let n = self.n_batches + 1;
        let n_rep = reported_orders(s.n_order_bins);
        let per_gate = s.n_order_bins * s.n_fov * s.n_channels;
        let mut acc = vec![0.0; s.n_channels];
        // The 2+ bin's offset from the total, if there is one.
        let ms = (s.n_order_bins >= 3).then_some(s.n_order_bins + 1);
        for gate in 0..s.n_gates {
            if bins[gate * per_gate..(gate + 1) * per_gate]
                .iter()
                .all(|v| *v == 0.0)
            {
                continue;
            }
            self.catch_up_gate(gate, n - 1);
            for k in 0..s.n_channels {
                for fov in 0..s.n_fov {
                    let i = self.reported_start(k, fov, gate);
                    self.scratch[i..i + n_rep].fill(0.0);
                }
            }
            for ob in 0..s.n_order_bins {
                // Cumulative over annuli: FOV j holds every annulus up to its own.
                acc.iter_mut().for_each(|v| *v = 0.0);
                for a in 0..s.n_fov {
                    let base = s.base(gate, ob, a);
                    let fov = self.fov_of_annulus[a];
                    for k in 0..s.n_channels {
                        acc[k] += bins[base + k];
                        let i = self.reported_start(k, fov, gate);
                        self.scratch[i + 1 + ob] = acc[k];
                        self.scratch[i] += acc[k];
                        if let Some(m) = ms.filter(|_| ob >= 1) {
                            self.scratch[i + m] += acc[k];
                        }
                    }
                }
            }
            for k in 0..s.n_channels {
                for fov in 0..s.n_fov {
                    let start = self.reported_start(k, fov, gate);
                    for i in start..start + n_rep {
                        stats::welford_add_scaled(
                            &mut self.mean[i],
                            &mut self.m2[i],
                            &mut self.m2_scale[i],
                            n,
                            self.scratch[i],
                        );
                    }
                }
            }
            if let Some(c) = &mut self.combined {
                for fov in 0..s.n_fov {
                    let b = (fov * s.n_gates + gate) * n_rep;
                    c.add_bins(&self.scratch, b..b + n_rep, n);
                }
            }
            self.gate_count[gate] = n;
        }
        for ((dst, dst2), (sc, src)) in self
            .flux_mean
            .parts_mut()
            .into_iter()
            .zip(self.flux_m2.parts_mut())
            .zip(self.flux_scale.parts_mut().into_iter().zip(flux.parts()))
        {
            for k in 0..src.len() {
                stats::welford_add_scaled(&mut dst[k], &mut dst2[k], &mut sc[k], n, src[k]);
            }
        }
        self.n_batches += 1;
    }

    /// Fold the zeros gate `gate` is owed up to `n` batches, in every bin of it.
    fn catch_up_gate(&mut self, gate: usize, n: usize) {
        let s = self.shape;
        let c = self.gate_count[gate];
        if c == n {
            return;
        }
        let n_rep = reported_orders(s.n_order_bins);
        for k in 0..s.n_channels {
            for fov in 0..s.n_fov {
                let start = self.reported_start(k, fov, gate);
                for i in start..start + n_rep {
                    stats::welford_add_zeros_scaled(
                        &mut self.mean[i],
                        &mut self.m2[i],
                        self.m2_scale[i],
                        c,
                        n - c,
                    );
                }
            }
        }
        if let Some(comb) = &mut self.combined {
            for fov in 0..s.n_fov {
                let b = (fov * s.n_gates + gate) * n_rep;
                comb.catch_up(b..b + n_rep, c, n);
            }
        }
        self.gate_count[gate] = n;
    }

    /// Fold the zeros every gate is still owed, so that all hold every batch.
    fn catch_up(&mut self) {
        for gate in 0..self.shape.n_gates {
            self.catch_up_gate(gate, self.n_batches);
        }
    }

    /// Means and standard errors as [`Returns`], and the flux with its standard errors.
    pub fn finish(
        &mut self,
        channels: Vec<String>,
        fov_full_angle_mrad: Vec<f64>,
        range_m: Vec<f64>,
    ) -> (Returns, Flux, Flux, Option<Returns>) {
        let n_exact = self.shape.n_order_bins as u32 - 1;
        let mut orders = vec![Order::Total];
        orders.extend((1..=n_exact).map(Order::Exactly));
        orders.push(Order::AtLeast(n_exact + 1));
        if n_exact >= 2 {
            orders.push(Order::AtLeast(2));
        }
        let mut r = Returns::zeros(
            Source::MonteCarlo,
            channels,
            fov_full_angle_mrad,
            range_m,
            orders,
        );
        self.catch_up();
        let n = self.n_batches;
        r.energy_j.copy_from_slice(&self.mean);
        for i in 0..self.m2.len() {
            r.stderr_j[i] = stats::std_error_scaled(self.m2[i], self.m2_scale[i], n);
        }
        let combined = self.combined.as_ref().map(|c| {
            let mut r = Returns::zeros(
                Source::MonteCarlo,
                c.combos.iter().map(|x| x.name.clone()).collect(),
                r.fov_full_angle_mrad.clone(),
                r.range_m.clone(),
                r.orders.clone(),
            );
            r.energy_j.copy_from_slice(&c.mean);
            for i in 0..c.m2.len() {
                r.stderr_j[i] = stats::std_error_scaled(c.m2[i], c.scale[i], n);
            }
            // Covariance of the means: co-moment / (n (n − 1)), as the standard error.
            let nf = n as f64;
            let scale = if n >= 2 {
                1.0 / (nf * (nf - 1.0))
            } else {
                f64::NAN
            };
            let bins = c.bins;
            let cov_j2 = c
                .pairs
                .iter()
                .enumerate()
                .flat_map(|(p, &(a, b))| {
                    (0..bins).map(move |i| {
                        c.c2[p * bins + i] * scale * c.scale[a * bins + i] * c.scale[b * bins + i]
                    })
                })
                .collect();
            r.covariance = Some(Covariance {
                pairs: c.pairs.clone(),
                cov_j2,
            });
            r
        });
        let mean = self.flux_mean.clone();
        let mut err = Flux::zeros(self.flux_mean.up.len());
        for (e, (m2, sc)) in err.parts_mut().into_iter().zip(
            self.flux_m2
                .parts()
                .into_iter()
                .zip(self.flux_scale.parts()),
        ) {
            for k in 0..m2.len() {
                e[k] = stats::std_error_scaled(m2[k], sc[k], n);
            }
        }
        (r, mean, err, combined)
    }
}

impl Combined {
    /// Fold one batch at the reported bins `range` (without the channel): `reported` holds the
    /// batch's values in the reported layout [channel][fov][gate][order]; `n` counts batches
    /// including this one. Co-moments follow Welford's update for covariances: C += (x_a −
    /// x̄_a,old)(x_b − x̄_b,new).
    fn add_bins(&mut self, reported: &[f64], range: std::ops::Range<usize>, n: usize) {
        let bins = self.bins;
        for (j, c) in self.combos.iter().enumerate() {
            let dst = &mut self.values[j * bins..(j + 1) * bins][range.clone()];
            dst.fill(0.0);
            for (k, coef) in &c.terms {
                let src = &reported[k * bins..(k + 1) * bins][range.clone()];
                for (d, s) in dst.iter_mut().zip(src) {
                    *d += coef * s;
                }
            }
        }
        for j in 0..self.combos.len() {
            for i in range.clone().map(|b| j * bins + b) {
                self.old_scale[i] = self.scale[i];
                self.delta[i] = self.values[i] - self.mean[i];
                stats::welford_add_scaled(
                    &mut self.mean[i],
                    &mut self.m2[i],
                    &mut self.scale[i],
                    n,
                    self.values[i],
                );
            }
        }
        for (p, (a, b)) in self.pairs.iter().enumerate() {
            for i in range.clone() {
                let (ia, ib) = (a * bins + i, b * bins + i);
                let (sa, sb) = (self.scale[ia], self.scale[ib]);
                if sa == 0.0 || sb == 0.0 {
                    // Every value of one of the two so far is 0: no co-moment yet.
                    continue;
                }
                let c = &mut self.c2[p * bins + i];
                // Rescale the co-moment to the new scales (exact: powers of two), then add.
                *c *= (self.old_scale[ia] / sa) * (self.old_scale[ib] / sb);
                *c += (self.delta[ia] / sa) * ((self.values[ib] - self.mean[ib]) / sb);
            }
        }
    }

    /// Fold the zeros the bins `range` are owed, k = n − c of them after c batches, in every
    /// combination and pair: C ← C + x̄_a x̄_b c k/n (Chan et al. 1979), before the means move.
    fn catch_up(&mut self, range: std::ops::Range<usize>, c: usize, n: usize) {
        let bins = self.bins;
        let k = n - c;
        if k == 0 || c == 0 {
            return;
        }
        let f = c as f64 * k as f64 / n as f64;
        for (p, (a, b)) in self.pairs.iter().enumerate() {
            for bin in range.clone() {
                let (ia, ib) = (a * bins + bin, b * bins + bin);
                let (sa, sb) = (self.scale[ia], self.scale[ib]);
                if sa == 0.0 || sb == 0.0 {
                    continue;
                }
                self.c2[p * bins + bin] += (self.mean[ia] / sa) * (self.mean[ib] / sb) * f;
            }
        }
        for j in 0..self.combos.len() {
            for i in range.clone().map(|b| j * bins + b) {
                stats::welford_add_zeros_scaled(
                    &mut self.mean[i],
                    &mut self.m2[i],
                    self.scale[i],
                    c,
                    k,
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    const SHAPE: TallyShape = TallyShape {
        n_gates: 5,
        n_order_bins: 4,
        n_fov: 2,
        n_channels: 3,
    };

    /// 40 batches, sparse (`p_gate`: share of gates a batch touches, `p_bin`: share of their
    /// bins with a value) or dense, the values spread over decades.
    fn batches(p_gate: f64, p_bin: f64, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
        let per_gate = SHAPE.len() / SHAPE.n_gates;
        (0..40)
            .map(|_| {
                let mut b = vec![0.0; SHAPE.len()];
                for g in 0..SHAPE.n_gates {
                    if rng.random::<f64>() < p_gate {
                        for v in &mut b[g * per_gate..(g + 1) * per_gate] {
                            if rng.random::<f64>() < p_bin {
                                *v = 10f64.powf(-3.0 * rng.random::<f64>()) * 1e-15;
                            }
                        }
                    }
                }
                b
            })
            .collect()
    }

    fn fold(batches: &[Vec<f64>]) -> (Returns, Option<Returns>) {
        let combos = vec![
            Combination {
                name: "a".into(),
                terms: vec![(0, 1.0), (1, 0.5)],
            },
            Combination {
                name: "b".into(),
                terms: vec![(2, 1.0)],
            },
        ];
        let mut acc =
            Accumulator::new(SHAPE, 3, vec![0, 1]).with_combinations(combos, vec![(0, 1)]);
        for b in batches {
            acc.add_batch(b, &Flux::zeros(3));
        }
        let (r, _, _, c) = acc.finish(
            vec!["0".into(), "1".into(), "2".into()],
            vec![1.0, 2.0],
            (0..SHAPE.n_gates).map(|g| g as f64).collect(),
        );
        (r, c)
    }

    /// A batch's value of (channel k, FOV f, gate g, order): the annuli up to f, the exact
    /// order bin (`Some`) or all of them from `from` on (the total: 0, 2+: 1).
    fn value(b: &[f64], k: usize, f: usize, g: usize, ob: Option<usize>, from: usize) -> f64 {
        let bins: Vec<usize> = match ob {
            Some(o) => vec![o],
            None => (from..SHAPE.n_order_bins).collect(),
        };
        let mut v = 0.0;
        for o in bins {
            for a in 0..=f {
                v += b[SHAPE.base(g, o, a) + k];
            }
        }
        v
    }

    /// Mean, standard error of the mean and covariance of the means by two passes.
    fn moments(x: &[f64], y: &[f64]) -> (f64, f64, f64) {
        let n = x.len() as f64;
        let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
        let vx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum::<f64>() / (n * (n - 1.0));
        let cxy: f64 = x
            .iter()
            .zip(y)
            .map(|(a, b)| (a - mx) * (b - my))
            .sum::<f64>()
            / (n * (n - 1.0));
        (mx, vx.sqrt(), cxy)
    }

    fn close(a: f64, b: f64, what: &str) {
        assert!(
            (a - b).abs() <= 1e-12 * a.abs().max(b.abs()),
            "{what}: {a} vs {b}"
        );
    }

    /// Folding only what each batch touched (the zeros caught up at once) gives the means,
    /// standard errors and covariances of the batch values computed by two passes, for sparse
    /// batches (half the gates untouched, a fifth of the bins with a value) and dense ones.
    #[test]
    fn folding_what_a_batch_touched_gives_the_moments_of_every_batch() {
        for (p_gate, p_bin) in [(0.5, 0.2), (1.0, 1.0), (0.1, 0.05)] {
            let batches = batches(p_gate, p_bin, 7);
            let (r, c) = fold(&batches);
            let c = c.unwrap();
            let cov = c.covariance.as_ref().unwrap();
            let orders: Vec<(Order, Option<usize>, usize)> = vec![
                (Order::Total, None, 0),
                (Order::Exactly(1), Some(0), 0),
                (Order::Exactly(2), Some(1), 0),
                (Order::Exactly(3), Some(2), 0),
                (Order::AtLeast(4), Some(3), 0),
                (Order::AtLeast(2), None, 1),
            ];
            for g in 0..SHAPE.n_gates {
                for f in 0..SHAPE.n_fov {
                    for (oi, &(order, ob, from)) in orders.iter().enumerate() {
                        let per: Vec<Vec<f64>> = (0..3)
                            .map(|k| {
                                batches
                                    .iter()
                                    .map(|b| value(b, k, f, g, ob, from))
                                    .collect()
                            })
                            .collect();
                        for k in 0..3 {
                            let (m, se, _) = moments(&per[k], &per[k]);
                            let what = format!("channel {k}, FOV {f}, gate {g}, {order:?}");
                            close(r.energy(k, f, g, order).unwrap(), m, &what);
                            close(r.stderr(k, f, g, order).unwrap(), se, &what);
                        }
                        let a: Vec<f64> = (0..40).map(|i| per[0][i] + 0.5 * per[1][i]).collect();
                        let (ma, sa, cab) = moments(&a, &per[2]);
                        let what = format!("combination, FOV {f}, gate {g}, {order:?}");
                        close(c.energy(0, f, g, order).unwrap(), ma, &what);
                        close(c.stderr(0, f, g, order).unwrap(), sa, &what);
                        close(cov.cov_j2[c.index(0, f, g, oi)], cab, &what);
                    }
                }
            }
        }
    }
}
