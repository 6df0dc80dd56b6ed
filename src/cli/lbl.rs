//! `lidarsim lbl`: line-by-line absorption cross-sections at one (p, T), or layer optical depths
//! along a line of sight through a profile. Method and formats: `docs/spectroscopy.md`.
//!
//! Cross-sections (`--pressure-atm` and `--temperature-k`): columns `wavenumber_cm1` and
//! `sigma_<MOLECULE>_cm2` per molecule of the line file [cm²/molecule], air-broadened.
//! Layer optical depths (`--atmosphere` or `--profile`, with the path options): one row per
//! wavenumber and layer with the Curtis-Godson p and T, the vertical and the slant optical
//! depth (vertical / |cos θ|, plane-parallel).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use lidarsim::atmosphere::StandardAtmosphere;
use lidarsim::input::Bounds;
use lidarsim::limits::{MAX_LBL_ROWS, MAX_PATH_LAYERS, check_product};
use lidarsim::output::{self, OutputSet};
use lidarsim::products;
use lidarsim::products::lbl::{SpectralRange, SpectralUnit};
use lidarsim::spectroscopy::isotopologues::molecule_name;
use lidarsim::spectroscopy::xsec::GasState;
use lidarsim::spectroscopy::{
    GasOpticalDepthTable, LblOptions, LineFilter, LineList, LineOfSight, VoigtMethod,
    WavenumberGrid, WingCentre, cross_section,
};

use super::real;

/// Arguments of `lidarsim lbl`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Line file: HITRAN 160-character records (.par, or a HAPI .data table), or a CSV with
    /// HITRAN parameter names (`*.csv`, beyond-Voigt parameters included). Repeatable (e.g.
    /// CO2 and H2O): the lines are merged. Without it: the built-in CO2 30012←00001 band model
    /// (approximate).
    #[arg(long, value_name = "FILE")]
    lines: Vec<PathBuf>,
    /// Line profile: voigt, sdvoigt (speed-dependent Voigt) or ht (Hartmann-Tran); the last two
    /// need a CSV line list with their parameters.
    #[arg(long, default_value = "voigt")]
    line_shape: lidarsim::spectroscopy::LineShapeModel,
    /// First-order line mixing (the CSV's y_air, y_self).
    #[arg(long)]
    line_mixing: bool,
    /// Mole fraction of the absorbing gas, for self broadening (cross-section mode; 0: pure air
    /// broadening).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true, value_parser = real(Bounds::closed(0.0, 1.0)))]
    vmr: f64,
    /// Pressure [atm] (cross-section mode).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(0.0, 100.0)))]
    pressure_atm: Option<f64>,
    /// Temperature \[K\] (cross-section mode).
    #[arg(long, allow_negative_numbers = true, value_parser = real(lidarsim::atmosphere::TEMPERATURE_K))]
    temperature_k: Option<f64>,
    /// First wavenumber [cm⁻¹]. The range is given in one unit: --start-cm1/--end-cm1,
    /// --start-nm/--end-nm or --start-um/--end-um (vacuum wavelengths); the grid is uniform
    /// in wavenumber either way.
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::positive(1e6)))]
    start_cm1: Option<f64>,
    /// Last wavenumber [cm⁻¹] (inclusive).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::positive(1e6)))]
    end_cm1: Option<f64>,
    /// First vacuum wavelength [nm] (instead of --start-cm1).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(10.0, 1e9)))]
    start_nm: Option<f64>,
    /// Last vacuum wavelength [nm] (inclusive).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(10.0, 1e9)))]
    end_nm: Option<f64>,
    /// First vacuum wavelength [µm] (instead of --start-cm1).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(0.01, 1e6)))]
    start_um: Option<f64>,
    /// Last vacuum wavelength [µm] (inclusive).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(0.01, 1e6)))]
    end_um: Option<f64>,
    /// Grid step [cm⁻¹] (also with a range in nm or µm: the grid is uniform in wavenumber).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::positive(100.0)))]
    step_cm1: f64,
    /// Output CSV.
    #[arg(long, value_name = "OUT.csv")]
    out: PathBuf,
    /// Line wing cutoff [cm⁻¹], measured from the unshifted centre unless --shifted-wing.
    #[arg(long, default_value_t = 25.0, allow_negative_numbers = true, value_parser = real(Bounds::positive(1e3)))]
    wing_cm1: f64,
    /// Centre the wing cutoff on the pressure-shifted line centre.
    #[arg(long)]
    shifted_wing: bool,
    /// Exact Faddeeva function at every line and grid point (slow reference path).
    #[arg(long)]
    exact: bool,
    /// Draw the result to this PNG.
    #[arg(long, value_name = "OUT.png")]
    plot: Option<PathBuf>,
    /// Layer-mode options (boxed: keeps the subcommand enum small).
    #[command(flatten)]
    layer: Box<LayerArgs>,
}

