//! `lidarsim select-lines`: sensitivities of a CO2 IPDA's XCO2 to temperature, laser frequency,
//! surface pressure and humidity errors, and its random error, for candidate on-line positions
//! (method: `lidarsim::study::select`, docs/retrieval.md; the study's set-up:
//! `lidarsim::study::select_study`). Writes `DIR/sensitivities.csv`, `DIR/sensitivities.nc` and,
//! unless `--no-plots`, per atmosphere `transmission_<atm>.png` (Figure 4 of the seed paper) and
//! `errors_<atm>.png` (Figure 5); with `--shard I/N` only the shard file of a slice of the
//! profiles (`lidarsim::study::select_shard`), which `lidarsim merge` puts together.

use std::path::{Path, PathBuf};

use anyhow::Context;
use plotters::prelude::*;

use lidarsim::atmosphere::{LatitudeClass, StandardAtmosphere};
use lidarsim::input::Bounds;
use lidarsim::output::{self, OutputError, OutputSet, csv_field};
use lidarsim::scene::Scene;
use lidarsim::shard::{self, ShardSpec};
use lidarsim::study;
use lidarsim::study::select::{self, MemberFailure, Row, StudyConfig, Uncertainties};
use lidarsim::study::select_shard;
use lidarsim::study::select_study::{
    GroupSummary, MemberOutcome, SPECTRUM_HALF_GHZ, SelectOptions, SelectSource, SelectStudy,
};

use super::plot::{FONT, draw_legend, init_font};

/// Arguments of `lidarsim select-lines`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Built-in AFGL atmospheres, comma-separated (tropical, midlatitude_summer,
    /// midlatitude_winter, subarctic_summer, subarctic_winter, us_standard).
    #[arg(
        long,
        value_delimiter = ',',
        required_unless_present_any = ["profiles", "ensemble"],
        conflicts_with_all = ["profiles", "ensemble"]
    )]
    atmosphere: Vec<StandardAtmosphere>,
    /// A lidarsim profile-set CSV; statistics per latitude class.
    #[arg(long, value_name = "SET", conflicts_with = "ensemble")]
    profiles: Option<PathBuf>,
    /// Instead of a set: N members per class around the class's AFGL mean with the
    /// representative NWP forecast-error covariance (as `lidarsim dial --ensemble`: class i of
    /// tropical, mid, high takes seed S + i).
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = super::count_usize(2, lidarsim::limits::MAX_ENSEMBLE_LEVELS))]
    ensemble: Option<usize>,
    /// Seed of --ensemble.
    #[arg(long, default_value_t = 1, requires = "ensemble")]
    seed: u64,
    /// Latitude class of --profiles or --ensemble: high, mid, tropical, or all (one group per
    /// class).
    #[arg(long, default_value = "all", value_parser = super::latitude_class)]
    class: String,
    /// With --profiles: also one row per profile id (atmosphere = the id).
    #[arg(long)]
    per_profile: bool,
    /// HITRAN .par line files (repeatable; e.g. CO2 and H2O). Without: the built-in CO2
    /// 30012←00001 band model (CO2 626 only, approximate).
    #[arg(long, value_name = "FILE")]
    lines: Vec<PathBuf>,
    /// On-line positions [cm⁻¹], comma-separated. Without: scan the band's lines (--max-j,
    /// --offsets-ghz).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e6)))]
    on_cm1: Vec<f64>,
    /// The off-line [cm⁻¹].
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e6)))]
    off_cm1: f64,
    /// CO2 dry-air column average of every profile [ppm] (rescaled, or set if absent).
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::open(0.0, 1e6)))]
    co2_ppm: f64,
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    /// Scan: largest J″ of the band's lines.
    #[arg(long, default_value_t = 40, allow_negative_numbers = true, value_parser = super::count_u32(0, 200))]
    max_j: u32,
    /// Scan: offsets from each line's centre [GHz], comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        default_value = "-3,-2.5,-2,-1.5,-1,-0.5,0,0.5,1,1.5,2,2.5,3",
        value_parser = super::real(Bounds::closed(-1e3, 1e3)),
    )]
    offsets_ghz: Vec<f64>,
    /// Layer thickness of the grid [m].
    #[arg(long, default_value_t = 250.0, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e5)))]
    layer_m: f64,
    /// Top of the grid [km] (clipped to the lowest top of the profiles).
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e3)))]
    top_km: f64,
    /// Line wing cutoff [cm⁻¹].
    #[arg(long, default_value_t = 25.0, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e3)))]
    wing_cm1: f64,
    /// Scene whose instrument sets the random error (default: the embedded default scene).
    #[arg(long, value_name = "FILE")]
    scene: Option<PathBuf>,
    /// Uncertainty of the assumed temperature [K] (total error).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 100.0)))]
    temperature_uncertainty_k: f64,
    /// Uncertainty of the laser frequency [MHz] (total error).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 1e5)))]
    frequency_uncertainty_mhz: f64,
    /// Uncertainty of the assumed surface pressure [hPa] (total error).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 100.0)))]
    surface_pressure_uncertainty_hpa: f64,
    /// Uncertainty of the assumed humidity [%] (total error).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 1000.0)))]
    h2o_uncertainty_percent: f64,
    /// Lines drawn in the figures, comma-separated labels.
    #[arg(long, value_delimiter = ',', default_value = "R16e,R26e")]
    figure_lines: Vec<String>,
    /// Do not draw figures.
    #[arg(long)]
    no_plots: bool,
    /// Worker threads, 0 for all cores; at most the cores available.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = super::threads())]
    threads: usize,
    /// Study only shard I of N (0 ≤ I < N) of the profiles and write their results raw to
    /// DIR/shard-I-of-N.lshard; `lidarsim merge` puts the N files together into this study's
    /// outputs.
    #[arg(long, value_name = "I/N", value_parser = clap::value_parser!(ShardSpec))]
    shard: Option<ShardSpec>,
}

