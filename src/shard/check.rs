//! The checks of a fold that no single shard can make: conservation of energy, finite sums,
//! shards that belong together.

use super::*;

/// Standard errors of the mean a merge allows the received energy above its bound
/// ([`check_folded`]): a sound run exceeds it by chance with probability 3e-5 per channel.
pub const CONSERVATION_SIGMAS: f64 = 4.0;

/// Relative rounding a merge allows the received energy above its bound.
const CONSERVATION_ROUNDING: f64 = 1e-9;

/// A batch's received energy beyond this many times the bound `E` times the batches `B` is
/// taken for impossible: it is ≥ 0 with a mean of at most `E`, so by Markov's inequality one
/// of `B` batches exceeds `B·E·F` with a probability of at most 1/`F`, whatever its
/// distribution.
const IMPROBABLE_FACTOR: f64 = 1e9;

/// Refuse a fold whose numbers no run makes, though every shard's numbers were finite and
/// ≥ 0 one by one. The received energy of a channel (every gate, order and field of view) is at
/// most what the pulse sends through the receiver, `limit_j` = pulse energy × optical
/// efficiency (every channel of the transport runs with the lidar's pulse energy); refused:
/// a batch whose received energy is not finite or exceeds `B·limit_j·`[`IMPROBABLE_FACTOR`]
/// (a single absurd batch, which would also make the standard error as large as the mean); a
/// folded energy, standard error, covariance or flux that is not finite (a mean of huge tallies
/// or a sum of their squares overflows); a mean received energy above `limit_j` by more than
/// [`CONSERVATION_SIGMAS`] standard errors and rounding. `received` holds each batch's received
/// energy per channel \[J\], batch after batch; the standard error is that of their mean, so
/// it holds the gates' and orders' covariances (with one batch there is none, and the bound
/// holds as it is). The error names the shard whose batch received the most in the channel at
/// fault.
pub(super) fn check_folded(
    set: &ShardSet,
    r: &McResult,
    received: &[f64],
    channels: usize,
    limit_j: f64,
) -> Result<(), ShardError> {
    let batches = received.len() / channels.max(1);
    let fold = Received {
        set,
        names: &r.returns.channels,
        received,
        channels,
        batches,
    };
    fold.check_batches(limit_j)?;
    fold.check_finite(r)?;
    fold.check_conservation(limit_j)
}

/// Each batch's received energy per channel, and the shards they came from: what the checks of
/// [`check_folded`] blame.
struct Received<'a> {
    set: &'a ShardSet,
    names: &'a [String],
    /// Batch after batch, `channels` values each \[J\].
    received: &'a [f64],
    channels: usize,
    batches: usize,
}