/// Options of the layer mode of `lidarsim lbl`.
#[derive(clap::Args, Debug)]
pub struct LayerArgs {
    /// Layer mode: a built-in AFGL atmosphere (tropical, midlatitude_summer, midlatitude_winter,
    /// subarctic_summer, subarctic_winter, us_standard).
    #[arg(long, conflicts_with_all = ["profile", "pressure_atm", "temperature_k"])]
    atmosphere: Option<StandardAtmosphere>,
    /// Layer mode: a profile file in the AFGL table format (z_km, p_hPa, T_K, <GAS>_ppmv…).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["pressure_atm", "temperature_k"])]
    profile: Option<PathBuf>,
    /// Layer mode: scale the CO2 profile so that its surface value is this [ppmv] (AFGL tables
    /// carry 330; the shape, which falls above 80 km, is kept).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::below(0.0, 1e6)))]
    co2_ppmv: Option<f64>,
    /// Layer mode: sensor altitude \[m\].
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(-1e4, 1e8)))]
    sensor_altitude_m: Option<f64>,
    /// Layer mode: zenith angle of the line of sight \[deg\] (0 up, 180 nadir).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(0.0, 180.0)))]
    zenith_deg: Option<f64>,
    /// Layer mode: surface altitude \[m\].
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true, value_parser = real(Bounds::closed(-1e4, 1e8)))]
    surface_altitude_m: f64,
    /// Layer mode: layer thickness \[m\].
    #[arg(long, default_value_t = 1000.0, allow_negative_numbers = true, value_parser = real(Bounds::positive(1e6)))]
    layer_m: f64,
    /// Layer mode: also save the optical-depth table (binary, reloadable) here.
    #[arg(long, value_name = "FILE")]
    save_table: Option<PathBuf>,
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let outputs: Vec<&PathBuf> = [Some(&args.out), args.plot.as_ref()]
        .into_iter()
        .chain([args.layer.save_table.as_ref()])
        .flatten()
        .collect();
    output::check_paths(&outputs)?;
    let range = SpectralRange::from_options(&[
        (SpectralUnit::Cm1, args.start_cm1, args.end_cm1),
        (SpectralUnit::Nm, args.start_nm, args.end_nm),
        (SpectralUnit::Um, args.start_um, args.end_um),
    ])?;
    let (start_cm1, end_cm1) = range.cm1();
    let grid = WavenumberGrid::new(start_cm1, end_cm1, args.step_cm1)
        .with_context(|| format!("{}, --step-cm1 {}", range.describe(), args.step_cm1))?;
    check_product(
        "the output",
        &[("wavenumbers", grid.len as u64)],
        MAX_LBL_ROWS,
    )
    .map_err(anyhow::Error::msg)?;
    let mut opts = LblOptions {
        wing_cm1: args.wing_cm1,
        line_shape: args.line_shape,
        line_mixing: args.line_mixing,
        ..Default::default()
    };
    if args.shifted_wing {
        opts.wing_centre = WingCentre::Shifted;
    }
    if args.exact {
        opts.voigt = VoigtMethod::Exact;
        opts.multigrid = false;
    }
    let window = LineFilter::window(
        grid.start_cm1 - opts.wing_cm1 - 1.0,
        grid.end_cm1() + opts.wing_cm1 + 1.0,
    );
    let lines = products::lbl::read_lines(&args.lines, &window)?;
    let layer_mode = args.layer.atmosphere.is_some() || args.layer.profile.is_some();
    // Cross-sections of no line are refused (a wrong unit, most often); a path's optical
    // depth through a window without lines is zero, which the layer table says.
    if !layer_mode && lines.filtered(&window).is_empty() {
        return Err(products::lbl::no_lines_error(
            &args.lines,
            &range,
            opts.wing_cm1,
            &lines.source,
        )
        .into());
    }
    if layer_mode {
        run_layers(&args, &lines, &grid, &opts)
    } else {
        let (Some(p_atm), Some(t_k)) = (args.pressure_atm, args.temperature_k) else {
            bail!(
                "give --pressure-atm and --temperature-k (cross-sections), or --atmosphere/--profile \
                 with the path options (layer optical depths)"
            );
        };
        run_cross_sections(&args, &lines, &grid, &opts, p_atm, t_k)
    }
}

