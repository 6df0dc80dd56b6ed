//! The results of a run as one CF-conventions NetCDF file, `run.nc`: the numbers of
//! `returns.csv`, `backscatter.csv`, `signals.csv`, `retrieval.csv` and `jacobians.csv` on
//! named dimensions, for xarray and every other NetCDF client.
//!
//! **Format.** NetCDF-3 "64-bit offset" (CDF-2), as the NetCDF User Guide's *File Format
//! Specification* defines it (Unidata, NUG §"Classic Format Specification": big-endian
//! values, a header of dimensions, attributes and variables, each variable's values padded to
//! four bytes), written by the pure-Rust `netcdf3` crate. Every NetCDF library reads it (the
//! netCDF-C library, netCDF4-python, xarray, scipy.io); it needs no C library to write. The
//! 64-bit offsets lift the classic format's 2 GiB bound on where a variable may start;
//! [`crate::limits`] keeps a run far below either bound. NetCDF-3 has no string type and no
//! 64-bit integers: text is a char array whose last dimension is its length (CF-1.8 §2.2), and
//! counts that may pass 2³¹ (photons, shots) are doubles, exact to 2⁵³.
//!
//! **Conventions.** CF-1.8 (Eaton et al., *NetCDF Climate and Forecast (CF) Metadata
//! Conventions*, version 1.8, 2020): every variable has `units` and `long_name`, and a
//! `standard_name` where the CF standard-name table (version 93) has one that fits
//! (`dry_atmosphere_mole_fraction_of_carbon_dioxide` / `_of_methane`, and
//! `volume_attenuated_backwards_scattering_function_in_air` for the attenuated backscatter, as
//! COSP's CALIPSO simulator writes it); range, field of view, wavenumber, received energy,
//! range-corrected signal and photo-electrons have none. Range gates have `bounds` (§7.1); an
//! estimate names its standard error in `ancillary_variables` (§3.4); a bin with no value
//! holds `_FillValue` (§2.5.1; the CSV writes those as empty fields). No file holds `NaN` or
//! `inf`: a variable without `_FillValue` (a coordinate, bounds, a count) that holds one is
//! refused as a bug, and so is a non-finite attribute ([`Dataset::encode`]).
//!
//! **Layout** (README, "Output: `run.nc`"). The dimensions and coordinates carry the CSV
//! columns' names: `source` (`mc`, `analytic`), `channel`, `fov_full_angle_mrad`, `range_m`
//! (gate centres, with `range_m_bounds`), `order` (`total`, `1st`, `2nd`, …, `Nth+`). Returns and
//! signals are variables over all five; a (source, order) pair a run does not compute (the
//! analytic returns above order 1, say) is `_FillValue`. Retrievals are tables, one per
//! quantity (its unit differs: ppm, m⁻², m⁻³), with a dimension `<quantity>_product` and the
//! columns of `retrieval.csv` as `<quantity>_<column>` variables, rows in the CSV's order.
//! Jacobians (with `[simulation] jacobians`) are Monte Carlo only: `jacobian_j_m` and its
//! standard error over (`channel`, `fov_full_angle_mrad`, `range_m`, `jacobian_order`,
//! `layer`, `jacobian_quantity`), the order of `jacobians.csv`'s rows, with the layers' edges
//! `layer_bottom_m`, `layer_top_m`; a derivative the layer does not have is `_FillValue`.
//! Without Jacobians none of these dimensions or variables is in the file.

use std::time::{SystemTime, UNIX_EPOCH};

use thiserror::Error;

use crate::instrument::laser::Line;
use crate::instrument::signals::Signals;
use crate::jacobians::{JacobianQuantity, Jacobians};
use crate::retrieval::{Product, Quantity};
use crate::returns::Returns;
use crate::scene::Gates;

/// The CF version the file declares in its `Conventions` attribute.
pub const CONVENTIONS: &str = "CF-1.8";

/// A missing double's value (`_FillValue`): NetCDF's default fill for doubles.
pub const FILL_F64: f64 = netcdf3::NC_FILL_F64;

/// Name of the file `lidarsim run` writes beside its CSV files.
pub const RUN_FILE: &str = "run.nc";

/// Why the file could not be made.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum NetcdfError {
    /// The sets of returns or signals are not on one grid (a bug upstream, not bad input).
    #[error("NetCDF output: {0}")]
    Layout(String),
    /// The NetCDF writer refused the data set.
    #[error("NetCDF output: {0}")]
    Format(String),
}

/// What the global attributes record about the run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunAttributes {
    /// `title`: what was run.
    pub title: String,
    /// `history`: when and by which command line (CF §2.6.2); the caller's, so that the
    /// rest of the file depends on nothing but the run.
    pub history: String,
    /// The scene file's path (or the embedded default scene's name).
    pub scene_file: String,
    /// The scene file's whole text (TOML).
    pub scene_text: String,
    /// Random seed.
    pub seed: u64,
    /// Photon packets traced (0: analytic only).
    pub photons: u64,
    /// Independent batches of the Monte Carlo.
    pub batches: u64,
}

