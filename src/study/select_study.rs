//! The whole `lidarsim select-lines` study, shared by a single run, its shards
//! ([`crate::study::select_shard`]) and their merge: the options ([`SelectOptions`]), the inputs
//! built from them ([`SelectStudy::build`]: line list, on-line positions, fine-spectrum
//! windows, instrument, groups of profiles), every member's outcome ([`SelectStudy::study`])
//! and the summary of each group ([`SelectStudy::summarise`]).
//!
//! The unit of work is the member: the groups' members in group order, each studied alone
//! ([`select::study_member`] after [`select::set_co2_column_average`]), so a slice of them
//! gives the same numbers as the whole study on any thread count. Nothing in a member's study
//! is random; a generated ensemble is drawn whole from the seed (class i of tropical, mid,
//! high takes seed S + i, as `lidarsim dial --ensemble`) before any member is studied.

use std::ops::Range;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::atmosphere::{
    LatitudeClass, ProfileSet, SetMember, StandardAtmosphere, StateShift, read_profile_set,
    shift_member,
};
use crate::scene::Scene;
use crate::spectroscopy::{LblOptions, LineFilter, LineList};
use crate::study::dial::{self, ProfileSource};
use crate::study::select::{
    self, GHZ_PER_CM1, GridSpec, MemberFailure, MemberResult, NoiseModel, OnPosition, Row,
    SelectError, SpectrumWindow, Steps, StudyConfig, Uncertainties,
};

/// Half width of the fine spectra of the transmission figure \[GHz\].
pub const SPECTRUM_HALF_GHZ: f64 = 4.0;
/// Step of the fine spectra \[GHz\].
pub const SPECTRUM_STEP_GHZ: f64 = 0.02;

/// Where the profiles of a line-selection study come from.
#[derive(Debug, Clone, PartialEq)]
pub enum SelectSource {
    /// Built-in AFGL atmospheres, one group of one member each.
    Atmospheres(Vec<StandardAtmosphere>),
    /// A profile set file: one group per latitude class.
    Set(PathBuf),
    /// `n` members per class around the class's AFGL mean (one group per class).
    Ensemble(usize),
}

/// The options of `lidarsim select-lines`: everything but the scene that changes its outputs.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectOptions {
    /// The profiles.
    pub source: SelectSource,
    /// Seed of a generated ensemble.
    pub seed: u64,
    /// Latitude classes of a set or ensemble: `high`, `mid`, `tropical` or `all`.
    pub class: String,
    /// Also one row per profile.
    pub per_profile: bool,
    /// HITRAN `.par` files (empty: the built-in CO2 30012←00001 band model).
    pub lines: Vec<PathBuf>,
    /// On-line positions \[cm⁻¹\] (empty: scan the band's lines).
    pub on_cm1: Vec<f64>,
    /// The off-line \[cm⁻¹\].
    pub off_cm1: f64,
    /// CO2 dry-air column average of every profile \[ppm\].
    pub co2_ppm: f64,
    /// Scan: largest J″.
    pub max_j: u32,
    /// Scan: offsets from each line's centre \[GHz\].
    pub offsets_ghz: Vec<f64>,
    /// Layer thickness \[m\].
    pub layer_m: f64,
    /// Top of the grid \[km\].
    pub top_km: f64,
    /// Line wing cutoff \[cm⁻¹\].
    pub wing_cm1: f64,
    /// Uncertainties of the total error.
    pub uncertainties: Uncertainties,
    /// Lines whose fine spectra the figures show (labels).
    pub figure_lines: Vec<String>,
    /// Whether the figures are drawn (and their fine spectra computed).
    pub plots: bool,
}

/// A study set up: its options, scene, configuration and groups of profiles.
#[derive(Debug, Clone)]
pub struct SelectStudy {
    /// The options it was built from.
    pub options: SelectOptions,
    /// The scene whose instrument sets the random error.
    pub scene: Scene,
    /// What is computed for every member.
    pub config: StudyConfig,
    /// The groups (atmosphere or class name, members), in report order.
    pub groups: Vec<(String, Vec<SetMember>)>,
}

/// The outcome of one member: its results, or why it could not be studied.
pub type MemberOutcome = Result<MemberResult, MemberFailure>;

