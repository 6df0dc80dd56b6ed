//! Sharded ensemble studies: `lidarsim dial --shard I/N` runs a slice of the profiles and
//! stores their records in one shard file; [`merge`] puts the slices back together into the
//! outcomes of the single study, bit for bit.
//!
//! Profile `p` of a set of `P` belongs to shard `⌊p·N/P⌋` (as a run's batches,
//! [`ShardSpec::batches`]), so shard `i` holds profiles `⌈i·P/N⌉ … ⌈(i+1)·P/N⌉ − 1`. Every shard
//! builds the whole set and its class means (the retrieval's virtual cross-sections are those
//! of the class-mean profile) and runs its profiles with the noise seed each has in the single
//! study ([`dial::run_slice`]), so a shard gives the same bytes on any machine and thread count.
//!
//! # The dial shard file (`shard-I-of-N.lshard`, `kind` = `dial`)
//!
//! The framing of every shard file ([`crate::shard`]): magic, format, header length, a JSON
//! header ([`DialShardHeader`]), the body, and an FNV-1a 64 checksum of every byte before it.
//! The body holds the slice's outcomes in profile order, little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | string | profile id (u64 length, UTF-8) |
//! | 1 | latitude class (0 tropical, 1 mid, 2 high) |
//! | 1 | 0: records follow; 1: the profile failed, the reason (a string) follows |
//! | 8 | number of records (u64), then per record: pair (string), method (u8: 0 IPDA, 1 IPDA virtual σ, 2 DIAL), altitudes bottom and top, truth, retrieved, noisy, own-reference (f64), the budget rows (f64 each) |
//!
//! Floats are stored as their IEEE-754 bits, so the records round-trip exactly (NaN included).

use std::fs;
use std::io::{self, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::atmosphere::{LatitudeClass, ProfileSet};
use crate::output;
use crate::retrieval::Method;
use crate::scene::Scene;
use crate::shard::{
    self, Body, KIND_DIAL, ShardError, ShardSpec, Sharded, VERSION, debug_digest, write_str,
};
use crate::study::dial::{
    self, BudgetSteps, N_SOURCES, ProfileOutcome, ProfileSource, Record, StudyOptions, StudyResult,
    Timing,
};

/// Everything a study is made of: the scene, where its profiles come from, and the options
/// that change its numbers.
#[derive(Debug, Clone)]
pub struct StudyInputs {
    /// The scene (read by its absolute path for a shard, [`shard::read_scene`]).
    pub scene: Scene,
    /// Where the profiles come from (a set file by its absolute path for a shard).
    pub source: ProfileSource,
    /// The latitude classes run: `tropical`, `mid`, `high` or `all`.
    pub class: String,
    /// The profiles ([`dial::profile_set`] of `source`, `class` and `options.seed`).
    pub set: ProfileSet,
    /// The study's options.
    pub options: StudyOptions,
}

/// The header of a dial shard file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DialShardHeader {
    /// [`KIND_DIAL`].
    pub kind: String,
    /// lidarsim version that wrote the shard.
    pub lidarsim_version: String,
    /// The scene file's absolute path (or the default scene's name).
    pub scene_path: String,
    /// The scene text.
    pub scene_text: String,
    /// [`shard::scene_digest`] of the scene.
    pub scene_digest: String,
    /// The profile set file's absolute path, for a set.
    pub profiles_path: Option<String>,
    /// Members per class, for generated ensembles.
    pub ensemble: Option<u64>,
    /// The classes run.
    pub class: String,
    /// [`debug_digest`] of the profile set as built.
    pub set_digest: String,
    /// Profiles in the set.
    pub profiles: u64,
    /// Photons per profile (0: analytic).
    pub photons: u64,
    /// Seed of the ensemble, the noise and the Monte Carlo.
    pub seed: u64,
    /// (on, off) line indices.
    pub pairs: Vec<[u64; 2]>,
    /// Budget steps (temperature, humidity, surface pressure, frequency offset, line width)
    /// as IEEE-754 bits.
    pub budget_steps_bits: [u64; 5],
    /// Field of view of the retrievals.
    pub fov: u64,
    /// This shard, `0..shard_count`.
    pub shard_index: u64,
    /// Shards of the study.
    pub shard_count: u64,
    /// First profile of the shard.
    pub first_profile: u64,
    /// One past its last profile.
    pub end_profile: u64,
    /// The shard's [`Timing`] \[s\]: class means, truth optics, returns, references,
    /// retrievals, wall.
    pub timing_s: [f64; 6],
    /// Worker threads it ran on.
    pub threads: u64,
}

