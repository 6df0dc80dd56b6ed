//! Limits that protect memory and time, in one place (README: "Limits").
//!
//! Each limit bounds the size of a whole problem (a product such as gates × channels × fields of
//! view × orders), not one of its factors, and is checked when the inputs are validated: before
//! any large allocation, so that a scene or a command line asking for too much is refused in
//! milliseconds with the product named, instead of exhausting memory or running for days. Every
//! shipped scene and validation run sits at least a hundredfold below each limit.

/// Worker threads of one run (`--threads`, `simulation.threads`). More threads than this
/// only add stacks and scheduling; 0 still means "all cores".
pub const MAX_THREADS: u64 = 1024;

/// Photon packets of one Monte Carlo run (about a day on one core at 10⁷ photons/s, far
/// beyond any run the validation needs).
pub const MAX_PHOTONS: u64 = 1_000_000_000_000;

/// Independent batches of one Monte Carlo run: each batch folds every tally bin once, so
/// batches × bins is the bookkeeping time.
pub const MAX_BATCHES: u64 = 10_000;

/// Bins of the returns: gates × fields of view × order bins (total, 1…N, N+) × (channels +
/// line sums + line pairs whose covariance is kept). Each bin is held several times (means,
/// second moments, one buffer per batch in flight) and written as one CSV row, so 4·10⁶ bins
/// are a few hundred MB.
pub const MAX_RETURN_BINS: u64 = 4_000_000;

/// Tally values of the batches in flight at once (each batch fills its own buffer); fewer
/// batches run together when the buffers are large, which does not change the numbers.
pub const MAX_LIVE_TALLY_VALUES: usize = 64_000_000;

/// Layers of the molecular grid of a scene, and of a line of sight (`lbl`, `select-lines`):
/// 1 m layers through 100 km.
pub const MAX_PATH_LAYERS: u64 = 100_000;

/// Optical layers × channels of a scene's optical atmosphere (each cell carries several
/// coefficients and the cumulative optical depths).
pub const MAX_OPTICAL_CELLS: u64 = 10_000_000;

/// Values of a gas optical-depth table: wavenumber grid points × molecular layers (8 bytes
/// each, held in memory and saved whole).
pub const MAX_GAS_TABLE_VALUES: u64 = 50_000_000;

/// Points of one wavenumber grid (a cross-section vector of 8-byte values).
pub const MAX_GRID_POINTS: u64 = 50_000_000;

/// Rows of an `lbl` output table: grid points (cross-sections) or grid points × layers (layer
/// optical depths); the table is built as text before it is written.
pub const MAX_LBL_ROWS: u64 = 5_000_000;

/// Values of a generated profile ensemble: profiles × levels (`profiles generate --n`,
/// `dial --ensemble`, `select-lines --ensemble`, `bench --study`), each member a few values
/// per level in memory and a CSV row per level.
pub const MAX_ENSEMBLE_LEVELS: u64 = 2_000_000;

/// Mie work of one particle layer (all its channels' wavelengths) or of one `lidarsim mie`, in
/// term-angles (`particles::distribution::MieWork`: Mie terms summed over the radii of the
/// finest size grids × (phase-function angles + the coefficients' cost in angles)). About 2.4 h
/// on one core at [`MIE_SECONDS_PER_WORK`]: several hundredfold the largest shipped
/// computation, OPAC maritime clean at 532 nm with its phase function (1.26·10¹¹ since the
/// size grids are refined panel by panel in ln x and the coefficients counted once; it was
/// 3.9·10¹¹ and 42 s before).
pub const MAX_MIE_WORK: f64 = 4.0e13;

/// Mie work above which the size integration says, before it starts, how long it may take
/// (about a minute on one core).
pub const MIE_WORK_WARN: f64 = 3.0e11;

/// Seconds per term-angle of Mie work on one core of the reference machine (measured on
/// `lidarsim mie` with one thread: 2.0–2.3·10⁻¹⁰ where the size grid reaches its bound, as
/// for the C.1 cloud at 532 and 1064 nm; less where it converges sooner). Times in messages are
/// this machine's, as an order of magnitude.
pub const MIE_SECONDS_PER_WORK: f64 = 2.2e-10;

/// Cost of the Mie coefficients of one radius in units of the matrix products of one angle
/// (measured: about 50 ns a term against 0.25 ns a term and angle).
pub const MIE_COEFFICIENT_ANGLES: u64 = 200;

/// Values of a Mie angle table: phase-function angles × Mie terms at the largest radius (two
/// tables of 8-byte values, 2.4 GB at the limit, are held while a size distribution's matrix is
/// integrated; the largest shipped, maritime clean at 532 nm, has 1.04·10⁶).
pub const MAX_MIE_ANGLE_TABLE_VALUES: u64 = 150_000_000;

