//! Sharded Monte Carlo runs: a slice of a run's batches traced on any machine, stored raw in
//! one file, and the files of all slices folded into the outputs of the single run.
//!
//! A run of `B` batches is cut into `N` shards of consecutive batches: batch `b` belongs to
//! shard `⌊b·N/B⌋` ([`ShardSpec::of_batch`]), so shard `i` holds batches `⌈i·B/N⌉ …
//! ⌈(i+1)·B/N⌉ − 1` and shard sizes differ by one at most. Each batch draws from its own random
//! stream (seed, batch index), as in a single run, so a shard gives the same bytes on any
//! machine and thread count, and folding the shards' batches in batch order ([`merge`]) gives
//! the single run's numbers bit for bit (its wall time and thread count aside).
//!
//! # The shard file (`shard-I-of-N.lshard`, format 1)
//!
//! Little-endian throughout:
//!
//! | bytes | content |
//! |---|---|
//! | 16 | magic `lidarsim shard\n\0` |
//! | 4 | format version (u32, [`FORMAT`]) |
//! | 8 | header length `H` (u64) |
//! | `H` | header: JSON ([`ShardHeader`]; floats that matter as their IEEE-754 bits) |
//! | per batch, in batch order | batch index (u64), the nine [`RunStats`] counters (u64, in declaration order), `bins_per_batch` tallies (f64), the flux tally up, down, absorbed, cut (`channels` f64 each) |
//! | 8 | the shard's transport wall time \[s\] (f64) |
//! | 8 | worker threads it used (u64) |
//! | 8 | FNV-1a 64 checksum of every byte before it |
//!
//! The magic, format, header length, JSON header and trailing checksum are the framing of
//! every shard file (`FrameWriter`, `Frame`); the header's `kind` ([`KIND_RUN`];
//! [`KIND_DIAL`] for the ensemble shards of [`crate::study::shard`], [`KIND_SELECT`] for the
//! line-selection shards of [`crate::study::select_shard`]) says what the body holds, and
//! [`common_kind`] lets `lidarsim merge` tell them apart and refuse a mix. The checks of a
//! whole set of shards (one version, each shard once, none missing: `whole_set`) and the body
//! reader of the study shards (`Body`) are shared by every kind too.
//!
//! The tallies are the raw per-batch sums of [`BatchTally`] (before normalisation), so no
//! rounding happens between a shard and the fold. The header holds the lidarsim version, the
//! scene's path, text and digest ([`scene_digest`]), the seed, photons and batches, the shard
//! `I/N` and its batch range, and every transport option that changes the numbers.
//!
//! A merge reads the scene again from the text stored in every shard (relative paths in it
//! anchored at the scene's absolute path, as on a cluster's shared filesystem), checks that its
//! digest is still each shard's ([`scene_of`]), and runs every stage of [`pipeline::run_with`]
//! with the Monte Carlo folded from the files, checked finite and energy-conserving
//! ([`check_folded`]).

use std::fmt::{self, Write as _};
use std::fs;
use std::io::{self, BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Instant;

use rayon::prelude::*;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::digest::Fnv;
use crate::input::InputError;
use crate::output::{self, OutputError, OutputSet};
use crate::pipeline::{self, RunError, RunOutput};
use crate::scene::Scene;
use crate::transport::{
    self, BatchTally, Flux, McResult, RunStats, TransportError, TransportOptions,
};

/// First bytes of every shard file.
pub const MAGIC: &[u8; 16] = b"lidarsim shard\n\0";
/// Version of the shard file layout this lidarsim writes and reads.
pub const FORMAT: u32 = 1;
/// Extension of shard files; a merge of a directory reads every file with it.
pub const EXTENSION: &str = "lshard";
/// The lidarsim version written into shards; a merge refuses shards of another version, whose
/// tracer may draw differently.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
/// A header longer than this is taken for a corrupt length field (a scene text is kilobytes).
const MAX_HEADER_BYTES: u64 = 64 << 20;
/// Bytes before the header: magic, format, header length.
const PREAMBLE_BYTES: usize = 16 + 4 + 8;
/// Bytes after the batch records: wall time, threads, checksum.
const TRAILER_BYTES: usize = 8 + 8 + 8;
/// Counters of [`RunStats`] stored per batch.
const N_COUNTERS: usize = 9;

/// One shard of a run: `index` of `count`, written `I/N` on the command line (0-based, as
/// Slurm's `SLURM_ARRAY_TASK_ID`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShardSpec {
    /// Which shard, `0..count`.
    pub index: usize,
    /// Number of shards, at least 1.
    pub count: usize,
}

impl FromStr for ShardSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let bad = || format!("`{text}` is not I/N: shard I (0 to N − 1) of N shards, e.g. 3/8");
        let (i, n) = text.trim().split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        let max = crate::limits::MAX_BATCHES as usize;
        if count == 0 || count > max {
            return Err(format!(
                "`{text}`: the number of shards must lie in 1..={max}"
            ));
        }
        if index >= count {
            return Err(format!(
                "`{text}`: shard {index} of {count} does not exist (shards are numbered 0 to {})",
                count - 1
            ));
        }
        Ok(ShardSpec { index, count })
    }
}

impl fmt::Display for ShardSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl ShardSpec {
    /// The shard that batch `batch` of `batches` belongs to among `count`: `⌊batch·count /
    /// batches⌋`.
    pub fn of_batch(batch: usize, count: usize, batches: usize) -> usize {
        (batch as u128 * count as u128 / batches.max(1) as u128) as usize
    }

    /// The batches of this shard in a run of `batches`: `⌈i·B/N⌉ .. ⌈(i+1)·B/N⌉`, the batches
    /// `b` with [`ShardSpec::of_batch`]`(b) = i`.
    pub fn batches(&self, batches: usize) -> Range<usize> {
        let start = |i: usize| (i as u128 * batches as u128).div_ceil(self.count as u128) as usize;
        start(self.index)..start(self.index + 1)
    }

    /// The shard's file name, `shard-I-of-N.lshard`, I zero-padded to N's width so that the
    /// files list in order.
    pub fn file_name(&self) -> String {
        let w = self.count.to_string().len();
        format!(
            "shard-{:0w$}-of-{}.{EXTENSION}",
            self.index,
            self.count,
            w = w
        )
    }
}

