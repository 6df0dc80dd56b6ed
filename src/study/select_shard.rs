//! Sharded line-selection studies: `lidarsim select-lines --shard I/N` studies a slice of the
//! profiles and stores their results in one shard file; [`merge`] puts the slices back
//! together into the outcomes of the single study, bit for bit.
//!
//! The unit of work is the member ([`SelectStudy::members`]: the groups' members in group
//! order). Member `p` of `P` belongs to shard `⌊p·N/P⌋`, as the profiles of a dial study
//! ([`crate::study::shard`]), so shard `i` holds members `⌈i·P/N⌉ … ⌈(i+1)·P/N⌉ − 1`. Every
//! shard builds the whole study (line list, positions, instrument, every profile; a generated
//! ensemble whole from its seed) and studies its own members, each alone and with nothing
//! random in it, so a shard gives the same bytes on any machine and thread count. A member is
//! not split by on-line position: its line-by-line work (four reference states, the
//! weighting function) is shared by all its positions.
//!
//! # The select shard file (`shard-I-of-N.lshard`, `kind` = `select`)
//!
//! The framing of every shard file ([`crate::shard`]): magic, format, header length, a JSON
//! header ([`SelectShardHeader`]), the body, and an FNV-1a 64 checksum of every byte before it.
//! The body holds the slice's outcomes in member order, little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | string | profile id (u64 length, UTF-8) |
//! | 1 | 0: results follow; 1: the member failed, the reason (a string) follows |
//! | 1 | latitude class (0 tropical, 1 mid, 2 high) |
//! | 8 | XCO2 over the grid \[ppm\] (f64) |
//! | 8 + 8·n | layer edges \[m\]: n (u64), n f64 |
//! | 8 + 64·n | positions: n (u64), per position the eight values of [`PositionResult`] in declaration order (f64) |
//!
//! (The figures' spectra are not in it: they are of each group's mean profile, computed when
//! the study is summarised, [`SelectStudy::summarise`].)
//!
//! Floats are stored as their IEEE-754 bits, so the results round-trip exactly (NaN included).

use std::io::{self, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::atmosphere::{SetMember, StandardAtmosphere};
use crate::output;
use crate::shard::{
    self, Body, KIND_SELECT, ShardError, ShardSpec, VERSION, debug_digest, write_str,
};
use crate::study::select::{
    MemberFailure, MemberResult, PositionResult, StudyConfig, Uncertainties,
};
use crate::study::select_study::{MemberOutcome, SelectOptions, SelectSource, SelectStudy};
use crate::study::shard::{
    ReadOutcome, StudyHeader, StudyShardFile, StudyShardReport, class_code, class_of_code,
    profile_slice,
};

/// The header of a select shard file: the lidarsim version, the scene, every option of the
/// study (floats as IEEE-754 bits), the digests of what it read, and the slice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SelectShardHeader {
    /// [`KIND_SELECT`].
    pub kind: String,
    /// lidarsim version that wrote the shard.
    pub lidarsim_version: String,
    /// The scene file's absolute path (or the default scene's name).
    pub scene_path: String,
    /// The scene text.
    pub scene_text: String,
    /// [`shard::scene_digest`] of the scene.
    pub scene_digest: String,
    /// The built-in atmospheres (names), for a study of atmospheres.
    pub atmospheres: Option<Vec<String>>,
    /// The profile set file's absolute path, for a set.
    pub profiles_path: Option<String>,
    /// Members per class, for a generated ensemble.
    pub ensemble: Option<u64>,
    /// The classes of a set or ensemble.
    pub class: String,
    /// Seed of a generated ensemble.
    pub seed: u64,
    /// [`debug_digest`] of the groups of profiles as built.
    pub groups_digest: String,
    /// Members of the study.
    pub profiles: u64,
    /// One row per profile too.
    pub per_profile: bool,
    /// The line files' absolute paths (none: the built-in band model).
    pub lines: Vec<String>,
    /// [`lines_digest`] of the study.
    pub lines_digest: String,
    /// On-line positions \[cm⁻¹\] (none: a scan).
    pub on_cm1_bits: Vec<u64>,
    /// Off-line \[cm⁻¹\].
    pub off_cm1_bits: u64,
    /// CO2 column average \[ppm\].
    pub co2_ppm_bits: u64,
    /// Scan: largest J″.
    pub max_j: u32,
    /// Scan: offsets \[GHz\].
    pub offsets_ghz_bits: Vec<u64>,
    /// Layer thickness \[m\].
    pub layer_m_bits: u64,
    /// Top of the grid \[km\].
    pub top_km_bits: u64,
    /// Wing cutoff \[cm⁻¹\].
    pub wing_cm1_bits: u64,
    /// Uncertainties: temperature \[K\], frequency \[MHz\], surface pressure \[hPa\], H2O \[%\].
    pub uncertainties_bits: [u64; 4],
    /// Lines of the figures.
    pub figure_lines: Vec<String>,
    /// Whether the figures are drawn (no `--no-plots`): the merge draws them too.
    pub plots: bool,
    /// This shard, `0..shard_count`.
    pub shard_index: u64,
    /// Shards of the study.
    pub shard_count: u64,
    /// First member of the shard.
    pub first_profile: u64,
    /// One past its last member.
    pub end_profile: u64,
    /// Wall time of the shard's study \[s\].
    pub wall_s: f64,
    /// Worker threads it ran on.
    pub threads: u64,
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn floats(v: &[u64]) -> Vec<f64> {
    v.iter().map(|b| f64::from_bits(*b)).collect()
}

/// The digest of what the line files give a study: its line list as read and what the band's
/// lines place (the on-line positions and the fine-spectrum windows).
pub fn lines_digest(config: &StudyConfig) -> String {
    debug_digest(&(&config.lines, &config.positions, &config.spectra))
}

impl StudyHeader for SelectShardHeader {
    type Outcome = MemberOutcome;
    const KIND: &'static str = KIND_SELECT;

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
        (vec![("wall", self.wall_s)], self.threads)
    }
}

