//! Tallies: one zeroed buffer per batch, folded in batch order into raw moments.
//!
//! A batch scores into FOV *annuli* (each local estimate lands in the narrowest field of view
//! that contains it) and exact-order bins, the cheapest scoring; when the batch ends its buffer
//! is turned into the reported bins — cumulative fields of view, orders 1…N, N+1 and more, and
//! the total — and the running mean and M2 of every reported bin take that batch's values
//! ([`stats::welford_add`]).
//! Folding happens in batch order, so results do not depend on the number of threads.

use crate::returns::{Order, Returns, Source};
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

    fn parts(&self) -> [&Vec<f64>; 4] {
        [&self.up, &self.down, &self.absorbed, &self.cut]
    }

    fn parts_mut(&mut self) -> [&mut Vec<f64>; 4] {
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
    /// Reported bins: [channel][fov][gate][order: total, 1..=N, N+].
    mean: Vec<f64>,
    m2: Vec<f64>,
    flux_mean: Flux,
    flux_m2: Flux,
    /// Annulus a ↔ scene FOV index.
    fov_of_annulus: Vec<usize>,
    scratch: Vec<f64>,
}

impl Accumulator {
    pub fn new(shape: TallyShape, fov_of_annulus: Vec<usize>) -> Self {
        let reported = shape.n_channels * shape.n_fov * shape.n_gates * (shape.n_order_bins + 1);
        Accumulator {
            shape,
            n_batches: 0,
            mean: vec![0.0; reported],
            m2: vec![0.0; reported],
            flux_mean: Flux::zeros(shape.n_channels),
            flux_m2: Flux::zeros(shape.n_channels),
            fov_of_annulus,
            scratch: vec![0.0; reported],
        }
    }

    #[inline]
    fn reported_index(&self, k: usize, fov: usize, gate: usize, order: usize) -> usize {
        let s = &self.shape;
        ((k * s.n_fov + fov) * s.n_gates + gate) * (s.n_order_bins + 1) + order
    }

    /// Fold one batch (already normalised to energy per pulse) into the running moments.
    pub fn add_batch(&mut self, bins: &[f64], flux: &Flux) {
        let s = self.shape;
        let n_rep = s.n_order_bins + 1;
        self.scratch.iter_mut().for_each(|v| *v = 0.0);
        let mut acc = vec![0.0; s.n_channels];
        for gate in 0..s.n_gates {
            for ob in 0..s.n_order_bins {
                // Cumulative over annuli: FOV j holds every annulus up to its own.
                acc.iter_mut().for_each(|v| *v = 0.0);
                for a in 0..s.n_fov {
                    let base = s.base(gate, ob, a);
                    let fov = self.fov_of_annulus[a];
                    for k in 0..s.n_channels {
                        acc[k] += bins[base + k];
                        let i = self.reported_index(k, fov, gate, 0);
                        self.scratch[i + 1 + ob] = acc[k];
                        self.scratch[i] += acc[k];
                    }
                }
            }
        }
        debug_assert_eq!(self.scratch.len() % n_rep, 0);
        let n = self.n_batches + 1;
        for (i, v) in self.scratch.iter().enumerate() {
            stats::welford_add(&mut self.mean[i], &mut self.m2[i], n, *v);
        }
        for (dst, (dst2, src)) in self
            .flux_mean
            .parts_mut()
            .into_iter()
            .zip(self.flux_m2.parts_mut().into_iter().zip(flux.parts()))
        {
            for k in 0..src.len() {
                stats::welford_add(&mut dst[k], &mut dst2[k], n, src[k]);
            }
        }
        self.n_batches += 1;
    }

    /// Means and standard errors as [`Returns`], and the flux with its standard errors.
    pub fn finish(
        &self,
        channels: Vec<String>,
        fov_full_angle_mrad: Vec<f64>,
        range_m: Vec<f64>,
    ) -> (Returns, Flux, Flux) {
        let n_exact = self.shape.n_order_bins as u32 - 1;
        let mut orders = vec![Order::Total];
        orders.extend((1..=n_exact).map(Order::Exactly));
        orders.push(Order::AtLeast(n_exact + 1));
        let mut r = Returns::zeros(
            Source::MonteCarlo,
            channels,
            fov_full_angle_mrad,
            range_m,
            orders,
        );
        let n = self.n_batches;
        r.energy_j.copy_from_slice(&self.mean);
        for i in 0..self.m2.len() {
            r.stderr_j[i] = stats::std_error(self.m2[i], n);
        }
        let mean = self.flux_mean.clone();
        let mut err = Flux::zeros(self.shape.n_channels);
        for (e, m2) in err.parts_mut().into_iter().zip(self.flux_m2.parts()) {
            for k in 0..m2.len() {
                e[k] = stats::std_error(m2[k], n);
            }
        }
        (r, mean, err)
    }
}
