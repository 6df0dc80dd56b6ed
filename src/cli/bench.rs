//! `lidarsim bench`: speed and Monte Carlo efficiency of the transport on a fixed workload.
//!
//! The workload is the Bissonnette et al. (1995) case C.1 (`scenes/bissonnette_c1.toml`, compiled
//! in) with one 1 mrad field of view. The figure of merit is FOM = 1/(rel_err² · t) of the
//! multiple-scattering return (orders ≥ 2) in the gate starting 100 m into the cloud
//! (1100–1110 m), t the wall-clock time of the transport at the given thread count.

use std::io::Write;
use std::path::{Path, PathBuf};

use lidarsim::optics::OpticalAtmosphere;
use lidarsim::returns::Order;
use lidarsim::scene::Scene;
use lidarsim::stats;
use lidarsim::transport::{self, TransportOptions};

const C1_SCENE: &str = include_str!("../../scenes/bissonnette_c1.toml");
const C1_TABLE_FILE: &str = r#"file = "../phase_functions/bissonnette_c1_1064nm.txt""#;
const C1_TABLE_BUILTIN: &str = r#"builtin = "bissonnette_c1_1064nm""#;

/// Arguments of `lidarsim bench`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Photon packets per run.
    #[arg(long, default_value_t = 1_000_000)]
    pub photons: u64,
    /// Thread counts to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    pub threads: Vec<usize>,
    /// Runs per thread count; the fastest is reported (the least disturbed by other load).
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Probability of detector-directed importance sampling (0: off).
    #[arg(long, default_value_t = lidarsim::transport::DDIS_EPSILON)]
    pub ddis_epsilon: f64,
    /// Probability of drawing the first collision uniformly in range (0: off).
    #[arg(long, default_value_t = lidarsim::transport::RANGE_STRATIFICATION)]
    pub range_stratification: f64,
    /// Write the figures as JSON here as well.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The C.1 scene with a single 1 mrad field of view, orders split into 1 and 2+.
pub fn c1_scene() -> anyhow::Result<Scene> {
    anyhow::ensure!(
        C1_SCENE.contains(C1_TABLE_FILE),
        "the C.1 scene no longer names its table"
    );
    let text = C1_SCENE.replace(C1_TABLE_FILE, C1_TABLE_BUILTIN);
    let mut scene = Scene::from_toml(Path::new("<embedded scenes/bissonnette_c1.toml>"), &text)?;
    scene.lidar.fov_full_angle_mrad = vec![1.0];
    scene.simulation.max_order = 1;
    Ok(scene)
}

/// Run the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut scene = c1_scene()?;
    scene.simulation.photons = args.photons;
    scene.simulation.seed = args.seed;
    let atm = OpticalAtmosphere::build(&scene)?;
    let gate = scene
        .gates
        .count
        .min(((1100.0 - scene.gates.start_m) / scene.gates.width_m).round() as usize);

    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "Bissonnette C.1, 1064 nm, FOV 1 mrad, {} photons; FOM of the multiple-scattering return at {}–{} m",
        args.photons,
        scene.gates.start_m + gate as f64 * scene.gates.width_m,
        scene.gates.start_m + (gate + 1) as f64 * scene.gates.width_m
    )?;
    writeln!(
        out,
        "threads  wall_s   photons/s   events/s  events/s/thread   E_ms [J]      rel_err     FOM [1/s]"
    )?;
    let mut rows = Vec::new();
    for &threads in &args.threads {
        let mut best: Option<transport::McResult> = None;
        for _ in 0..args.repeat.max(1) {
            let mut opts = TransportOptions::from_scene(&scene);
            opts.threads = threads;
            opts.ddis_epsilon = args.ddis_epsilon;
            opts.range_stratification = args.range_stratification;
            let r = transport::run(&scene, &atm, &opts)?;
            if best.as_ref().is_none_or(|b| r.wall_s < b.wall_s) {
                best = Some(r);
            }
        }
        let Some(r) = best else { continue };
        let ms = Order::AtLeast(2);
        let e = r.returns.energy(0, 0, gate, ms).unwrap_or(0.0);
        let se = r.returns.stderr(0, 0, gate, ms).unwrap_or(f64::NAN);
        let rel = stats::rel_err(e, se);
        let fom = stats::figure_of_merit(rel, r.wall_s);
        let pps = r.photons as f64 / r.wall_s;
        let eps = r.stats.collisions as f64 / r.wall_s;
        writeln!(
            out,
            "{:>7} {:>7.2} {:>11.3e} {:>10.3e} {:>16.3e} {:>10.4e} {:>11.3e} {:>11.3e}",
            r.threads,
            r.wall_s,
            pps,
            eps,
            eps / r.threads as f64,
            e,
            rel,
            fom
        )?;
        rows.push(serde_json::json!({
            "threads": r.threads, "wall_s": r.wall_s, "photons": r.photons,
            "photons_per_s": pps, "events_per_s": eps, "events_per_s_per_thread": eps / r.threads as f64,
            "multiple_scattering_j": e, "rel_err": rel, "fom_per_s": fom,
        }));
    }
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&rows)?)?;
    }
    Ok(())
}