impl StudyHeader for DialShardHeader {
    type Outcome = ProfileOutcome;
    const KIND: &'static str = KIND_DIAL;

    fn lidarsim_version(&self) -> &str {
        &self.lidarsim_version
    }

    fn shard_of(&self) -> [u64; 3] {
        [self.shard_index, self.shard_count, self.profiles]
    }

    fn held(&self) -> (u64, u64) {
        (self.first_profile, self.end_profile)
    }

    fn times(&self) -> (Vec<(&'static str, f64)>, u64) {
        let names = [
            "class-mean",
            "truth-optics",
            "returns",
            "reference-state",
            "retrieval",
            "wall",
        ];
        (names.into_iter().zip(self.timing_s).collect(), self.threads)
    }

    /// From the analytic lidar equation (photons 0) every noise-free value is defined: a
    /// NaN there is one the study cannot have made (`dial::check_records`).
    fn check_outcome(&self, o: &ProfileOutcome) -> Result<(), String> {
        let Ok(records) = &o.records else {
            return Ok(());
        };
        match records
            .iter()
            .find(|r| self.photons == 0 && !r.is_defined())
        {
            Some(r) => Err(format!(
                "profile {}, {} {} {}–{} m: a noise-free value is not a finite number, which the analytic lidar equation (photons 0) never gives",
                o.id,
                r.pair,
                r.method.label(),
                r.altitude_m.0,
                r.altitude_m.1
            )),
            None => Ok(()),
        }
    }
}

impl DialShardHeader {
    fn steps(&self) -> BudgetSteps {
        let b = self.budget_steps_bits.map(f64::from_bits);
        BudgetSteps {
            temperature_k: b[0],
            humidity_fraction: b[1],
            surface_pressure_hpa: b[2],
            frequency_offset_mhz: b[3],
            linewidth_fraction: b[4],
        }
    }