/// Half width of the laser's spectral window marked in Figure 4 \[GHz\].
const WINDOW_HALF_GHZ: f64 = 0.5;

/// `lidarsim select-lines`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let scene = match (&a.scene, a.shard) {
        (Some(p), Some(_)) => shard::read_scene(Some(p))?,
        (Some(p), None) => Scene::read(p)?,
        (None, _) => Scene::default_scene()?,
    };
    let study = SelectStudy::build(options(&a)?, scene)?;
    // Before the work; the figures' names depend on the groups and are checked when written.
    let out_files = match a.shard {
        Some(spec) => vec![a.out.join(spec.file_name())],
        None => vec![
            a.out.join("sensitivities.csv"),
            a.out.join("sensitivities.nc"),
            a.out.join(FAILED_CSV),
        ],
    };
    output::check_paths(&out_files)?;
    print_setup(&study)?;
    let pool = super::study_pool(a.threads)?;
    if let Some(spec) = a.shard {
        let n = spec.batches(study.len()).len();
        return super::merge::study_shard(spec, n, "select-lines shard", &pool, |tick| {
            select_shard::run(&study, spec, &a.out, tick)
        });
    }
    let bar = super::progress::Progress::new(study.len(), "select-lines", "profiles");
    let outcomes = pool.install(|| study.study(0..study.len(), &|| bar.tick()));
    bar.finish();
    write_outputs(&a.out, a.no_plots, &study, &outcomes)
}

