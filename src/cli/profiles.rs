//! `lidarsim profiles`: generate perturbed profile ensembles, plot and inspect profile sets,
//! convert the ECMWF/RFMIP files to the lidarsim profile-set format (docs/atmosphere.md).

use std::path::{Path, PathBuf};

use anyhow::bail;
use lidarsim::atmosphere::native::{read_ecmwf52, read_ecmwf83, read_rfmip};
use lidarsim::atmosphere::{
    Co2Scaling, LatitudeClass, ProfileSet, StandardAtmosphere, read_profile_set,
};

use lidarsim::input::Bounds;
use lidarsim::limits::MAX_ENSEMBLE_LEVELS;

use super::{count_usize, real};
use lidarsim::output::{self, OutputSet};
use lidarsim::products::{self, profiles::GenerateRequest};

/// Arguments of `lidarsim profiles`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Generate a perturbed ensemble x = x̄ + L z around a mean profile and write a profile set.
    Generate(Box<GenerateArgs>),
    /// Plot temperature, humidity and CO2 against pressure, one column of panels per latitude class.
    Plot(PlotArgs),
    /// Convert ECMWF 83 / ECMWF 52 / RFMIP files as distributed to the lidarsim profile-set format.
    Convert(ConvertArgs),
    /// Print location, class, surface pressure and columns of each profile of a set or atmosphere.
    Info(InfoArgs),
}

/// `lidarsim profiles generate`.
#[derive(clap::Args, Debug)]
struct GenerateArgs {
    /// Number of members.
    #[arg(long, allow_negative_numbers = true, value_parser = count_usize(1, MAX_ENSEMBLE_LEVELS))]
    n: usize,
    /// Seed of the random generator (same seed, same file).
    #[arg(long)]
    seed: u64,
    /// Output profile set (CSV).
    #[arg(long)]
    out: PathBuf,
    /// Latitude class: with --set, the mean of that class of the set; alone, the mean of the AFGL
    /// atmospheres of the class (tropical; mid-latitude summer+winter; sub-arctic summer+winter).
    #[arg(long)]
    class: Option<LatitudeClass>,
    /// Mean profile: a built-in AFGL atmosphere (tropical, midlatitude_summer, ..., us_standard).
    #[arg(long, conflicts_with_all = ["set", "mean_profile"])]
    atmosphere: Option<StandardAtmosphere>,
    /// Mean profile: the mean of this profile set (of --class if given).
    #[arg(long, conflicts_with = "mean_profile")]
    set: Option<PathBuf>,
    /// Mean profile: a profile of this profile-set file (the only one, or --profile-id).
    #[arg(long)]
    mean_profile: Option<PathBuf>,
    /// Which profile of --mean-profile.
    #[arg(long, requires = "mean_profile")]
    profile_id: Option<String>,
    /// CO2 of the mean [ppm]: by default well mixed, this dry-air mole fraction at every level
    /// (see --co2-scaling).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::positive(1e6)))]
    co2_ppm: Option<f64>,
    /// How --co2-ppm is applied: `well_mixed` (the dry-air mole fraction at every level, the
    /// profile's CO2 replaced or added) or `profile_shape` (the profile's own CO2 rescaled by
    /// one factor to that dry-air column average).
    #[arg(long, default_value = "well_mixed", requires = "co2_ppm")]
    co2_scaling: Co2Scaling,
    /// Covariance (a): a covariance file (docs/atmosphere.md), projected to the mean's levels.
    #[arg(long, conflicts_with_all = ["error_model", "pairs"])]
    covariance: Option<PathBuf>,
    /// Covariance (b): a per-level error table (p_hPa, T_std_K, lnq_std[, CO2_std_ppmv]);
    /// default: the embedded representative NWP forecast error (data/nwp_error).
    #[arg(long, conflicts_with = "pairs")]
    error_model: Option<PathBuf>,
    /// Covariance (c): forecast and analysis profile sets (pairs matched by profile id).
    #[arg(long, num_args = 2, value_names = ["FORECAST", "ANALYSIS"])]
    pairs: Option<Vec<PathBuf>>,
    /// Gaussian localization length (ln p) for the covariance from --pairs.
    #[arg(long, requires = "pairs", allow_negative_numbers = true, value_parser = real(Bounds::positive(100.0)))]
    localization_lnp: Option<f64>,
    /// Error model: temperature correlation length (ln p) [default 0.35].
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::positive(100.0)))]
    t_corr_length: Option<f64>,
    /// Error model: ln humidity correlation length (ln p) [default 0.25].
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::positive(100.0)))]
    q_corr_length: Option<f64>,
    /// Error model: surface pressure standard deviation [hPa] [default 0.7].
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(0.0, 100.0)))]
    ps_std_hpa: Option<f64>,
    /// Error model: CO2 standard deviation [ppm] at all levels [default 0: not perturbed].
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::closed(0.0, 1e3)))]
    co2_std_ppm: Option<f64>,
    /// Error model: CO2 correlation length (ln p) [default 0.35].
    #[arg(long, default_value_t = 0.35, allow_negative_numbers = true, value_parser = real(Bounds::positive(100.0)))]
    co2_corr_length: f64,
    /// Error model: do not apply the class scaling of data/nwp_error (T ×0.8/1/1.2, lnq ×1/1/1.2).
    #[arg(long)]
    no_class_scaling: bool,
    /// Repair a covariance that is not positive semi-definite beyond rounding (nearest PSD matrix).
    #[arg(long)]
    repair_covariance: bool,
    /// Cap water vapour at this relative humidity [%].
    #[arg(long, default_value_t = 100.0, allow_negative_numbers = true, value_parser = real(Bounds::positive(200.0)))]
    max_rh_percent: f64,
    /// Relative humidity over `water` (all temperatures) or `ice` (below 273.16 K).
    #[arg(long, default_value = "water", value_parser = ["water", "ice"])]
    rh_over: String,
    /// Also write the covariance used (on the mean's levels) to this file.
    #[arg(long)]
    covariance_out: Option<PathBuf>,
}