/// Everything `run.nc` holds.
#[derive(Debug, Clone, Copy)]
pub struct RunFile<'a> {
    /// The sets of line returns of `returns.csv`, in its order (Monte Carlo, then analytic).
    pub returns: &'a [&'a Returns],
    /// The lidar constant C = E₀ η A_tel of each channel of the returns \[J m²\]
    /// ([`crate::backscatter`]): with it the file holds `backscatter.csv`'s attenuated
    /// backscatter and range-corrected signal; `None`, only the energies.
    pub lidar_constant_j_m2: Option<&'a [f64]>,
    /// The range gates of the returns (for the gate edges).
    pub gates: &'a Gates,
    /// The lidar's altitude \[m\] and the cosine of its zenith angle (1 looks up, −1 down):
    /// with them each gate's altitude, `altitude_m` = lidar altitude + μ r.
    pub lidar_altitude_m: f64,
    /// Cosine of the pointing zenith angle.
    pub mu: f64,
    /// The laser lines (each channel's wavenumber, where a channel is one of them).
    pub lines: &'a [Line],
    /// With polarised light, the co- and cross-polarised parts of the sets of returns
    /// (`returns.csv`'s `co` and `cross` rows, `depolarisation.csv`); empty otherwise.
    pub polarised: &'a [PolarisedSet<'a>],
    /// The sets of signals of `signals.csv` (may be empty).
    pub signals: &'a [Signals],
    /// The rows of `retrieval.csv` (may be empty).
    pub products: &'a [Product],
    /// The derivatives of the Monte Carlo returns of `jacobians.csv` (with `[simulation]
    /// jacobians`), per laser line: those of the channels of the returns go into the file.
    pub jacobians: Option<&'a Jacobians>,
    /// The retrieved gas (`CO2`, …), for the mixing ratio's standard name.
    pub gas: Option<&'a str>,
    /// Global attributes.
    pub attributes: &'a RunAttributes,
}

/// The co- and cross-polarised parts of one set of returns (its source's).
#[derive(Debug, Clone, Copy)]
pub struct PolarisedSet<'a> {
    /// Co-polarised returns.
    pub co: &'a Returns,
    /// Cross-polarised returns, on the grid of `co`.
    pub cross: &'a Returns,
    /// Covariance of the two means bin by bin \[J²\] (`None`: analytic, no error).
    pub cov_j2: Option<&'a [f64]>,
}

/// The bytes of `run.nc` (module documentation).
pub fn run_file(run: &RunFile) -> Result<Vec<u8>, NetcdfError> {
    run_dataset(run)?.encode()
}

/// What `run.nc` holds, before it is written ([`run_file`]).
pub fn run_dataset(run: &RunFile) -> Result<Dataset, NetcdfError> {
    let mut nc = Dataset::default();
    let grid = Grid::of(run.returns)?;
    globals(&mut nc, run.attributes);
    coordinates(&mut nc, &grid, run)?;
    returns_variables(&mut nc, &grid, run.returns);
    if let Some(constants) = run.lidar_constant_j_m2 {
        backscatter_variables(&mut nc, &grid, run, constants)?;
    }
    if !run.polarised.is_empty() {
        polarised_variables(
            &mut nc,
            &grid,
            run.polarised,
            run.lidar_constant_j_m2,
            run.gates,
        )?;
    }
    if !run.signals.is_empty() {
        signal_variables(&mut nc, &grid, run.signals)?;
    }
    if let Some(j) = run.jacobians {
        jacobian_variables(&mut nc, &grid, j)?;
    }
    for q in [
        Quantity::MixingRatio,
        Quantity::SlantColumn,
        Quantity::NumberDensity,
    ] {
        let rows: Vec<&Product> = run.products.iter().filter(|p| p.quantity == q).collect();
        if !rows.is_empty() {
            product_variables(&mut nc, q, &rows, run.gas);
        }
    }
    add_range_coordinates(&mut nc);
    nc.check()?;
    Ok(nc)
}

/// One column of a table ([`table_file`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// Variable name: the CSV column's.
    pub name: &'static str,
    /// `long_name`.
    pub long_name: &'static str,
    /// `units` (UDUNITS); `None` for text.
    pub units: Option<&'static str>,
    /// One value per row.
    pub values: ColumnValues,
}

/// The values of a [`Column`].
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnValues {
    /// Text (a char array).
    Text(Vec<String>),
    /// Numbers; a non-finite one is `_FillValue`.
    Number(Vec<f64>),
}

/// A table (the rows of one CSV file) as a CF NetCDF file: one dimension `row_dim`, one
/// variable per column, named as the column; text columns are the numbers' auxiliary
/// coordinates (CF-1.8 §5). Global attributes `Conventions`, `title`, `source`, `history`.
pub fn table_file(
    row_dim: &str,
    columns: &[Column],
    title: &str,
    history: &str,
) -> Result<Vec<u8>, NetcdfError> {
    table_dataset(row_dim, columns, title, history)?.encode()
}

/// What [`table_file`] writes, before it is written.
pub fn table_dataset(
    row_dim: &str,
    columns: &[Column],
    title: &str,
    history: &str,
) -> Result<Dataset, NetcdfError> {
    let rows = columns.first().map_or(0, |c| match &c.values {
        ColumnValues::Text(v) => v.len(),
        ColumnValues::Number(v) => v.len(),
    });
    if rows == 0 {
        return Err(NetcdfError::Layout("a table without rows".into()));
    }
    let mut nc = Dataset::default();
    nc.global("Conventions", Attr::text(CONVENTIONS));
    nc.global("title", Attr::text(title));
    nc.global(
        "source",
        Attr::text(format!("lidarsim {}", env!("CARGO_PKG_VERSION"))),
    );
    nc.global("history", Attr::text(history));
    nc.global("lidarsim_version", Attr::text(env!("CARGO_PKG_VERSION")));
    nc.dim(row_dim, rows);
    let texts: Vec<&str> = columns
        .iter()
        .filter(|c| matches!(c.values, ColumnValues::Text(_)))
        .map(|c| c.name)
        .collect();
    let coordinates = texts.join(" ");
    for c in columns {
        let len = match &c.values {
            ColumnValues::Text(v) => v.len(),
            ColumnValues::Number(v) => v.len(),
        };
        if len != rows {
            return Err(NetcdfError::Layout(format!(
                "column {} has {len} rows, not {rows}",
                c.name
            )));
        }
        match &c.values {
            ColumnValues::Text(v) => {
                nc.text(c.name, row_dim, v)
                    .attrs([("long_name", c.long_name)]);
            }
            ColumnValues::Number(v) => {
                let var = nc
                    .f64(c.name, &[row_dim], v.clone())
                    .attrs([("long_name", c.long_name)])
                    .fill();
                if let Some(u) = c.units {
                    var.attrs([("units", u)]);
                }
                if !coordinates.is_empty() {
                    var.attrs([("coordinates", coordinates.as_str())]);
                }
            }
        }
    }
    nc.check()?;
    Ok(nc)
}