    fn options(&self) -> StudyOptions {
        StudyOptions {
            photons: self.photons,
            seed: self.seed,
            pairs: self
                .pairs
                .iter()
                .map(|p| (p[0] as usize, p[1] as usize))
                .collect(),
            steps: self.steps(),
            fov: self.fov as usize,
        }
    }
}

/// What a study shard (dial or select-lines) did.
#[derive(Debug, Clone)]
pub struct StudyShardReport {
    /// The file written.
    pub path: PathBuf,
    /// Its profiles.
    pub profiles: Range<usize>,
    /// Profiles of the whole set.
    pub total_profiles: usize,
    /// Profiles of the slice that failed.
    pub failed: usize,
    /// Wall time \[s\].
    pub wall_s: f64,
    /// Worker threads.
    pub threads: usize,
}

/// Run shard `spec` of the study `inputs` on the current rayon pool and write it as
/// `out_dir/`[`ShardSpec::file_name`] (whole or not at all). `progress` is called once per
/// finished profile of the slice.
pub fn run(
    inputs: &StudyInputs,
    spec: ShardSpec,
    out_dir: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<StudyShardReport, ShardError> {
    let total = inputs.set.len();
    let range = profile_slice(spec, total)?;
    let path = out_dir.join(spec.file_name());
    output::check_paths(&[&path])?;
    let result = dial::run_slice(
        &inputs.scene,
        &inputs.set,
        &inputs.options,
        range.clone(),
        progress,
        None,
    )
    .map_err(|e| ShardError::Spec {
        spec,
        what: e.to_string(),
    })?;
    let threads = rayon::current_num_threads();
    let header = header_of(inputs, spec, range.clone(), &result.timing, threads)?;
    shard::write_frame(&path, &header, |w| {
        for o in &result.outcomes {
            write_outcome(w, o)?;
        }
        Ok(())
    })?;
    Ok(StudyShardReport {
        path,
        profiles: range,
        total_profiles: total,
        failed: result
            .outcomes
            .iter()
            .filter(|o| o.records.is_err())
            .count(),
        wall_s: result.timing.wall_s,
        threads,
    })
}

/// The profiles of shard `spec` of a study of `total` (as a run's batches,
/// [`ShardSpec::batches`]); refused if some shard would have none.
pub(crate) fn profile_slice(spec: ShardSpec, total: usize) -> Result<Range<usize>, ShardError> {
    if spec.count > total {
        return Err(ShardError::Spec {
            spec,
            what: format!(
                "{} shards of a study of {total} profiles leave some without a profile (at most one shard per profile)",
                spec.count
            ),
        });
    }
    Ok(spec.batches(total))
}

/// The profiles `first..end` that the header of the study shard `path` says it holds, refused
/// unless they are those of shard `index` of `count` of a study of `total` profiles.
fn header_slice(
    path: &Path,
    [index, count, total]: [u64; 3],
    (first, end): (u64, u64),
) -> Result<Range<usize>, ShardError> {
    let valid = count > 0 && index < count && count <= total;
    let range = if valid {
        ShardSpec {
            index: index as usize,
            count: count as usize,
        }
        .batches(total as usize)
    } else {
        0..0
    };
    if !valid || (first, end) != (range.start as u64, range.end as u64) {
        return Err(ShardError::Bad {
            path: path.to_path_buf(),
            what: format!(
                "inconsistent header: profiles {first}..{end} as shard {index}/{count} of {total} profiles"
            ),
        });
    }
    Ok(range)
}

/// A latitude class as one byte: its index in [`LatitudeClass::ALL`].
pub(crate) fn class_code(class: LatitudeClass) -> u8 {
    LatitudeClass::ALL
        .iter()
        .position(|c| *c == class)
        .unwrap_or(0) as u8
}

/// The class of [`class_code`] `c` (of profile `id`, named in the error).
pub(crate) fn class_of_code(c: u8, id: &str) -> Result<LatitudeClass, String> {
    LatitudeClass::ALL
        .get(c as usize)
        .copied()
        .ok_or_else(|| format!("corrupt: latitude class {c} of profile {id}"))
}

fn header_of(
    inputs: &StudyInputs,
    spec: ShardSpec,
    range: Range<usize>,
    t: &Timing,
    threads: usize,
) -> Result<DialShardHeader, ShardError> {
    let (profiles_path, ensemble) = match &inputs.source {
        ProfileSource::Set(p) => (Some(p.to_string_lossy().into_owned()), None),
        ProfileSource::Ensemble(n) => (None, Some(*n as u64)),
        // A shard's profiles must be found again by every other shard and by the merge.
        ProfileSource::Given(set) => {
            return Err(ShardError::Bad {
                path: set.name.clone().into(),
                what: "profiles given in memory cannot be run in shards (give a profile-set file)"
                    .into(),
            });
        }
    };
    let o = &inputs.options;
    let st = &o.steps;
    Ok(DialShardHeader {
        kind: KIND_DIAL.to_string(),
        lidarsim_version: VERSION.to_string(),
        scene_path: inputs.scene.path.to_string_lossy().into_owned(),
        scene_text: inputs.scene.text().to_string(),
        scene_digest: shard::scene_digest(&inputs.scene),
        profiles_path,
        ensemble,
        class: inputs.class.clone(),
        set_digest: debug_digest(&inputs.set),
        profiles: inputs.set.len() as u64,
        photons: o.photons,
        seed: o.seed,
        pairs: o.pairs.iter().map(|&(a, b)| [a as u64, b as u64]).collect(),
        budget_steps_bits: [
            st.temperature_k,
            st.humidity_fraction,
            st.surface_pressure_hpa,
            st.frequency_offset_mhz,
            st.linewidth_fraction,
        ]
        .map(f64::to_bits),
        fov: o.fov as u64,
        shard_index: spec.index as u64,
        shard_count: spec.count as u64,
        first_profile: range.start as u64,
        end_profile: range.end as u64,
        timing_s: [
            t.mean_references_s,
            t.truth_optics_s,
            t.returns_s,
            t.references_s,
            t.retrievals_s,
            t.wall_s,
        ],
        threads: threads as u64,
    })
}

const METHODS: [Method; 3] = [Method::Ipda, Method::IpdaVirtual, Method::Dial];

fn write_outcome(w: &mut impl Write, o: &ProfileOutcome) -> io::Result<()> {
    write_str(w, &o.id)?;
    w.write_all(&[class_code(o.class)])?;
    match &o.records {
        Err(reason) => {
            w.write_all(&[1])?;
            write_str(w, reason)
        }
        Ok(records) => {
            w.write_all(&[0])?;
            w.write_all(&(records.len() as u64).to_le_bytes())?;
            for r in records {
                write_str(w, &r.pair)?;
                let m = METHODS.iter().position(|m| *m == r.method).unwrap_or(0) as u8;
                w.write_all(&[m])?;
                let values = [
                    r.altitude_m.0,
                    r.altitude_m.1,
                    r.truth_ppm,
                    r.retrieved_ppm,
                    r.retrieved_noisy_ppm,
                    r.retrieved_own_ppm,
                ];
                for v in values.iter().chain(&r.budget_ppm) {
                    w.write_all(&v.to_le_bytes())?;
                }
            }
            Ok(())
        }
    }
}

/// One profile's outcome, as [`write_outcome`] writes it.
fn read_outcome(body: &mut Body) -> Result<ProfileOutcome, String> {
    let id = body.string()?;
    let class = class_of_code(body.u8()?, &id)?;
    let records = match body.u8()? {
        1 => Err(body.string()?),
        0 => {
            // Each record takes at least this many bytes: a bound before allocating.
            let n = body.count(
                8 + 1 + 8 * (6 + N_SOURCES),
                &format!("records of profile {id}"),
            )?;
            let mut records = Vec::with_capacity(n);
            for _ in 0..n {
                let pair = body.string()?;
                let m = body.u8()?;
                let method = *METHODS
                    .get(m as usize)
                    .ok_or_else(|| format!("corrupt: method {m} in profile {id}"))?;
                let mut v = [0.0; 6];
                for x in &mut v {
                    *x = body.f64()?;
                }
                let mut budget_ppm = [0.0; N_SOURCES];
                for x in &mut budget_ppm {
                    *x = body.f64()?;
                }
                records.push(Record {
                    pair,
                    method,
                    altitude_m: (v[0], v[1]),
                    truth_ppm: v[2],
                    retrieved_ppm: v[3],
                    retrieved_noisy_ppm: v[4],
                    retrieved_own_ppm: v[5],
                    budget_ppm,
                });
            }
            Ok(records)
        }
        s => return Err(format!("corrupt: status {s} of profile {id}")),
    };
    Ok(ProfileOutcome { id, class, records })
}

/// The header of a study shard file (dial or select-lines): its kind, the version that wrote
/// it, its slice of the study's profiles, and what each profile's record in the body holds.
pub trait StudyHeader: DeserializeOwned {
    /// One profile's outcome, as the body holds it.
    type Outcome: ReadOutcome;
    /// The header's `kind`.
    const KIND: &'static str;
    /// The lidarsim version that wrote the shard.
    fn lidarsim_version(&self) -> &str;
    /// The shard's index, the shard count and the study's profiles.
    fn shard_of(&self) -> [u64; 3];
    /// The shard's profiles: the first, and one past the last.
    fn held(&self) -> (u64, u64);
    /// The times it records, named \[s\], and the threads it ran on: checked on reading
    /// ([`shard::check_wall_and_threads`]).
    fn times(&self) -> (Vec<(&'static str, f64)>, u64);
    /// Checks of one outcome that need the header ([`ReadOutcome::check`] has done the
    /// others): none but a dial shard's.
    fn check_outcome(&self, _outcome: &Self::Outcome) -> Result<(), String> {
        Ok(())
    }
}

/// The outcome of one profile as a study shard's body holds it.
pub trait ReadOutcome: Sized {
    /// Read one from `body`; the error says what is wrong, the caller names the file.
    fn read(body: &mut Body) -> Result<Self, String>;
    /// Refuse values the study cannot have made (NaN or infinite where it computes a number,
    /// negative where it cannot be): a checksum proves only that the file is as written.
    fn check(&self) -> Result<(), String>;
}

impl ReadOutcome for ProfileOutcome {
    fn read(body: &mut Body) -> Result<Self, String> {
        read_outcome(body)
    }

    /// The altitudes and the truth finite, the truth a mixing ratio in (0, 10⁶] ppm; every
    /// other value finite or NaN (undefined: a noisy measurement, or with Monte Carlo returns
    /// a window without energy, `dial::check_records`), never infinite; the random error ≥ 0.
    fn check(&self) -> Result<(), String> {
        let Ok(records) = &self.records else {
            return Ok(());
        };
        for r in records {
            let at = || {
                format!(
                    "profile {}, {} {} {}–{} m",
                    self.id,
                    r.pair,
                    r.method.label(),
                    r.altitude_m.0,
                    r.altitude_m.1
                )
            };
            let finite = [
                ("altitude_bottom_m", r.altitude_m.0),
                ("altitude_top_m", r.altitude_m.1),
                ("truth_ppm", r.truth_ppm),
            ];
            let undefined_or_finite = [
                ("retrieved_ppm", r.retrieved_ppm),
                ("retrieved_noisy_ppm", r.retrieved_noisy_ppm),
                ("retrieved_own_profile_ppm", r.retrieved_own_ppm),
            ];
            let budget = crate::study::dial::Source::ALL
                .iter()
                .zip(&r.budget_ppm)
                .map(|(s, v)| (s.column(), *v));
            let bad = finite
                .into_iter()
                .find(|(_, v)| !v.is_finite())
                .or_else(|| {
                    undefined_or_finite
                        .into_iter()
                        .chain(budget)
                        .find(|(_, v)| v.is_infinite())
                });
            if let Some((name, v)) = bad {
                return Err(format!(
                    "{}: {name} is {}: not a finite number",
                    at(),
                    shard::number(v)
                ));
            }
            if !(r.truth_ppm > 0.0 && r.truth_ppm <= 1e6) {
                return Err(format!(
                    "{}: truth_ppm is {}: a mixing ratio lies in (0, 1e6] ppm",
                    at(),
                    shard::number(r.truth_ppm)
                ));
            }
            if r.budget_ppm[0] < 0.0 {
                return Err(format!(
                    "{}: random_ppm is {}: a standard deviation is never negative",
                    at(),
                    shard::number(r.budget_ppm[0])
                ));
            }
        }
        Ok(())
    }
}

/// A study shard file read and checked: its header and its profiles' outcomes.
#[derive(Debug, Clone)]
pub struct StudyShardFile<H: StudyHeader> {
    /// Where it was read from.
    pub path: PathBuf,
    /// Its header.
    pub header: H,
    /// Its profiles' outcomes, in profile order.
    pub outcomes: Vec<H::Outcome>,
}

/// A dial shard file read and checked.
pub type DialShardFile = StudyShardFile<DialShardHeader>;

impl<H: StudyHeader> Sharded for StudyShardFile<H> {
    fn path(&self) -> &Path {
        &self.path
    }

    fn version(&self) -> &str {
        self.header.lidarsim_version()
    }

    fn spec(&self) -> ShardSpec {
        let [index, count, _] = self.header.shard_of();
        ShardSpec {
            index: index as usize,
            count: count as usize,
        }
    }
}

impl<H: StudyHeader> StudyShardFile<H> {
    /// Read `path` and check that it is a whole shard file of the kind `H::KIND`, consistent
    /// in itself.
    pub fn read(path: &Path) -> Result<Self, ShardError> {
        let bytes = fs::read(path).map_err(|error| ShardError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        Self::parse(path, &bytes)
    }

    /// [`StudyShardFile::read`] on bytes already read.
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<Self, ShardError> {
        let bad = |what: String| ShardError::Bad {
            path: path.to_path_buf(),
            what,
        };
        let (frame, header): (_, H) = shard::read_header(path, bytes, 0, H::KIND)?;
        frame.check_sum(path)?;
        let range = header_slice(path, header.shard_of(), header.held())?;
        let (times, threads) = header.times();
        for (name, t) in times {
            if !(t.is_finite() && t >= 0.0) {
                return Err(bad(format!(
                    "its {name} time is {} s: a time is a finite number ≥ 0",
                    shard::number(t)
                )));
            }
        }
        shard::check_wall_and_threads(path, 0.0, threads)?;
        let mut body = Body::new(&bytes[frame.body_at..frame.sum_at]);
        let mut outcomes = Vec::with_capacity(range.len().min(1 << 20));
        for _ in range {
            let o = H::Outcome::read(&mut body).map_err(&bad)?;
            o.check()
                .and_then(|()| header.check_outcome(&o))
                .map_err(&bad)?;
            outcomes.push(o);
        }
        if body.left() != 0 {
            return Err(bad(format!(
                "{} bytes beyond its last profile",
                body.left()
            )));
        }
        Ok(StudyShardFile {
            path: path.to_path_buf(),
            header,
            outcomes,
        })
    }
}

/// `b`'s header against `a`'s: the first difference, named.
fn check_same(
    a: &Path,
    ha: &DialShardHeader,
    b: &Path,
    hb: &DialShardHeader,
) -> Result<(), ShardError> {
    let fields: [(&'static str, String, String); 11] = [
        (
            "the lidarsim version",
            ha.lidarsim_version.clone(),
            hb.lidarsim_version.clone(),
        ),
        ("the seed", ha.seed.to_string(), hb.seed.to_string()),
        (
            "the scene (digest)",
            format!("{} {}", ha.scene_path, ha.scene_digest),
            format!("{} {}", hb.scene_path, hb.scene_digest),
        ),
        (
            "the profile set",
            format!("{:?} {:?}", ha.profiles_path, ha.ensemble),
            format!("{:?} {:?}", hb.profiles_path, hb.ensemble),
        ),
        ("the class", ha.class.clone(), hb.class.clone()),
        (
            "the profile set (digest)",
            format!("{} profiles {}", ha.profiles, ha.set_digest),
            format!("{} profiles {}", hb.profiles, hb.set_digest),
        ),
        (
            "the shard count",
            ha.shard_count.to_string(),
            hb.shard_count.to_string(),
        ),
        (
            "the photon count",
            ha.photons.to_string(),
            hb.photons.to_string(),
        ),
        (
            "the choice of line pairs",
            format!("{:?}", ha.pairs),
            format!("{:?}", hb.pairs),
        ),
        (
            "the set of budget steps",
            format!("{:?}", ha.steps()),
            format!("{:?}", hb.steps()),
        ),
        ("the field of view", ha.fov.to_string(), hb.fov.to_string()),
    ];
    crate::shard::first_mismatch(a, b, fields)
}

/// A merged study: its inputs and the single study's result. The result's `mean_profiles` is
/// empty (the shards do not store them), its timing the shards' summed (wall time included).
#[derive(Debug)]
pub struct DialMerged {
    /// The study's inputs, rebuilt from the shards and checked against their digests.
    pub inputs: StudyInputs,
    /// The outcomes of every profile in set order.
    pub result: StudyResult,
    /// Shards merged.
    pub shards: usize,
}

/// Merge the dial shard files `paths` ([`shard::shard_paths`]): every shard of one study, each
/// once, of the same version, scene, profile set, seed and options; the scene and the set are
/// built again and must have the shards' digests.
pub fn merge(paths: &[PathBuf]) -> Result<DialMerged, ShardError> {
    let files = shard::whole_set(
        paths,
        DialShardFile::read,
        |a: &DialShardFile, b: &DialShardFile| check_same(&a.path, &a.header, &b.path, &b.header),
    )?;
    let count = files.len();
    let h = files[0].header.clone();
    let path0 = files[0].path.clone();
    let claims: Vec<shard::SceneClaim> = files
        .iter()
        .map(|f| shard::SceneClaim {
            file: &f.path,
            path: &f.header.scene_path,
            text: &f.header.scene_text,
            digest: &f.header.scene_digest,
        })
        .collect();
    let scene = shard::scene_of(&claims, |_| Ok(()), shard::scene_digest)?;
    let source = match (&h.profiles_path, h.ensemble) {
        (Some(p), None) => ProfileSource::Set(PathBuf::from(p)),
        (None, Some(n)) => ProfileSource::Ensemble(n as usize),
        _ => {
            return Err(ShardError::Bad {
                path: path0,
                what:
                    "inconsistent header: it names both or neither of a profile set and an ensemble"
                        .into(),
            });
        }
    };
    let set = dial::profile_set(&source, &h.class, h.seed).map_err(|e| ShardError::Bad {
        path: path0.clone(),
        what: format!("its profile set cannot be built again: {e}"),
    })?;
    let digest = debug_digest(&set);
    if digest != h.set_digest || set.len() as u64 != h.profiles {
        return Err(ShardError::Bad {
            path: path0,
            what: format!(
                "the profile set {} as built now ({} profiles, digest {digest}) is not the one the shards ran ({} profiles, digest {}): its file has changed since",
                match &source {
                    ProfileSource::Set(p) => p.display().to_string(),
                    ProfileSource::Ensemble(n) => format!("of {n} members per class"),
                    ProfileSource::Given(given) => given.name.clone(),
                },
                set.len(),
                h.profiles,
                h.set_digest
            ),
        });
    }
    let mut outcomes = Vec::with_capacity(set.len());
    let mut timing = Timing::default();
    for f in files {
        let t = f.header.timing_s;
        timing.mean_references_s += t[0];
        timing.truth_optics_s += t[1];
        timing.returns_s += t[2];
        timing.references_s += t[3];
        timing.retrievals_s += t[4];
        timing.wall_s += t[5];
        let start = f.header.first_profile as usize;
        for (k, o) in f.outcomes.into_iter().enumerate() {
            let m = &set.members[start + k].meta;
            if o.id != m.id || o.class != m.class() {
                return Err(ShardError::Bad {
                    path: f.path,
                    what: format!(
                        "profile {} is `{}` ({}) where the set has `{}` ({})",
                        start + k,
                        o.id,
                        o.class,
                        m.id,
                        m.class()
                    ),
                });
            }
            outcomes.push(o);
        }
    }
    let options = h.options();
    Ok(DialMerged {
        inputs: StudyInputs {
            scene,
            source,
            class: h.class,
            set,
            options,
        },
        result: StudyResult {
            outcomes,
            mean_profiles: Vec::new(),
            timing,
        },
        shards: count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Outcomes round-trip exactly: every f64 by its bits (NaN, −0, infinities, subnormals),
    /// failed profiles with their reason, text with commas and non-ASCII; and a truncated body
    /// is refused, never read past.
    #[test]
    fn outcomes_round_trip_bit_for_bit() {
        let record = |x: f64| Record {
            pair: "on,1/off é".into(),
            method: Method::Dial,
            altitude_m: (-0.0, f64::INFINITY),
            truth_ppm: x,
            retrieved_ppm: f64::from_bits(0x7ff8_0000_0000_1234),
            retrieved_noisy_ppm: f64::MIN_POSITIVE / 3.0,
            retrieved_own_ppm: 1.0 / 3.0,
            budget_ppm: [x; N_SOURCES],
        };
        let outcomes = vec![
            ProfileOutcome {
                id: "a".into(),
                class: LatitudeClass::High,
                records: Ok(vec![record(420.123), record(f64::NEG_INFINITY)]),
            },
            ProfileOutcome {
                id: "b\n\"x\"".into(),
                class: LatitudeClass::Tropical,
                records: Err("supersaturated, 101 %".into()),
            },
            ProfileOutcome {
                id: String::new(),
                class: LatitudeClass::Mid,
                records: Ok(Vec::new()),
            },
        ];
        let mut bytes = Vec::new();
        for o in &outcomes {
            write_outcome(&mut bytes, o).unwrap();
        }
        let mut body = Body::new(&bytes);
        let back: Vec<ProfileOutcome> = (0..3).map(|_| read_outcome(&mut body).unwrap()).collect();
        assert_eq!(body.left(), 0);
        let bits = |o: &[ProfileOutcome]| format!("{o:?}");
        assert_eq!(bits(&back), bits(&outcomes));
        for (a, b) in back.iter().zip(&outcomes) {
            if let (Ok(ra), Ok(rb)) = (&a.records, &b.records) {
                for (x, y) in ra.iter().zip(rb) {
                    assert_eq!(x.retrieved_ppm.to_bits(), y.retrieved_ppm.to_bits());
                    assert_eq!(x.altitude_m.0.to_bits(), y.altitude_m.0.to_bits());
                    assert_eq!(x.retrieved_noisy_ppm, y.retrieved_noisy_ppm);
                }
            }
        }
        for n in 0..bytes.len() {
            let mut body = Body::new(&bytes[..n]);
            let r: Result<Vec<ProfileOutcome>, String> =
                (0..3).map(|_| read_outcome(&mut body)).collect();
            assert!(r.is_err(), "{n} bytes");
        }
    }
}