/// Monte Carlo work of one run (`pipeline::McWork`: photons × estimated scattering events per
/// photon × channels), over all its shards or ranks: about a year of one core at
/// [`MC_SECONDS_PER_WORK`] (a day of 350), a hundredfold the largest run the README shows (the
/// C.1 cloud with 10¹⁰ photons over 100 Slurm shards, 2.1·10¹¹).
pub const MAX_MC_WORK: f64 = 3.0e13;

/// Monte Carlo work above which a run says, before tracing, how long it may take (about an
/// hour of one core).
pub const MC_WORK_WARN: f64 = 3.6e9;

/// Seconds per channel-event of Monte Carlo work on one core of the reference machine, as an
/// order of magnitude: measured 0.3–2.5·10⁻⁶ on the shipped and validation scenes (2 threads,
/// per core), up to 1.4·10⁻⁵ where a photon scatters little but crosses a thousand gates.
pub const MC_SECONDS_PER_WORK: f64 = 1.0e-6;

/// Line evaluations of a study over many profiles (`pipeline::StudyWork`: profile runs × 8
/// states × channels × molecular layers × gas lines; `lidarsim dial`, `lidarsim bench
/// --study`): about 44 h of one core at [`STUDY_SECONDS_PER_EVALUATION`], a hundredfold the
/// largest study the README shows (`bench --study 1000` at its default threads 1,2 and 3
/// repeats: 18 000 profile runs of `scenes/study_co2_ipda.toml`, 5.6·10¹⁰).
pub const MAX_STUDY_WORK: f64 = 1.0e13;

/// Study work above which a study says, before its first profile, how long it may take (about
/// an hour of one core).
pub const STUDY_WORK_WARN: f64 = 2.25e11;

/// Seconds per line evaluation of a study, all of a profile's work counted (measured: 51 ms a
/// profile of `scenes/study_co2_ipda.toml` on one core, 3.1·10⁶ evaluations; README
/// "Benchmarks").
pub const STUDY_SECONDS_PER_EVALUATION: f64 = 1.6e-8;

/// Points of one figure (plotters draws about 4·10⁶ a second: 25 s at the limit). The figures
/// of `run` and `dial` stay below 10⁷ within the returns and ensemble limits; this one bounds
/// `profiles plot`, whose profile-set file may hold any number of profiles (three panels ×
/// members × levels; an RFMIP-sized set of 1800 profiles × 61 levels draws 3.3·10⁵).
pub const MAX_FIGURE_POINTS: u64 = 100_000_000;

/// Say on standard error that a run allowed by a limit will be long (the warning tier of a
/// limit: README, "Limits").
pub fn warn(message: &str) {
    eprintln!("lidarsim: warning: {message}");
}

/// A duration for messages: "40 s", "12 min", "3.5 h", "40 days".
pub fn fmt_seconds(s: f64) -> String {
    if s < 100.0 {
        format!("{} s", (s.max(0.0) * 10.0).round() / 10.0)
    } else if s < 6000.0 {
        format!("{} min", (s / 60.0).round())
    } else if s < 360_000.0 {
        format!("{} h", (s / 360.0).round() / 10.0)
    } else {
        format!("{} days", (s / 86_400.0).round())
    }
}

/// The product of `factors` if it is at most `limit`, else a message naming the product, its
/// factors and the limit. Saturates instead of overflowing, so any input can be checked.
pub fn check_product(what: &str, factors: &[(&str, u64)], limit: u64) -> Result<u64, String> {
    let product = factors
        .iter()
        .fold(1u64, |acc, (_, f)| acc.saturating_mul(*f));
    if product <= limit {
        return Ok(product);
    }
    let fmt = |v: u64| crate::input::fmt_bound(v as f64);
    let names: Vec<String> = factors
        .iter()
        .map(|(n, f)| format!("{} {n}", fmt(*f)))
        .collect();
    let total = if factors.len() > 1 {
        format!(" = {}", fmt(product))
    } else {
        String::new()
    };
    Err(format!(
        "{what}: {}{total}, more than the limit of {} (README, \"Limits\")",
        names.join(" × "),
        fmt(limit)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_saturate_and_name_their_factors() {
        assert_eq!(check_product("x", &[("a", 3), ("b", 4)], 12), Ok(12));
        let e = check_product("grid", &[("points", u64::MAX), ("layers", 3)], 10).unwrap_err();
        assert!(
            e.contains("points × 3 layers") && e.contains("limit of 10"),
            "{e}"
        );
    }
}
