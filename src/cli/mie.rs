//! `lidarsim mie`: Mie scattering of one sphere, or bulk optics of a size distribution written as
//! a phase-function table (see `docs/particles.md`).

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::ValueEnum;
use lidarsim::input::{Bounds, check_finite_range};
use lidarsim::particles::distribution::{
    BulkOptions, Component, MIN_INDEX_CONTRAST, MieProgress, MieWork, SizeDistribution,
    bulk_optics_mixture_with_progress, format_refractive_index,
};
use lidarsim::particles::mie::{
    MAX_SIZE_PARAMETER, MieCoefficients, MieError, parse_refractive_index,
};
use lidarsim::products::{self, ProductError, mie::Opac};
use num_complex::Complex64;
use serde_json::json;

/// Kind of size distribution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Distribution {
    /// Log-normal: --number-density-per-cm3, --median-radius-um, --sigma-g (or --mode, repeated).
    Lognormal,
    /// Modified gamma n(r) = a r^alpha exp(-b r^gamma): --a, --alpha, --b, --gamma.
    ModifiedGamma,
    /// Deirmendjian's C.1 cloud (modified gamma a=2.373, alpha=6, b=1.5, gamma=1).
    C1,
    /// OPAC aerosol (Hess et al. 1998), dry: --aerosol-type TYPE (a mixture) or --opac-component
    /// NAME (one component, --number-density-per-cm3); refractive indices from OPAC's table.
    Opac,
}