/// `lidarsim profiles plot`.
#[derive(clap::Args, Debug)]
struct PlotArgs {
    /// Profile set (lidarsim format).
    set: PathBuf,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Lowest pressure shown [hPa].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = real(Bounds::positive(1100.0)))]
    top_hpa: f64,
}

/// `lidarsim profiles convert`.
#[derive(clap::Args, Debug)]
struct ConvertArgs {
    /// Source format.
    #[arg(long, value_parser = ["ecmwf83", "ecmwf52", "rfmip"])]
    format: String,
    /// The level (or layer) file.
    #[arg(long)]
    levels: PathBuf,
    /// The meta file.
    #[arg(long)]
    meta: PathBuf,
    /// Output profile set.
    #[arg(long)]
    out: PathBuf,
    /// Give every profile this CO2 [ppm] (ECMWF 52 has none): by default well mixed, this
    /// dry-air mole fraction at every level (see --co2-scaling).
    #[arg(long, allow_negative_numbers = true, value_parser = real(Bounds::positive(1e6)))]
    co2_ppm: Option<f64>,
    /// How --co2-ppm is applied: `well_mixed` (the dry-air mole fraction at every level, the
    /// profile's CO2 replaced or added) or `profile_shape` (the profile's own CO2 rescaled by
    /// one factor to that dry-air column average).
    #[arg(long, default_value = "well_mixed", requires = "co2_ppm")]
    co2_scaling: Co2Scaling,
}

/// `lidarsim profiles info`.
#[derive(clap::Args, Debug)]
struct InfoArgs {
    /// Profile set (lidarsim format).
    #[arg(required_unless_present = "atmosphere")]
    set: Option<PathBuf>,
    /// A built-in AFGL atmosphere instead of a set.
    #[arg(long, conflicts_with = "set")]
    atmosphere: Option<StandardAtmosphere>,
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Generate(a) => generate(*a),
        Command::Plot(a) => plot(a),
        Command::Convert(a) => convert(a),
        Command::Info(a) => info(a),
    }
}

fn read_set(path: &Path) -> anyhow::Result<ProfileSet> {
    Ok(read_profile_set(path)?)
}

