//! What a scene does not need (docs/design.md §1): whether the Monte Carlo runs at all. What skipping
//! saves is measured by [`crate::pipeline::compare_skip`].
//!
//! Consumes a [`Scene`], its [`OpticalAtmosphere`] and the photons asked for; produces a
//! [`Decision`] that the pipeline ([`crate::pipeline::prepare`]) follows and that the run summary prints. The analytic lidar
//! equation always runs (it costs microseconds to milliseconds); the Monte Carlo adds multiple
//! scattering, and is skipped where that cannot matter:
//!
//! | `[simulation] multiple_scattering` | Monte Carlo |
//! |---|---|
//! | `"auto"` (default) | runs, unless no particle layer scatters **and** the bound of [`lidar_eq::multiple_scattering_bound`] on all orders ≥ 2 is at most `multiple_scattering_tolerance` (default 1e-3) in every field of view, gate and channel |
//! | `"always"` | runs (`photons` > 0); `--photons N > 0` on the command line means this |
//! | `"never"` | never |
//!
//! `photons = 0` (or `--photons 0`) skips it whatever the mode, as before. Skipped runs write
//! the analytic rows alone, exactly as `--photons 0` does.
//!
//! The other skips live where the work is: no `[gas_absorption]` means no line-by-line call at
//! all (`optics`), a gas whose column is zero in a layer is not computed there
//! (`spectroscopy::xsec`), and photons that can no longer reach a gate are ended in the photon
//! loop (`transport`, `docs/transport.md` steps 2–3).

use crate::lidar_eq::{self, MultipleScatteringBound};
use crate::optics::OpticalAtmosphere;
use crate::scene::{MultipleScattering, Scene};

/// Whether the Monte Carlo runs, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    /// True if photons are traced.
    pub run: bool,
    /// The mode it was decided under.
    pub mode: MultipleScattering,
    /// One sentence for the run summary: what was skipped or run, and why.
    pub reason: String,
    /// The bound on the multiple-scattering share (all orders ≥ 2) where it was computed
    /// (`auto` without scattering particle layers), and the field of view \[mrad\] where it is
    /// largest.
    pub bound: Option<(f64, f64)>,
}

/// The particle layers that scatter in some channel (by name, or `[[layer]] n` without one).
pub fn scattering_layers(scene: &Scene) -> Vec<String> {
    scene
        .layers
        .iter()
        .enumerate()
        .filter(|(_, l)| {
            l.extinction_per_m
                .iter()
                .zip(&l.single_scattering_albedo)
                .any(|(e, w)| e * w > 0.0)
        })
        .map(|(i, l)| {
            if l.name.is_empty() {
                format!("[[layer]] {}", i + 1)
            } else {
                format!("`{}`", l.name)
            }
        })
        .collect()
}

/// Decide whether the Monte Carlo runs for `scene` with `photons` photons (the module docs).
pub fn decide(scene: &Scene, atm: &OpticalAtmosphere, photons: u64) -> Decision {
    let sim = &scene.simulation;
    let mode = sim.multiple_scattering;
    let decision = |run: bool, reason: String, bound| Decision {
        run,
        mode,
        reason,
        bound,
    };
    if photons == 0 {
        return decision(
            false,
            "Monte Carlo skipped: 0 photons (analytic single scattering only)".into(),
            None,
        );
    }
    match mode {
        MultipleScattering::Always => {
            return decision(
                true,
                "Monte Carlo run: multiple_scattering = \"always\" (or --photons)".into(),
                None,
            );
        }
        MultipleScattering::Never => {
            return decision(
                false,
                "Monte Carlo skipped: multiple_scattering = \"never\" (analytic single scattering only)"
                    .into(),
                None,
            );
        }
        MultipleScattering::Auto => {}
    }
    let particles = scattering_layers(scene);
    if !particles.is_empty() {
        return decision(
            true,
            format!(
                "Monte Carlo run: particle layer{} {} scatter{} (multiple_scattering = \"auto\")",
                if particles.len() > 1 { "s" } else { "" },
                particles.join(", "),
                if particles.len() > 1 { "" } else { "s" },
            ),
            None,
        );
    }
    let bound = lidar_eq::multiple_scattering_bound(scene, atm);
    let (k, fov) = bound.worst();
    let all = MultipleScatteringBound::all_orders(k);
    let tol = sim.multiple_scattering_tolerance;
    if all <= tol {
        decision(
            false,
            format!(
                "Monte Carlo skipped: no particle layers, and molecular multiple scattering is at most \
                 {all:.1e} of single scattering (bound of docs/transport.md, largest at FOV {fov} mrad) \
                 ≤ multiple_scattering_tolerance {tol:.0e}: analytic single scattering only \
                 (multiple_scattering = \"always\" or --photons N runs it)"
            ),
            Some((all, fov)),
        )
    } else {
        decision(
            true,
            format!(
                "Monte Carlo run: molecular multiple scattering may reach {all:.1e} of single scattering \
                 (bound of docs/transport.md, FOV {fov} mrad) > multiple_scattering_tolerance {tol:.0e}"
            ),
            Some((all, fov)),
        )
    }
}
