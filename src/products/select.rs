//! The products of `lidarsim select-lines` (and of `lidarsim merge` of its shards):
//! `sensitivities.csv`, `sensitivities.nc` and `failed.csv` from a study's member outcomes, and
//! the lines of its report.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::ProductError;
use crate::atmosphere::{LatitudeClass, StandardAtmosphere};
use crate::output::{OutputError, OutputSet, csv_field};
use crate::study::select::{self, MemberFailure, Row};
use crate::study::select_study::{GroupSummary, MemberOutcome, SelectSource, SelectStudy};
use crate::study::{FailurePolicy, FailureReport};

/// The line of the report that says what the study computes.
pub fn setup_line(study: &SelectStudy) -> String {
    let cfg = &study.config;
    format!(
        "select-lines: {} on-line positions, off-line {} cm-1, lines {} ({} lines), grid {} m to {} km",
        cfg.positions.len(),
        cfg.off_cm1,
        cfg.lines.source,
        cfg.lines.len(),
        study.options.layer_m,
        study.options.top_km
    )
}

/// A study's results ready to be reported and written: the study, its members' outcomes (all
/// of them, in member order), its groups' statistics and the rows of `sensitivities.csv`.
pub struct SelectProducts<'a> {
    /// The study.
    pub study: &'a SelectStudy,
    /// Its members' outcomes.
    pub outcomes: &'a [MemberOutcome],
    /// Its groups' statistics ([`SelectStudy::summarise`]).
    pub summaries: Vec<GroupSummary>,
    /// The rows of `sensitivities.csv`: every group's, then the per-profile ones.
    pub rows: Vec<Row>,
    /// Its failed members, grouped by reason over the whole study.
    pub failures: FailureReport,
}

impl<'a> SelectProducts<'a> {
    /// `sensitivities.nc` ([`select::to_dataset`]) with the global attributes of every study
    /// file ([`crate::netcdf::study_globals`]): the scene's file name and text (the instrument
    /// of the random error) and the seed.
    pub fn dataset(
        &self,
        history: &str,
    ) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
        let title = "lidarsim select-lines: CO2 IPDA line selection";
        let mut nc = select::to_dataset(&self.rows, title, history)?;
        let scene = &self.study.scene;
        let file = scene.path.file_name().map_or_else(
            || scene.path.display().to_string(),
            |f| f.to_string_lossy().into_owned(),
        );
        crate::netcdf::study_globals(
            &mut nc,
            &crate::netcdf::StudyAttributes {
                title,
                history,
                scene_file: Some(&file),
                scene_text: Some(scene.text()),
                seed: Some(self.study.options.seed),
                profile_set: None,
            },
        );
        Ok(nc)
    }

    /// The products of a study; an error when every member failed (nothing is written as if
    /// the study had succeeded).
    pub fn new(
        study: &'a SelectStudy,
        outcomes: &'a [MemberOutcome],
    ) -> Result<Self, ProductError> {
        Self::with_policy(study, outcomes, FailurePolicy::Tolerate)
    }

    /// [`Self::new`] under `policy`: with [`FailurePolicy::Strict`] an error when any member
    /// failed ([`FailureReport::verdict`]).
    pub fn with_policy(
        study: &'a SelectStudy,
        outcomes: &'a [MemberOutcome],
        policy: FailurePolicy,
    ) -> Result<Self, ProductError> {
        let failed: Vec<&MemberFailure> =
            outcomes.iter().filter_map(|o| o.as_ref().err()).collect();
        let report = FailureReport::new(
            outcomes.len(),
            failed.iter().map(|f| (f.id.as_str(), f.reason.as_str())),
        );
        if report.failed() > 0 {
            let o = &study.options;
            let of = match &o.source {
                SelectSource::Set(p) => p.display().to_string(),
                SelectSource::Ensemble(n) => {
                    format!("the ensemble ({n} members per class, seed {})", o.seed)
                }
                SelectSource::Atmospheres(a) => {
                    let names: Vec<&str> = a.iter().map(|s| s.name()).collect();
                    format!("--atmosphere {}", names.join(","))
                }
            };
            report
                .verdict(&of, policy)
                .map_err(ProductError::ProfilesFailed)?;
        }
        let summaries = study.summarise(outcomes);
        let mut rows: Vec<Row> = Vec::new();
        let mut per_profile: Vec<Row> = Vec::new();
        for g in &summaries {
            rows.extend(g.rows.iter().cloned());
            per_profile.extend(g.per_profile.iter().cloned());
        }
        rows.extend(per_profile);
        Ok(SelectProducts {
            study,
            outcomes,
            summaries,
            rows,
            failures: report,
        })
    }

    /// Write the study's files into `dir`, all or none: the tables, `sensitivities.nc` (with
    /// `history`, the NetCDF `history` attribute) when there are rows, and the figures
    /// `figures` stages. Returns the files written, in order.
    pub fn write(
        &self,
        dir: &Path,
        history: &str,
        figures: impl FnOnce(&mut OutputSet) -> Result<(), OutputError>,
    ) -> Result<Vec<PathBuf>, ProductError> {
        // An earlier study's files this one does not rewrite (the figures of other groups, a
        // NetCDF file) go with the commit.
        let mut files = OutputSet::new();
        let names = file_names();
        files.replaces(dir, &names.iter().map(String::as_str).collect::<Vec<_>>())?;
        files.write(dir.join("sensitivities.csv"), select::to_csv(&self.rows))?;
        files.write(dir.join(FAILED_CSV), failed_csv(self.study, self.outcomes))?;
        if !self.rows.is_empty() {
            let nc = self.dataset(history)?.encode()?;
            files.write(dir.join("sensitivities.nc"), nc)?;
        }
        figures(&mut files)?;
        Ok(files.commit()?)
    }
}