fn usage(message: String) -> SelectError {
    SelectError::Usage(message)
}

/// Read and merge the line files (all molecules) with `filter`; the band model without files.
fn read_lines(paths: &[PathBuf], filter: &LineFilter) -> Result<LineList, SelectError> {
    if paths.is_empty() {
        return Ok(LineList::co2_30012_band_model().filtered(filter));
    }
    let mut out = LineList {
        source: String::new(),
        lines: Vec::new(),
    };
    let mut sources = Vec::new();
    for p in paths {
        let l = LineList::read_par(p, filter).map_err(|error| SelectError::Lines {
            path: p.clone(),
            error,
        })?;
        sources.push(l.source);
        out.lines.extend(l.lines);
    }
    out.lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
    out.source = sources.join(" + ");
    Ok(out)
}

impl SelectOptions {
    /// The candidate positions and the fine-spectrum windows, from the band's lines (626).
    fn positions_and_windows(&self) -> Result<(Vec<OnPosition>, Vec<SpectrumWindow>), SelectError> {
        let band_all = select::band_lines(&read_lines(
            &self.lines,
            &LineFilter {
                isotopologues: Some(vec![(2, 1)]),
                ..Default::default()
            },
        )?);
        let positions: Vec<OnPosition> = if self.on_cm1.is_empty() {
            if self.offsets_ghz.is_empty() {
                return Err(usage("--offsets-ghz: give at least one offset".into()));
            }
            let p = select::scan_positions(&band_all, self.max_j, &self.offsets_ghz);
            if p.is_empty() {
                return Err(usage(format!(
                    "no line of the CO2 30012<-00001 band (626) with J'' <= {} in {}",
                    self.max_j,
                    match self.lines.first() {
                        None => "the band model".to_string(),
                        Some(l) => format!("--lines {}", l.display()),
                    }
                )));
            }
            p
        } else {
            select::label_positions(&band_all, &self.on_cm1)
        };
        if !self.plots {
            return Ok((positions, Vec::new()));
        }
        let n = (2.0 * SPECTRUM_HALF_GHZ / SPECTRUM_STEP_GHZ).round() as usize;
        let offsets: Vec<f64> = (0..=n)
            .map(|k| -SPECTRUM_HALF_GHZ + k as f64 * SPECTRUM_STEP_GHZ)
            .collect();
        let windows = self
            .figure_lines
            .iter()
            .map(|label| match band_all.iter().find(|b| &b.label == label) {
                Some(b) => Ok(SpectrumWindow {
                    label: label.clone(),
                    centre_cm1: b.nu_cm1,
                    offsets_ghz: offsets.clone(),
                }),
                None => Err(usage(format!(
                    "--figure-lines: no band line `{label}` (labels look like R16e, P20e)"
                ))),
            })
            .collect::<Result<_, _>>()?;
        Ok((positions, windows))
    }

    /// The groups of members: (atmosphere or class name, members).
    fn groups(&self) -> Result<Vec<(String, Vec<SetMember>)>, SelectError> {
        let (set, path) = match &self.source {
            SelectSource::Atmospheres(a) => {
                return Ok(a
                    .iter()
                    .map(|s| (s.name().to_string(), vec![s.member()]))
                    .collect());
            }
            SelectSource::Set(p) => (read_profile_set(p)?, p.clone()),
            SelectSource::Ensemble(n) => {
                let set = dial::profile_set(&ProfileSource::Ensemble(*n), &self.class, self.seed)?;
                let name = PathBuf::from(&set.name);
                (set, name)
            }
        };
        if set.is_empty() {
            return Err(usage(format!(
                "--profiles {}: the set has no profiles",
                path.display()
            )));
        }
        let classes: Vec<LatitudeClass> = if self.class == "all" {
            LatitudeClass::ALL.to_vec()
        } else {
            vec![
                self.class
                    .parse()
                    .map_err(|e: String| usage(format!("--class: {e}")))?,
            ]
        };
        let mut out = Vec::new();
        for c in classes {
            let members = set.class(c).members;
            if !members.is_empty() {
                out.push((c.name().to_string(), members));
            }
        }
        if out.is_empty() {
            return Err(usage(format!(
                "--profiles {}: no profile in class `{}`",
                path.display(),
                self.class
            )));
        }
        Ok(out)
    }
}