/// The header of a shard file: what it is a slice of, and the options that shape its numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardHeader {
    /// What the shard is a slice of: [`KIND_RUN`] (absent in files of lidarsim 0.x before the
    /// ensemble shards: read as a run shard).
    #[serde(default = "run_kind")]
    pub kind: String,
    /// lidarsim version that wrote the shard.
    pub lidarsim_version: String,
    /// The scene file's absolute path ([`crate::scene::DEFAULT_SCENE_NAME`] for the default
    /// scene); relative paths inside the scene are anchored at it when a merge reads it again.
    pub scene_path: String,
    /// The scene text.
    pub scene_text: String,
    /// [`scene_digest`] of the scene as the shard ran it.
    pub scene_digest: String,
    /// Random seed.
    pub seed: u64,
    /// Photons asked for (the run traces `photons_per_batch × batches`).
    pub photons: u64,
    /// Batches of the whole run.
    pub batches: u64,
    /// Photons of each batch.
    pub photons_per_batch: u64,
    /// This shard, `0..shard_count`.
    pub shard_index: u64,
    /// Shards of the run.
    pub shard_count: u64,
    /// First batch of the shard.
    pub first_batch: u64,
    /// One past its last batch.
    pub end_batch: u64,
    /// Highest order tallied separately.
    pub max_order: u32,
    /// Probability of detector-directed importance sampling, as IEEE-754 bits.
    pub ddis_epsilon_bits: u64,
    /// Probability of range-stratified first collisions, as IEEE-754 bits.
    pub range_stratification_bits: u64,
    /// Whether the flux tally was on.
    pub flux_tally: bool,
    /// Tallies per batch (gate × order bin × FOV annulus × channel).
    pub bins_per_batch: u64,
    /// Monochromatic channels (values per flux part).
    pub channels: u64,
}

/// The `kind` of a run shard (`lidarsim run --shard`).
pub const KIND_RUN: &str = "run";
/// The `kind` of an ensemble shard (`lidarsim dial --shard`, [`crate::study::shard`]).
pub const KIND_DIAL: &str = "dial";
/// The `kind` of a line-selection shard (`lidarsim select-lines --shard`,
/// [`crate::study::select_shard`]).
pub const KIND_SELECT: &str = "select";

/// The subcommand that writes shards of `kind`.
fn command_of(kind: &str) -> &str {
    match kind {
        KIND_SELECT => "select-lines",
        k => k,
    }
}

fn run_kind() -> String {
    KIND_RUN.to_string()
}

impl ShardHeader {
    fn spec(&self) -> ShardSpec {
        ShardSpec {
            index: self.shard_index as usize,
            count: self.shard_count as usize,
        }
    }

    /// Bytes of one batch record.
    fn record_bytes(&self) -> Option<u64> {
        let values = (1 + N_COUNTERS as u64)
            .checked_add(self.bins_per_batch)?
            .checked_add(self.channels.checked_mul(4)?)?;
        values.checked_mul(8)
    }
}