fn run_cross_sections(
    args: &Args,
    lines: &LineList,
    grid: &WavenumberGrid,
    opts: &LblOptions,
    p_atm: f64,
    t_k: f64,
) -> anyhow::Result<()> {
    let state = GasState {
        pressure_pa: p_atm * lidarsim::constants::STANDARD_ATMOSPHERE_PA,
        temperature_k: t_k,
        self_vmr: args.vmr,
    };
    let molecules = lines.molecules();
    if molecules.is_empty() {
        bail!(
            "no lines of {} reach {}–{} cm⁻¹ (with the {} cm⁻¹ wing)",
            lines.source,
            grid.start_cm1,
            grid.end_cm1(),
            opts.wing_cm1
        );
    }
    let mut columns = Vec::new();
    for &m in &molecules {
        let name = molecule_name(m).unwrap_or("?").to_string();
        columns.push((name, cross_section(lines, m, &state, grid, opts)?));
    }
    let text = products::lbl::cross_section_csv(
        lines,
        grid,
        opts,
        (p_atm, t_k, args.vmr),
        args.exact,
        &columns,
    );
    let mut files = OutputSet::new();
    files.write(&args.out, text)?;
    if let Some(png) = &args.plot {
        let series: Vec<(String, Vec<f64>)> = columns
            .iter()
            .map(|(n, s)| (format!("σ {n}"), s.clone()))
            .collect();
        crate::figures::lbl::plot(
            &mut files,
            png,
            &format!(
                "Absorption cross-section of {} at {p_atm} atm, {t_k} K (lines: {})",
                columns
                    .iter()
                    .map(|(n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
                file_name(&lines.source)
            ),
            "cross-section [cm²/molecule]",
            &grid.wavenumbers(),
            &series,
        )?;
    }
    files.commit()?;
    Ok(())
}

fn run_layers(
    args: &Args,
    lines: &LineList,
    grid: &WavenumberGrid,
    opts: &LblOptions,
) -> anyhow::Result<()> {
    let prof = products::lbl::profile(
        args.layer.atmosphere,
        args.layer.profile.as_deref(),
        args.layer.co2_ppmv,
    )?;
    let (Some(sensor), Some(zenith)) = (args.layer.sensor_altitude_m, args.layer.zenith_deg) else {
        bail!("layer mode needs --sensor-altitude-m and --zenith-deg");
    };
    let los = LineOfSight {
        sensor_altitude_m: sensor,
        zenith_angle_deg: zenith,
        surface_altitude_m: args.layer.surface_altitude_m,
    };
    // The library names the path's fields; the user gave options.
    let path = || {
        format!(
            "--sensor-altitude-m {sensor}, --zenith-deg {zenith}, --surface-altitude-m {}",
            args.layer.surface_altitude_m
        )
    };
    let mu = los.mu().with_context(path)?;
    // The layers and the table rows they make, before any is computed.
    let (lo, hi) = los.vertical_extent(&prof).with_context(path)?;
    let layers = ((hi - lo) / args.layer.layer_m).ceil().max(1.0) as u64;
    check_product("--layer-m", &[("layers", layers)], MAX_PATH_LAYERS)
        .and_then(|_| {
            check_product(
                "the output",
                &[("wavenumbers", grid.len as u64), ("layers", layers)],
                MAX_LBL_ROWS,
            )
        })
        .map_err(anyhow::Error::msg)?;
    let edges = los
        .layer_edges(&prof, args.layer.layer_m)
        .with_context(|| format!("--layer-m {}", args.layer.layer_m))?;
    let bar = super::progress::Progress::new(0, "lbl", "layers");
    let table =
        GasOpticalDepthTable::compute_reporting(&prof, lines, &edges, grid, opts, &|d, n| {
            bar.reach(d, n)
        });
    bar.finish();
    let table = table?;
    let mut files = OutputSet::new();
    if let Some(path) = &args.layer.save_table {
        let bytes = table
            .to_bytes()
            .with_context(|| format!("cannot write {}", path.display()))?;
        files.write(path, bytes)?;
    }
    let (text, column_slant) =
        products::lbl::layer_csv(&table, lines, &prof.name, &los, mu, grid, opts.wing_cm1);
    files.write(&args.out, text)?;
    if let Some(png) = &args.plot {
        crate::figures::lbl::plot(
            &mut files,
            png,
            &format!(
                "Slant gas optical depth, {} atmosphere, {} m to {} m (lines: {})",
                file_name(&prof.name),
                edges[0],
                edges[edges.len() - 1],
                file_name(&lines.source)
            ),
            "slant gas optical depth",
            &grid.wavenumbers(),
            &[("τ (whole path)".into(), column_slant)],
        )?;
    }
    files.commit()?;
    Ok(())
}

/// The file names of a line list's source (paths, several joined by " + "), for a figure's
/// title.
fn file_name(source: &str) -> String {
    source
        .split(" + ")
        .map(|s| match s.starts_with('<') {
            // A built-in list's name (`<built-in …>`) is no path.
            true => s.to_string(),
            false => Path::new(s)
                .file_name()
                .map_or_else(|| s.to_string(), |f| f.to_string_lossy().into_owned()),
        })
        .collect::<Vec<_>>()
        .join(" + ")
}