/// The ranges of the study's numbers: the command line's options are parsed against them, and
/// [`SelectOptions::check`] holds options built in code (the Python package's) to them.
pub mod ranges {
    use crate::input::Bounds;
    /// `on_cm1`, `off_cm1` \[cm⁻¹\].
    pub const WAVENUMBER_CM1: Bounds = Bounds::positive(1e6);
    /// `co2_ppm`.
    pub const CO2_PPM: Bounds = Bounds::open(0.0, 1e6);
    /// `max_j`: at most.
    pub const MAX_J: u32 = 200;
    /// `offsets_ghz`.
    pub const OFFSET_GHZ: Bounds = Bounds::closed(-1e3, 1e3);
    /// `layer_m`.
    pub const LAYER_M: Bounds = Bounds::positive(1e5);
    /// `top_km`.
    pub const TOP_KM: Bounds = Bounds::positive(1e3);
    /// `wing_cm1`.
    pub const WING_CM1: Bounds = Bounds::positive(1e3);
    /// Uncertainty of temperature \[K\].
    pub const TEMPERATURE_K: Bounds = Bounds::closed(0.0, 100.0);
    /// Uncertainty of frequency \[MHz\].
    pub const FREQUENCY_MHZ: Bounds = Bounds::closed(0.0, 1e5);
    /// Uncertainty of surface pressure \[hPa\].
    pub const SURFACE_PRESSURE_HPA: Bounds = Bounds::closed(0.0, 100.0);
    /// Uncertainty of water vapour \[%\].
    pub const H2O_PERCENT: Bounds = Bounds::closed(0.0, 1000.0);
}

impl SelectOptions {
    /// Every number inside its range ([`ranges`]); an error names the field (`layer_m: …`).
    pub fn check(&self) -> Result<(), SelectError> {
        use crate::input::check_finite_range as check;
        let at = |name: &'static str| move |m: String| usage(format!("{name}: {m}"));
        for v in &self.on_cm1 {
            check(*v, ranges::WAVENUMBER_CM1).map_err(at("on_cm1"))?;
        }
        check(self.off_cm1, ranges::WAVENUMBER_CM1).map_err(at("off_cm1"))?;
        check(self.co2_ppm, ranges::CO2_PPM).map_err(at("co2_ppm"))?;
        if self.max_j > ranges::MAX_J {
            return Err(usage(format!(
                "max_j: {} is above {}",
                self.max_j,
                ranges::MAX_J
            )));
        }
        for v in &self.offsets_ghz {
            check(*v, ranges::OFFSET_GHZ).map_err(at("offsets_ghz"))?;
        }
        check(self.layer_m, ranges::LAYER_M).map_err(at("layer_m"))?;
        check(self.top_km, ranges::TOP_KM).map_err(at("top_km"))?;
        check(self.wing_cm1, ranges::WING_CM1).map_err(at("wing_cm1"))?;
        let u = &self.uncertainties;
        check(u.temperature_k, ranges::TEMPERATURE_K).map_err(at("temperature_uncertainty_k"))?;
        check(u.frequency_mhz, ranges::FREQUENCY_MHZ).map_err(at("frequency_uncertainty_mhz"))?;
        check(u.surface_pressure_hpa, ranges::SURFACE_PRESSURE_HPA)
            .map_err(at("surface_pressure_uncertainty_hpa"))?;
        check(u.h2o_percent, ranges::H2O_PERCENT).map_err(at("h2o_uncertainty_percent"))?;
        Ok(())
    }
}