impl SelectShardHeader {
    /// The study's options.
    fn options(&self) -> Result<SelectOptions, String> {
        let source = match (&self.atmospheres, &self.profiles_path, self.ensemble) {
            (Some(a), None, None) => SelectSource::Atmospheres(
                a.iter()
                    .map(|n| n.parse::<StandardAtmosphere>())
                    .collect::<Result<_, _>>()?,
            ),
            (None, Some(p), None) => SelectSource::Set(PathBuf::from(p)),
            (None, None, Some(n)) => SelectSource::Ensemble(n as usize),
            _ => {
                return Err("inconsistent header: it names more or fewer than one of atmospheres, a profile set and an ensemble".into());
            }
        };
        let [t, f, p, q] = self.uncertainties_bits.map(f64::from_bits);
        Ok(SelectOptions {
            source,
            seed: self.seed,
            class: self.class.clone(),
            per_profile: self.per_profile,
            lines: self.lines.iter().map(PathBuf::from).collect(),
            on_cm1: floats(&self.on_cm1_bits),
            off_cm1: f64::from_bits(self.off_cm1_bits),
            co2_ppm: f64::from_bits(self.co2_ppm_bits),
            max_j: self.max_j,
            offsets_ghz: floats(&self.offsets_ghz_bits),
            layer_m: f64::from_bits(self.layer_m_bits),
            top_km: f64::from_bits(self.top_km_bits),
            wing_cm1: f64::from_bits(self.wing_cm1_bits),
            uncertainties: Uncertainties {
                temperature_k: t,
                frequency_mhz: f,
                surface_pressure_hpa: p,
                h2o_percent: q,
            },
            figure_lines: self.figure_lines.clone(),
            plots: self.plots,
        })
    }
}

