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
//! digest is still each shard's ([`scene_of`]), and runs the pipeline ([`pipeline::prepare`],
//! [`pipeline::Prepared::finish`]) with the Monte Carlo folded from the files, checked finite
//! and energy-conserving ([`check_folded`]).

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
use crate::transport::{self, BatchTally, Flux, McResult, RunStats, TallyLayout, TransportError};

mod check;
mod file;
mod frame;
mod kinds;
mod set;
mod write;

pub use check::CONSERVATION_SIGMAS;
pub(crate) use check::first_mismatch;
use check::{check_folded, check_same};
pub use file::ShardFile;
use file::check_returns_signs;
pub(crate) use file::{check_wall_and_threads, number};
pub use frame::Body;
use frame::u64_at;
pub(crate) use frame::{Frame, FrameWriter, read_header, write_frame, write_str};
use kinds::header_kind;
pub(crate) use kinds::{SceneClaim, Sharded, scene_of, whole_set};
pub use kinds::{common_kind, shard_kind};
pub use set::{ShardSet, shard_paths};
pub use write::run;

/// First bytes of every shard file.
pub const MAGIC: &[u8; 16] = b"lidarsim shard\n\0";
/// Version of the shard file layout this lidarsim writes and reads (2: a select-lines shard no
/// longer carries each profile's transmission spectra, which the figures now take from each
/// group's mean profile).
pub const FORMAT: u32 = 2;
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
    let prepared = pipeline::prepare(&scene)?;
    let mc = match prepared.plan()? {
        Some(plan) => Some(set.fold(&plan, &scene)?),
        None => None,
    };
    let run = prepared.finish(mc)?;
    let shards = set.shards.len();
    Ok(Merged { scene, run, shards })
}

#[cfg(test)]
mod tests;