impl SelectStudy {
    /// Set up the study of `options` with the instrument of `scene`: read the line files,
    /// place the on-line positions, check that the lines reach them and the off-line, and
    /// build the groups of profiles. Every refusal names the option.
    pub fn build(options: SelectOptions, scene: Scene) -> Result<SelectStudy, SelectError> {
        let o = &options;
        // Each number (the command line's parser checked them already), then the grid's size.
        o.check()?;
        crate::limits::check_product(
            "--layer-m",
            &[("layers", (o.top_km * 1e3 / o.layer_m).ceil() as u64)],
            crate::limits::MAX_PATH_LAYERS,
        )
        .map_err(usage)?;
        let wing = o.wing_cm1;
        let (positions, spectra) = o.positions_and_windows()?;

        // Every line reaching a position, the off-line or a spectrum with its wing.
        let mut nus: Vec<f64> = positions.iter().map(|p| p.nu_cm1).collect();
        nus.push(o.off_cm1);
        for w in &spectra {
            nus.push(w.centre_cm1 - SPECTRUM_HALF_GHZ / GHZ_PER_CM1);
            nus.push(w.centre_cm1 + SPECTRUM_HALF_GHZ / GHZ_PER_CM1);
        }
        let lo = nus.iter().copied().fold(f64::INFINITY, f64::min) - wing - 1.0;
        let hi = nus.iter().copied().fold(f64::NEG_INFINITY, f64::max) + wing + 1.0;
        let lines = read_lines(&o.lines, &LineFilter::window(lo, hi))?;
        let reaches = |nu: f64| {
            lines
                .lines
                .iter()
                .any(|l| l.molecule_id == 2 && (l.nu_cm1 - nu).abs() <= wing)
        };
        if !reaches(o.off_cm1) {
            return Err(usage(format!(
                "--off-cm1 {}: no CO2 line within the wing cutoff ({wing} cm-1) in {}; the off-line must lie in the CO2 band the lines cover",
                o.off_cm1,
                if o.lines.is_empty() {
                    "the built-in 30012 band model"
                } else {
                    "the line files"
                }
            )));
        }
        if let Some(p) = positions.iter().find(|p| !reaches(p.nu_cm1)) {
            return Err(usage(format!(
                "--on-cm1 {}: no CO2 line within the wing cutoff ({wing} cm-1)",
                p.nu_cm1
            )));
        }
        if !(5000.0..=1e5).contains(&o.off_cm1) {
            return Err(usage(format!(
                "--off-cm1 {}: outside 5000–100000 cm-1 (the Rayleigh cross-sections cover 100–2000 nm)",
                o.off_cm1
            )));
        }
        let noise = NoiseModel::from_scene(&scene)?;
        let config = StudyConfig {
            lines,
            options: LblOptions {
                wing_cm1: wing,
                ..Default::default()
            },
            off_cm1: o.off_cm1,
            positions,
            grid: GridSpec {
                layer_m: o.layer_m,
                top_m: o.top_km * 1e3,
            },
            steps: Steps::CONTRACT,
            noise: Some(noise),
            spectra,
        };
        let groups = o.groups()?;
        Ok(SelectStudy {
            options,
            scene,
            config,
            groups,
        })
    }

    /// Every member, in group order: the study's units of work.
    pub fn members(&self) -> impl Iterator<Item = &SetMember> {
        self.groups.iter().flat_map(|(_, m)| m)
    }

    /// Number of members.
    pub fn len(&self) -> usize {
        self.groups.iter().map(|(_, m)| m.len()).sum()
    }

    /// Whether the study has no member (never, once built).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Study the members `range` (of [`SelectStudy::members`]) in parallel on the current
    /// rayon pool, each with its CO2 set to the column average first, in member order.
    /// `progress` is called once per member.
    pub fn study(&self, range: Range<usize>, progress: &(dyn Fn() + Sync)) -> Vec<MemberOutcome> {
        let members: Vec<&SetMember> = self.members().skip(range.start).take(range.len()).collect();
        select::study_members(&members, &self.config, self.options.co2_ppm, progress, None)
    }

    /// [`Self::study`] of every member, the members not yet begun when `stop` is set (from
    /// another thread: a user's Ctrl-C) left out: `None` when stopped.
    pub fn study_until(
        &self,
        progress: &(dyn Fn() + Sync),
        stop: &AtomicBool,
    ) -> Option<Vec<MemberOutcome>> {
        let members: Vec<&SetMember> = self.members().collect();
        let outcomes = select::study_members(
            &members,
            &self.config,
            self.options.co2_ppm,
            progress,
            Some(stop),
        );
        (!stop.load(Ordering::Relaxed)).then_some(outcomes)
    }