/// Why a shard could not be written or shards could not be merged. Every variant names the
/// file(s) concerned.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ShardError {
    /// A file or directory could not be read.
    #[error("cannot read {}: {error}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What the system reported.
        error: io::Error,
    },
    /// A file is not a shard file, or is truncated or corrupt.
    #[error("{}: {what}", path.display())]
    Bad {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        what: String,
    },
    /// Two shards are not slices of the same run (or study: `dial`, `select-lines`).
    #[error("{} and {} are not shards of the same run or study: {what} differs ({first} against {second})", a.display(), b.display())]
    Mismatch {
        /// The first shard read.
        a: PathBuf,
        /// The shard that differs from it.
        b: PathBuf,
        /// What differs.
        what: &'static str,
        /// Its value in `a`.
        first: String,
        /// Its value in `b`.
        second: String,
    },
    /// The same shard twice.
    #[error("shard {spec} is given twice: {} and {}", a.display(), b.display())]
    Duplicate {
        /// The shard.
        spec: ShardSpec,
        /// One file.
        a: PathBuf,
        /// The other.
        b: PathBuf,
    },
    /// Shards are missing.
    #[error("{} of {count} shards missing ({}) among {}", missing.len(), list_indices(missing), list_paths(files))]
    Missing {
        /// Shards of the run.
        count: usize,
        /// The missing shard indices.
        missing: Vec<usize>,
        /// The files that were found.
        files: Vec<PathBuf>,
    },
    /// No shard file among the inputs.
    #[error("no shard files (*.{EXTENSION}) in {}", list_paths(.0))]
    NoShards(Vec<PathBuf>),
    /// The scene read again for the merge, from the same text in every shard, is not the
    /// scene the shards ran.
    #[error(
        "the scene {path} as read now from the text in {} is not the one the shards ran (digest {now}, shards {recorded}): a file it reads (phase table, line list, profile) has changed since, or is not at the same path, or the text was changed in every shard",
        list_paths(shards)
    )]
    SceneChanged {
        /// The scene's path.
        path: String,
        /// The shard files.
        shards: Vec<PathBuf>,
        /// Digest now.
        now: String,
        /// Digest in the shards.
        recorded: String,
    },
    /// A shard cannot be made of this run.
    #[error("--shard {spec}: {what}")]
    Spec {
        /// The shard asked for.
        spec: ShardSpec,
        /// Why not.
        what: String,
    },
    /// The scene stored in the shards could not be read.
    #[error(transparent)]
    Scene(#[from] InputError),
    /// A stage of the run failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// Output could not be written.
    #[error(transparent)]
    Output(#[from] OutputError),
}

fn list_indices(v: &[usize]) -> String {
    let mut s: Vec<String> = v.iter().take(20).map(|i| i.to_string()).collect();
    if v.len() > 20 {
        s.push(format!("… {} more", v.len() - 20));
    }
    s.join(", ")
}

fn list_paths(v: &[PathBuf]) -> String {
    let mut s: Vec<String> = v.iter().take(8).map(|p| p.display().to_string()).collect();
    if v.len() > 8 {
        s.push(format!("… {} more", v.len() - 8));
    }
    s.join(", ")
}

/// The digest of a scene as parsed: FNV-1a 64 of its `Debug` text, which holds every value
/// of the scene after validation (floats in their shortest exact form), its text, its path,
/// the overrides of photons and seed, and the contents of every file it read (phase tables,
/// line lists, profiles, line shapes) as parsed; the thread count is left out, as it does not
/// change the numbers. Two scenes with the same digest run the same photons.
pub fn scene_digest(scene: &Scene) -> String {
    let mut s = scene.clone();
    s.simulation.threads = 0;
    debug_digest(&s)
}

/// The digest of a run shard's scene: [`scene_digest`] of the scene as every shard runs it,
/// with its Monte Carlo on. A shard traces photons whether `--photons` asked for them or the
/// scene's own `photons` and `multiple_scattering` did (`--photons` sets
/// [`MultipleScattering::Always`](crate::scene::MultipleScattering::Always)), so the digest
/// identifies the scene and the settings it ran with, not how they were given: shards run with
/// or without `--photons` and `--seed` merge when they traced the same photons.
pub fn run_scene_digest(scene: &Scene) -> String {
    let mut s = scene.clone();
    s.simulation.multiple_scattering = crate::scene::MultipleScattering::Always;
    scene_digest(&s)
}

/// FNV-1a 64 of a value's `Debug` text, as 16 hex digits: the digest of a parsed input (a
/// scene, a profile set), which holds every value (floats in their shortest exact form).
pub fn debug_digest(value: &impl fmt::Debug) -> String {
    let mut h = Fnv::new();
    // Writing into the hasher cannot fail.
    let _ = write!(h, "{value:?}");
    format!("{:016x}", h.0)
}

/// Read a scene for a shard: by its absolute path, so that the shards of one scene file have
/// the same digest whatever directory each started in (`None`: the embedded default scene).
pub fn read_scene(path: Option<&Path>) -> Result<Scene, ShardError> {
    match path {
        Some(p) => {
            let abs = fs::canonicalize(p).map_err(|error| ShardError::Io {
                path: p.to_path_buf(),
                error,
            })?;
            Ok(Scene::read(&abs)?)
        }
        None => Ok(Scene::default_scene()?),
    }
}

/// What a shard run did.
#[derive(Debug, Clone)]
pub struct ShardReport {
    /// The file written.
    pub path: PathBuf,
    /// Its batches.
    pub batches: Range<usize>,
    /// Batches of the whole run.
    pub total_batches: usize,
    /// Photons per batch.
    pub photons_per_batch: u64,
    /// Wall time of the tracing \[s\].
    pub wall_s: f64,
    /// Worker threads.
    pub threads: usize,
}

/// The framing every shard file shares, whatever its kind: a writer that puts the magic, the
/// format and the JSON header first and hashes every byte that passes through it, so that
/// [`FrameWriter::finish`] can append the FNV-1a 64 checksum.
pub(crate) struct FrameWriter<W: Write> {
    inner: W,
    hash: Fnv,
}

impl<W: Write> FrameWriter<W> {
    /// Start a shard file on `inner` with the header `json`.
    pub(crate) fn start(inner: W, json: &[u8]) -> io::Result<Self> {
        let mut w = FrameWriter {
            inner,
            hash: Fnv::new(),
        };
        w.write_all(MAGIC)?;
        w.write_all(&FORMAT.to_le_bytes())?;
        w.write_all(&(json.len() as u64).to_le_bytes())?;
        w.write_all(json)?;
        Ok(w)
    }

    /// Append the checksum of every byte written and flush.
    pub(crate) fn finish(mut self) -> io::Result<()> {
        let sum = self.hash.0;
        self.inner.write_all(&sum.to_le_bytes())?;
        self.inner.flush()
    }
}

impl<W: Write> Write for FrameWriter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hash.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// Write the study shard file `path` whole or not at all: the framing with `header` (JSON),
/// the body that `body` writes, the checksum.
pub(crate) fn write_frame(
    path: &Path,
    header: &impl Serialize,
    body: impl FnOnce(&mut FrameWriter<BufWriter<&mut fs::File>>) -> io::Result<()>,
) -> Result<(), ShardError> {
    let json = serde_json::to_vec(header).map_err(|e| ShardError::Bad {
        path: path.to_path_buf(),
        what: format!("cannot encode the header: {e}"),
    })?;
    let mut set = OutputSet::new();
    set.write_with(path, |file| {
        let mut w = FrameWriter::start(BufWriter::new(file), &json)?;
        body(&mut w)?;
        w.finish()
    })?;
    set.commit()?;
    Ok(())
}

/// Write batch `t` as one record.
fn write_record(w: &mut impl Write, t: &BatchTally) -> io::Result<()> {
    // Destructured in full so that a new counter cannot be left out of the format silently.
    let RunStats {
        photons,
        collisions,
        surface_reflections,
        local_estimates,
        roulette_kills,
        cut,
        escaped,
        zero_weight,
        splits,
    } = t.stats;
    let counters: [u64; N_COUNTERS] = [
        photons,
        collisions,
        surface_reflections,
        local_estimates,
        roulette_kills,
        cut,
        escaped,
        zero_weight,
        splits,
    ];
    w.write_all(&(t.index as u64).to_le_bytes())?;
    for c in counters {
        w.write_all(&c.to_le_bytes())?;
    }
    for part in [
        &t.bins,
        &t.flux.up,
        &t.flux.down,
        &t.flux.absorbed,
        &t.flux.cut,
    ] {
        for v in part {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    Ok(())
}

/// Run shard `spec` of `scene` with `transport` and write it as `out_dir/`[`ShardSpec::file_name`]
/// (whole or not at all).
///
/// The shard runs [`pipeline::run_with`] up to the Monte Carlo, so that everything checked
/// before it in a single run (the optics, the analytic returns, the retrieval's set-up and its
/// analytic products) is checked here too: a scene a merge would refuse is refused before any
/// photon is traced. The Monte Carlo step traces the shard's batches on `transport.threads`
/// threads and writes them; the stages after it are the merge's.
pub fn run(
    scene: &Scene,
    transport: &TransportOptions,
    spec: ShardSpec,
    out_dir: &Path,
) -> Result<ShardReport, ShardError> {
    if transport.photons == 0 {
        return Err(ShardError::Spec {
            spec,
            what: "a shard needs photons (0 photons runs the analytic lidar equation only)".into(),
        });
    }
    let path = out_dir.join(spec.file_name());
    output::check_paths(&[&path])?;
    let mut outcome: Option<Result<ShardReport, ShardError>> = None;
    let result = pipeline::run_with(scene, transport, &mut |plan| {
        outcome = Some(write_shard(scene, transport, plan, spec, &path));
        // Stop the pipeline here: the stages after the Monte Carlo belong to the merge.
        Err(TransportError::Options("shard written".into()))
    });
    match (outcome, result) {
        (Some(done), _) => done,
        (None, Err(e)) => Err(e.into()),
        // `run_with` calls the Monte Carlo whenever photons > 0.
        (None, Ok(_)) => Err(ShardError::Spec {
            spec,
            what: "the scene runs no Monte Carlo".into(),
        }),
    }
}

/// Trace the batches of `spec` from `plan` and write the shard file.
fn write_shard(
    scene: &Scene,
    transport: &TransportOptions,
    plan: &transport::Plan,
    spec: ShardSpec,
    path: &Path,
) -> Result<ShardReport, ShardError> {
    let total = plan.batches();
    if spec.count > total {
        return Err(ShardError::Spec {
            spec,
            what: format!(
                "{} shards of a run of {total} batches leave some without a batch (at most one shard per batch; `simulation.batches` sets the batches)",
                spec.count
            ),
        });
    }
    let range = spec.batches(total);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(transport.threads)
        .build()
        .map_err(|e| {
            RunError::Transport(TransportError::Threads(transport.threads, e.to_string()))
        })?;
    let threads = pool.current_num_threads();
    let started = Instant::now();
    // The first batch alone: its buffers give the header's sizes and the chunk size.
    let first = plan.trace_batch(range.start);
    let header = ShardHeader {
        kind: KIND_RUN.to_string(),
        lidarsim_version: VERSION.to_string(),
        scene_path: scene.path.to_string_lossy().into_owned(),
        scene_text: scene.text().to_string(),
        scene_digest: run_scene_digest(scene),
        seed: transport.seed,
        photons: transport.photons,
        batches: total as u64,
        photons_per_batch: plan.photons_per_batch(),
        shard_index: spec.index as u64,
        shard_count: spec.count as u64,
        first_batch: range.start as u64,
        end_batch: range.end as u64,
        max_order: transport.max_order,
        ddis_epsilon_bits: transport.ddis_epsilon.to_bits(),
        range_stratification_bits: transport.range_stratification.to_bits(),
        flux_tally: transport.flux_tally,
        bins_per_batch: first.bins.len() as u64,
        channels: first.flux.up.len() as u64,
    };
    let json = serde_json::to_vec(&header).map_err(|e| ShardError::Bad {
        path: path.to_path_buf(),
        what: format!("cannot encode the header: {e}"),
    })?;
    // A few batch buffers per thread at a time, within the memory limit; the size does not
    // change the bytes.
    let chunk = (4 * threads)
        .min(crate::limits::MAX_LIVE_TALLY_VALUES / first.bins.len().max(1))
        .max(1);
    let mut wall_s = 0.0;
    let mut set = OutputSet::new();
    set.write_with(path, |file| {
        let mut w = FrameWriter::start(BufWriter::new(file), &json)?;
        write_record(&mut w, &first)?;
        let mut start = range.start + 1;
        while start < range.end {
            let end = (start + chunk).min(range.end);
            let tallies: Vec<BatchTally> = pool.install(|| {
                (start..end)
                    .into_par_iter()
                    .map(|b| plan.trace_batch(b))
                    .collect()
            });
            for t in &tallies {
                write_record(&mut w, t)?;
            }
            start = end;
        }
        wall_s = started.elapsed().as_secs_f64();
        w.write_all(&wall_s.to_le_bytes())?;
        w.write_all(&(threads as u64).to_le_bytes())?;
        w.finish()
    })?;
    set.commit()?;
    Ok(ShardReport {
        path: path.to_path_buf(),
        batches: range,
        total_batches: total,
        photons_per_batch: plan.photons_per_batch(),
        wall_s,
        threads,
    })
}

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

/// Little-endian u64 at `at` (the caller has checked the length).
fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

/// The framing of a shard file read back, whatever its kind: where its header and body lie,
/// its `kind`, and whether its checksum matches (checked last by the caller, so that a
/// truncation reads as one).
#[derive(Debug, Clone)]
pub(crate) struct Frame {
    /// The header's `kind` ([`KIND_RUN`] when it has none or cannot be read).
    pub(crate) kind: String,
    /// Offset of the header.
    header_at: usize,
    /// Offset of the body (one past the header).
    pub(crate) body_at: usize,
    /// Offset of the checksum (one past the body and any trailer).
    pub(crate) sum_at: usize,
    /// Whether the checksum matches.
    pub(crate) checksum_ok: bool,
    computed: u64,
    stored: u64,
}

impl Frame {
    /// Check the magic, format and header length of `bytes` (read from `path`), with
    /// `trailer` bytes before the checksum at the end, and compute the checksum.
    pub(crate) fn parse(path: &Path, bytes: &[u8], trailer: usize) -> Result<Frame, ShardError> {
        let bad = |what: String| ShardError::Bad {
            path: path.to_path_buf(),
            what,
        };
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            return Err(bad(
                "not a lidarsim shard file (no `lidarsim shard` magic at its start)".into(),
            ));
        }
        if bytes.len() < PREAMBLE_BYTES + trailer + 8 {
            return Err(bad(format!(
                "truncated: {} bytes, too short for a shard file",
                bytes.len()
            )));
        }
        let format = u32::from_le_bytes([bytes[16], bytes[17], bytes[18], bytes[19]]);
        if format != FORMAT {
            return Err(bad(format!(
                "shard file format {format}; this lidarsim ({VERSION}) reads format {FORMAT}"
            )));
        }
        let header_len = u64_at(bytes, 20);
        let available = (bytes.len() - PREAMBLE_BYTES - trailer - 8) as u64;
        if header_len > MAX_HEADER_BYTES || header_len > available {
            return Err(bad(format!(
                "truncated or corrupt: a header of {header_len} bytes in a file of {} bytes",
                bytes.len()
            )));
        }
        let body_at = PREAMBLE_BYTES + header_len as usize;
        let sum_at = bytes.len() - 8;
        let mut h = Fnv::new();
        h.update(&bytes[..sum_at]);
        let stored = u64_at(bytes, sum_at);
        Ok(Frame {
            kind: header_kind(&bytes[PREAMBLE_BYTES..body_at]),
            header_at: PREAMBLE_BYTES,
            body_at,
            sum_at,
            checksum_ok: h.0 == stored,
            computed: h.0,
            stored,
        })
    }

    /// The header's bytes (JSON).
    pub(crate) fn header<'b>(&self, bytes: &'b [u8]) -> &'b [u8] {
        &bytes[self.header_at..self.body_at]
    }

    /// Refuse the file if its checksum does not match.
    pub(crate) fn check_sum(&self, path: &Path) -> Result<(), ShardError> {
        if self.checksum_ok {
            return Ok(());
        }
        Err(ShardError::Bad {
            path: path.to_path_buf(),
            what: format!(
                "corrupt: checksum {:016x} where the file records {:016x}",
                self.computed, self.stored
            ),
        })
    }
}

