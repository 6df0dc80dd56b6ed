//! A run shard's file read back and checked on its own.

use super::*;

/// A shard file read and checked: its header, and its bytes for the fold.
#[derive(Debug, Clone)]
pub struct ShardFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// Its header.
    pub header: ShardHeader,
    /// Transport wall time of the shard \[s\].
    pub wall_s: f64,
    /// Worker threads it ran on.
    pub threads: u64,
    /// Offset of the first batch record in `bytes`.
    records_at: usize,
    bytes: Vec<u8>,
}

impl ShardFile {
    /// Read `path` and check that it is a whole shard file of this format, consistent in
    /// itself.
    pub fn read(path: &Path) -> Result<ShardFile, ShardError> {
        let bytes = fs::read(path).map_err(|error| ShardError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        Self::parse(path, bytes)
    }

    /// [`ShardFile::read`] on bytes already read.
    pub fn parse(path: &Path, bytes: Vec<u8>) -> Result<ShardFile, ShardError> {
        let bad = |what: String| ShardError::Bad {
            path: path.to_path_buf(),
            what,
        };
        let (frame, header): (Frame, ShardHeader) =
            read_header(path, &bytes, TRAILER_BYTES, KIND_RUN)?;
        let records_at = frame.body_at;
        let body = bytes.len() - 8;
        let spec = header.spec();
        let n_records = header.end_batch.saturating_sub(header.first_batch);
        let expected = header
            .record_bytes()
            .and_then(|r| r.checked_mul(n_records))
            .and_then(|r| r.checked_add((records_at + TRAILER_BYTES) as u64));
        match expected {
            Some(e) if e == bytes.len() as u64 => {}
            Some(e) if e > bytes.len() as u64 => {
                return Err(bad(format!(
                    "truncated: {} bytes where its header announces {e} ({n_records} batches of {} tallies)",
                    bytes.len(),
                    header.bins_per_batch
                )));
            }
            Some(e) => {
                return Err(bad(format!(
                    "{} bytes where its header announces {e}: bytes beyond the end",
                    bytes.len()
                )));
            }
            None => {
                return Err(bad(
                    "corrupt: its header announces an impossible size".into()
                ));
            }
        }
        frame.check_sum(path)?;
        if header.shard_count == 0
            || header.shard_index >= header.shard_count
            || header.shard_count > header.batches
            || header.photons_per_batch != header.photons.div_ceil(header.batches.max(1))
        {
            return Err(bad(format!(
                "inconsistent header: shard {}/{} of {} batches of {} photons for {} photons",
                header.shard_index,
                header.shard_count,
                header.batches,
                header.photons_per_batch,
                header.photons
            )));
        }
        let range = spec.batches(header.batches as usize);
        if (header.first_batch, header.end_batch) != (range.start as u64, range.end as u64) {
            return Err(bad(format!(
                "inconsistent header: batches {}..{} where shard {spec} of {} batches holds {}..{}",
                header.first_batch, header.end_batch, header.batches, range.start, range.end
            )));
        }
        let wall_s = f64::from_bits(u64_at(&bytes, body - 16));
        let threads = u64_at(&bytes, body - 8);
        check_wall_and_threads(path, wall_s, threads)?;
        check_records(path, &header, &bytes[records_at..body - 16])?;
        Ok(ShardFile {
            path: path.to_path_buf(),
            header,
            wall_s,
            threads,
            records_at,
            bytes,
        })
    }

    /// The shard's batches, in order.
    pub fn batches(&self) -> impl Iterator<Item = BatchTally> + '_ {
        let h = &self.header;
        let (bins, ch) = (h.bins_per_batch as usize, h.channels as usize);
        // The length was checked against the header in `parse`.
        let rec = h.record_bytes().unwrap_or(0) as usize;
        let n = (h.end_batch - h.first_batch) as usize;
        (0..n).map(move |r| {
            let at = self.records_at + r * rec;
            let f = |i: usize| {
                f64::from_le_bytes(
                    self.bytes[at + 8 * i..at + 8 * i + 8]
                        .try_into()
                        .unwrap_or([0; 8]),
                )
            };
            let u = |i: usize| u64_at(&self.bytes, at + 8 * i);
            let stats = RunStats {
                photons: u(1),
                collisions: u(2),
                surface_reflections: u(3),
                local_estimates: u(4),
                roulette_kills: u(5),
                cut: u(6),
                escaped: u(7),
                zero_weight: u(8),
                splits: u(9),
            };
            let v0 = 1 + N_COUNTERS;
            let part = |p: usize| {
                (0..ch)
                    .map(|k| f(v0 + bins + p * ch + k))
                    .collect::<Vec<f64>>()
            };
            BatchTally {
                index: u(0) as usize,
                bins: (0..bins).map(|i| f(v0 + i)).collect(),
                flux: Flux {
                    up: part(0),
                    down: part(1),
                    absorbed: part(2),
                    cut: part(3),
                },
                jacobian: Vec::new(),
                stats,
            }
        })
    }
}