/// Arguments of `lidarsim mie`.
///
/// One sphere: `lidarsim mie --refractive-index 1.33+0.0i --size-parameter 10` prints JSON with
/// qext, qsca, qback, g and ssa (add --angles-deg 0,90,180 for the amplitudes S1, S2).
///
/// A size distribution: `lidarsim mie --distribution c1 --refractive-index 1.3205+1.28e-6i
/// --wavelength-nm 1064 --out table.txt` writes a phase-function table and prints the bulk
/// properties (per-particle cross-sections, single-scattering albedo, g, lidar ratio) as JSON;
/// `--matrix-out matrix.txt` writes the scattering-matrix table on the same angles.
///
/// An OPAC aerosol type (dry components, refractive indices built in): `lidarsim mie
/// --distribution opac --aerosol-type continental-average --wavelength-nm 532 --out table.txt`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Complex refractive index relative to the medium, n+ki: 1.33, 1.33+0.0i, 1.5+1e-3i. A
    /// POSITIVE imaginary part means ABSORPTION (MIEV0 and miepython write the same as n-ki).
    /// Not used with --distribution opac (OPAC's own indices are built in).
    /// No `allow_hyphen_values`: with it the next option was taken for the value
    /// (`--refractive-index --wavelength-nm 1064`, the value forgotten: "unexpected argument
    /// '1064'"); no index starts with `-` (its real part is > 0) and `-1.5` still reaches the
    /// parser, which names the bound.
    #[arg(long, allow_negative_numbers = true, value_parser = refractive_index)]
    refractive_index: Option<Complex64>,
    /// Size parameter x = 2 pi r / lambda of a single sphere.
    #[arg(long, conflicts_with = "distribution", allow_negative_numbers = true, value_parser = super::real(Bounds::positive(MAX_SIZE_PARAMETER)))]
    size_parameter: Option<f64>,
    /// Scattering angles \[deg\] at which to print S1, S2 for a single sphere (comma-separated).
    #[arg(long, value_delimiter = ',', requires = "size_parameter", allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 180.0)))]
    angles_deg: Vec<f64>,
    /// Size distribution (instead of --size-parameter).
    #[arg(long, value_enum)]
    distribution: Option<Distribution>,
    /// Wavelength in the medium \[nm\] (distributions), in (10, 1e6): the size integration's
    /// range (10 nm to 1 mm), checked here so that a refusal names this option.
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::open(10.0, 1e6)))]
    wavelength_nm: Option<f64>,
    /// Log-normal (or single OPAC component) total number density [cm^-3].
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e10)))]
    number_density_per_cm3: f64,
    /// OPAC aerosol type (dry components): continental-clean, continental-average,
    /// continental-polluted, urban, maritime-clean, maritime-polluted, maritime-tropical, arctic.
    #[arg(long, conflicts_with = "opac_component")]
    aerosol_type: Option<String>,
    /// One OPAC component (dry): inso, waso, soot, ssam, sscm.
    #[arg(long)]
    opac_component: Option<String>,
    /// Log-normal median (number mode) radius [um], in [1e-4, 1e4] ([`MEDIAN_RADIUS_UM`]).
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(MEDIAN_RADIUS_UM))]
    median_radius_um: Option<f64>,
    /// Log-normal geometric standard deviation (> 1).
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::above(1.0, 10.0)))]
    sigma_g: Option<f64>,
    /// A log-normal mode N_per_cm3,r_g_um,sigma_g; repeat for a multimodal distribution.
    #[arg(long = "mode", value_name = "N,R_G,SIGMA_G")]
    modes: Vec<String>,
    /// Modified gamma: a [cm^-3 um^-(alpha+1)].
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e30)))]
    a: Option<f64>,
    /// Modified gamma: alpha.
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::above(-1.0, 100.0)))]
    alpha: Option<f64>,
    /// Modified gamma: b [um^-gamma].
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e4)))]
    b: Option<f64>,
    /// Modified gamma: gamma.
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::above(0.0, 10.0)))]
    gamma: Option<f64>,
    /// Truncate every mode below this radius [um].
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::closed(0.0, 1e4)))]
    r_min_um: Option<f64>,
    /// Truncate every mode above this radius [um].
    #[arg(long, allow_negative_numbers = true, value_parser = super::real(Bounds::positive(1e4)))]
    r_max_um: Option<f64>,
    /// Fraction of the geometric cross-section left outside the integrated radius range.
    #[arg(long, default_value_t = 1e-5, allow_negative_numbers = true, value_parser = super::real(Bounds::open(0.0, 0.1)))]
    tail_fraction: f64,
    /// Relative convergence tolerance of the size integration (two successive halvings).
    #[arg(long, default_value_t = 1e-3, allow_negative_numbers = true, value_parser = super::real(Bounds::open(0.0, 0.5)))]
    rel_tol: f64,
    /// Write the phase-function table here (distributions).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the scattering-matrix table (F11, F22, F33, F44, F12, F34 on the same angles; the
    /// format of `phase = { kind = "matrix_table" }`) here (distributions).
    #[arg(long, value_name = "PATH")]
    matrix_out: Option<PathBuf>,
    /// Extra metadata line KEY=VALUE for the table (repeatable), e.g. the refractive index's source.
    #[arg(long = "meta", value_name = "KEY=VALUE")]
    meta: Vec<String>,
}

/// Range of a log-normal median radius \[µm\]: 0.1 nm (a molecule) to 1 cm. The integration
/// range is sought within 1e-7 … 1e7 µm; a median far below it (1e-301 µm) was refused as
/// "r_max_um = 1e-7: the truncation range holds none of the distribution".
const MEDIAN_RADIUS_UM: Bounds = Bounds::closed(1e-4, 1e4);

/// `--refractive-index`'s value parser: [`parse_refractive_index`], with a hint when the value
/// looks like the next option (the value was forgotten).
fn refractive_index(text: &str) -> Result<Complex64, String> {
    if text.starts_with("--") {
        return Err(format!(
            "`{text}` is not a refractive index (its value missing?): write n or n+ki, e.g. 1.33, 1.5+1e-3i"
        ));
    }
    parse_refractive_index(text)
}

fn need(v: Option<f64>, flag: &str) -> anyhow::Result<f64> {
    v.with_context(|| format!("{flag} is required for this distribution"))
}

