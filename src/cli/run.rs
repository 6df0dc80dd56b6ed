//! `lidarsim run [SCENE] [--out DIR] [--photons N] [--seed S] [--threads T]`

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;

use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::returns::{self, Order, Returns};
use lidarsim::scene::Scene;
use lidarsim::transport::{self, McResult, TransportOptions};

/// Arguments of `lidarsim run`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file (TOML). Without it the embedded default scene runs.
    pub scene: Option<PathBuf>,
    /// Output directory (created if needed); receives returns.csv and summary.json.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Photon packets (overrides the scene's `simulation.photons`); 0 runs only the analytic
    /// single-scatter lidar equation.
    #[arg(long)]
    pub photons: Option<u64>,
    /// Random seed (overrides `simulation.seed`).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads, 0 for all cores (overrides `simulation.threads`).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Probability of detector-directed importance sampling near the line of sight (0 turns
    /// this variance reduction off; results are unbiased either way).
    #[arg(long, default_value_t = lidarsim::transport::DDIS_EPSILON)]
    pub ddis_epsilon: f64,
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut scene = match &args.scene {
        Some(p) => Scene::read(p)?,
        None => Scene::default_scene()?,
    };
    scene
        .override_simulation(args.photons, args.seed, args.threads)
        .map_err(anyhow::Error::msg)?;
    let atm = OpticalAtmosphere::build(&scene)?;
    let analytic = lidar_eq::single_scatter(&scene, &atm);
    let mut opts = TransportOptions::from_scene(&scene);
    opts.progress = true;
    anyhow::ensure!(
        (0.0..1.0).contains(&args.ddis_epsilon),
        "--ddis-epsilon {} must lie in [0, 1)",
        args.ddis_epsilon
    );
    opts.ddis_epsilon = args.ddis_epsilon;
    // Skip what the scene does not need: 0 photons is the analytic equation alone.
    let mc = if opts.photons > 0 {
        Some(transport::run(&scene, &atm, &opts)?)
    } else {
        None
    };

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the output directory {}", args.out.display()))?;
    let csv = args.out.join("returns.csv");
    let sets: Vec<&Returns> = mc.iter().map(|m| &m.returns).chain([&analytic]).collect();
    returns::write_csv(&csv, &sets).with_context(|| format!("cannot write {}", csv.display()))?;
    let summary = args.out.join("summary.json");
    write_summary(&summary, &scene, mc.as_ref())
        .with_context(|| format!("cannot write {}", summary.display()))?;

    let mut out = std::io::stdout().lock();
    print_summary(&mut out, &scene, mc.as_ref(), &analytic)?;
    if let Some(note) = &atm.gas_note {
        writeln!(out, "{note}")?;
    }
    writeln!(out, "wrote {} and {}", csv.display(), summary.display())?;
    Ok(())
}

fn print_summary(
    out: &mut impl Write,
    scene: &Scene,
    mc: Option<&McResult>,
    analytic: &Returns,
) -> std::io::Result<()> {
    let name = if scene.description.is_empty() {
        scene.path.display().to_string()
    } else {
        scene.description.clone()
    };
    writeln!(out, "scene: {name}")?;
    let Some(mc) = mc else {
        writeln!(out, "analytic single scattering only (0 photons)")?;
        for (k, ch) in analytic.channels.iter().enumerate() {
            for (f, fov) in analytic.fov_full_angle_mrad.iter().enumerate() {
                let an: f64 = (0..analytic.range_m.len())
                    .map(|g| analytic.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0))
                    .sum();
                writeln!(out, "  channel {ch}, FOV {fov} mrad: all gates {an:.4e} J")?;
            }
        }
        return Ok(());
    };
    writeln!(
        out,
        "transport: {} photons, {} scattering events in {:.2} s on {} threads ({:.2} M events/s)",
        mc.photons,
        mc.stats.collisions,
        mc.wall_s,
        mc.threads,
        mc.stats.collisions as f64 / mc.wall_s.max(1e-9) * 1e-6
    )?;
    let r = &mc.returns;
    for (k, ch) in r.channels.iter().enumerate() {
        for (f, fov) in r.fov_full_angle_mrad.iter().enumerate() {
            let (mut total, mut single, mut single_var, mut an) = (0.0, 0.0, 0.0, 0.0);
            for g in 0..r.range_m.len() {
                total += r.energy(k, f, g, Order::Total).unwrap_or(0.0);
                single += r.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0);
                // Gates are not independent; this sum of variances is only a rough guide.
                single_var += r.stderr(k, f, g, Order::Exactly(1)).unwrap_or(0.0).powi(2);
                an += analytic.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0);
            }
            let share = if total > 0.0 {
                100.0 * single / total
            } else {
                0.0
            };
            writeln!(
                out,
                "  channel {ch}, FOV {fov} mrad: all gates {total:.4e} J, single scattering {share:.1} % \
                 (MC {single:.4e} ± {:.1e} J, analytic {an:.4e} J)",
                single_var.sqrt()
            )?;
        }
    }
    Ok(())
}

fn write_summary(
    path: &std::path::Path,
    scene: &Scene,
    mc: Option<&McResult>,
) -> std::io::Result<()> {
    let Some(mc) = mc else {
        let json = serde_json::json!({
            "scene": scene.path.display().to_string(),
            "description": scene.description,
            "photons": 0,
        });
        return write_json(path, &json);
    };
    let s = &mc.stats;
    let json = serde_json::json!({
        "scene": scene.path.display().to_string(),
        "description": scene.description,
        "photons": mc.photons,
        "batches": scene.simulation.batches,
        "seed": scene.simulation.seed,
        "threads": mc.threads,
        "wall_s": mc.wall_s,
        "counters": {
            "collisions": s.collisions,
            "surface_reflections": s.surface_reflections,
            "local_estimates": s.local_estimates,
            "roulette_kills": s.roulette_kills,
            "cut": s.cut,
            "escaped": s.escaped,
            "zero_weight": s.zero_weight,
        },
    });
    write_json(path, &json)
}

/// Write JSON through a temporary file and a rename.
fn write_json(path: &std::path::Path, json: &serde_json::Value) -> std::io::Result<()> {
    let tmp = path.with_extension("json.tmp");
    std::fs::write(
        &tmp,
        serde_json::to_string_pretty(&json).unwrap_or_default(),
    )?;
    std::fs::rename(&tmp, path)
}
