//! Folding batches in order into means and standard errors ([`Fold`]), and the polarised
//! run's tally layout.

use super::*;

/// How a polarised run's tallies are laid out: co-polarised returns as channels 0..n, cross
/// as n..2n; the accumulator then folds, as combinations, per channel its total, co and cross
/// (3n), and per user combination its total, co and cross (3m); its pairs are (co, cross) of
/// each channel, then of each user combination, then the user's own pairs of totals.
#[derive(Debug, Clone)]
pub(super) struct PolarisedLayout {
    pub(super) n: usize,
    pub(super) m: usize,
}

impl PolarisedLayout {
    /// The combinations and pairs the accumulator folds for `n` channels, `user` combinations
    /// and `user_pairs` of them.
    pub(super) fn combinations(
        n: usize,
        user: &[Combination],
        user_pairs: &[(usize, usize)],
    ) -> (Self, Vec<Combination>, Vec<(usize, usize)>) {
        let m = user.len();
        let mut c = Vec::with_capacity(3 * (n + m));
        for (part, terms) in [
            ("total", [1.0, 1.0]),
            ("co", [1.0, 0.0]),
            ("cross", [0.0, 1.0]),
        ] {
            for k in 0..n {
                c.push(Combination {
                    name: format!("{part} {k}"),
                    terms: [(k, terms[0]), (n + k, terms[1])]
                        .into_iter()
                        .filter(|(_, w)| *w != 0.0)
                        .collect(),
                });
            }
        }
        for (part, on) in [
            ("total", [true, true]),
            ("co", [true, false]),
            ("cross", [false, true]),
        ] {
            for u in user {
                let mut terms = Vec::new();
                for (k, w) in &u.terms {
                    if on[0] {
                        terms.push((*k, *w));
                    }
                    if on[1] {
                        terms.push((n + k, *w));
                    }
                }
                c.push(Combination {
                    name: format!("{part} {}", u.name),
                    terms,
                });
            }
        }
        let mut pairs: Vec<(usize, usize)> = (0..n).map(|k| (n + k, 2 * n + k)).collect();
        pairs.extend((0..m).map(|j| (3 * n + m + j, 3 * n + 2 * m + j)));
        pairs.extend(user_pairs.iter().map(|(a, b)| (3 * n + a, 3 * n + b)));
        (PolarisedLayout { n, m }, c, pairs)
    }
}

/// Channels `start..start + n` of a set of returns, named `names`.
pub(super) fn channel_slice(r: &Returns, start: usize, names: &[String]) -> Returns {
    let b = r.bins_per_channel();
    let mut out = Returns::zeros(
        r.source,
        names.to_vec(),
        r.fov_full_angle_mrad.clone(),
        r.range_m.clone(),
        r.orders.clone(),
    );
    let span = start * b..(start + names.len()) * b;
    out.energy_j.copy_from_slice(&r.energy_j[span.clone()]);
    out.stderr_j.copy_from_slice(&r.stderr_j[span]);
    out
}

/// The covariances of pairs `first..first + count` of `r`, one channel's bins after another.
pub(super) fn pair_covariances(r: &Returns, first: usize, count: usize) -> Vec<f64> {
    let b = r.bins_per_channel();
    r.covariance
        .as_ref()
        .map(|c| c.cov_j2[first * b..(first + count) * b].to_vec())
        .unwrap_or_else(|| vec![f64::NAN; count * b])
}

/// Batches folded in order into running means and second moments.
pub struct Fold<'p> {
    pub(super) plan: &'p Plan<'p>,
    pub(super) acc: Accumulator,
    pub(super) jac: Option<super::jacobian::JacFold>,
    pub(super) stats: RunStats,
    pub(super) next: usize,
}