/// How a study's NetCDF file was made ([`study_globals`]).
#[derive(Debug, Clone, Copy)]
pub struct StudyAttributes<'a> {
    /// `title`: what was run.
    pub title: &'a str,
    /// `history`: when and by which command line (CF §2.6.2).
    pub history: &'a str,
    /// The scene file's path (or the embedded default scene's name); `None` without a scene.
    pub scene_file: Option<&'a str>,
    /// The scene's whole text (TOML).
    pub scene_text: Option<&'a str>,
    /// Random seed of the study (its ensembles and noise).
    pub seed: Option<u64>,
    /// The profile set the study ran over (its name).
    pub profile_set: Option<&'a str>,
}

/// The global attributes of a study's NetCDF file: `Conventions`, `title`, `source`,
/// `history`, `lidarsim_version`, and where known `scene_file`, `scene` (its TOML text, as
/// `run.nc` has it), `seed` (text: NetCDF-3 has no 64-bit integer) and `profile_set`.
pub fn study_globals(nc: &mut Dataset, a: &StudyAttributes) {
    let version = env!("CARGO_PKG_VERSION");
    nc.globals.clear();
    nc.global("Conventions", Attr::text(CONVENTIONS));
    nc.global("title", Attr::text(a.title));
    nc.global("source", Attr::text(format!("lidarsim {version}")));
    nc.global("history", Attr::text(a.history));
    nc.global("lidarsim_version", Attr::text(version));
    if let Some(f) = a.scene_file {
        nc.global("scene_file", Attr::text(f));
    }
    if let Some(t) = a.scene_text {
        nc.global("scene", Attr::text(t));
    }
    if let Some(seed) = a.seed {
        nc.global("seed", Attr::text(seed.to_string()));
    }
    if let Some(set) = a.profile_set {
        nc.global("profile_set", Attr::text(set));
    }
}

/// The CF `history` attribute of a NetCDF file written now by `command` (the command line,
/// `args_os`, so that a path that is not UTF-8 does not panic): the UTC time and the command.
pub fn history(command: impl IntoIterator<Item = std::ffi::OsString>) -> String {
    let command: Vec<String> = command
        .into_iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    format!(
        "{}: {}",
        utc_timestamp(SystemTime::now()),
        command.join(" ")
    )
}

/// `t` as an ISO 8601 UTC time to the second (`2026-11-23T20:30:03Z`), for `history`.
pub fn utc_timestamp(t: SystemTime) -> String {
    let s = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, sec) = ((s / 86_400) as i64, s % 86_400);
    // Civil date from days since 1970-01-01 (H. Hinnant, "chrono-Compatible Low-Level Date
    // Algorithms", days_from_civil's inverse), proleptic Gregorian calendar.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        sec / 3600,
        sec / 60 % 60,
        sec % 60
    )
}

// ---------------------------------------------------------------------------------------------
// The content

/// The common grid of all sets of returns: their sources, channels, fields of view and gates,
/// and the union of their order bins (in the order the sets list them).
struct Grid {
    sources: Vec<String>,
    channels: Vec<String>,
    fov_full_angle_mrad: Vec<f64>,
    range_m: Vec<f64>,
    orders: Vec<String>,
}

impl Grid {
    fn of(sets: &[&Returns]) -> Result<Grid, NetcdfError> {
        let Some(first) = sets.first() else {
            return Err(NetcdfError::Layout("no returns to write".into()));
        };
        let mut grid = Grid {
            sources: Vec::new(),
            channels: first.channels.clone(),
            fov_full_angle_mrad: first.fov_full_angle_mrad.clone(),
            range_m: first.range_m.clone(),
            orders: Vec::new(),
        };
        for r in sets {
            if r.channels != grid.channels
                || r.fov_full_angle_mrad != grid.fov_full_angle_mrad
                || r.range_m != grid.range_m
            {
                return Err(NetcdfError::Layout(format!(
                    "the {} returns are not on the grid of the {} returns",
                    r.source.label(),
                    first.source.label()
                )));
            }
            let s = r.source.label().to_string();
            if grid.sources.contains(&s) {
                return Err(NetcdfError::Layout(format!("two sets of {s} returns")));
            }
            grid.sources.push(s);
            for o in &r.orders {
                let label = o.label();
                if !grid.orders.contains(&label) {
                    grid.orders.push(label);
                }
            }
        }
        Ok(grid)
    }

    fn len(&self) -> usize {
        self.sources.len()
            * self.channels.len()
            * self.fov_full_angle_mrad.len()
            * self.range_m.len()
            * self.orders.len()
    }

    /// Flat index of (source, channel, fov, gate, order) in a variable over [`GRID_DIMS`].
    fn index(&self, s: usize, c: usize, f: usize, g: usize, o: usize) -> usize {
        (((s * self.channels.len() + c) * self.fov_full_angle_mrad.len() + f) * self.range_m.len()
            + g)
            * self.orders.len()
            + o
    }

    fn position(list: &[String], what: &str, label: &str) -> Result<usize, NetcdfError> {
        list.iter()
            .position(|x| x == label)
            .ok_or_else(|| NetcdfError::Layout(format!("{what} `{label}` is not in the returns")))
    }
}

/// The dimensions of returns and signals, slowest first (the order of `returns.csv`'s rows).
const GRID_DIMS: [&str; 5] = [
    "source",
    "channel",
    "fov_full_angle_mrad",
    "range_m",
    "order",
];