/// The study's options from the command line. A shard names its files by their absolute
/// paths, so that shards started from different directories agree.
fn options(a: &Args) -> anyhow::Result<SelectOptions> {
    let path = |p: &PathBuf| -> anyhow::Result<PathBuf> {
        match a.shard {
            Some(_) => {
                std::fs::canonicalize(p).with_context(|| format!("cannot read {}", p.display()))
            }
            None => Ok(p.clone()),
        }
    };
    let source = match (&a.profiles, a.ensemble) {
        (Some(p), _) => SelectSource::Set(path(p)?),
        (None, Some(n)) => SelectSource::Ensemble(n),
        (None, None) => SelectSource::Atmospheres(a.atmosphere.clone()),
    };
    Ok(SelectOptions {
        source,
        seed: a.seed,
        class: a.class.clone(),
        per_profile: a.per_profile,
        lines: a.lines.iter().map(path).collect::<anyhow::Result<_>>()?,
        on_cm1: a.on_cm1.clone(),
        off_cm1: a.off_cm1,
        co2_ppm: a.co2_ppm,
        max_j: a.max_j,
        offsets_ghz: a.offsets_ghz.clone(),
        layer_m: a.layer_m,
        top_km: a.top_km,
        wing_cm1: a.wing_cm1,
        uncertainties: Uncertainties {
            temperature_k: a.temperature_uncertainty_k,
            frequency_mhz: a.frequency_uncertainty_mhz,
            surface_pressure_hpa: a.surface_pressure_uncertainty_hpa,
            h2o_percent: a.h2o_uncertainty_percent,
        },
        figure_lines: a.figure_lines.clone(),
        plots: !a.no_plots,
    })
}

/// The line of the report that says what the study computes.
pub fn print_setup(study: &SelectStudy) -> anyhow::Result<()> {
    let cfg = &study.config;
    outln!(
        "select-lines: {} on-line positions, off-line {} cm-1, lines {} ({} lines), grid {} m to {} km",
        cfg.positions.len(),
        cfg.off_cm1,
        cfg.lines.source,
        cfg.lines.len(),
        study.options.layer_m,
        study.options.top_km
    );
    Ok(())
}