impl SelectProducts<'_> {
    /// The line that says how many members of the whole study failed, pointing at `failed.csv`
    /// (each reason is said once per group by [`report_failures`]); nothing when none failed.
    pub fn report_failed(&self, out: &mut impl Write) -> std::io::Result<()> {
        let failed = self.failures.failed();
        if failed > 0 {
            writeln!(
                out,
                "{failed} of {} profiles failed and were left out of the statistics ({FAILED_CSV})",
                self.failures.total
            )?;
        }
        Ok(())
    }
}

/// The group's failed members, each reason once with its count and first profile: not a line
/// per profile.
pub fn report_failures(out: &mut impl Write, g: &GroupSummary) -> std::io::Result<()> {
    let name = &g.name;
    for f in g.failure_groups() {
        writeln!(out, "{name}: excluded {f}")?;
    }
    Ok(())
}

/// The group's size and mean XCO2, and its five best-ranked positions; for a group none of
/// whose members could be studied, that it has no rows.
pub fn report_group(out: &mut impl Write, g: &GroupSummary) -> std::io::Result<()> {
    let name = &g.name;
    if g.profiles == 0 {
        return writeln!(
            out,
            "{name}: every profile failed ({} excluded): no rows, no figures",
            g.failed.len()
        );
    }
    writeln!(
        out,
        "{name}: {} profiles ({} excluded), XCO2 {:.2} ppm, {} positions kept, {} dropped (DAOD ≤ 0)",
        g.profiles,
        g.failed.len(),
        g.mean_xco2_ppm,
        g.rows.len(),
        g.dropped.len()
    )?;
    for r in g.rows.iter().take(5) {
        writeln!(
            out,
            "  #{} {:.4} cm-1 {} {:+.2} GHz: DAOD {:.3}, WF peak {:.0} hPa, per K {:+.3}, per MHz {:+.3}, per hPa {:+.3}, per 10% H2O {:+.3}, random {:.3}, total {:.3} ppm",
            r.rank,
            r.position.nu_cm1,
            r.position.line.as_deref().unwrap_or("-"),
            r.position.offset_ghz,
            r.daod_one_way,
            r.wf_peak_hpa,
            r.dxco2_per_k_ppm,
            r.dxco2_per_mhz_ppm,
            r.dxco2_per_hpa_ppm,
            r.dxco2_per_10pct_h2o_ppm,
            r.random_error_ppm,
            r.total_error_ppm
        )?;
    }
    Ok(())
}

/// The file that lists the profiles that could not be studied.
pub const FAILED_CSV: &str = "failed.csv";

/// Every file `select-lines` may write into its directory: the tables, and the two figures of
/// each group it can have (an AFGL atmosphere or a latitude class).
pub fn file_names() -> Vec<String> {
    let mut v: Vec<String> = ["sensitivities.csv", "sensitivities.nc", FAILED_CSV]
        .map(String::from)
        .to_vec();
    let groups = StandardAtmosphere::ALL
        .iter()
        .map(|a| a.name())
        .chain(LatitudeClass::ALL.iter().map(|c| c.name()));
    for g in groups {
        v.push(format!("transmission_{g}.png"));
        v.push(format!("errors_{g}.png"));
    }
    v
}

/// Header of `failed.csv`, one row per member that could not be studied.
pub const FAILED_HEADER: &str = "index,profile_id,group,reason";

/// `failed.csv`: one row per member that could not be studied, in member order: its 0-based
/// index in the study (groups in report order, each group's members in set order), id, group
/// (the AFGL atmosphere or latitude class) and reason (the header alone when none failed).
pub fn failed_csv(study: &SelectStudy, outcomes: &[MemberOutcome]) -> String {
    use std::fmt::Write as _;
    let mut s = format!("{FAILED_HEADER}\n");
    let groups = study
        .groups
        .iter()
        .flat_map(|(name, members)| std::iter::repeat_n(name, members.len()));
    for (i, (o, group)) in outcomes.iter().zip(groups).enumerate() {
        if let Err(f) = o {
            let _ = writeln!(
                s,
                "{i},{},{},{}",
                csv_field(&f.id),
                csv_field(group),
                csv_field(&f.reason)
            );
        }
    }
    s
}