impl Received<'_> {
    fn name(&self, k: usize) -> String {
        self.names.get(k).cloned().unwrap_or_else(|| k.to_string())
    }

    fn at(&self, b: usize, k: usize) -> f64 {
        self.received[b * self.channels + k]
    }

    /// The batch that received the most in channel k (a non-finite sum first).
    fn worst(&self, k: usize) -> usize {
        (0..self.batches)
            .max_by(|&a, &b| {
                let key = |v: f64| if v.is_finite() { v } else { f64::INFINITY };
                key(self.at(a, k)).total_cmp(&key(self.at(b, k)))
            })
            .unwrap_or(0)
    }

    /// The error of channel `k`, naming the shard of its largest batch.
    fn blame(&self, k: usize, what: String) -> ShardError {
        let b = self.worst(k);
        ShardError::Bad {
            path: self.set.file_of_batch(b).to_path_buf(),
            what: format!(
                "channel `{}`: {what} (the largest share comes from its batch {b}; the shards fold into it, each finite and ≥ 0 alone)",
                self.name(k)
            ),
        }
    }

    /// No single batch receives an impossible energy (Markov's inequality).
    fn check_batches(&self, limit_j: f64) -> Result<(), ShardError> {
        let batches = self.batches;
        let improbable_j = batches as f64 * limit_j * IMPROBABLE_FACTOR;
        for k in 0..self.channels {
            if batches == 0 {
                break;
            }
            let b = self.worst(k);
            let v = self.at(b, k);
            if !v.is_finite() || v > improbable_j {
                return Err(ShardError::Bad {
                    path: self.set.file_of_batch(b).to_path_buf(),
                    what: format!(
                        "channel `{}`: its batch {b} receives {} J over all gates, orders and fields of view, where the pulse sends {} J through the receiver (pulse energy × optical efficiency): in a run that conserves energy one of its {batches} batches exceeds {} J with a probability below {:e} (Markov's inequality)",
                        self.name(k),
                        number(v),
                        number(limit_j),
                        number(improbable_j),
                        1.0 / IMPROBABLE_FACTOR
                    ),
                });
            }
        }
        Ok(())
    }

    /// Every folded energy, standard error, covariance and flux is finite.
    fn check_finite(&self, r: &McResult) -> Result<(), ShardError> {
        let channels = self.channels;
        // Every set of returns the fold made, with what it is and whether its channels are the
        // transport's (a combination's blames the transport channel whose batch received most).
        let mut sets: Vec<(&str, &crate::returns::Returns, bool)> =
            vec![("returns", &r.returns, true)];
        if let Some(c) = &r.combined {
            sets.push(("combined returns", c, false));
        }
        if let Some(p) = &r.polarised {
            sets.push(("co-polarised returns", &p.channels.co, true));
            sets.push(("cross-polarised returns", &p.channels.cross, true));
            if let Some(c) = &p.combined {
                sets.push(("combined co-polarised returns", &c.co, false));
                sets.push(("combined cross-polarised returns", &c.cross, false));
            }
        }
        let most = (0..channels)
            .max_by(|&a, &b| {
                let m = |k: usize| {
                    let v = self.at(self.worst(k), k);
                    if v.is_finite() { v } else { f64::INFINITY }
                };
                m(a).total_cmp(&m(b))
            })
            .unwrap_or(0);
        for (what, ret, own) in sets {
            let per_channel = ret.bins_per_channel().max(1);
            let channel_of = |i: usize| {
                if own {
                    (i / per_channel).min(channels - 1)
                } else {
                    most
                }
            };
            for (values, kind) in [(&ret.energy_j, "energy"), (&ret.stderr_j, "standard error")] {
                if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                    return Err(self.blame(
                        channel_of(i),
                        format!(
                            "the merged {what} hold a{} {kind} of {} J in {}: a tally or the sum of its squares is beyond the range of a double",
                            if kind == "energy" { "n" } else { "" },
                            number(values[i]),
                            describe_bin(ret, i)
                        ),
                    ));
                }
            }
            // NaN stands for a covariance not computed.
            if let Some(c) = &ret.covariance
                && let Some(i) = c.cov_j2.iter().position(|v| v.is_infinite())
            {
                return Err(self.blame(
                    channel_of(0),
                    format!(
                        "the merged {what} hold a covariance of {} J² (value {i}): the products of the tallies are beyond the range of a double",
                        number(c.cov_j2[i])
                    ),
                ));
            }
        }
        for (part, values) in ["up", "down", "absorbed", "cut"]
            .iter()
            .zip(r.flux.parts().into_iter().zip(r.flux_stderr.parts()))
        {
            let (mean, err) = values;
            if let Some(k) = (0..mean.len()).find(|&k| !(mean[k].is_finite() && err[k].is_finite()))
            {
                return Err(self.blame(
                    k.min(channels - 1),
                    format!(
                        "the merged flux `{part}` is {} ± {}: not finite",
                        number(mean[k]),
                        number(err[k])
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The mean received energy of every channel at most what the pulse sends through the
    /// receiver, within [`CONSERVATION_SIGMAS`] standard errors and rounding.
    fn check_conservation(&self, limit_j: f64) -> Result<(), ShardError> {
        let batches = self.batches;
        if batches == 0 {
            return Ok(());
        }
        for k in 0..self.channels {
            let values = (0..batches).map(|b| self.at(b, k));
            let n = batches as f64;
            // Scaled by the largest, so that neither the mean nor the squares overflow.
            let scale = values.clone().fold(0.0f64, |m, v| m.max(v.abs()));
            if !scale.is_finite() {
                return Err(self.blame(
                    k,
                    "a batch's received energy over all gates, orders and fields of view is not finite"
                        .into(),
                ));
            }
            if scale == 0.0 {
                continue;
            }
            let mean = values.clone().map(|v| v / scale).sum::<f64>() / n;
            let stderr = if batches > 1 {
                let ss: f64 = values.map(|v| (v / scale - mean).powi(2)).sum();
                (ss / (n - 1.0) / n).sqrt() * scale
            } else {
                0.0
            };
            let mean = mean * scale;
            if mean > limit_j * (1.0 + CONSERVATION_ROUNDING) + CONSERVATION_SIGMAS * stderr {
                return Err(self.blame(
                    k,
                    format!(
                        "it receives {} ± {} J over all gates, orders and fields of view, more than the {} J the pulse sends through the receiver (pulse energy × optical efficiency) by {:.3} standard errors; energy is conserved, a run never exceeds it by more than {CONSERVATION_SIGMAS}",
                        number(mean),
                        number(stderr),
                        number(limit_j),
                        if stderr > 0.0 {
                            (mean - limit_j) / stderr
                        } else {
                            f64::INFINITY
                        }
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Where bin `i` of `r` lies: its field of view, gate and order.
fn describe_bin(r: &crate::returns::Returns, i: usize) -> String {
    let per_channel = r.bins_per_channel().max(1);
    let j = i % per_channel;
    let (no, ng) = (r.orders.len().max(1), r.range_m.len().max(1));
    let (fov, gate, order) = (j / (no * ng), (j / no) % ng, j % no);
    let or_unknown = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_else(|| "?".into());
    format!(
        "the FOV of {} mrad, the gate at {} m, order {}",
        or_unknown(r.fov_full_angle_mrad.get(fov).copied()),
        or_unknown(r.range_m.get(gate).copied()),
        r.orders.get(order).map(|o| o.label()).unwrap_or_default()
    )
}

/// `b`'s header against `a`'s: the first difference, named.
pub(super) fn check_same(
    a: &Path,
    ha: &ShardHeader,
    b: &Path,
    hb: &ShardHeader,
) -> Result<(), ShardError> {
    let fields: [(&'static str, String, String); 10] = [
        (
            "the lidarsim version",
            ha.lidarsim_version.clone(),
            hb.lidarsim_version.clone(),
        ),
        ("the seed", ha.seed.to_string(), hb.seed.to_string()),
        (
            "the photon count",
            ha.photons.to_string(),
            hb.photons.to_string(),
        ),
        (
            "the batch count",
            ha.batches.to_string(),
            hb.batches.to_string(),
        ),
        (
            "the shard count",
            ha.shard_count.to_string(),
            hb.shard_count.to_string(),
        ),
        (
            "the highest order",
            ha.max_order.to_string(),
            hb.max_order.to_string(),
        ),
        (
            "the DDIS probability",
            f64::from_bits(ha.ddis_epsilon_bits).to_string(),
            f64::from_bits(hb.ddis_epsilon_bits).to_string(),
        ),
        (
            "the range stratification",
            f64::from_bits(ha.range_stratification_bits).to_string(),
            f64::from_bits(hb.range_stratification_bits).to_string(),
        ),
        (
            "the flux tally",
            ha.flux_tally.to_string(),
            hb.flux_tally.to_string(),
        ),
        (
            "the scene (digest)",
            format!("{} {}", ha.scene_path, ha.scene_digest),
            format!("{} {}", hb.scene_path, hb.scene_digest),
        ),
    ];
    first_mismatch(a, b, fields)
}

/// The first of the (what, value in `a`, value in `b`) pairs that differ, as the error naming
/// both files; shard headers of every kind are compared this way.
pub(crate) fn first_mismatch(
    a: &Path,
    b: &Path,
    fields: impl IntoIterator<Item = (&'static str, String, String)>,
) -> Result<(), ShardError> {
    match fields
        .into_iter()
        .find(|(_, first, second)| first != second)
    {
        Some((what, first, second)) => Err(ShardError::Mismatch {
            a: a.to_path_buf(),
            b: b.to_path_buf(),
            what,
            first,
            second,
        }),
        None => Ok(()),
    }
}