/// Check the framing of `bytes` (read from `path`, with `trailer` bytes before the checksum)
/// and read its JSON header as a shard of `kind`. The checksum is the caller's to check
/// ([`Frame::check_sum`]), after any check of the body's length, so that a truncation reads
/// as one.
pub(crate) fn read_header<H: DeserializeOwned>(
    path: &Path,
    bytes: &[u8],
    trailer: usize,
    kind: &str,
) -> Result<(Frame, H), ShardError> {
    let bad = |what: String| ShardError::Bad {
        path: path.to_path_buf(),
        what,
    };
    let frame = Frame::parse(path, bytes, trailer)?;
    if frame.kind != kind {
        return Err(bad(format!(
            "a `{}` shard (from `lidarsim {} --shard`), not a {kind} shard",
            frame.kind,
            command_of(&frame.kind)
        )));
    }
    match serde_json::from_slice(frame.header(bytes)) {
        Ok(h) => Ok((frame, h)),
        Err(e) if frame.checksum_ok => Err(bad(format!("its header cannot be read: {e}"))),
        Err(_) => Err(bad(
            "corrupt or truncated: its header cannot be read and its checksum does not match"
                .into(),
        )),
    }
}

/// Write a string as its length (u64) and its UTF-8 bytes ([`Body::string`] reads it).
pub(crate) fn write_str(w: &mut impl Write, s: &str) -> io::Result<()> {
    w.write_all(&(s.len() as u64).to_le_bytes())?;
    w.write_all(s.as_bytes())
}