fn globals(nc: &mut Dataset, a: &RunAttributes) {
    let version = env!("CARGO_PKG_VERSION");
    nc.global("Conventions", Attr::text(CONVENTIONS));
    nc.global("title", Attr::text(&a.title));
    nc.global("source", Attr::text(format!("lidarsim {version}")));
    nc.global("history", Attr::text(&a.history));
    nc.global(
        "comment",
        Attr::text(
            "The numbers of returns.csv, signals.csv and retrieval.csv written beside this file \
             (at full double precision); the lidarsim README, section \"Output: run.nc\", \
             describes every variable.",
        ),
    );
    nc.global("lidarsim_version", Attr::text(version));
    nc.global("scene_file", Attr::text(&a.scene_file));
    nc.global("scene", Attr::text(&a.scene_text));
    // Text, because NetCDF-3 has no 64-bit integer and a double is exact only to 2^53.
    nc.global("seed", Attr::text(a.seed.to_string()));
    nc.global("photons", Attr::F64(vec![a.photons as f64]));
    nc.global("batches", Attr::F64(vec![a.batches as f64]));
}

fn coordinates(nc: &mut Dataset, grid: &Grid, run: &RunFile) -> Result<(), NetcdfError> {
    nc.dim("source", grid.sources.len());
    nc.dim("channel", grid.channels.len());
    nc.dim("fov_full_angle_mrad", grid.fov_full_angle_mrad.len());
    nc.dim("range_m", grid.range_m.len());
    nc.dim("order", grid.orders.len());
    nc.dim("nv", 2);

    nc.text("source", "source", &grid.sources).attrs([
        ("long_name", "source of the returns: mc = Monte Carlo transport, analytic = single-scatter lidar equation"),
    ]);
    nc.text("channel", "channel", &grid.channels)
        .attrs([("long_name", "laser line (channel) name")]);
    let wavenumber: Vec<f64> = grid
        .channels
        .iter()
        .map(|c| {
            run.lines
                .iter()
                .find(|l| l.name == *c)
                .map_or(f64::NAN, |l| l.wavenumber_cm1)
        })
        .collect();
    nc.f64("channel_wavenumber_cm1", &["channel"], wavenumber)
        .attrs([
            // No standard name: the CF table (version 93) has `radiation_wavelength` but no
            // wavenumber of radiation; `sensor_band_central_radiation_wavenumber` is the first
            // moment of a band's response, which a laser's frequency offset moves away from.
            ("long_name", "nominal vacuum wavenumber of the laser line"),
            ("units", "cm-1"),
        ])
        .fill();
    nc.f64(
        "fov_full_angle_mrad",
        &["fov_full_angle_mrad"],
        grid.fov_full_angle_mrad.clone(),
    )
    .attrs([
        ("long_name", "receiver field of view, full angle"),
        ("units", "mrad"),
    ]);
    nc.f64("range_m", &["range_m"], grid.range_m.clone())
        .attrs([
            (
                "long_name",
                "range along the beam, centre of the range gate (r = c t / 2)",
            ),
            ("units", "m"),
            ("bounds", "range_m_bounds"),
        ]);
    let g = run.gates;
    if g.count != grid.range_m.len() {
        return Err(NetcdfError::Layout(format!(
            "{} gates in the scene, {} in the returns",
            g.count,
            grid.range_m.len()
        )));
    }
    let edges = edges_of(g);
    let altitude = |r: f64| run.lidar_altitude_m + run.mu * r;
    let altitude_edges = edges_of(g).into_iter().map(altitude).collect();
    // CF §7.1: a boundary variable takes its units from its coordinate; it needs none of its own.
    nc.f64("range_m_bounds", &["range_m", "nv"], edges);
    // The altitude of each gate's centre along the line of sight (plane-parallel, as the
    // transport): an auxiliary coordinate on `range_m` (CF-1.8 §5), named in the
    // `coordinates` of every variable over `range_m`.
    if !(run.lidar_altitude_m.is_finite() && run.mu.is_finite() && run.mu.abs() <= 1.0) {
        return Err(NetcdfError::Layout(format!(
            "lidar altitude {} m, cosine of the zenith angle {}",
            run.lidar_altitude_m, run.mu
        )));
    }
    nc.f64(
        "altitude_m",
        &["range_m"],
        grid.range_m.iter().map(|&r| altitude(r)).collect(),
    )
    .attrs([
        ("standard_name", "altitude"),
        (
            "long_name",
            "altitude of the centre of the range gate along the line of sight",
        ),
        ("units", "m"),
        ("positive", "up"),
        ("axis", "Z"),
        ("bounds", "altitude_m_bounds"),
    ]);
    nc.f64("altitude_m_bounds", &["range_m", "nv"], altitude_edges);
    nc.text("order", "order", &grid.orders).attrs([(
        "long_name",
        "scattering-order bin: total = all orders, 1st, 2nd, ... = exactly that many scattering \
         events (surface reflections count), 2nd+, 6th+ = that many or more",
    )]);
    Ok(())
}

/// The gates' near and far edges \[m\], gate by gate.
fn edges_of(g: &Gates) -> Vec<f64> {
    (0..g.count)
        .flat_map(|i| {
            [
                g.start_m + i as f64 * g.width_m,
                g.start_m + (i + 1) as f64 * g.width_m,
            ]
        })
        .collect()
}

/// The gates' altitude (`altitude_m`) named in the `coordinates` attribute of every data
/// variable over `range_m` (CF-1.8 §5: an auxiliary coordinate is found through it), added to
/// the coordinates it names already.
fn add_range_coordinates(nc: &mut Dataset) {
    const SKIP: [&str; 4] = [
        "range_m",
        "range_m_bounds",
        "altitude_m",
        "altitude_m_bounds",
    ];
    for v in &mut nc.vars {
        if SKIP.contains(&v.name.as_str()) || !v.dims.iter().any(|d| d == "range_m") {
            continue;
        }
        match v.attrs.iter_mut().find(|(k, _)| k == "coordinates") {
            Some((_, Attr::Text(c))) => *c = format!("altitude_m {c}"),
            _ => v
                .attrs
                .push(("coordinates".into(), Attr::text("altitude_m"))),
        }
    }
}