    /// Summarise every group from the outcomes of all members ([`SelectStudy::study`] of
    /// `0..len`, in member order); the groups in parallel on the current rayon pool (each
    /// alone: the same numbers on any thread count).
    pub fn summarise(&self, outcomes: &[MemberOutcome]) -> Vec<GroupSummary> {
        let unc = &self.options.uncertainties;
        let starts: Vec<usize> = self
            .groups
            .iter()
            .scan(0, |at, (_, m)| {
                let s = *at;
                *at += m.len();
                Some(s)
            })
            .collect();
        self.groups
            .par_iter()
            .zip(starts)
            .map(|((name, members), at)| {
                let group = outcomes.get(at..at + members.len()).unwrap_or(&[]);
                let mut ok: Vec<&MemberResult> = Vec::new();
                let mut failed = Vec::new();
                for r in group {
                    match r {
                        Ok(m) => ok.push(m),
                        Err(f) => failed.push(f.clone()),
                    }
                }
                let (rows, dropped) = select::summarise(name, &ok, &self.config, unc);
                let per_profile = if self.options.per_profile {
                    ok.iter()
                        .flat_map(|m| select::summarise(&m.id, &[*m], &self.config, unc).0)
                        .collect()
                } else {
                    Vec::new()
                };
                let spectra = if self.options.plots && !ok.is_empty() {
                    let studied: Vec<&SetMember> = members
                        .iter()
                        .zip(group)
                        .filter(|(_, o)| o.is_ok())
                        .map(|(m, _)| m)
                        .collect();
                    self.mean_spectra(&studied).map_err(|e| e.to_string())
                } else {
                    Ok(Vec::new())
                };
                GroupSummary {
                    name: name.clone(),
                    rows,
                    dropped,
                    failed,
                    profiles: ok.len(),
                    mean_xco2_ppm: ok.iter().map(|m| m.xco2_ppm).sum::<f64>() / ok.len() as f64,
                    per_profile,
                    spectra,
                }
            })
            .collect()
    }
}

impl SelectStudy {
    /// The figures' transmission spectra ([`select::transmission_spectra`]) of the mean
    /// profile of `members` ([`ProfileSet::mean_member`], as the class-mean profiles of
    /// `lidarsim dial`; a single member itself), its CO2 set as every member's and shifted by
    /// nothing as a member's unshifted state is.
    fn mean_spectra(&self, members: &[&SetMember]) -> Result<Vec<Vec<f64>>, SelectError> {
        let mut mean = match members {
            [one] => (*one).clone(),
            _ => ProfileSet {
                name: "the group's profiles".into(),
                members: members.iter().map(|m| (*m).clone()).collect(),
                notes: Vec::new(),
            }
            .mean_member()?,
        };
        select::set_co2_column_average(&mut mean.profile, self.options.co2_ppm)?;
        let mean = shift_member(&mean, &StateShift::NONE)?;
        select::transmission_spectra(&self.config, &mean.profile)
    }
}

/// One group's summary: what `select-lines` reports and writes for it.
#[derive(Debug, Clone)]
pub struct GroupSummary {
    /// Atmosphere or class name.
    pub name: String,
    /// Its rows, in rank order ([`select::summarise`]).
    pub rows: Vec<Row>,
    /// Positions dropped (indices into [`StudyConfig::positions`]).
    pub dropped: Vec<usize>,
    /// Members that could not be studied, in member order.
    pub failed: Vec<MemberFailure>,
    /// Members studied.
    pub profiles: usize,
    /// Mean XCO2 of the members studied \[ppm\] (NaN for none).
    pub mean_xco2_ppm: f64,
    /// One group of rows per member studied, with `per_profile` (else empty).
    pub per_profile: Vec<Row>,
    /// Two-way transmission of the group's mean profile per [`StudyConfig::spectra`] window
    /// and offset, with plots (else empty), or why it could not be computed.
    pub spectra: Result<Vec<Vec<f64>>, String>,
}

impl GroupSummary {
    /// The members that could not be studied, grouped by reason
    /// ([`crate::study::group_failures`]).
    pub fn failure_groups(&self) -> Vec<crate::study::FailureGroup> {
        crate::study::group_failures(
            self.failed
                .iter()
                .map(|f| (f.id.as_str(), f.reason.as_str())),
        )
    }

