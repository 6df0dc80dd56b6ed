//! `lidarsim select-lines`: sensitivities of a CO2 IPDA's XCO2 to temperature, laser frequency,
//! surface pressure and humidity errors, and its random error, for candidate on-line positions
//! (method: `lidarsim::study::select`, docs/retrieval.md). Writes `DIR/sensitivities.csv` and,
//! unless `--no-plots`, per atmosphere `transmission_<atm>.png` (Figure 4 of the seed paper) and
//! `errors_<atm>.png` (Figure 5).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use plotters::prelude::*;

use lidarsim::atmosphere::{LatitudeClass, SetMember, StandardAtmosphere, read_profile_set};
use lidarsim::input::Bounds;
use lidarsim::output::{self, OutputError, OutputSet};
use lidarsim::scene::Scene;
use lidarsim::spectroscopy::{LblOptions, LineFilter, LineList};
use lidarsim::study::select::{
    self, GridSpec, MemberResult, NoiseModel, OnPosition, Row, SpectrumWindow, Steps, StudyConfig,
    Uncertainties,
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
    #[arg(long, default_value = "all")]
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
}

/// Half width of the fine spectra of Figure 4 \[GHz\] and their step.
const SPECTRUM_HALF_GHZ: f64 = 4.0;
const SPECTRUM_STEP_GHZ: f64 = 0.02;
/// Half width of the laser's spectral window marked in Figure 4 \[GHz\].
const WINDOW_HALF_GHZ: f64 = 0.5;

/// Read and merge the line files (all molecules) with `filter`; the band model without files.
fn read_lines(paths: &[PathBuf], filter: &LineFilter) -> anyhow::Result<LineList> {
    if paths.is_empty() {
        return Ok(LineList::co2_30012_band_model().filtered(filter));
    }
    let mut out = LineList {
        source: String::new(),
        lines: Vec::new(),
    };
    let mut sources = Vec::new();
    for p in paths {
        let l =
            LineList::read_par(p, filter).with_context(|| format!("--lines {}", p.display()))?;
        sources.push(l.source);
        out.lines.extend(l.lines);
    }
    out.lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
    out.source = sources.join(" + ");
    Ok(out)
}