fn returns_variables(nc: &mut Dataset, grid: &Grid, sets: &[&Returns]) {
    let mut energy = vec![f64::NAN; grid.len()];
    let mut stderr = vec![f64::NAN; grid.len()];
    for (s, r) in sets.iter().enumerate() {
        for (o, order) in r.orders.iter().enumerate() {
            // The grid's orders are the union of every set's: always found.
            let Some(go) = grid.orders.iter().position(|l| *l == order.label()) else {
                continue;
            };
            for c in 0..grid.channels.len() {
                for f in 0..grid.fov_full_angle_mrad.len() {
                    for g in 0..grid.range_m.len() {
                        let i = r.index(c, f, g, o);
                        let j = grid.index(s, c, f, g, go);
                        energy[j] = r.energy_j[i];
                        stderr[j] = r.stderr_j[i];
                    }
                }
            }
        }
    }
    nc.f64("energy_j", &GRID_DIMS, energy)
        .attrs([
            (
                "long_name",
                "expected energy received in the range gate per pulse",
            ),
            ("units", "J"),
            ("ancillary_variables", "stderr_j"),
        ])
        .fill();
    nc.f64("stderr_j", &GRID_DIMS, stderr)
        .attrs([
            (
                "long_name",
                "standard error of energy_j (from independent batches; 0 for analytic returns)",
            ),
            ("units", "J"),
        ])
        .fill();
}

/// `backscatter.csv`'s numbers ([`crate::backscatter`]): the lidar constant of each channel,
/// the attenuated backscatter β′ = E r₁ r₂/(C Δr) and the range-corrected signal E r_c² of
/// every bin of the returns, with their standard errors.
fn backscatter_variables(
    nc: &mut Dataset,
    grid: &Grid,
    run: &RunFile,
    constants: &[f64],
) -> Result<(), NetcdfError> {
    if constants.len() != grid.channels.len() {
        return Err(NetcdfError::Layout(format!(
            "{} lidar constants for {} channels",
            constants.len(),
            grid.channels.len()
        )));
    }
    const NAMES: [(&str, &str, &str); 4] = [
        (
            "attenuated_backscatter_per_m_sr",
            "attenuated backscatter coefficient of the range gate, beta' = E r1 r2 / (C (r2 - r1)): the 1/r^2-weighted gate mean of beta T^2 O (lidar_constant_j_m2 is C; the overlap O is not in C)",
            "m-1 sr-1",
        ),
        (
            "attenuated_backscatter_stderr_per_m_sr",
            "standard error of attenuated_backscatter_per_m_sr (0 for analytic returns)",
            "m-1 sr-1",
        ),
        (
            "range_corrected_signal_j_m2",
            "range-corrected signal E r^2, r the centre of the range gate",
            "J m2",
        ),
        (
            "range_corrected_signal_stderr_j_m2",
            "standard error of range_corrected_signal_j_m2 (0 for analytic returns)",
            "J m2",
        ),
    ];
    let mut values: Vec<Vec<f64>> = vec![vec![f64::NAN; grid.len()]; NAMES.len()];
    for (s, r) in run.returns.iter().enumerate() {
        let b = crate::backscatter::Backscatter::of(r, run.gates, constants);
        for (o, order) in r.orders.iter().enumerate() {
            let go = Grid::position(&grid.orders, "order", &order.label())?;
            for c in 0..grid.channels.len() {
                for f in 0..grid.fov_full_angle_mrad.len() {
                    for g in 0..grid.range_m.len() {
                        let i = b.index(c, f, g, o);
                        let j = grid.index(s, c, f, g, go);
                        for (v, x) in values.iter_mut().zip([
                            &b.attenuated_backscatter_per_m_sr,
                            &b.attenuated_backscatter_stderr_per_m_sr,
                            &b.range_corrected_signal_j_m2,
                            &b.range_corrected_signal_stderr_j_m2,
                        ]) {
                            v[j] = x[i];
                        }
                    }
                }
            }
        }
    }
    nc.f64("lidar_constant_j_m2", &["channel"], constants.to_vec())
        .attrs([
            (
                "long_name",
                "lidar constant C = pulse energy x receiver optical efficiency x telescope area (without the overlap)",
            ),
            ("units", "J m2"),
        ])
        .fill();
    for (n, ((name, long_name, units), v)) in NAMES.into_iter().zip(values).enumerate() {
        let var = nc
            .f64(name, &GRID_DIMS, v)
            .attrs([("long_name", long_name), ("units", units)])
            .fill();
        if n % 2 == 0 {
            var.attrs([("ancillary_variables", NAMES[n + 1].0)]);
        }
        if n == 0 {
            // CF's name for β′ (the backscatter attenuated by the two-way transmission); with a
            // field of view narrower than the beam it also holds the overlap, as a lidar's does.
            var.attrs([(
                "standard_name",
                "volume_attenuated_backwards_scattering_function_in_air",
            )]);
        }
    }
    Ok(())
}