/// Report every group of a study from its members' `outcomes` (all of them, in member order)
/// and write its files into `dir` (all or none): `lidarsim select-lines`, and `lidarsim merge`
/// of its shards. The figures are drawn if the study computed their spectra and `no_plots` is
/// not set.
pub fn write_outputs(
    dir: &Path,
    no_plots: bool,
    study: &SelectStudy,
    outcomes: &[MemberOutcome],
) -> anyhow::Result<()> {
    let failed: Vec<&MemberFailure> = outcomes.iter().filter_map(|o| o.as_ref().err()).collect();
    if !outcomes.is_empty() && failed.len() == outcomes.len() {
        // Nothing to report: no file is written as if the study had succeeded.
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
        anyhow::bail!(
            "{}",
            study::all_failed_message(
                &of,
                &study::group_failures(failed.iter().map(|f| (f.id.as_str(), f.reason.as_str())))
            )
        );
    }
    let summaries = study.summarise(outcomes);
    let mut rows: Vec<Row> = Vec::new();
    let mut per_profile: Vec<Row> = Vec::new();
    for g in &summaries {
        let name = &g.name;
        // Each reason once, with its count and first profile: not a line per profile.
        for f in g.failure_groups() {
            outln!("{name}: excluded {f}");
        }
        g.check(study)?;
        outln!(
            "{name}: {} profiles ({} excluded), XCO2 {:.2} ppm, {} positions kept, {} dropped (DAOD ≤ 0)",
            g.profiles,
            g.failed.len(),
            g.mean_xco2_ppm,
            g.rows.len(),
            g.dropped.len()
        );
        for r in g.rows.iter().take(5) {
            outln!(
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
            );
        }
        rows.extend(g.rows.iter().cloned());
        per_profile.extend(g.per_profile.iter().cloned());
    }
    rows.extend(per_profile);
    // An earlier study's files this one does not rewrite (the figures of other groups, a
    // NetCDF file) go with the commit.
    let mut files = OutputSet::new();
    let names = file_names();
    files.replaces(dir, &names.iter().map(String::as_str).collect::<Vec<_>>())?;
    files.write(dir.join("sensitivities.csv"), select::to_csv(&rows))?;
    files.write(dir.join(FAILED_CSV), failed_csv(study, outcomes))?;
    if !rows.is_empty() {
        let history = super::netcdf_history();
        let nc = select::to_netcdf(
            &rows,
            "lidarsim select-lines: CO2 IPDA line selection",
            &history,
        )?;
        files.write(dir.join("sensitivities.nc"), nc)?;
    }
    if study.options.plots && !no_plots {
        init_font();
        for g in &summaries {
            draw_figures(
                &mut files,
                dir,
                g,
                &study.config,
                &study.options.uncertainties,
            )?;
        }
    }
    for p in files.commit()? {
        outln!("wrote {}", p.display());
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

/// `failed.csv`: `profile_id,group,reason`, one row per member that could not be studied, in
/// member order (the header alone when none failed).
fn failed_csv(study: &SelectStudy, outcomes: &[MemberOutcome]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from("profile_id,group,reason\n");
    let groups = study
        .groups
        .iter()
        .flat_map(|(name, members)| std::iter::repeat_n(name, members.len()));
    for (o, group) in outcomes.iter().zip(groups) {
        if let Err(f) = o {
            let _ = writeln!(
                s,
                "{},{},{}",
                csv_field(&f.id),
                csv_field(group),
                csv_field(&f.reason)
            );
        }
    }
    s
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Stage the figures of one group in `files`, for the directory `dir`.
fn draw_figures(
    files: &mut OutputSet,
    dir: &Path,
    g: &GroupSummary,
    cfg: &StudyConfig,
    unc: &Uncertainties,
) -> Result<(), OutputError> {
    let (name, rows, stats, members) = (g.name.as_str(), &g.rows, &g.spectra, g.profiles);
    files.write_via(dir.join(format!("transmission_{name}.png")), |p| {
        transmission_figure(p, name, rows, cfg, stats, members)
    })?;
    let labels: Vec<&str> = cfg.spectra.iter().map(|w| w.label.as_str()).collect();
    if rows.iter().any(|r| {
        r.position
            .line
            .as_deref()
            .is_some_and(|l| labels.contains(&l))
    }) {
        files.write_via(dir.join(format!("errors_{name}.png")), |p| {
            errors_figure(p, name, rows, &labels, unc)
        })?;
    } else {
        eprintln!("{name}: no on-line position on {labels:?}: no error figure");
    }
    Ok(())
}

/// The best-ranked position on a line, if any.
fn best_on<'a>(rows: &'a [Row], label: &str) -> Option<&'a Row> {
    rows.iter()
        .filter(|r| r.position.line.as_deref() == Some(label))
        .min_by_key(|r| r.rank)
}

/// Figure 4: the two-way transmission (mean, and its standard deviation over the members of a
/// set) against the offset from each line's centre, the 1 GHz window of the laser marked around
/// the best-ranked on-line position of the line (around the centre if none).
fn transmission_figure(
    path: &Path,
    name: &str,
    rows: &[Row],
    cfg: &StudyConfig,
    stats: &[(Vec<f64>, Vec<f64>)],
    members: usize,
) -> DrawResult {
    let n = cfg.spectra.len().max(1);
    let root = BitMapBackend::new(path, (520 * n as u32, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, n));
    for ((w, (mean, std)), area) in cfg.spectra.iter().zip(stats).zip(&panels) {
        let std_max = std.iter().copied().fold(0.0f64, f64::max);
        let show_std = members > 1 && std_max > 0.0;
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!(
                    "{name}: {} ({members} profile{})",
                    w.label,
                    if members == 1 { "" } else { "s" }
                ),
                (FONT, 17),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .right_y_label_area_size(if show_std { 70 } else { 0 })
            .build_cartesian_2d(-SPECTRUM_HALF_GHZ..SPECTRUM_HALF_GHZ, 0.0..1.0)?
            .set_secondary_coord(
                -SPECTRUM_HALF_GHZ..SPECTRUM_HALF_GHZ,
                0.0..(1.1 * std_max).max(1e-6),
            );
        chart
            .configure_mesh()
            .x_desc(format!(
                "frequency from the line centre {:.3} cm⁻¹ [GHz]",
                w.centre_cm1
            ))
            .y_desc("two-way transmission T² (mean)")
            .label_style((FONT, 13))
            .draw()?;
        let centre = best_on(rows, &w.label).map_or(0.0, |r| r.position.offset_ghz);
        let (a, b) = (centre - WINDOW_HALF_GHZ, centre + WINDOW_HALF_GHZ);
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(a, 0.0), (b, 1.0)],
                BLUE.mix(0.12).filled(),
            )))?
            .label(format!(
                "laser window ±{WINDOW_HALF_GHZ} GHz at {centre:+.1} GHz"
            ))
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], BLUE.mix(0.3).filled()));
        chart
            .draw_series(LineSeries::new(
                w.offsets_ghz.iter().copied().zip(mean.iter().copied()),
                BLACK.stroke_width(2),
            ))?
            .label("T² mean")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        if show_std {
            chart
                .configure_secondary_axes()
                .y_desc("T² standard deviation")
                .label_style((FONT, 13))
                .draw()?;
            chart
                .draw_secondary_series(LineSeries::new(
                    w.offsets_ghz.iter().copied().zip(std.iter().copied()),
                    RED.stroke_width(2),
                ))?
                .label("T² std over profiles (right axis)")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        }
        draw_legend(&mut chart)?;
    }
    root.present()?;
    Ok(())
}