impl Fold<'_> {
    /// Fold the next batch. Batches must come in order, each once, with this plan's shape.
    pub fn add(&mut self, mut batch: BatchTally) -> Result<(), TransportError> {
        let shape = self.plan.setup.shape;
        let n = self.plan.channels.len();
        if batch.index != self.next {
            return Err(TransportError::Options(format!(
                "batch {} folded where batch {} was expected",
                batch.index, self.next
            )));
        }
        if batch.bins.len() != shape.len() || batch.flux.parts().iter().any(|p| p.len() != n) {
            return Err(TransportError::Options(format!(
                "batch {} has {} bins where the run has {}",
                batch.index,
                batch.bins.len(),
                shape.len()
            )));
        }
        let (scale, flux_scale) = (self.plan.scale, self.plan.flux_scale);
        batch.bins.iter_mut().for_each(|v| *v *= scale);
        for part in batch.flux.parts_mut() {
            part.iter_mut().for_each(|v| *v *= flux_scale);
        }
        let want = self.plan.setup.jac.as_ref().map_or(0, |js| js.len(&shape));
        if batch.jacobian.len() != want {
            return Err(TransportError::Options(format!(
                "batch {} has {} Jacobian values where the run has {want}: Jacobians are \
                 traced on one machine (not by shards or MPI ranks)",
                batch.index,
                batch.jacobian.len()
            )));
        }
        self.acc.add_batch(&batch.bins, &batch.flux);
        if let Some(j) = &mut self.jac {
            batch.jacobian.iter_mut().for_each(|v| *v *= scale);
            j.add_batch(&batch.jacobian);
        }
        self.stats.add(&batch.stats);
        self.next += 1;
        Ok(())
    }

    /// Means and standard errors once every batch is in; `wall_s` and `threads` describe how
    /// the batches were computed.
    pub fn finish(self, wall_s: f64, threads: usize) -> Result<McResult, TransportError> {
        let plan = self.plan;
        if self.next != plan.batches {
            return Err(TransportError::Options(format!(
                "{} of {} batches folded",
                self.next, plan.batches
            )));
        }
        // A polarised run's accumulator knows co as channels 0..n and cross as n..2n.
        let tally_names: Vec<String> = match &plan.polarised {
            None => plan.channels.clone(),
            Some(_) => ["co", "cross"]
                .iter()
                .flat_map(|p| plan.channels.iter().map(move |c| format!("{c} {p}")))
                .collect(),
        };
        let mut acc = self.acc;
        let (returns, flux, flux_stderr, combined) = acc.finish(
            tally_names,
            plan.fov_full_angle_mrad.clone(),
            plan.range_m.clone(),
        );
        let (returns, combined, polarised) = match (&plan.polarised, combined) {
            (Some(l), Some(all)) => {
                let (n, m) = (l.n, l.m);
                let names = &plan.channels;
                let user = &plan.combination_names;
                let channels = Polarised {
                    co: channel_slice(&all, n, names),
                    cross: channel_slice(&all, 2 * n, names),
                    cov_j2: pair_covariances(&all, 0, n),
                };
                let (combined, combined_pol) = if m > 0 {
                    let mut totals = channel_slice(&all, 3 * n, user);
                    let pairs = &plan.combination_pairs[n + m..];
                    totals.covariance = Some(crate::returns::Covariance {
                        pairs: pairs.iter().map(|(a, b)| (a - 3 * n, b - 3 * n)).collect(),
                        cov_j2: pair_covariances(&all, n + m, pairs.len()),
                    });
                    let pol = Polarised {
                        co: channel_slice(&all, 3 * n + m, user),
                        cross: channel_slice(&all, 3 * n + 2 * m, user),
                        cov_j2: pair_covariances(&all, n, m),
                    };
                    (Some(totals), Some(pol))
                } else {
                    (None, None)
                };
                (
                    channel_slice(&all, 0, names),
                    combined,
                    Some(PolarisedMc {
                        channels,
                        combined: combined_pol,
                    }),
                )
            }
            (_, combined) => (returns, combined, None),
        };
        let jacobians = self.jac.as_ref().and_then(|j| {
            j.finish(
                plan.channels.clone(),
                plan.fov_full_angle_mrad.clone(),
                plan.range_m.clone(),
            )
        });
        let jacobians_combined = self.jac.as_ref().and_then(|j| {
            j.finish_combined(plan.fov_full_angle_mrad.clone(), plan.range_m.clone())
        });
        Ok(McResult {
            jacobians,
            jacobians_combined,
            returns,
            combined,
            flux,
            flux_stderr,
            polarised,
            stats: self.stats,
            wall_s,
            photons: plan.per_batch * plan.batches as u64,
            threads,
        })
    }
}