/// With polarised light: the co- and cross-polarised returns on a last dimension
/// `polarisation` (`co`, `cross`), and the depolarisation ratio with its standard error
/// (`depolarisation.csv`'s numbers).
fn polarised_variables(
    nc: &mut Dataset,
    grid: &Grid,
    sets: &[PolarisedSet],
    constants: Option<&[f64]>,
    gates: &Gates,
) -> Result<(), NetcdfError> {
    nc.dim("polarisation", 2);
    nc.text("polarisation", "polarisation", &["co".to_string(), "cross".to_string()])
        .attrs([(
            "long_name",
            "polarisation relative to the emitted light: co = what a sphere's single backscatter returns, cross = the rest",
        )]);
    let n = grid.len();
    let (mut energy, mut stderr) = (vec![f64::NAN; 2 * n], vec![f64::NAN; 2 * n]);
    let (mut delta, mut delta_se) = (vec![f64::NAN; n], vec![f64::NAN; n]);
    // β′ of each part: the energy times the factor of its channel and gate (Eq. B1).
    let (mut beta, mut beta_se) = (vec![f64::NAN; 2 * n], vec![f64::NAN; 2 * n]);
    let factor = |c: usize, g: usize| {
        let r1 = gates.start_m + g as f64 * gates.width_m;
        constants.and_then(|k| k.get(c)).map_or(f64::NAN, |k| {
            crate::backscatter::backscatter_factor(r1, r1 + gates.width_m, *k)
        })
    };
    for set in sets {
        let s = Grid::position(&grid.sources, "source", set.co.source.label())?;
        for (o, order) in set.co.orders.iter().enumerate() {
            let go = Grid::position(&grid.orders, "order", &order.label())?;
            for c in 0..grid.channels.len() {
                for f in 0..grid.fov_full_angle_mrad.len() {
                    for g in 0..grid.range_m.len() {
                        let i = set.co.index(c, f, g, o);
                        let j = grid.index(s, c, f, g, go);
                        let b = factor(c, g);
                        for (p, part) in [set.co, set.cross].iter().enumerate() {
                            energy[2 * j + p] = part.energy_j[i];
                            stderr[2 * j + p] = part.stderr_j[i];
                            beta[2 * j + p] = b * part.energy_j[i];
                            beta_se[2 * j + p] = b * part.stderr_j[i];
                        }
                        (delta[j], delta_se[j]) =
                            crate::returns::depolarisation_ratio(set.co, set.cross, set.cov_j2, i);
                    }
                }
            }
        }
    }
    let dims = [
        GRID_DIMS[0],
        GRID_DIMS[1],
        GRID_DIMS[2],
        GRID_DIMS[3],
        GRID_DIMS[4],
        "polarisation",
    ];
    nc.f64("polarised_energy_j", &dims, energy)
        .attrs([
            (
                "long_name",
                "energy_j in each polarisation (co + cross = energy_j)",
            ),
            ("units", "J"),
            ("ancillary_variables", "polarised_stderr_j"),
        ])
        .fill();
    nc.f64("polarised_stderr_j", &dims, stderr)
        .attrs([
            ("long_name", "standard error of polarised_energy_j"),
            ("units", "J"),
        ])
        .fill();
    if constants.is_some() {
        nc.f64("polarised_attenuated_backscatter_per_m_sr", &dims, beta)
            .attrs([
                (
                    "long_name",
                    "attenuated_backscatter_per_m_sr in each polarisation (co + cross = attenuated_backscatter_per_m_sr)",
                ),
                ("units", "m-1 sr-1"),
                (
                    "ancillary_variables",
                    "polarised_attenuated_backscatter_stderr_per_m_sr",
                ),
            ])
            .fill();
        nc.f64(
            "polarised_attenuated_backscatter_stderr_per_m_sr",
            &dims,
            beta_se,
        )
        .attrs([
            (
                "long_name",
                "standard error of polarised_attenuated_backscatter_per_m_sr",
            ),
            ("units", "m-1 sr-1"),
        ])
        .fill();
    }
    nc.f64("depolarisation_ratio", &GRID_DIMS, delta)
        .attrs([
            (
                "long_name",
                "volume depolarisation ratio cross/co of the received energy",
            ),
            ("units", "1"),
            ("ancillary_variables", "depolarisation_ratio_stderr"),
        ])
        .fill();
    nc.f64("depolarisation_ratio_stderr", &GRID_DIMS, delta_se)
        .attrs([
            (
                "long_name",
                "standard error of depolarisation_ratio (batch errors of co and cross and their covariance; 0 for analytic)",
            ),
            ("units", "1"),
        ])
        .fill();
    Ok(())
}

fn signal_variables(nc: &mut Dataset, grid: &Grid, signals: &[Signals]) -> Result<(), NetcdfError> {
    const NAMES: [(&str, &str); 5] = [
        (
            "signal_photoelectrons",
            "mean signal photo-electrons per pulse in the range gate (primary, before avalanche gain)",
        ),
        (
            "background_photoelectrons",
            "mean background photo-electrons per pulse in the range gate",
        ),
        (
            "dark_electrons",
            "mean dark-current electrons per pulse in the range gate",
        ),
        (
            "noise_std_photoelectrons",
            "standard deviation of the noise per pulse in the range gate (shot, excess, background, dark, NEP, amplifier, readout)",
        ),
        ("snr", "signal-to-noise ratio per pulse in the range gate"),
    ];
    let mut values: Vec<Vec<f64>> = vec![vec![f64::NAN; grid.len()]; NAMES.len()];
    for sig in signals {
        if sig.fov_full_angle_mrad != grid.fov_full_angle_mrad || sig.range_m != grid.range_m {
            return Err(NetcdfError::Layout(
                "signals are not on the grid of the returns".into(),
            ));
        }
        let s = Grid::position(&grid.sources, "source", sig.source.label())?;
        let o = Grid::position(&grid.orders, "order", &sig.order.label())?;
        for (l, line) in sig.lines.iter().enumerate() {
            let c = Grid::position(&grid.channels, "channel", &line.name)?;
            for f in 0..grid.fov_full_angle_mrad.len() {
                for g in 0..grid.range_m.len() {
                    let n = sig.gate(l, f, g);
                    let j = grid.index(s, c, f, g, o);
                    for (v, x) in values.iter_mut().zip([
                        n.signal_pe,
                        n.background_pe,
                        n.dark_pe,
                        n.std_pe(),
                        n.snr(),
                    ]) {
                        v[j] = x;
                    }
                }
            }
        }
    }
    for ((name, long_name), v) in NAMES.into_iter().zip(values) {
        // Counts of electrons are numbers: CF's unit "1".
        nc.f64(name, &GRID_DIMS, v)
            .attrs([("long_name", long_name), ("units", "1")])
            .fill();
    }
    Ok(())
}