fn parse_mode(text: &str) -> anyhow::Result<SizeDistribution> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != 3 {
        bail!("--mode `{text}`: expected N_per_cm3,r_g_um,sigma_g");
    }
    // The same ranges as --number-density-per-cm3, --median-radius-um and --sigma-g.
    let bounds = [
        ("N_per_cm3", Bounds::positive(1e10)),
        ("r_g_um", MEDIAN_RADIUS_UM),
        ("sigma_g", Bounds::above(1.0, 10.0)),
    ];
    let v: Vec<f64> = parts
        .iter()
        .zip(bounds)
        .map(|(p, (name, b))| {
            let v = p
                .trim()
                .parse::<f64>()
                .with_context(|| format!("--mode `{text}`: `{p}` is not a number"))?;
            check_finite_range(v, b).map_err(|m| anyhow::anyhow!("--mode `{text}`: {name} {m}"))
        })
        .collect::<Result<_, _>>()?;
    SizeDistribution::lognormal(v[0], v[1], v[2]).with_context(|| format!("--mode `{text}`"))
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.distribution == Some(Distribution::Opac) {
        return run_opac(&args);
    }
    if args.aerosol_type.is_some() || args.opac_component.is_some() {
        bail!("--aerosol-type and --opac-component need --distribution opac");
    }
    let Some(m) = args.refractive_index else {
        bail!("--refractive-index is required (except with --distribution opac)");
    };
    if let Some(x) = args.size_parameter {
        let k = MieCoefficients::compute(m, x).context("--size-parameter")?;
        let out = products::mie::sphere_json(&k, m, x, &args.angles_deg)?;
        outln!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let Some(kind) = args.distribution else {
        bail!("give either --size-parameter (one sphere) or --distribution (a size distribution)");
    };
    let wavelength_nm = need(args.wavelength_nm, "--wavelength-nm")?;
    if (m - 1.0).norm() < MIN_INDEX_CONTRAST {
        bail!(
            "--refractive-index {}: |m − 1| = {:e} must be ≥ {MIN_INDEX_CONTRAST:e} for a size \
             distribution (particles with the medium's index scatter nothing: no phase function or \
             lidar ratio follows)",
            format_refractive_index(m),
            (m - 1.0).norm()
        );
    }
    let mut dist = match kind {
        Distribution::Opac => unreachable!("handled by run_opac"),
        Distribution::C1 => SizeDistribution::deirmendjian_c1(),
        Distribution::ModifiedGamma => SizeDistribution::modified_gamma(
            need(args.a, "--a")?,
            need(args.alpha, "--alpha")?,
            need(args.b, "--b")?,
            need(args.gamma, "--gamma")?,
        )?,
        Distribution::Lognormal => {
            if args.modes.is_empty() {
                SizeDistribution::lognormal(
                    args.number_density_per_cm3,
                    need(args.median_radius_um, "--median-radius-um")?,
                    need(args.sigma_g, "--sigma-g")?,
                )?
            } else {
                if args.median_radius_um.is_some() || args.sigma_g.is_some() {
                    bail!(
                        "give either --mode (repeated) or --median-radius-um/--sigma-g, not both"
                    );
                }
                SizeDistribution::sum(
                    args.modes
                        .iter()
                        .map(|s| parse_mode(s))
                        .collect::<Result<_, _>>()?,
                )?
            }
        }
    };
    if args.r_min_um.is_some() || args.r_max_um.is_some() {
        let (lo, hi) = (
            args.r_min_um.unwrap_or(0.0),
            args.r_max_um.unwrap_or(f64::INFINITY),
        );
        if hi <= lo {
            bail!("--r-max-um {hi} must exceed --r-min-um {lo}");
        }
        dist = dist.truncated(lo, hi)?;
    }
    let opts = bulk_opts(&args);
    let components = [Component {
        name: "particles".into(),
        distribution: dist.clone(),
        refractive_index: m,
    }];
    let work = products::mie::check_work(&components, wavelength_nm * 1e-9, &opts)
    .map_err(|e| match &e {
        // The library names its own field; say which options made the range empty.
        ProductError::Mie(MieError::Parameter {
            name: "r_max_um",
            reason,
            ..
        }) if args.r_min_um.is_some() || args.r_max_um.is_some() => anyhow::anyhow!(
            "--r-min-um {} --r-max-um {}: {reason} (it is integrated where all but --tail-fraction {} of its cross-section lies)",
            args.r_min_um.unwrap_or(0.0),
            args.r_max_um.map_or("(none)".to_string(), |v| v.to_string()),
            args.tail_fraction
        ),
        _ => e.into(),
    })?;
    let mut b = bulk_optics_mixture_with_progress(
        &components,
        wavelength_nm * 1e-9,
        &opts,
        &progress_lines(),
    )?;
    products::mie::add_meta(&mut b, &args.meta)?;
    finish(
        &b,
        &args,
        wavelength_nm,
        json!(format_refractive_index(m)),
        dist.to_string(),
        &work,
    )
}