/// The groups of members: (atmosphere name, members).
fn groups(a: &Args) -> anyhow::Result<Vec<(String, Vec<SetMember>)>> {
    if a.profiles.is_some() || a.ensemble.is_some() {
        let set = match (&a.profiles, a.ensemble) {
            (Some(path), _) => read_profile_set(path)?,
            (None, Some(n)) => {
                let mut set = lidarsim::atmosphere::ProfileSet::default();
                for (i, c) in LatitudeClass::ALL.iter().enumerate() {
                    if a.class == "all" || a.class.parse::<LatitudeClass>().ok() == Some(*c) {
                        let (s, _) = lidarsim::atmosphere::class_ensemble(
                            *c,
                            n,
                            a.seed.wrapping_add(i as u64),
                        )?;
                        set.members.extend(s.members);
                    }
                }
                set.name = format!("{n} members per class, seed {}", a.seed);
                set
            }
            (None, None) => bail!("give --profiles SET or --ensemble N"),
        };
        let path = a
            .profiles
            .clone()
            .unwrap_or_else(|| PathBuf::from(set.name.clone()));
        if set.is_empty() {
            bail!("--profiles {}: the set has no profiles", path.display());
        }
        let classes: Vec<LatitudeClass> = if a.class == "all" {
            LatitudeClass::ALL.to_vec()
        } else {
            vec![
                a.class
                    .parse()
                    .map_err(|e: String| anyhow::anyhow!("--class: {e}"))?,
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
            bail!(
                "--profiles {}: no profile in class `{}`",
                path.display(),
                a.class
            );
        }
        Ok(out)
    } else {
        Ok(a.atmosphere
            .iter()
            .map(|s| (s.name().to_string(), vec![s.member()]))
            .collect())
    }
}

/// `lidarsim select-lines`.
pub fn run(a: Args) -> anyhow::Result<()> {
    // Each number was checked by the argument parser; here the size of the grid.
    lidarsim::limits::check_product(
        "--layer-m",
        &[("layers", (a.top_km * 1e3 / a.layer_m).ceil() as u64)],
        lidarsim::limits::MAX_PATH_LAYERS,
    )
    .map_err(anyhow::Error::msg)?;
    let wing = a.wing_cm1;

    // Candidate positions: the band's lines (626 only) first when scanning.
    let band_all = select::band_lines(&read_lines(
        &a.lines,
        &LineFilter {
            isotopologues: Some(vec![(2, 1)]),
            ..Default::default()
        },
    )?);
    let positions: Vec<OnPosition> = if a.on_cm1.is_empty() {
        if a.offsets_ghz.is_empty() {
            bail!("--offsets-ghz: give at least one offset");
        }
        let p = select::scan_positions(&band_all, a.max_j, &a.offsets_ghz);
        if p.is_empty() {
            bail!(
                "no line of the CO2 30012<-00001 band (626) with J'' <= {} in {}",
                a.max_j,
                if a.lines.is_empty() {
                    "the band model".to_string()
                } else {
                    format!("--lines {}", a.lines[0].display())
                }
            );
        }
        p
    } else {
        select::label_positions(&band_all, &a.on_cm1)
    };
    let spectra: Vec<SpectrumWindow> = if a.no_plots {
        Vec::new()
    } else {
        let n = (2.0 * SPECTRUM_HALF_GHZ / SPECTRUM_STEP_GHZ).round() as usize;
        let offsets: Vec<f64> = (0..=n)
            .map(|k| -SPECTRUM_HALF_GHZ + k as f64 * SPECTRUM_STEP_GHZ)
            .collect();
        a.figure_lines
            .iter()
            .map(|label| match band_all.iter().find(|b| &b.label == label) {
                Some(b) => Ok(SpectrumWindow {
                    label: label.clone(),
                    centre_cm1: b.nu_cm1,
                    offsets_ghz: offsets.clone(),
                }),
                None => {
                    bail!("--figure-lines: no band line `{label}` (labels look like R16e, P20e)")
                }
            })
            .collect::<anyhow::Result<_>>()?
    };

    // Every line reaching a position, the off-line or a spectrum with its wing.
    let mut nus: Vec<f64> = positions.iter().map(|p| p.nu_cm1).collect();
    nus.push(a.off_cm1);
    for w in &spectra {
        nus.push(w.centre_cm1 - SPECTRUM_HALF_GHZ / select::GHZ_PER_CM1);
        nus.push(w.centre_cm1 + SPECTRUM_HALF_GHZ / select::GHZ_PER_CM1);
    }
    let lo = nus.iter().copied().fold(f64::INFINITY, f64::min) - wing - 1.0;
    let hi = nus.iter().copied().fold(f64::NEG_INFINITY, f64::max) + wing + 1.0;
    let lines = read_lines(&a.lines, &LineFilter::window(lo, hi))?;
    let reaches = |nu: f64| {
        lines
            .lines
            .iter()
            .any(|l| l.molecule_id == 2 && (l.nu_cm1 - nu).abs() <= wing)
    };
    if !reaches(a.off_cm1) {
        bail!(
            "--off-cm1 {}: no CO2 line within the wing cutoff ({wing} cm-1) in {}; the off-line must lie in the CO2 band the lines cover",
            a.off_cm1,
            if a.lines.is_empty() {
                "the built-in 30012 band model"
            } else {
                "the line files"
            }
        );
    }
    if let Some(p) = positions.iter().find(|p| !reaches(p.nu_cm1)) {
        bail!(
            "--on-cm1 {}: no CO2 line within the wing cutoff ({wing} cm-1)",
            p.nu_cm1
        );
    }
    if !(5000.0..=1e5).contains(&a.off_cm1) {
        bail!(
            "--off-cm1 {}: outside 5000–100000 cm-1 (the Rayleigh cross-sections cover 100–2000 nm)",
            a.off_cm1
        );
    }

    let scene = match &a.scene {
        Some(p) => Scene::read(p)?,
        None => Scene::default_scene()?,
    };
    let noise = NoiseModel::from_scene(&scene)?;
    let cfg = StudyConfig {
        lines,
        options: LblOptions {
            wing_cm1: wing,
            ..Default::default()
        },
        off_cm1: a.off_cm1,
        positions,
        grid: GridSpec {
            layer_m: a.layer_m,
            top_m: a.top_km * 1e3,
        },
        steps: Steps::CONTRACT,
        noise: Some(noise),
        spectra,
    };
    let unc = Uncertainties {
        temperature_k: a.temperature_uncertainty_k,
        frequency_mhz: a.frequency_uncertainty_mhz,
        surface_pressure_hpa: a.surface_pressure_uncertainty_hpa,
        h2o_percent: a.h2o_uncertainty_percent,
    };

    let groups = groups(&a)?;
    // Before the work; the figures' names depend on the groups and are checked when written.
    output::check_paths(&[
        a.out.join("sensitivities.csv"),
        a.out.join("sensitivities.nc"),
    ])?;
    outln!(
        "select-lines: {} on-line positions, off-line {} cm-1, lines {} ({} lines), grid {} m to {} km",
        cfg.positions.len(),
        cfg.off_cm1,
        cfg.lines.source,
        cfg.lines.len(),
        a.layer_m,
        a.top_km
    );
    let mut rows: Vec<Row> = Vec::new();
    let mut per_profile: Vec<Row> = Vec::new();
    let mut figures: Vec<GroupFigures> = Vec::new();
    let total: usize = groups.iter().map(|(_, m)| m.len()).sum();
    let bar = super::progress::Progress::new(total, "select-lines", "profiles");
    for (name, mut members) in groups {
        let mut failed = Vec::new();
        members.retain_mut(
            |m| match select::set_co2_column_average(&mut m.profile, a.co2_ppm) {
                Ok(()) => true,
                Err(e) => {
                    failed.push((m.meta.id.clone(), e.to_string()));
                    false
                }
            },
        );
        let results = select::study_members(&members, &cfg, &|| bar.tick());
        let mut ok: Vec<&MemberResult> = Vec::new();
        for r in &results {
            match r {
                Ok(m) => ok.push(m),
                Err(f) => failed.push((f.id.clone(), f.reason.clone())),
            }
        }
        for (id, reason) in &failed {
            outln!("{name}: profile {id} excluded: {reason}");
        }
        if ok.is_empty() {
            bail!("{name}: every profile failed (see above)");
        }
        let (group_rows, dropped) = select::summarise(&name, &ok, &cfg, &unc);
        if !a.on_cm1.is_empty() && !dropped.is_empty() {
            let v: Vec<String> = dropped
                .iter()
                .map(|i| format!("{}", cfg.positions[*i].nu_cm1))
                .collect();
            bail!(
                "--on-cm1 {}: the on-line does not absorb more than the off-line {} cm-1 (DAOD ≤ 0) in `{name}`",
                v.join(","),
                cfg.off_cm1
            );
        }
        outln!(
            "{name}: {} profiles ({} excluded), XCO2 {:.2} ppm, {} positions kept, {} dropped (DAOD ≤ 0)",
            ok.len(),
            failed.len(),
            ok.iter().map(|m| m.xco2_ppm).sum::<f64>() / ok.len() as f64,
            group_rows.len(),
            dropped.len()
        );
        for r in group_rows.iter().take(5) {
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
        if a.per_profile {
            for m in &ok {
                per_profile.extend(select::summarise(&m.id, &[*m], &cfg, &unc).0);
            }
        }
        if !a.no_plots {
            let stats = select::spectrum_statistics(&ok, cfg.spectra.len());
            figures.push(GroupFigures {
                name: name.clone(),
                rows: group_rows.clone(),
                stats,
                members: ok.len(),
            });
        }
        rows.extend(group_rows);
    }
    bar.finish();
    rows.extend(per_profile);
    let mut files = OutputSet::new();
    files.write(a.out.join("sensitivities.csv"), select::to_csv(&rows))?;
    if !rows.is_empty() {
        let command: Vec<String> = std::env::args_os()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        let history = format!(
            "{}: {}",
            lidarsim::netcdf::utc_timestamp(std::time::SystemTime::now()),
            command.join(" ")
        );
        let nc = select::to_netcdf(
            &rows,
            "lidarsim select-lines: CO2 IPDA line selection",
            &history,
        )?;
        files.write(a.out.join("sensitivities.nc"), nc)?;
    }
    if !a.no_plots {
        init_font();
        for g in &figures {
            draw_figures(&mut files, &a.out, g, &cfg, &unc)?;
        }
    }
    for p in files.commit()? {
        outln!("wrote {}", p.display());
    }
    Ok(())
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// What the figures of one atmosphere (or class) show.
struct GroupFigures {
    /// Atmosphere or class name.
    name: String,
    /// Its rows, in rank order.
    rows: Vec<Row>,
    /// Mean and standard deviation of each fine spectrum.
    stats: Vec<(Vec<f64>, Vec<f64>)>,
    /// Profiles averaged.
    members: usize,
}

/// Stage the figures of one group in `files`, for the directory `dir`.
fn draw_figures(
    files: &mut OutputSet,
    dir: &Path,
    g: &GroupFigures,
    cfg: &StudyConfig,
    unc: &Uncertainties,
) -> Result<(), OutputError> {
    let (name, rows, stats, members) = (g.name.as_str(), &g.rows, &g.stats, g.members);
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