/// A reader of a study shard's body (little-endian) that refuses to read past its end; its
/// errors say what is wrong, the caller names the file.
#[derive(Debug)]
pub struct Body<'b> {
    bytes: &'b [u8],
    at: usize,
}

impl<'b> Body<'b> {
    /// A reader at the start of `bytes`.
    pub fn new(bytes: &'b [u8]) -> Self {
        Body { bytes, at: 0 }
    }

    /// Bytes not read yet.
    pub fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn take(&mut self, n: usize) -> Result<&'b [u8], String> {
        if n > self.left() {
            return Err(format!(
                "truncated or corrupt: its records end {} bytes early",
                n - self.left()
            ));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }

    /// One byte.
    pub fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }

    /// A u64.
    pub fn u64(&mut self) -> Result<u64, String> {
        let mut a = [0u8; 8];
        a.copy_from_slice(self.take(8)?);
        Ok(u64::from_le_bytes(a))
    }

    /// An f64 from its bits.
    pub fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_bits(self.u64()?))
    }

    /// A string: its length (u64), then its UTF-8 bytes.
    pub fn string(&mut self) -> Result<String, String> {
        let n = self.u64()?;
        let n = usize::try_from(n).map_err(|_| format!("corrupt: a string of {n} bytes"))?;
        String::from_utf8(self.take(n)?.to_vec())
            .map_err(|_| "corrupt: a string that is not UTF-8".to_string())
    }

    /// A count (u64) of `what`, each at least `min_bytes` long: refused if the rest of the
    /// body cannot hold them, so that nothing is allocated on a corrupt count.
    pub fn count(&mut self, min_bytes: usize, what: &str) -> Result<usize, String> {
        let n = self.u64()?;
        let left = self.left();
        if n > (left / min_bytes.max(1)) as u64 {
            return Err(format!("truncated or corrupt: {n} {what} in {left} bytes"));
        }
        Ok(n as usize)
    }

    /// A count (u64) of f64 and the values.
    pub fn f64s(&mut self, what: &str) -> Result<Vec<f64>, String> {
        let n = self.count(8, what)?;
        (0..n).map(|_| self.f64()).collect()
    }
}

/// A shard file as the checks of a set see it: where it was read from, the lidarsim version
/// that wrote it, and which shard it is.
pub(crate) trait Sharded {
    /// The file.
    fn path(&self) -> &Path;
    /// The lidarsim version that wrote it.
    fn version(&self) -> &str;
    /// Which shard of how many.
    fn spec(&self) -> ShardSpec;
}

impl Sharded for (PathBuf, ShardHeader) {
    fn path(&self) -> &Path {
        &self.0
    }

    fn version(&self) -> &str {
        &self.1.lidarsim_version
    }

    fn spec(&self) -> ShardSpec {
        self.1.spec()
    }
}

/// Every shard of one run or study, in shard order: each of `paths` read by `read` and
/// refused if another lidarsim version wrote it or if `same` finds that it differs from the
/// first (naming both files); then the set refused if a shard is given twice or is missing.
pub(crate) fn whole_set<F: Sharded>(
    paths: &[PathBuf],
    read: impl Fn(&Path) -> Result<F, ShardError>,
    same: impl Fn(&F, &F) -> Result<(), ShardError>,
) -> Result<Vec<F>, ShardError> {
    let mut files: Vec<F> = Vec::with_capacity(paths.len());
    for p in paths {
        let f = read(p)?;
        if f.version() != VERSION {
            return Err(ShardError::Bad {
                path: p.clone(),
                what: format!(
                    "written by lidarsim {}; this is lidarsim {VERSION} (shard format {FORMAT}), whose numbers may differ",
                    f.version()
                ),
            });
        }
        if let Some(first) = files.first() {
            same(first, &f)?;
        }
        files.push(f);
    }
    files.sort_by_key(|f| f.spec().index);
    for w in files.windows(2) {
        if w[0].spec().index == w[1].spec().index {
            return Err(ShardError::Duplicate {
                spec: w[0].spec(),
                a: w[0].path().to_path_buf(),
                b: w[1].path().to_path_buf(),
            });
        }
    }
    let Some(first) = files.first() else {
        return Err(ShardError::NoShards(paths.to_vec()));
    };
    let count = first.spec().count;
    if files.len() != count {
        // In shard order, each once.
        let have: Vec<usize> = files.iter().map(|f| f.spec().index).collect();
        return Err(ShardError::Missing {
            count,
            missing: (0..count)
                .filter(|i| have.binary_search(i).is_err())
                .collect(),
            files: files.iter().map(|f| f.path().to_path_buf()).collect(),
        });
    }
    Ok(files)
}

/// What one shard says of its scene: the shard file, and its header's scene path, text and
/// digest.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SceneClaim<'a> {
    /// The shard file.
    pub(crate) file: &'a Path,
    /// The scene's path as the shard recorded it.
    pub(crate) path: &'a str,
    /// The scene's text stored in the shard.
    pub(crate) text: &'a str,
    /// The digest of the scene as the shard ran it.
    pub(crate) digest: &'a str,
}