fn header_of(
    study: &SelectStudy,
    spec: ShardSpec,
    range: Range<usize>,
    wall_s: f64,
    threads: usize,
) -> SelectShardHeader {
    let o = &study.options;
    let path = |p: &Path| p.to_string_lossy().into_owned();
    let (atmospheres, profiles_path, ensemble) = match &o.source {
        SelectSource::Atmospheres(a) => (
            Some(a.iter().map(|s| s.name().to_string()).collect()),
            None,
            None,
        ),
        SelectSource::Set(p) => (None, Some(path(p)), None),
        SelectSource::Ensemble(n) => (None, None, Some(*n as u64)),
    };
    let u = &o.uncertainties;
    SelectShardHeader {
        kind: KIND_SELECT.to_string(),
        lidarsim_version: VERSION.to_string(),
        scene_path: path(&study.scene.path),
        scene_text: study.scene.text().to_string(),
        scene_digest: shard::scene_digest(&study.scene),
        atmospheres,
        profiles_path,
        ensemble,
        class: o.class.clone(),
        seed: o.seed,
        groups_digest: debug_digest(&study.groups),
        profiles: study.len() as u64,
        per_profile: o.per_profile,
        lines: o.lines.iter().map(|p| path(p)).collect(),
        lines_digest: lines_digest(&study.config),
        on_cm1_bits: bits(&o.on_cm1),
        off_cm1_bits: o.off_cm1.to_bits(),
        co2_ppm_bits: o.co2_ppm.to_bits(),
        max_j: o.max_j,
        offsets_ghz_bits: bits(&o.offsets_ghz),
        layer_m_bits: o.layer_m.to_bits(),
        top_km_bits: o.top_km.to_bits(),
        wing_cm1_bits: o.wing_cm1.to_bits(),
        uncertainties_bits: [
            u.temperature_k,
            u.frequency_mhz,
            u.surface_pressure_hpa,
            u.h2o_percent,
        ]
        .map(f64::to_bits),
        figure_lines: o.figure_lines.clone(),
        plots: o.plots,
        shard_index: spec.index as u64,
        shard_count: spec.count as u64,
        first_profile: range.start as u64,
        end_profile: range.end as u64,
        wall_s,
        threads: threads as u64,
    }
}