fn generate(a: GenerateArgs) -> anyhow::Result<()> {
    let outputs: Vec<&PathBuf> = [Some(&a.out), a.covariance_out.as_ref()]
        .into_iter()
        .flatten()
        .collect();
    output::check_paths(&outputs)?;
    let request = GenerateRequest {
        n: a.n,
        seed: a.seed,
        class: a.class,
        atmosphere: a.atmosphere,
        set: a.set.clone(),
        mean_profile: a.mean_profile.clone(),
        profile_id: a.profile_id.clone(),
        co2_ppm: a.co2_ppm,
        co2_scaling: a.co2_scaling,
        covariance: a.covariance.clone(),
        error_model: a.error_model.clone(),
        pairs: a.pairs.clone(),
        localization_lnp: a.localization_lnp,
        t_corr_length: a.t_corr_length,
        q_corr_length: a.q_corr_length,
        ps_std_hpa: a.ps_std_hpa,
        co2_std_ppm: a.co2_std_ppm,
        co2_corr_length: a.co2_corr_length,
        no_class_scaling: a.no_class_scaling,
        repair_covariance: a.repair_covariance,
        max_rh_percent: a.max_rh_percent,
        rh_over: a.rh_over.clone(),
    };
    let (set, cov) = products::profiles::generate(&request, &mut |line| {
        use std::io::Write as _;
        Ok(writeln!(std::io::stdout().lock(), "{line}")?)
    })?;
    let mut files = OutputSet::new();
    files.write(&a.out, set.to_csv()?)?;
    if let Some(path) = &a.covariance_out {
        files.write(path, cov.to_csv())?;
    }
    files.commit()?;
    outln!("wrote {} profiles to {}", set.len(), a.out.display());
    Ok(())
}

fn convert(a: ConvertArgs) -> anyhow::Result<()> {
    let mut set = match a.format.as_str() {
        "ecmwf83" => read_ecmwf83(&a.levels, &a.meta)?,
        "ecmwf52" => read_ecmwf52(&a.levels, &a.meta)?,
        _ => read_rfmip(&a.levels, &a.meta)?,
    };
    if let Some(ppm) = a.co2_ppm {
        products::profiles::set_co2(&mut set, ppm, a.co2_scaling)?;
    }
    set.write(&a.out)?;
    let [t, m, h] = set.class_counts();
    outln!(
        "wrote {} profiles ({t} tropical, {m} mid, {h} high) to {}",
        set.len(),
        a.out.display()
    );
    Ok(())
}

fn info(a: InfoArgs) -> anyhow::Result<()> {
    let set = match (&a.set, a.atmosphere) {
        (_, Some(atm)) => ProfileSet {
            name: atm.name().into(),
            members: vec![atm.member()],
            notes: vec![],
        },
        (Some(p), None) => read_set(p)?,
        (None, None) => bail!("give a profile set or --atmosphere"),
    };
    outln!(
        "{}",
        lidarsim::products::profiles::info_csv(&set).trim_end()
    );
    let [t, mi, h] = set.class_counts();
    eprintln!("{} profiles: {t} tropical, {mi} mid, {h} high", set.len());
    Ok(())
}

fn plot(a: PlotArgs) -> anyhow::Result<()> {
    let set = read_set(&a.set)?;
    // Three panels (T, H2O, CO2) of every member's levels (README, "Limits").
    lidarsim::limits::check_product(
        &format!("profiles plot {}", a.set.display()),
        &[
            ("panels", 3),
            (
                "level values",
                set.members.iter().map(|m| m.profile.len() as u64).sum(),
            ),
        ],
        lidarsim::limits::MAX_FIGURE_POINTS,
    )
    .map_err(anyhow::Error::msg)?;
    if a.out.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("--out must end in .png");
    }
    let draw = |tmp: &Path| crate::figures::profiles::draw(tmp, &set, &a.set, a.top_hpa);
    let mut files = OutputSet::new();
    files.write_via(&a.out, draw)?;
    files.commit()?;
    outln!("wrote {}", a.out.display());
    Ok(())
}