/// `v` as the shorter of its decimal and its exponent form (`-1e300`, not 300 zeros), for
/// messages that quote a number read from a file.
pub(crate) fn number(v: f64) -> String {
    let (plain, exp) = (format!("{v}"), format!("{v:e}"));
    if exp.len() < plain.len() { exp } else { plain }
}

/// Refuse a shard whose recorded wall time is negative or not finite, or whose thread count is
/// 0: a checksum proves only that the file is as written, not that what was written is sound.
pub(crate) fn check_wall_and_threads(
    path: &Path,
    wall_s: f64,
    threads: u64,
) -> Result<(), ShardError> {
    let bad = |what: String| ShardError::Bad {
        path: path.to_path_buf(),
        what,
    };
    if !(wall_s.is_finite() && wall_s >= 0.0) {
        return Err(bad(format!(
            "its wall time is {} s: a time is a finite number ≥ 0",
            number(wall_s)
        )));
    }
    if threads == 0 {
        return Err(bad("it ran on 0 threads".into()));
    }
    Ok(())
}

/// Check every batch record of a run shard (`records`, laid out as its `header` says): each
/// holds its batch, in order; its photon counter is the header's photons per batch; and every
/// tally is a finite number, the flux tally's (energies) ≥ 0. The sign of the returns' bins is
/// checked by [`ShardSet::fold`], which knows whether they are co- and cross-polarised.
pub(super) fn check_records(
    path: &Path,
    header: &ShardHeader,
    records: &[u8],
) -> Result<(), ShardError> {
    let bad = |what: String| ShardError::Bad {
        path: path.to_path_buf(),
        what,
    };
    let (bins, ch) = (header.bins_per_batch as usize, header.channels as usize);
    let rec = header.record_bytes().unwrap_or(0) as usize;
    let parts = ["up", "down", "absorbed", "cut"];
    for (r, record) in records.chunks_exact(rec.max(1)).enumerate() {
        let batch = header.first_batch + r as u64;
        let index = u64_at(record, 0);
        if index != batch {
            return Err(bad(format!(
                "its record {r} holds batch {index} where batch {batch} belongs"
            )));
        }
        let photons = u64_at(record, 8);
        if photons != header.photons_per_batch {
            return Err(bad(format!(
                "batch {batch}: {photons} photons counted where each batch traces {}",
                header.photons_per_batch
            )));
        }
        let values = record[8 * (1 + N_COUNTERS)..].chunks_exact(8);
        for (i, v) in values
            .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
            .enumerate()
        {
            let what = || {
                if i < bins {
                    format!("returns tally {i} of {bins}")
                } else {
                    let k = i - bins;
                    format!(
                        "flux tally `{}` of channel {}",
                        parts[k / ch.max(1)],
                        k % ch.max(1)
                    )
                }
            };
            if !v.is_finite() {
                return Err(bad(format!(
                    "batch {batch}: {} is {}: a tally is a finite number",
                    what(),
                    number(v)
                )));
            }
            if i >= bins && v < 0.0 {
                return Err(bad(format!(
                    "batch {batch}: {} is {}: an energy is never negative",
                    what(),
                    number(v)
                )));
            }
        }
    }
    Ok(())
}

/// Refuse a batch whose returns tallies are negative: energies, ≥ 0 exactly for scalar light.
/// With polarised light each (gate, order, annulus) holds the co-polarised returns of the
/// `channels` channels, then the cross-polarised ones; each is half the intensity plus or
/// minus the analysed part, so rounding can leave one a few ulps below 0 where it is 0: each
/// must be ≥ −1e-9 times their sum, which must be ≥ 0.
pub(super) fn check_returns_signs(
    path: &Path,
    batch: &BatchTally,
    channels: usize,
    polarised: bool,
) -> Result<(), ShardError> {
    let bad = |i: usize, v: f64, why: &str| ShardError::Bad {
        path: path.to_path_buf(),
        what: format!(
            "batch {}: returns tally {i} of {} is {}: {why}",
            batch.index,
            batch.bins.len(),
            number(v)
        ),
    };
    if !polarised {
        return match batch.bins.iter().position(|v| *v < 0.0) {
            Some(i) => Err(bad(i, batch.bins[i], "an energy is never negative")),
            None => Ok(()),
        };
    }
    let n = channels.max(1);
    for (g, group) in batch.bins.chunks(2 * n).enumerate() {
        for k in 0..n.min(group.len()) {
            let (co, cross) = (group[k], group.get(n + k).copied().unwrap_or(0.0));
            // The smaller of the two decides.
            let (j, v) = if cross < co { (n + k, cross) } else { (k, co) };
            if v < -1e-9 * (co + cross).max(0.0) {
                return Err(bad(
                    g * 2 * n + j,
                    v,
                    "a co- or cross-polarised energy is never negative",
                ));
            }
        }
    }
    Ok(())
}