/// Figure 5: the XCO2 error contributions (sensitivity × uncertainty, signed), the random error
/// and the total against the on-line's offset from each chosen line's centre.
fn errors_figure(
    path: &Path,
    name: &str,
    rows: &[Row],
    labels: &[&str],
    unc: &Uncertainties,
) -> DrawResult {
    let n = labels.len().max(1);
    let root = BitMapBackend::new(path, (520 * n as u32, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, n));
    for (label, area) in labels.iter().zip(&panels) {
        let mut pts: Vec<&Row> = rows
            .iter()
            .filter(|r| r.position.line.as_deref() == Some(*label))
            .collect();
        pts.sort_by(|a, b| a.position.offset_ghz.total_cmp(&b.position.offset_ghz));
        if pts.is_empty() {
            continue;
        }
        let names = [
            format!("T ± {} K", unc.temperature_k),
            format!("frequency ± {} MHz", unc.frequency_mhz),
            format!("surface pressure ± {} hPa", unc.surface_pressure_hpa),
            format!("H2O ± {} %", unc.h2o_percent),
            "random".to_string(),
            "total".to_string(),
        ];
        let series: Vec<Vec<(f64, f64)>> = (0..6)
            .map(|k| {
                pts.iter()
                    .map(|r| {
                        let c = unc.contributions_ppm(r);
                        let v = match k {
                            0..=3 => c[k],
                            4 => r.random_error_ppm,
                            _ => r.total_error_ppm,
                        };
                        (r.position.offset_ghz, v)
                    })
                    .filter(|p| p.1.is_finite())
                    .collect()
            })
            .collect();
        let (lo, hi) = series
            .iter()
            .flatten()
            .fold((0.0f64, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
        let pad = 0.05 * (hi - lo).max(1e-3);
        let (x0, x1) = (
            pts[0].position.offset_ghz,
            pts[pts.len() - 1].position.offset_ghz,
        );
        let (x0, x1) = if x1 > x0 {
            (x0, x1)
        } else {
            (x0 - 1.0, x1 + 1.0)
        };
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("{name}: XCO2 errors, on-line on {label}"),
                (FONT, 17),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, (lo - pad)..(hi + pad))?;
        chart
            .configure_mesh()
            .x_desc("on-line offset from the line centre [GHz]")
            .y_desc("XCO2 error [ppm]")
            .label_style((FONT, 13))
            .draw()?;
        let colours = [RED, BLUE, GREEN, CYAN, MAGENTA, BLACK];
        for ((s, c), label) in series.into_iter().zip(colours).zip(names) {
            let width = if label == "total" { 3 } else { 2 };
            chart
                .draw_series(LineSeries::new(s.clone(), c.stroke_width(width)))?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
            chart.draw_series(s.into_iter().map(|p| Circle::new(p, 3, c.filled())))?;
        }
        draw_legend(&mut chart)?;
    }
    root.present()?;
    Ok(())
}
