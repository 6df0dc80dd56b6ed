//! Writing a command's products with its figures, and printing its report: for `run`, `dial`
//! and `select-lines`, and for `merge` of their shards, whose files must be the same. The
//! library makes the files ([`lidarsim::products`]); the command line draws the figures.

use std::io::Write as _;
use std::path::Path;

use lidarsim::pipeline::RunOutput;
use lidarsim::products::{self, dial::DialProducts, select::SelectProducts};
use lidarsim::scene::Scene;
use lidarsim::study::FailurePolicy;
use lidarsim::study::dial::StudyResult;
use lidarsim::study::select_study::{MemberOutcome, SelectStudy};
use lidarsim::study::shard::StudyInputs;

use crate::figures::init_font;

/// Write the files of a run into `out` (all together or none, [`products::run::write`]) with
/// its figures unless `no_plots`, and print its report.
pub fn run(
    out_dir: &Path,
    no_plots: bool,
    netcdf: bool,
    scene: &Scene,
    run: &RunOutput,
) -> anyhow::Result<()> {
    // Once, before the files: the scene's and the run's warnings (also in the summary).
    for w in &run.warnings {
        lidarsim::limits::warn(w);
    }
    let history = netcdf.then(super::netcdf_history);
    let written =
        products::run::write(
            out_dir,
            scene,
            run,
            history.as_deref(),
            |files| match no_plots {
                true => Ok(()),
                false => crate::figures::run::draw(files, out_dir, scene, run),
            },
        )?;
    products::run::report(&mut std::io::stdout().lock(), scene, run, &written)?;
    Ok(())
}

/// Write a study's files into `dir` (all or none) with its figures unless `no_plots`, and
/// print its report: `lidarsim dial`, and `lidarsim merge` of dial shards.
pub fn dial(
    dir: &Path,
    no_plots: bool,
    netcdf: bool,
    inputs: &StudyInputs,
    result: &StudyResult,
    policy: FailurePolicy,
) -> anyhow::Result<()> {
    // Once for the study, not per profile: the scene's own warnings.
    for w in &inputs.scene.warnings {
        lidarsim::limits::warn(w);
    }
    let p = DialProducts::with_policy(inputs, result, policy)?;
    let history = netcdf.then(super::netcdf_history);
    let written = p.write(dir, history.as_deref(), |files| match no_plots {
        true => Ok(()),
        false => crate::figures::dial::draw(files, dir, &inputs.set, result, &p.summaries),
    })?;
    p.report(&mut std::io::stdout().lock(), &written)?;
    Ok(())
}
/// Report every group of a study from its members' `outcomes` (all of them, in member order)
/// and write its files into `dir` (all or none): `lidarsim select-lines`, and `lidarsim merge`
/// of its shards. The figures are drawn if the study computed their spectra and `no_plots` is
/// not set.
pub fn select(
    dir: &Path,
    no_plots: bool,
    study: &SelectStudy,
    outcomes: &[MemberOutcome],
    policy: FailurePolicy,
) -> anyhow::Result<()> {
    let p = SelectProducts::with_policy(study, outcomes, policy)?;
    let out = &mut std::io::stdout().lock();
    p.report_failed(out)?;
    for g in &p.summaries {
        products::select::report_failures(out, g)?;
        g.check(study)?;
        products::select::report_group(out, g)?;
    }
    let written = p.write(dir, &super::netcdf_history(), |files| {
        if study.options.plots && !no_plots {
            init_font();
            // A group none of whose members could be studied has nothing to draw.
            for g in p.summaries.iter().filter(|g| g.profiles > 0) {
                crate::figures::select::draw_figures(
                    files,
                    dir,
                    g,
                    &study.config,
                    &study.options.uncertainties,
                )?;
            }
        }
        Ok(())
    })?;
    for f in written {
        writeln!(out, "wrote {}", f.display())?;
    }
    Ok(())
}