fn bulk_opts(args: &Args) -> BulkOptions {
    BulkOptions {
        tail_fraction: args.tail_fraction,
        rel_tol: args.rel_tol,
        angles_deg: if args.out.is_some() || args.matrix_out.is_some() {
            None
        } else {
            Some(Vec::new())
        },
        ..BulkOptions::default()
    }
}

/// `--distribution opac`: an OPAC type or one component, with OPAC's refractive indices.
fn run_opac(args: &Args) -> anyhow::Result<()> {
    if args.refractive_index.is_some() {
        bail!(
            "--distribution opac uses OPAC's own refractive indices: drop --refractive-index \
             (or describe the particles with --distribution lognormal)"
        );
    }
    if args.size_parameter.is_some() {
        bail!("--size-parameter and --distribution are exclusive");
    }
    let wavelength_nm = need(args.wavelength_nm, "--wavelength-nm")?;
    let which = match (&args.aerosol_type, &args.opac_component) {
        (Some(t), None) => Opac::Type(t),
        (None, Some(c)) => Opac::Component(c, args.number_density_per_cm3),
        _ => bail!("--distribution opac needs --aerosol-type TYPE or --opac-component NAME"),
    };
    let mut o = products::mie::opac_with_progress(
        which,
        wavelength_nm * 1e-9,
        &bulk_opts(args),
        &progress_lines(),
    )?;
    products::mie::add_meta(&mut o.bulk, &args.meta)?;
    let (indices, description) = (o.indices, o.description);
    finish(&o.bulk, args, wavelength_nm, indices, description, &o.work)
}

/// Progress of the size integration on stderr: a line every 2 s once it has taken 2 s; none
/// with `--quiet`.
fn progress_lines() -> Box<dyn Fn(&MieProgress)> {
    if crate::cli::progress::quiet() {
        Box::new(|_: &MieProgress| {})
    } else {
        Box::new(lidarsim::particles::distribution::progress_lines(
            "lidarsim mie".into(),
        ))
    }
}

/// Write the table (if --out) and print the bulk properties as JSON.
fn finish(
    b: &lidarsim::particles::distribution::BulkOptics,
    args: &Args,
    wavelength_nm: f64,
    refractive_index: serde_json::Value,
    distribution: String,
    work: &MieWork,
) -> anyhow::Result<()> {
    if let Some(path) = &args.out {
        b.phase.write(path)?;
    }
    if let Some(path) = &args.matrix_out {
        b.matrix.write(path)?;
    }
    let out = products::mie::bulk_json(
        b,
        wavelength_nm,
        refractive_index,
        distribution,
        work,
        (args.out.as_deref(), args.matrix_out.as_deref()),
    );
    outln!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
