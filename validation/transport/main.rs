//! Transport validation at full photon counts (README.md beside this file):
//! 1. every scene in scenes/: Monte Carlo order 1 against the analytic lidar equation, gate by
//!    gate (z-scores, relative deviations);
//! 2. Bissonnette et al. (1995) case C.1: total/single-scattering ratio by FOV and depth into
//!    the cloud, and the figure of merit of the multiple-scattering return.
//!
//! `cargo run --release --example transport_validation [-- PHOTONS]`

use lidarsim::lidar_eq;
use lidarsim::optics::OpticalAtmosphere;
use lidarsim::returns::Order;
use lidarsim::scene::Scene;
use lidarsim::transport::{self, TallyLayout};

fn main() -> anyhow::Result<()> {
    let photons: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(10_000_000);
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut paths: Vec<_> = std::fs::read_dir(root.join("scenes"))?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()?;
    paths.retain(|p| p.extension().is_some_and(|e| e == "toml"));
    paths.sort();

    println!("## Monte Carlo order 1 against the lidar equation ({photons} photons per scene)\n");
    println!(
        "| scene | wall [s] | atmospheric gates judged (rel. error < 10 %) | rms z | max abs z | max rel. deviation | mean MC/analytic | hard-target gate: MC/analytic − 1 |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for path in &paths {
        let mut scene = Scene::read(path)?;
        scene.simulation.photons = photons;
        let atm = OpticalAtmosphere::build(&scene)?;
        let an = lidar_eq::single_scatter(&scene, &atm);
        let mc = transport::run(&scene, &atm, &TallyLayout::default())?;
        // The gate holding the surface along the axis: there the analytic hard-target equation
        // is itself a far-field approximation (1e-8 for these beams) while the MC is nearly
        // noise-free, so it is reported as a relative deviation, not a z-score.
        let mu = scene.lidar.axis().z;
        let surface_gate = scene.surface.as_ref().filter(|_| mu < 0.0).map(|s| {
            ((scene.lidar.altitude_m - s.altitude_m) / -mu - scene.gates.start_m)
                / scene.gates.width_m
        });
        let surface_gate = surface_gate.filter(|x| *x >= 0.0).map(|x| x as usize);
        let (mut n, mut z2, mut zmax, mut dmax, mut ratio_sum) = (0usize, 0.0, 0.0f64, 0.0f64, 0.0);
        let mut surface_dev = 0.0f64;
        for k in 0..an.channels.len() {
            for f in 0..an.fov_full_angle_mrad.len() {
                for g in 0..an.range_m.len() {
                    let a = an.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0);
                    let m = mc.returns.energy(k, f, g, Order::Exactly(1)).unwrap_or(0.0);
                    let s = mc
                        .returns
                        .stderr(k, f, g, Order::Exactly(1))
                        .unwrap_or(f64::NAN);
                    if Some(g) == surface_gate {
                        surface_dev = surface_dev.max((m / a - 1.0).abs());
                        continue;
                    }
                    if a > 0.0 && s < 0.1 * m {
                        let z = (m - a) / s;
                        n += 1;
                        z2 += z * z;
                        zmax = zmax.max(z.abs());
                        dmax = dmax.max((m / a - 1.0).abs());
                        ratio_sum += m / a;
                    }
                }
            }
        }
        println!(
            "| {} | {:.1} | {n} | {:.3} | {:.2} | {:.2e} | {:.5} | {} |",
            path.file_name().unwrap().to_string_lossy(),
            mc.wall_s,
            (z2 / n.max(1) as f64).sqrt(),
            zmax,
            dmax,
            ratio_sum / n.max(1) as f64,
            surface_gate.map_or("–".to_string(), |_| format!("{surface_dev:.1e}"))
        );
    }

    let c1 = root.join("scenes/bissonnette_c1.toml");
    let mut scene = Scene::read(&c1)?;
    scene.simulation.photons = photons;
    let atm = OpticalAtmosphere::build(&scene)?;
    let an = lidar_eq::single_scatter(&scene, &atm);
    let mc = transport::run(&scene, &atm, &TallyLayout::default())?;
    println!(
        "\n## Bissonnette C.1: total / single scattering (analytic single scattering), {photons} photons, {:.1} s\n",
        mc.wall_s
    );
    print!("| depth into cloud [m] |");
    for f in &scene.lidar.fov_full_angle_mrad {
        print!(" {f} mrad |");
    }
    println!();
    println!(
        "|---|{}",
        "---|".repeat(scene.lidar.fov_full_angle_mrad.len())
    );
    for depth in [5.0, 45.0, 95.0, 145.0, 195.0, 245.0, 295.0] {
        let g = ((1000.0 + depth - scene.gates.start_m) / scene.gates.width_m) as usize;
        print!("| {}–{} |", depth - 5.0, depth + 5.0);
        for f in 0..scene.lidar.fov_full_angle_mrad.len() {
            let t = mc.returns.energy(0, f, g, Order::Total).unwrap_or(0.0);
            let s = mc.returns.stderr(0, f, g, Order::Total).unwrap_or(0.0);
            let a = an.energy(0, f, g, Order::Exactly(1)).unwrap_or(0.0);
            print!(" {:.3} ± {:.3} |", t / a, s / a);
        }
        println!();
    }
    Ok(())
}