/// The scene a set of shards ran, read again from the text every shard stores (each distinct
/// text once), made ready by `prepare` (a run shard's photons and seed) and refused unless its
/// digest (by `digest`) is the one that shard recorded; the shards' headers have been found to
/// agree on the path and the digest ([`whole_set`]).
///
/// A text that does not parse, or whose digest is not its shard's while another shard's text
/// differs from it, was damaged in that shard: the error names the shard file. When every
/// shard holds the same text and its digest is not theirs, a file the scene reads has changed
/// since (or the text was changed in every shard alike): [`ShardError::SceneChanged`], naming
/// the shards.
pub(crate) fn scene_of(
    claims: &[SceneClaim],
    prepare: impl Fn(&mut Scene) -> Result<(), String>,
    digest: impl Fn(&Scene) -> String,
) -> Result<Scene, ShardError> {
    let Some(first) = claims.first() else {
        return Err(ShardError::NoShards(Vec::new()));
    };
    let all_alike = claims.iter().all(|c| c.text == first.text);
    let bad = |c: &SceneClaim, what: String| ShardError::Bad {
        path: c.file.to_path_buf(),
        what,
    };
    let mut scene: Option<Scene> = None;
    let mut seen = std::collections::HashSet::new();
    for c in claims {
        if !seen.insert(c.text) {
            continue;
        }
        let mut s = Scene::from_toml(Path::new(c.path), c.text).map_err(|e| {
            if e.path == Path::new(c.path) {
                bad(c, format!("its scene text does not parse: {e}"))
            } else {
                bad(c, format!("its scene cannot be built again: {e}"))
            }
        })?;
        prepare(&mut s).map_err(|what| bad(c, what))?;
        let now = digest(&s);
        if now != c.digest {
            if !all_alike {
                return Err(bad(
                    c,
                    format!(
                        "its scene text does not match its digest (digest {now} of the text, {} recorded): the text has been changed since the shard was written",
                        c.digest
                    ),
                ));
            }
            return Err(ShardError::SceneChanged {
                path: c.path.to_string(),
                shards: claims.iter().map(|c| c.file.to_path_buf()).collect(),
                now,
                recorded: c.digest.to_string(),
            });
        }
        scene.get_or_insert(s);
    }
    // Every distinct text has its shard's digest, and the digests agree, so the texts do
    // (the digest holds the text): unless two texts collide in FNV-1a.
    if let Some(c) = claims.iter().find(|c| c.text != first.text) {
        return Err(bad(
            c,
            format!(
                "its scene text differs from that of {} under the same digest",
                first.file.display()
            ),
        ));
    }
    scene.ok_or_else(|| ShardError::NoShards(Vec::new()))
}

/// The `kind` of a shard header (JSON): [`KIND_RUN`] when it names none or cannot be read.
fn header_kind(json: &[u8]) -> String {
    serde_json::from_slice::<serde_json::Value>(json)
        .ok()
        .and_then(|v| v.get("kind").and_then(|k| k.as_str()).map(String::from))
        .unwrap_or_else(run_kind)
}

/// The kind of the shard file `path` ([`KIND_RUN`], [`KIND_DIAL`] or [`KIND_SELECT`]), from its
/// header only.
pub fn shard_kind(path: &Path) -> Result<String, ShardError> {
    use std::io::Read;
    let io_err = |error| ShardError::Io {
        path: path.to_path_buf(),
        error,
    };
    let bad = |what: String| ShardError::Bad {
        path: path.to_path_buf(),
        what,
    };
    let mut f = fs::File::open(path).map_err(io_err)?;
    let mut pre = [0u8; PREAMBLE_BYTES];
    let mut got = 0;
    while got < PREAMBLE_BYTES {
        match f.read(&mut pre[got..]).map_err(io_err)? {
            0 => break,
            n => got += n,
        }
    }
    if got < MAGIC.len() || &pre[..MAGIC.len()] != MAGIC {
        return Err(bad(
            "not a lidarsim shard file (no `lidarsim shard` magic at its start)".into(),
        ));
    }
    if got < PREAMBLE_BYTES {
        return Err(bad(format!(
            "truncated: {got} bytes, too short for a shard file"
        )));
    }
    let len = u64_at(&pre, 20);
    let size = f.metadata().map_err(io_err)?.len();
    if len > MAX_HEADER_BYTES || len > size.saturating_sub(PREAMBLE_BYTES as u64) {
        return Err(bad(format!(
            "truncated or corrupt: a header of {len} bytes in a file of {size} bytes"
        )));
    }
    let mut json = vec![0u8; len as usize];
    f.read_exact(&mut json).map_err(io_err)?;
    Ok(header_kind(&json))
}