    /// Refuse a group where a position given by `--on-cm1` was dropped. A group none of whose
    /// members could be studied has no rows and is not refused here: its failures are the
    /// study's ([`crate::study::FailureReport::verdict`] decides on them, for the whole study).
    pub fn check(&self, study: &SelectStudy) -> Result<(), SelectError> {
        if self.profiles == 0 {
            return Ok(());
        }
        if !study.options.on_cm1.is_empty() && !self.dropped.is_empty() {
            let v: Vec<String> = self
                .dropped
                .iter()
                .map(|i| format!("{}", study.config.positions[*i].nu_cm1))
                .collect();
            return Err(usage(format!(
                "--on-cm1 {}: the on-line does not absorb more than the off-line {} cm-1 (DAOD ≤ 0) in `{}`",
                v.join(","),
                study.config.off_cm1,
                self.name
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options() -> SelectOptions {
        SelectOptions {
            source: SelectSource::Atmospheres(vec![StandardAtmosphere::UsStandard]),
            seed: 1,
            class: "all".into(),
            per_profile: false,
            lines: Vec::new(),
            on_cm1: vec![6358.655],
            off_cm1: 6360.61,
            co2_ppm: 420.0,
            max_j: 40,
            offsets_ghz: vec![-3.0, 0.0, 3.0],
            layer_m: 250.0,
            top_km: 60.0,
            wing_cm1: 25.0,
            uncertainties: Uncertainties {
                temperature_k: 1.0,
                frequency_mhz: 1.0,
                surface_pressure_hpa: 1.0,
                h2o_percent: 10.0,
            },
            figure_lines: Vec::new(),
            plots: false,
        }
    }

    /// Options built in code are held to the command line's ranges, each refusal naming the
    /// field; the ends the options allow pass.
    #[test]
    fn options_are_held_to_the_command_lines_ranges() {
        assert!(options().check().is_ok());
        let with = |f: fn(&mut SelectOptions)| {
            let mut o = options();
            f(&mut o);
            o.check().map_err(|e| e.to_string())
        };
        for edge in [
            with(|o| o.max_j = ranges::MAX_J),
            with(|o| o.offsets_ghz = vec![-1e3, 1e3]),
            with(|o| o.uncertainties.temperature_k = 0.0),
            with(|o| o.uncertainties.h2o_percent = 1000.0),
            with(|o| o.layer_m = 1e5),
        ] {
            assert!(edge.is_ok(), "{edge:?}");
        }
        for (bad, name) in [
            (with(|o| o.on_cm1 = vec![6358.0, -1.0]), "on_cm1"),
            (with(|o| o.off_cm1 = 0.0), "off_cm1"),
            (with(|o| o.co2_ppm = f64::NAN), "co2_ppm"),
            (with(|o| o.max_j = ranges::MAX_J + 1), "max_j"),
            (with(|o| o.offsets_ghz = vec![1001.0]), "offsets_ghz"),
            (with(|o| o.layer_m = -250.0), "layer_m"),
            (with(|o| o.top_km = 1e4), "top_km"),
            (with(|o| o.wing_cm1 = 0.0), "wing_cm1"),
            (
                with(|o| o.uncertainties.temperature_k = -1.0),
                "temperature_uncertainty_k",
            ),
            (
                with(|o| o.uncertainties.frequency_mhz = 2e5),
                "frequency_uncertainty_mhz",
            ),
            (
                with(|o| o.uncertainties.surface_pressure_hpa = 101.0),
                "surface_pressure_uncertainty_hpa",
            ),
            (
                with(|o| o.uncertainties.h2o_percent = 1001.0),
                "h2o_uncertainty_percent",
            ),
        ] {
            assert!(
                bad.as_ref().is_err_and(|m| m.contains(name)),
                "{name}: {bad:?}"
            );
        }
    }

    /// A study watched for a stop (the Python package's path) is the study while the flag
    /// stays down, and `None` once it is up.
    #[test]
    fn a_watched_study_is_the_study_until_it_is_stopped() {
        let scene = Scene::default_scene().unwrap();
        let study = SelectStudy::build(options(), scene).unwrap();
        let whole = study.study(0..study.len(), &|| {});
        let watched = study.study_until(&|| {}, &AtomicBool::new(false)).unwrap();
        assert_eq!(whole.len(), watched.len());
        assert_eq!(format!("{whole:?}"), format!("{watched:?}"));
        assert!(study.study_until(&|| {}, &AtomicBool::new(true)).is_none());
    }
}