/// `jacobians.csv`'s numbers: ∂E/∂θ and its standard error over (channel,
/// fov_full_angle_mrad, range_m, jacobian_order, layer, jacobian_quantity), the layout of
/// [`Jacobians::index`] with the returns' channels; a derivative the layer does not have (the
/// molecular scattering of a layer without molecules) is `_FillValue`, as is a channel of the
/// returns without Jacobians. The layers are a dimension `layer` (index from the bottom, as
/// the CSV's `layer`) with `layer_bottom_m` and `layer_top_m`.
fn jacobian_variables(nc: &mut Dataset, grid: &Grid, j: &Jacobians) -> Result<(), NetcdfError> {
    if j.fov_full_angle_mrad != grid.fov_full_angle_mrad || j.range_m != grid.range_m {
        return Err(NetcdfError::Layout(
            "the Jacobians are not on the grid of the returns".into(),
        ));
    }
    // The quantities in J per (1/m); `gas_amount` (J per relative change) is the CSV's and
    // weighting.csv's.
    let (n_orders, n_layers, n_q) = (
        j.orders.len(),
        j.layer_bottom_m.len(),
        JacobianQuantity::ALL
            .iter()
            .filter(|q| q.unit() == "J m")
            .count(),
    );
    let per_channel =
        grid.fov_full_angle_mrad.len() * grid.range_m.len() * n_orders * n_layers * n_q;
    let n = grid.channels.len() * per_channel;
    let (mut value, mut stderr) = (vec![f64::NAN; n], vec![f64::NAN; n]);
    let mut found = 0;
    for (c, name) in grid.channels.iter().enumerate() {
        // The Jacobians of combinations that are not lines (a jittered line's slope and
        // curvature) are `jacobians.csv`'s only.
        let Some(jc) = j.channels.iter().position(|x| x == name) else {
            continue;
        };
        found += 1;
        for f in 0..grid.fov_full_angle_mrad.len() {
            for g in 0..grid.range_m.len() {
                for o in 0..n_orders {
                    for l in 0..n_layers {
                        for q in 0..n_q {
                            if !j.is_defined(jc, l, q) {
                                continue;
                            }
                            let i = j.index(jc, f, g, o, l, q);
                            let k = ((((c * grid.fov_full_angle_mrad.len() + f)
                                * grid.range_m.len()
                                + g)
                                * n_orders
                                + o)
                                * n_layers
                                + l)
                                * n_q
                                + q;
                            value[k] = j.value[i];
                            stderr[k] = j.stderr[i];
                        }
                    }
                }
            }
        }
    }
    if found == 0 {
        return Err(NetcdfError::Layout(format!(
            "Jacobians of {:?}, returns of {:?}: no channel in common",
            j.channels, grid.channels
        )));
    }
    nc.dim("jacobian_order", n_orders);
    nc.dim("layer", n_layers);
    nc.dim("jacobian_quantity", n_q);
    let orders: Vec<String> = j.orders.iter().map(|o| o.label()).collect();
    nc.text("jacobian_order", "jacobian_order", &orders)
        .attrs([(
            "long_name",
            "scattering-order bin of the Jacobians: total = all orders, 1st = single scattering, 2nd+ = multiple scattering",
        )]);
    nc.f64(
        "layer",
        &["layer"],
        (0..n_layers).map(|l| (j.first_layer + l) as f64).collect(),
    )
    .attrs([
        (
            "long_name",
            "layer of the optical atmosphere, index from the bottom (molecular layers split at every particle layer's edges)",
        ),
        ("units", "1"),
    ]);
    nc.f64("layer_bottom_m", &["layer"], j.layer_bottom_m.clone())
        .attrs([
            ("long_name", "altitude of the bottom of the layer"),
            ("units", "m"),
        ]);
    nc.f64("layer_top_m", &["layer"], j.layer_top_m.clone())
        .attrs([
            ("long_name", "altitude of the top of the layer"),
            ("units", "m"),
        ]);
    let quantities: Vec<String> = JacobianQuantity::ALL[..n_q]
        .iter()
        .map(|q| q.label().to_string())
        .collect();
    nc.text("jacobian_quantity", "jacobian_quantity", &quantities)
        .attrs([(
            "long_name",
            "coefficient the derivative is taken with respect to: absorption = the layer's absorption coefficient (gas and particles), molecular_scattering = its molecular scattering coefficient, particle_scattering = its particles' scattering coefficient (absorption fixed), particle_extinction = its particles' extinction coefficient at a fixed single-scattering albedo; all in 1/m",
        )]);
    let dims = [
        GRID_DIMS[1],
        GRID_DIMS[2],
        GRID_DIMS[3],
        "jacobian_order",
        "layer",
        "jacobian_quantity",
    ];
    let coordinates = "layer_bottom_m layer_top_m";
    nc.f64("jacobian_j_m", &dims, value)
        .attrs([
            (
                "long_name",
                "derivative dE/dtheta of the Monte Carlo energy_j (source mc) with respect to the layer's coefficient theta in 1/m named by jacobian_quantity, from the same photons (J per 1/m); _FillValue where the layer has no such scatterer",
            ),
            ("units", "J m"),
            ("ancillary_variables", "jacobian_stderr_j_m"),
            ("coordinates", coordinates),
        ])
        .fill();
    nc.f64("jacobian_stderr_j_m", &dims, stderr)
        .attrs([
            (
                "long_name",
                "standard error of jacobian_j_m (from the batches of the returns)",
            ),
            ("units", "J m"),
            ("coordinates", coordinates),
        ])
        .fill();
    Ok(())
}

/// A column of `retrieval.csv`: its value in a product.
type Getter<T> = fn(&Product) -> T;

/// One table of `retrieval.csv`'s rows of one quantity.
fn product_variables(nc: &mut Dataset, q: Quantity, rows: &[&Product], gas: Option<&str>) {
    let p = q.label();
    let dim = format!("{p}_product");
    nc.dim(&dim, rows.len());
    let name = |column: &str| format!("{p}_{column}");
    let coordinates = product_coordinates(nc, &dim, rows, &name);
    product_values(nc, q, &dim, rows, gas, &name, &coordinates);
}