/// Study shard `spec` of `study` on the current rayon pool and write it as
/// `out_dir/`[`ShardSpec::file_name`] (whole or not at all). `progress` is called once per
/// finished member of the slice.
pub fn run(
    study: &SelectStudy,
    spec: ShardSpec,
    out_dir: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<StudyShardReport, ShardError> {
    let total = study.len();
    let range = profile_slice(spec, total)?;
    let path = out_dir.join(spec.file_name());
    output::check_paths(&[&path])?;
    let started = Instant::now();
    let outcomes = study.study(range.clone(), progress);
    let wall_s = started.elapsed().as_secs_f64();
    let threads = rayon::current_num_threads();
    let header = header_of(study, spec, range.clone(), wall_s, threads);
    shard::write_frame(&path, &header, |w| {
        for o in &outcomes {
            write_outcome(w, o)?;
        }
        Ok(())
    })?;
    Ok(StudyShardReport {
        path,
        profiles: range,
        total_profiles: total,
        failed: outcomes.iter().filter(|o| o.is_err()).count(),
        wall_s,
        threads,
    })
}

/// The eight values of a position's results, in declaration order.
fn position_values(p: &PositionResult) -> [f64; 8] {
    // Destructured in full so that a new field cannot be left out of the format silently.
    let PositionResult {
        daod_one_way,
        wf_peak_hpa,
        dxco2_per_k_ppm,
        dxco2_per_mhz_ppm,
        dxco2_per_hpa_ppm,
        dxco2_per_10pct_h2o_ppm,
        t2_on,
        random_error_ppm,
    } = *p;
    [
        daod_one_way,
        wf_peak_hpa,
        dxco2_per_k_ppm,
        dxco2_per_mhz_ppm,
        dxco2_per_hpa_ppm,
        dxco2_per_10pct_h2o_ppm,
        t2_on,
        random_error_ppm,
    ]
}

fn write_f64s(w: &mut impl Write, v: &[f64]) -> io::Result<()> {
    w.write_all(&(v.len() as u64).to_le_bytes())?;
    for x in v {
        w.write_all(&x.to_le_bytes())?;
    }
    Ok(())
}

fn write_outcome(w: &mut impl Write, o: &MemberOutcome) -> io::Result<()> {
    match o {
        Err(f) => {
            write_str(w, &f.id)?;
            w.write_all(&[1])?;
            write_str(w, &f.reason)
        }
        Ok(m) => {
            write_str(w, &m.id)?;
            w.write_all(&[0, class_code(m.class)])?;
            w.write_all(&m.xco2_ppm.to_le_bytes())?;
            write_f64s(w, &m.edges_m)?;
            w.write_all(&(m.positions.len() as u64).to_le_bytes())?;
            for p in &m.positions {
                for v in position_values(p) {
                    w.write_all(&v.to_le_bytes())?;
                }
            }
            Ok(())
        }
    }
}

fn read_outcome(body: &mut Body) -> Result<MemberOutcome, String> {
    let id = body.string()?;
    match body.u8()? {
        1 => Ok(Err(MemberFailure {
            id,
            reason: body.string()?,
        })),
        0 => {
            let class = class_of_code(body.u8()?, &id)?;
            let xco2_ppm = body.f64()?;
            let edges_m = body.f64s(&format!("layer edges of profile {id}"))?;
            let n = body.count(64, &format!("positions of profile {id}"))?;
            let mut positions = Vec::with_capacity(n);
            for _ in 0..n {
                let mut v = [0.0; 8];
                for x in &mut v {
                    *x = body.f64()?;
                }
                let [a, b, c, d, e, f, g, h] = v;
                positions.push(PositionResult {
                    daod_one_way: a,
                    wf_peak_hpa: b,
                    dxco2_per_k_ppm: c,
                    dxco2_per_mhz_ppm: d,
                    dxco2_per_hpa_ppm: e,
                    dxco2_per_10pct_h2o_ppm: f,
                    t2_on: g,
                    random_error_ppm: h,
                });
            }
            Ok(Ok(MemberResult {
                id,
                class,
                edges_m,
                xco2_ppm,
                positions,
            }))
        }
        s => Err(format!("corrupt: status {s} of profile {id}")),
    }
}

/// A select shard file read and checked.
pub type SelectShardFile = StudyShardFile<SelectShardHeader>;

impl ReadOutcome for MemberOutcome {
    fn read(body: &mut Body) -> Result<Self, String> {
        read_outcome(body)
    }

    /// The XCO2 a mixing ratio in (0, 10⁶] ppm, the layer edges finite and increasing, every
    /// transmission in [0, 1]; a position whose DAOD is > 0 (one the study keeps) with its
    /// sensitivities finite, its weighting-function peak and random error ≥ 0 or NaN (a peak
    /// without a finite weighting function; no noise model), never infinite. Positions with a
    /// DAOD ≤ 0 are dropped by the study, and their values may be undefined.
    fn check(&self) -> Result<(), String> {
        let Ok(m) = self else { return Ok(()) };
        let id = &m.id;
        if !(m.xco2_ppm > 0.0 && m.xco2_ppm <= 1e6) {
            return Err(format!(
                "profile {id}: XCO2 is {} ppm: a mixing ratio lies in (0, 1e6] ppm",
                m.xco2_ppm
            ));
        }
        if m.edges_m.iter().any(|z| !z.is_finite()) || m.edges_m.windows(2).any(|w| w[1] <= w[0]) {
            return Err(format!(
                "profile {id}: its layer edges are not finite and increasing"
            ));
        }
        for (i, p) in m.positions.iter().enumerate() {
            if !p.daod_one_way.is_finite() {
                return Err(format!(
                    "profile {id}, position {i}: DAOD is {}: not a finite number",
                    p.daod_one_way
                ));
            }
            if p.daod_one_way <= 0.0 {
                continue;
            }
            let values = position_values(p);
            let sensitivities = [
                p.dxco2_per_k_ppm,
                p.dxco2_per_mhz_ppm,
                p.dxco2_per_hpa_ppm,
                p.dxco2_per_10pct_h2o_ppm,
            ];
            let nan_or_non_negative = |v: f64| v.is_nan() || (v.is_finite() && v >= 0.0);
            if !sensitivities.iter().all(|v| v.is_finite())
                || !(0.0..=1.0).contains(&p.t2_on)
                || !nan_or_non_negative(p.wf_peak_hpa)
                || !nan_or_non_negative(p.random_error_ppm)
            {
                return Err(format!(
                    "profile {id}, position {i}: values {values:?}: a sensitivity not finite, a transmission outside [0, 1], or a peak pressure or random error negative or infinite"
                ));
            }
        }
        Ok(())
    }
}

fn decimal(bits: &[u64]) -> String {
    let v: Vec<String> = floats(bits).iter().map(f64::to_string).collect();
    v.join(",")
}

/// `b`'s header against `a`'s: the first difference, named.
fn check_same(a: &SelectShardFile, b: &SelectShardFile) -> Result<(), ShardError> {
    type Field = (&'static str, fn(&SelectShardHeader) -> String);
    // The options first, so that the message names the one that differs rather than the
    // digests it changes.
    let fields: [Field; 20] = [
        ("the lidarsim version", |h| h.lidarsim_version.clone()),
        ("the seed", |h| h.seed.to_string()),
        ("the scene (digest)", |h| {
            format!("{} {}", h.scene_path, h.scene_digest)
        }),
        (
            "the source of profiles (--atmosphere, --profiles or --ensemble)",
            |h| format!("{:?} {:?} {:?}", h.atmospheres, h.profiles_path, h.ensemble),
        ),
        ("the class", |h| h.class.clone()),
        ("the shard count", |h| h.shard_count.to_string()),
        ("the choice of line files (--lines)", |h| {
            format!("{:?}", h.lines)
        }),
        ("the choice of on-line positions (--on-cm1)", |h| {
            decimal(&h.on_cm1_bits)
        }),
        ("the off-line (--off-cm1)", |h| decimal(&[h.off_cm1_bits])),
        ("the CO2 column (--co2-ppm)", |h| decimal(&[h.co2_ppm_bits])),
        ("the largest J'' (--max-j)", |h| h.max_j.to_string()),
        ("the choice of scan offsets (--offsets-ghz)", |h| {
            decimal(&h.offsets_ghz_bits)
        }),
        ("the layer thickness (--layer-m)", |h| {
            decimal(&[h.layer_m_bits])
        }),
        ("the top of the grid (--top-km)", |h| {
            decimal(&[h.top_km_bits])
        }),
        ("the wing cutoff (--wing-cm1)", |h| {
            decimal(&[h.wing_cm1_bits])
        }),
        ("the set of uncertainties (K, MHz, hPa, %)", |h| {
            decimal(&h.uncertainties_bits)
        }),
        ("the per-profile option (--per-profile)", |h| {
            h.per_profile.to_string()
        }),
        ("the choice of figures (--no-plots, --figure-lines)", |h| {
            format!("{} {:?}", h.plots, h.figure_lines)
        }),
        ("the profile set (digest)", |h| {
            format!("{} profiles {}", h.profiles, h.groups_digest)
        }),
        ("the line list (digest)", |h| h.lines_digest.clone()),
    ];
    shard::first_mismatch(
        &a.path,
        &b.path,
        fields
            .iter()
            .map(|(what, f)| (*what, f(&a.header), f(&b.header))),
    )
}

/// A merged line-selection study: the study rebuilt from the shards and every member's
/// outcome, as a single run computes them.
#[derive(Debug)]
pub struct SelectMerged {
    /// The study, set up again from the shards' options and checked against their digests.
    pub study: SelectStudy,
    /// The outcomes of every member, in member order.
    pub outcomes: Vec<MemberOutcome>,
    /// Shards merged.
    pub shards: usize,
}

/// `o` is the outcome of `member` with the study's shapes (class, positions), or what
/// differs.
fn check_outcome(
    config: &StudyConfig,
    member: &SetMember,
    o: &MemberOutcome,
) -> Result<(), String> {
    let id = match o {
        Ok(r) => &r.id,
        Err(f) => &f.id,
    };
    if *id != member.meta.id {
        return Err(format!("`{id}` where the study has `{}`", member.meta.id));
    }
    let Ok(r) = o else { return Ok(()) };
    if r.class != member.meta.class() || r.positions.len() != config.positions.len() {
        return Err(format!(
            "class {}, {} positions where the study has class {}, {} positions",
            r.class,
            r.positions.len(),
            member.meta.class(),
            config.positions.len()
        ));
    }
    Ok(())
}

/// Merge the select shard files `paths` ([`shard::shard_paths`]): every shard of one study,
/// each once, of the same version, scene, profiles, line files and options; the study is set
/// up again and its scene, profiles and line list must have the shards' digests.
pub fn merge(paths: &[PathBuf]) -> Result<SelectMerged, ShardError> {
    let files = shard::whole_set(paths, SelectShardFile::read, check_same)?;
    let h = &files[0].header;
    let bad = |what: String| ShardError::Bad {
        path: files[0].path.clone(),
        what,
    };
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
    let study = SelectStudy::build(h.options().map_err(&bad)?, scene)
        .map_err(|e| bad(format!("its study cannot be set up again: {e}")))?;
    let groups = debug_digest(&study.groups);
    if groups != h.groups_digest || study.len() as u64 != h.profiles {
        return Err(bad(format!(
            "the profiles as built now ({} profiles, digest {groups}) are not the ones the shards ran ({} profiles, digest {}): {} has changed since",
            study.len(),
            h.profiles,
            h.groups_digest,
            match &h.profiles_path {
                Some(p) => format!("the profile set {p}"),
                None => "the way lidarsim builds them".into(),
            }
        )));
    }
    let lines = lines_digest(&study.config);
    if lines != h.lines_digest {
        return Err(bad(format!(
            "the line list as read now (digest {lines}) is not the one the shards ran (digest {}): {} changed since",
            h.lines_digest,
            if h.lines.is_empty() {
                "the built-in band model has".to_string()
            } else {
                format!("a line file ({}) has", h.lines.join(", "))
            }
        )));
    }
    let count = files.len();
    let members: Vec<&SetMember> = study.members().collect();
    let mut outcomes = Vec::with_capacity(members.len());
    for f in files {
        let start = f.header.first_profile as usize;
        for (k, o) in f.outcomes.into_iter().enumerate() {
            let checked = match members.get(start + k) {
                Some(m) => check_outcome(&study.config, m, &o),
                None => Err("beyond the study's last profile".into()),
            };
            if let Err(what) = checked {
                return Err(ShardError::Bad {
                    path: f.path,
                    what: format!("profile {}: {what}", start + k),
                });
            }
            outcomes.push(o);
        }
    }
    Ok(SelectMerged {
        study,
        outcomes,
        shards: count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::LatitudeClass;

    /// Outcomes round-trip exactly: every f64 by its bits (NaN, −0, infinities, subnormals),
    /// failed members with their reason, text with commas and non-ASCII; and a truncated body
    /// is refused, never read past.
    #[test]
    fn outcomes_round_trip_bit_for_bit() {
        let p = |x: f64| PositionResult {
            daod_one_way: x,
            wf_peak_hpa: -0.0,
            dxco2_per_k_ppm: f64::from_bits(0x7ff8_0000_0000_1234),
            dxco2_per_mhz_ppm: f64::INFINITY,
            dxco2_per_hpa_ppm: f64::MIN_POSITIVE / 3.0,
            dxco2_per_10pct_h2o_ppm: 1.0 / 3.0,
            t2_on: f64::NEG_INFINITY,
            random_error_ppm: f64::NAN,
        };
        let outcomes: Vec<MemberOutcome> = vec![
            Ok(MemberResult {
                id: "a, é".into(),
                class: LatitudeClass::High,
                edges_m: vec![0.0, 1000.5, 2e4],
                xco2_ppm: 420.123,
                positions: vec![p(0.5), p(-1e-300)],
            }),
            Err(MemberFailure {
                id: "b\n\"x\"".into(),
                reason: "ends below 1 km, 101 %".into(),
            }),
            Ok(MemberResult {
                id: String::new(),
                class: LatitudeClass::Tropical,
                edges_m: Vec::new(),
                xco2_ppm: f64::NAN,
                positions: Vec::new(),
            }),
        ];
        let mut bytes = Vec::new();
        for o in &outcomes {
            write_outcome(&mut bytes, o).unwrap();
        }
        let mut body = Body::new(&bytes);
        let back: Vec<MemberOutcome> = (0..3).map(|_| read_outcome(&mut body).unwrap()).collect();
        assert_eq!(body.left(), 0);
        // Debug shows every float's value (NaN as NaN); the bits are compared below.
        assert_eq!(format!("{back:?}"), format!("{outcomes:?}"));
        let (Ok(x), Ok(y)) = (&back[0], &outcomes[0]) else {
            panic!("first outcome")
        };
        for (a, b) in x.positions.iter().zip(&y.positions) {
            assert_eq!(
                position_values(a).map(f64::to_bits),
                position_values(b).map(f64::to_bits)
            );
        }
        for n in 0..bytes.len() {
            let mut body = Body::new(&bytes[..n]);
            let r: Result<Vec<MemberOutcome>, String> =
                (0..3).map(|_| read_outcome(&mut body)).collect();
            assert!(r.is_err(), "{n} bytes");
        }
    }
}