/// The one kind of every shard file in `paths`; shards of different kinds are refused, naming
/// a file of each.
pub fn common_kind(paths: &[PathBuf]) -> Result<String, ShardError> {
    let mut first: Option<(&PathBuf, String)> = None;
    for p in paths {
        let k = shard_kind(p)?;
        match &first {
            None => first = Some((p, k)),
            Some((a, ka)) if *ka != k => {
                return Err(ShardError::Mismatch {
                    a: (*a).clone(),
                    b: p.clone(),
                    what: "the kind of shard (`run --shard`, `dial --shard` or `select-lines --shard`)",
                    first: ka.clone(),
                    second: k,
                });
            }
            Some(_) => {}
        }
    }
    first
        .map(|(_, k)| k)
        .ok_or_else(|| ShardError::NoShards(paths.to_vec()))
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
fn check_records(path: &Path, header: &ShardHeader, records: &[u8]) -> Result<(), ShardError> {
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
fn check_returns_signs(
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

/// The shard files among `inputs`: a directory gives every `*.lshard` file in it, a file is
/// taken as it is.
pub fn shard_paths(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, ShardError> {
    let mut out = Vec::new();
    for p in inputs {
        let meta = fs::metadata(p).map_err(|error| ShardError::Io {
            path: p.clone(),
            error,
        })?;
        if meta.is_dir() {
            let mut found = Vec::new();
            for entry in fs::read_dir(p).map_err(|error| ShardError::Io {
                path: p.clone(),
                error,
            })? {
                let entry = entry.map_err(|error| ShardError::Io {
                    path: p.clone(),
                    error,
                })?;
                let path = entry.path();
                if path.extension().is_some_and(|e| e == EXTENSION) && path.is_file() {
                    found.push(path);
                }
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    if out.is_empty() {
        return Err(ShardError::NoShards(inputs.to_vec()));
    }
    Ok(out)
}

/// Every shard of one run, checked against each other: same version, scene, seed, photons,
/// batches, shard count and options; each shard exactly once.
#[derive(Debug, Clone)]
pub struct ShardSet {
    /// The shard files in shard order, headers only (the fold reads them again).
    pub shards: Vec<(PathBuf, ShardHeader)>,
}

impl ShardSet {
    /// Read and check the shard files `paths` ([`shard_paths`]). Each file is read whole and
    /// checked here, so that a damaged shard is refused before the optics are built.
    pub fn open(paths: &[PathBuf]) -> Result<ShardSet, ShardError> {
        let shards = whole_set(
            paths,
            |p| {
                let f = ShardFile::read(p)?;
                Ok((f.path, f.header))
            },
            |(a, ha), (b, hb)| check_same(a, ha, b, hb),
        )?;
        Ok(ShardSet { shards })
    }

    fn first(&self) -> &ShardHeader {
        &self.shards[0].1
    }

    /// The scene the shards ran, read again from the text of every shard at their path, with
    /// their photons and seed; refused if its digest is no longer theirs ([`scene_of`]).
    pub fn scene(&self) -> Result<Scene, ShardError> {
        let h = self.first();
        let claims: Vec<SceneClaim> = self
            .shards
            .iter()
            .map(|(file, h)| SceneClaim {
                file,
                path: &h.scene_path,
                text: &h.scene_text,
                digest: &h.scene_digest,
            })
            .collect();
        scene_of(
            &claims,
            |s| s.override_simulation(Some(h.photons), Some(h.seed), None),
            run_scene_digest,
        )
    }

    /// The transport options the shards ran with (threads: all cores; they do not matter).
    pub fn transport_options(&self, scene: &Scene) -> TransportOptions {
        let h = self.first();
        let mut o = TransportOptions::from_scene(scene);
        o.photons = h.photons;
        o.seed = h.seed;
        o.max_order = h.max_order;
        o.ddis_epsilon = f64::from_bits(h.ddis_epsilon_bits);
        o.range_stratification = f64::from_bits(h.range_stratification_bits);
        o.flux_tally = h.flux_tally;
        o
    }

    /// Fold every shard's batches in batch order into the run's result. Its `wall_s` is the sum
    /// of the shards' transport times, its `threads` the most any shard used. `scene` is the
    /// scene the shards ran ([`ShardSet::scene`]): whether its light is polarised (the returns
    /// tallies are co- and cross-polarised), for the check of their signs, and its lidar, for
    /// the check of the energy received ([`check_folded`]).
    pub fn fold(&self, plan: &transport::Plan, scene: &Scene) -> Result<McResult, ShardError> {
        let polarised = scene.lidar.polarisation != crate::scene::Polarisation::None;
        let h = self.first();
        let (path0, _) = &self.shards[0];
        if plan.batches() as u64 != h.batches || plan.photons_per_batch() != h.photons_per_batch {
            return Err(ShardError::Bad {
                path: path0.clone(),
                what: format!(
                    "{} batches of {} photons, where the scene read now plans {} of {}",
                    h.batches,
                    h.photons_per_batch,
                    plan.batches(),
                    plan.photons_per_batch()
                ),
            });
        }
        let channels = plan.channels().max(1);
        // Returns tallies per channel: co- and cross-polarised ones count apart (channel fastest).
        let tally_channels = if polarised { 2 * channels } else { channels };
        // A batch's raw tallies in joules, as `Plan` scales them: pulse energy × optical
        // efficiency × telescope area per photon of the batch (the tallies are weight ×
        // geometric factor [sr⁻¹ m⁻², per m² of aperture]).
        let lidar = &scene.lidar;
        let joules_per_tally =
            lidar.pulse_energy_j * lidar.optical_efficiency * lidar.telescope_area_m2()
                / h.photons_per_batch.max(1) as f64;
        // Each batch's received energy per channel: every gate, order and field of view (the
        // tally's annuli and exact-order bins do not overlap), co and cross together.
        let mut received = Vec::with_capacity(h.batches as usize * channels);
        let mut fold = plan.fold();
        let (mut wall_s, mut threads) = (0.0, 0usize);
        for (path, header) in &self.shards {
            // Read again (one file in memory at a time); it may have changed since it was
            // checked.
            let f = ShardFile::read(path)?;
            if f.header != *header {
                return Err(ShardError::Bad {
                    path: path.clone(),
                    what: "changed while the merge was running".into(),
                });
            }
            for t in f.batches() {
                check_returns_signs(path, &t, h.channels as usize, polarised)?;
                let mut sums = vec![0.0; channels];
                for (i, v) in t.bins.iter().enumerate() {
                    sums[(i % tally_channels) % channels] += v;
                }
                received.extend(sums.iter().map(|v| v * joules_per_tally));
                fold.add(t).map_err(|e| ShardError::Bad {
                    path: path.clone(),
                    what: e.to_string(),
                })?;
            }
            wall_s += f.wall_s;
            threads = threads.max(f.threads as usize);
        }
        let result = fold.finish(wall_s, threads).map_err(|e| ShardError::Bad {
            path: path0.clone(),
            what: e.to_string(),
        })?;
        let limit_j = lidar.pulse_energy_j * lidar.optical_efficiency;
        check_folded(self, &result, &received, channels, limit_j)?;
        Ok(result)
    }

    /// The shard file that holds batch `batch`.
    fn file_of_batch(&self, batch: usize) -> &Path {
        let h = self.first();
        let i = ShardSpec::of_batch(batch, h.shard_count as usize, h.batches as usize);
        self.shards
            .get(i)
            .map(|(p, _)| p.as_path())
            .unwrap_or(&self.shards[0].0)
    }
}

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
fn check_folded(
    set: &ShardSet,
    r: &McResult,
    received: &[f64],
    channels: usize,
    limit_j: f64,
) -> Result<(), ShardError> {
    let batches = received.len() / channels.max(1);
    let names = &r.returns.channels;
    let name = |k: usize| names.get(k).cloned().unwrap_or_else(|| k.to_string());
    // The batch that received the most in channel k (a non-finite sum first).
    let worst = |k: usize| {
        (0..batches)
            .max_by(|&a, &b| {
                let (x, y) = (received[a * channels + k], received[b * channels + k]);
                let key = |v: f64| if v.is_finite() { v } else { f64::INFINITY };
                key(x).total_cmp(&key(y))
            })
            .unwrap_or(0)
    };
    let blame = |k: usize, what: String| {
        let b = worst(k);
        ShardError::Bad {
            path: set.file_of_batch(b).to_path_buf(),
            what: format!(
                "channel `{}`: {what} (the largest share comes from its batch {b}; the shards fold into it, each finite and ≥ 0 alone)",
                name(k)
            ),
        }
    };
    let improbable_j = batches as f64 * limit_j * IMPROBABLE_FACTOR;
    for k in 0..channels {
        if batches == 0 {
            break;
        }
        let b = worst(k);
        let v = received[b * channels + k];
        if !v.is_finite() || v > improbable_j {
            return Err(ShardError::Bad {
                path: set.file_of_batch(b).to_path_buf(),
                what: format!(
                    "channel `{}`: its batch {b} receives {} J over all gates, orders and fields of view, where the pulse sends {} J through the receiver (pulse energy × optical efficiency): in a run that conserves energy one of its {batches} batches exceeds {} J with a probability below {:e} (Markov's inequality)",
                    name(k),
                    number(v),
                    number(limit_j),
                    number(improbable_j),
                    1.0 / IMPROBABLE_FACTOR
                ),
            });
        }
    }
    // Every set of returns the fold made, with what it is and whether its channels are the
    // transport's (a combination's blames the transport channel whose batch received most).
    let mut sets: Vec<(&str, &crate::returns::Returns, bool)> = vec![("returns", &r.returns, true)];
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
                let v = received[worst(k) * channels + k];
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
                return Err(blame(
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
            return Err(blame(
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
        if let Some(k) = (0..mean.len()).find(|&k| !(mean[k].is_finite() && err[k].is_finite())) {
            return Err(blame(
                k.min(channels - 1),
                format!(
                    "the merged flux `{part}` is {} ± {}: not finite",
                    number(mean[k]),
                    number(err[k])
                ),
            ));
        }
    }
    if batches == 0 {
        return Ok(());
    }
    for k in 0..channels {
        let values = (0..batches).map(|b| received[b * channels + k]);
        let n = batches as f64;
        // Scaled by the largest, so that neither the mean nor the squares overflow.
        let scale = values.clone().fold(0.0f64, |m, v| m.max(v.abs()));
        if !scale.is_finite() {
            return Err(blame(
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
            return Err(blame(
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
fn check_same(a: &Path, ha: &ShardHeader, b: &Path, hb: &ShardHeader) -> Result<(), ShardError> {
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

/// A merged run: the scene and everything a single run of it produces.
#[derive(Debug)]
pub struct Merged {
    /// The scene the shards ran.
    pub scene: Scene,
    /// The run, its Monte Carlo folded from the shards.
    pub run: RunOutput,
    /// Shards folded.
    pub shards: usize,
}

/// Merge the shards found in `inputs` (directories or files): check them ([`ShardSet::open`]),
/// read their scene again ([`ShardSet::scene`]) and run every stage with the Monte Carlo folded
/// from them, which gives the single run's numbers.
pub fn merge(inputs: &[PathBuf]) -> Result<Merged, ShardError> {
    let set = ShardSet::open(&shard_paths(inputs)?)?;
    let scene = set.scene()?;
    let opts = set.transport_options(&scene);
    let mut failure: Option<ShardError> = None;
    let result = pipeline::run_with(&scene, &opts, &mut |plan| {
        set.fold(plan, &scene).map_err(|e| {
            failure = Some(e);
            // The real error is `failure`; this one only stops the pipeline.
            TransportError::Options("the shards could not be folded".into())
        })
    });
    if let Some(e) = failure {
        return Err(e);
    }
    Ok(Merged {
        scene,
        run: result?,
        shards: set.shards.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_specs_parse_and_refuse() {
        assert_eq!(
            "3/8".parse::<ShardSpec>(),
            Ok(ShardSpec { index: 3, count: 8 })
        );
        assert_eq!(
            " 0 / 1 ".parse::<ShardSpec>(),
            Ok(ShardSpec { index: 0, count: 1 })
        );
        for bad in [
            "8/8", "0/0", "3", "a/4", "-1/4", "1/-4", "1/2/3", "", "0/10001",
        ] {
            assert!(bad.parse::<ShardSpec>().is_err(), "{bad}");
        }
    }

    /// The shards' batch ranges tile 0..B in order, none empty, sizes within one of each
    /// other, and agree with `of_batch` for every batch.
    #[test]
    fn shards_tile_the_batches_and_agree_with_of_batch() {
        for batches in 1..=60 {
            for count in 1..=batches {
                let mut next = 0;
                let (mut small, mut large) = (usize::MAX, 0);
                for index in 0..count {
                    let r = ShardSpec { index, count }.batches(batches);
                    assert_eq!(r.start, next, "B {batches} N {count} shard {index}");
                    assert!(r.end > r.start);
                    small = small.min(r.len());
                    large = large.max(r.len());
                    for b in r.clone() {
                        assert_eq!(ShardSpec::of_batch(b, count, batches), index);
                    }
                    next = r.end;
                }
                assert_eq!(next, batches);
                assert!(large - small <= 1);
            }
        }
        // Large counts do not overflow.
        let r = ShardSpec {
            index: 9_999,
            count: 10_000,
        }
        .batches(10_000);
        assert_eq!(r, 9_999..10_000);
    }

    #[test]
    fn file_names_sort_in_shard_order() {
        assert_eq!(
            ShardSpec {
                index: 3,
                count: 100
            }
            .file_name(),
            "shard-003-of-100.lshard"
        );
        assert_eq!(
            ShardSpec { index: 0, count: 4 }.file_name(),
            "shard-0-of-4.lshard"
        );
    }

    /// FNV-1a 64 test vectors (Fowler, Noll and Vo; draft-eastlake-fnv).
    #[test]
    fn fnv_matches_its_published_vectors() {
        for (text, want) in [
            ("", 0xcbf2_9ce4_8422_2325u64),
            ("a", 0xaf63_dc4c_8601_ec8c),
            ("foobar", 0x8594_4171_f739_67e8),
        ] {
            let mut h = Fnv::new();
            h.update(text.as_bytes());
            assert_eq!(h.0, want, "{text:?}");
        }
    }

    /// The digest is that of the scene as parsed: the same for the same scene read twice or
    /// run on other threads, different for another seed, photon count or value.
    #[test]
    fn the_digest_follows_the_parsed_scene() {
        let a = Scene::default_scene().unwrap();
        let mut b = Scene::default_scene().unwrap();
        assert_eq!(scene_digest(&a), scene_digest(&b));
        b.override_simulation(None, None, Some(7)).unwrap();
        assert_eq!(scene_digest(&a), scene_digest(&b), "threads do not count");
        b.override_simulation(None, Some(2), None).unwrap();
        assert_ne!(scene_digest(&a), scene_digest(&b), "seed");
        let mut c = a.clone();
        c.override_simulation(Some(5000), None, None).unwrap();
        assert_ne!(scene_digest(&a), scene_digest(&c), "photons");
        let mut d = a.clone();
        d.lidar.telescope_diameter_m = f64::from_bits(d.lidar.telescope_diameter_m.to_bits() + 1);
        assert_ne!(scene_digest(&a), scene_digest(&d), "one ulp");
    }
}