/// The coordinates of a table of products: which retrieval, from which returns, where; their
/// variable names.
fn product_coordinates(
    nc: &mut Dataset,
    dim: &str,
    rows: &[&Product],
    name: &dyn Fn(&str) -> String,
) -> Vec<String> {
    let texts: [(&str, &str, Getter<String>); 4] = [
        (
            "method",
            "retrieval method: ipda (weighting function), ipda_virtual_sigma (virtual cross-sections), dial (range cell)",
            |r| r.method.label().into(),
        ),
        ("source", "returns retrieved from: mc or analytic", |r| {
            r.source.label().into()
        }),
        (
            "order",
            "scattering orders of those returns: 1 or total",
            |r| r.order.label(),
        ),
        ("channel_pair", "on/off laser lines", |r| {
            r.channel_pair.clone()
        }),
    ];
    let mut coordinates = Vec::new();
    for (column, long_name, get) in texts {
        let values: Vec<String> = rows.iter().map(|r| get(r)).collect();
        nc.text(&name(column), dim, &values)
            .attrs([("long_name", long_name)]);
        coordinates.push(name(column));
    }
    let geometry: [(&str, &str, &str, Getter<f64>); 5] = [
        (
            "fov_full_angle_mrad",
            "receiver field of view, full angle",
            "mrad",
            |r| r.fov_full_angle_mrad,
        ),
        (
            "range_start_m",
            "range at the start of the path (IPDA: 0; DIAL: centre of the cell's near gate)",
            "m",
            |r| r.range_m.0,
        ),
        (
            "range_end_m",
            "range at the end of the path (IPDA: the target; DIAL: centre of the cell's far gate)",
            "m",
            |r| r.range_m.1,
        ),
        (
            "altitude_bottom_m",
            "altitude of the bottom of the column or cell",
            "m",
            |r| r.altitude_m.0,
        ),
        (
            "altitude_top_m",
            "altitude of the top of the column or cell",
            "m",
            |r| r.altitude_m.1,
        ),
    ];
    for (column, long_name, units, get) in geometry {
        nc.f64(&name(column), &[dim], rows.iter().map(|r| get(r)).collect())
            .attrs([("long_name", long_name), ("units", units)])
            .fill();
        coordinates.push(name(column));
    }
    coordinates
}

/// The values of a table of products, in the quantity's unit, with their coordinates.
fn product_values(
    nc: &mut Dataset,
    q: Quantity,
    dim: &str,
    rows: &[&Product],
    gas: Option<&str>,
    name: &dyn Fn(&str) -> String,
    coordinates: &[String],
) {
    let (units, unit_text) = match q {
        // UDUNITS reads "1e-6" as parts per million; "ppm" is not in every UDUNITS database.
        Quantity::MixingRatio => ("1e-6", "dry-air mole fraction in ppm"),
        Quantity::SlantColumn => ("m-2", "molecules per square metre along the beam"),
        Quantity::NumberDensity => ("m-3", "molecules per cubic metre"),
    };
    let standard_name = match (q, gas) {
        (Quantity::MixingRatio, Some("CO2")) => {
            Some("dry_atmosphere_mole_fraction_of_carbon_dioxide")
        }
        (Quantity::MixingRatio, Some("CH4")) => Some("dry_atmosphere_mole_fraction_of_methane"),
        _ => None,
    };
    let gas = gas.unwrap_or("gas");
    let coordinates = coordinates.join(" ");
    let values: [(&str, String, Getter<f64>); 9] = [
        (
            "truth",
            format!("{gas} of the scene's own profile over the column or cell"),
            |r| r.truth,
        ),
        (
            "retrieved",
            format!("{gas} retrieved from the expected (noise-free) signals"),
            |r| r.retrieved,
        ),
        ("bias", "retrieved minus truth".into(), |r| r.bias()),
        (
            "mc_stderr",
            "standard error of retrieved from the Monte Carlo noise of the returns (0 analytic)"
                .into(),
            |r| r.mc_stderr,
        ),
        (
            "random_error_per_shot_pair",
            "analytic random error of one shot pair".into(),
            |r| r.random_error_per_shot_pair,
        ),
        (
            "random_error_averaged",
            "analytic random error after averaging shots_averaged shot pairs".into(),
            |r| r.random_error_averaged,
        ),
        (
            "simulated_error_per_shot_pair",
            "standard deviation of simulated noisy retrievals of one shot pair".into(),
            |r| r.simulated_error_per_shot_pair,
        ),
        (
            "simulated_error_averaged",
            "standard deviation of simulated noisy retrievals of shots_averaged shot pairs".into(),
            |r| r.simulated_error_averaged,
        ),
        (
            "simulated_bias_averaged",
            "mean of the simulated averaged retrievals minus truth".into(),
            |r| r.simulated_mean_averaged - r.truth,
        ),
    ];
    let ancillary = format!(
        "{} {} {}",
        name("mc_stderr"),
        name("random_error_per_shot_pair"),
        name("random_error_averaged")
    );
    for (column, long_name, get) in values {
        let v = nc
            .f64(&name(column), &[dim], rows.iter().map(|r| get(r)).collect())
            .attrs([
                ("long_name", format!("{long_name} ({unit_text})").as_str()),
                ("units", units),
                ("coordinates", &coordinates),
            ])
            .fill();
        if let (Some(sn), "truth" | "retrieved") = (standard_name, column) {
            v.attrs([("standard_name", sn)]);
        }
        if column == "retrieved" {
            v.attrs([("ancillary_variables", ancillary.as_str())]);
        }
    }
    nc.f64(
        &name("shots_averaged"),
        &[dim],
        rows.iter().map(|r| r.shots_averaged as f64).collect(),
    )
    .attrs([
        ("long_name", "shot pairs averaged in one measurement"),
        ("units", "1"),
    ]);
}

mod builder;
pub use builder::{Attr, Dataset, Values, Var};

#[cfg(test)]
mod tests;
