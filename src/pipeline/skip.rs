//! What a scene does not need (docs/design.md §1): whether the Monte Carlo runs at all. What skipping
//! saves is measured by [`crate::pipeline::compare_skip`].
//!
//! Consumes a [`Scene`], its [`OpticalAtmosphere`] and the photons asked for (and, from
//! [`crate::pipeline::prepare`], the analytic returns and the retrieval it has already built);
//! produces a [`Decision`] that the pipeline follows and that the run summary prints. The
//! analytic lidar equation always runs (it costs microseconds to milliseconds); the Monte Carlo
//! adds multiple scattering, and is skipped where that cannot matter:
//!
//! | `[simulation] multiple_scattering` | Monte Carlo |
//! |---|---|
//! | `"auto"` (default) | runs, unless the bound of [`lidar_eq::multiple_scattering_bound`] on all orders ≥ 2 is at most `multiple_scattering_tolerance` (default 1e-3) of every return (channel, line, field of view, gate; co- and cross-polarised parts with polarised light) **and** the retrievals it allows change by at most that much (relative) |
//! | `"always"` | runs (`photons` > 0); `--photons N > 0` on the command line means this |
//! | `"never"` | never |
//!
//! `photons = 0` (or `--photons 0`) skips it whatever the mode, as before. Skipped runs write
//! the analytic rows alone, exactly as `--photons 0` does.
//!
//! A retrieval is judged on its own change: multiple scattering only adds light, each return by
//! a share in [0, K] of its single scattering (K the bound), so each measured differential
//! optical depth — a sum of ±½ ln(P_off/P_on) over its windows — is largest and least at corners
//! of those boxes, and the retrieved quantity, increasing in it, too. The retrieval itself is run
//! on the analytic line returns raised at those corners (IPDA: the off-line raised, or the
//! on-line; DIAL: the far end's off-line and the near end's on-line, or the reverse), and its
//! largest relative change against the unperturbed one is compared with the tolerance.
//!
//! The other skips live where the work is: no `[gas_absorption]` means no line-by-line call at
//! all (`optics`), a gas whose column is zero in a layer is not computed there
//! (`spectroscopy::xsec`), and photons that can no longer reach a gate are ended in the photon
//! loop (`transport`, `docs/transport.md` steps 2–3).

use crate::instrument::laser::LineReturns;
use crate::lidar_eq::{self, MultipleScatteringBound};
use crate::optics::OpticalAtmosphere;
use crate::retrieval::{Product, Retrieval};
use crate::returns::{Order, Returns};
use crate::scene::{MultipleScattering, Scene};

/// Whether the Monte Carlo runs, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    /// True if photons are traced.
    pub run: bool,
    /// The mode it was decided under.
    pub mode: MultipleScattering,
    /// One sentence for the run summary: what was skipped or run, and why (which bound
    /// decided, its value and where).
    pub reason: String,
    /// The bound on the multiple-scattering share (all orders ≥ 2) of the returns, the largest
    /// over channels, lines, fields of view and gates, and the field of view \[mrad\] where it
    /// is (`auto` only).
    pub bound: Option<(f64, f64)>,
    /// The bound on the retrievals' relative change, the largest over the products, where it
    /// was computed (`auto`, every return within the tolerance, a scene with a retrieval).
    pub retrieval_bound: Option<f64>,
}

/// What [`crate::pipeline::prepare`] has already computed, so that the decision does not
/// compute it again: the analytic returns of the channels, their line returns, and the
/// retrieval (if the scene asks for one).
#[derive(Debug, Clone, Copy)]
pub struct Analytic<'a> {
    /// Analytic single scattering of every channel.
    pub returns: &'a Returns,
    /// The same combined into line returns.
    pub lines: &'a LineReturns,
    /// The retrieval set-up.
    pub retrieval: Option<&'a Retrieval>,
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
        .map(|(i, l)| layer_name(i, &l.name))
        .collect()
}

fn layer_name(i: usize, name: &str) -> String {
    if name.is_empty() {
        format!("[[layer]] {}", i + 1)
    } else {
        format!("`{name}`")
    }
}

/// Decide whether the Monte Carlo runs for `scene` with `photons` photons (the module docs),
/// computing the analytic returns (and the retrieval, where needed) itself.
pub fn decide(scene: &Scene, atm: &OpticalAtmosphere, photons: u64) -> Decision {
    decide_with(scene, atm, photons, None)
}

/// [`decide`] with what the pipeline has already computed.
pub fn decide_with(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    photons: u64,
    given: Option<Analytic<'_>>,
) -> Decision {
    let sim = &scene.simulation;
    let mode = sim.multiple_scattering;
    let decision = |run: bool, reason: String, bound, retrieval_bound| Decision {
        run,
        mode,
        reason,
        bound,
        retrieval_bound,
    };
    if photons == 0 {
        return decision(
            false,
            "Monte Carlo skipped: 0 photons (analytic single scattering only)".into(),
            None,
            None,
        );
    }
    match mode {
        MultipleScattering::Always => {
            return decision(
                true,
                "Monte Carlo run: multiple_scattering = \"always\" (or --photons)".into(),
                None,
                None,
            );
        }
        MultipleScattering::Never => {
            return decision(
                false,
                "Monte Carlo skipped: multiple_scattering = \"never\" (analytic single scattering only)"
                    .into(),
                None,
                None,
            );
        }
        MultipleScattering::Auto => {}
    }
    let tol = sim.multiple_scattering_tolerance;
    let particles = scattering_layers(scene);
    let scatterers = if particles.is_empty() {
        "no particle layers, and multiple scattering".to_string()
    } else {
        format!(
            "multiple scattering by particle layer{} {} and the air",
            if particles.len() > 1 { "s" } else { "" },
            particles.join(", ")
        )
    };
    let bound = lidar_eq::multiple_scattering_bound(scene, atm);
    let (owned_returns, owned_lines);
    let (returns, lines) = match &given {
        Some(a) => (a.returns, a.lines),
        None => {
            owned_returns = lidar_eq::single_scatter(scene, atm);
            owned_lines = scene.sampling.combine(&owned_returns);
            (&owned_returns, &owned_lines)
        }
    };
    let lb = LineBounds::new(scene, &bound, returns, lines);
    let worst = worst_return(scene, atm, &bound, &lb);
    let summary = Some((worst.value, worst.fov_mrad));
    if !(worst.value <= tol) {
        return decision(
            true,
            format!(
                "Monte Carlo run: multiple scattering may reach {} of single scattering (bound \
                 of docs/transport.md, {}) > multiple_scattering_tolerance {tol:.0e}",
                share(worst.value),
                worst.place
            ),
            summary,
            None,
        );
    }
    // Every return is within the tolerance: the retrievals on their own.
    let mut retrieval_bound = None;
    let mut retrieval_note = String::new();
    if scene.retrieval.is_some() && scene.receiver.is_some() {
        let own = match given.and_then(|a| a.retrieval) {
            Some(_) => None,
            None => Some(super::retrieval_setup(scene)),
        };
        let retrieval = match (given.and_then(|a| a.retrieval), &own) {
            (Some(r), _) => Ok(r),
            (None, Some(Ok(r))) => Ok(r),
            (None, Some(Err(e))) => Err(e.to_string()),
            (None, None) => Err("none was built".to_string()),
        };
        let (change, what) = match retrieval {
            Ok(r) => retrieval_change(scene, r, lines, &lb),
            Err(e) => (
                f64::INFINITY,
                format!("the retrieval, which cannot be set up ({e})"),
            ),
        };
        retrieval_bound = Some(change);
        if !(change <= tol) {
            return decision(
                true,
                format!(
                    "Monte Carlo run: {scatterers} is at most {} of single scattering in every \
                     return (bound of docs/transport.md, largest at {}), but may change {what} by \
                     {} (relative) > multiple_scattering_tolerance {tol:.0e}",
                    share(worst.value),
                    worst.place,
                    share(change)
                ),
                summary,
                retrieval_bound,
            );
        }
        retrieval_note = format!(
            ", and changes the retrievals by at most {} (relative, {what})",
            share(change)
        );
    }
    decision(
        false,
        format!(
            "Monte Carlo skipped: {scatterers} is at most {} of single scattering (bound of \
             docs/transport.md, largest at {}){retrieval_note} ≤ multiple_scattering_tolerance \
             {tol:.0e}: analytic single scattering only (multiple_scattering = \"always\" or \
             --photons N runs it)",
            share(worst.value),
            worst.place
        ),
        summary,
        retrieval_bound,
    )
}

/// A share for a sentence: `∞` where no bound is given.
fn share(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.1e}")
    } else {
        "∞ (no finite bound)".into()
    }
}

/// The largest bound on any return and where it is; between equal bounds (infinite ones: the
/// series over orders diverges) the place whose order-2 bound is largest.
struct Worst {
    value: f64,
    order2: f64,
    fov_mrad: f64,
    place: String,
}

impl Worst {
    fn offer(&mut self, value: f64, order2: f64, fov_mrad: f64, place: impl FnOnce() -> String) {
        let nan_inf = |v: f64| if v.is_nan() { f64::INFINITY } else { v };
        let (v, o) = (nan_inf(value), nan_inf(order2));
        if v > self.value || (v == self.value && o > self.order2) {
            self.value = v;
            self.order2 = o;
            self.fov_mrad = fov_mrad;
            self.place = place();
            if v.is_infinite() && o.is_finite() {
                self.place += &format!(", where order 2 alone may reach {o:.1e}");
            }
        }
    }
}

/// What a gate holds, for a sentence: the surface echo, the particle layers at its centre's
/// altitude, or clear air.
fn gate_place(scene: &Scene, g: usize) -> String {
    let gates = &scene.gates;
    let r = gates.centre_m(g);
    let lidar = &scene.lidar;
    let mu = lidar.axis().z;
    if let Some(s) = &scene.surface
        && mu < -1e-12
    {
        let rs = (lidar.altitude_m - s.altitude_m) / -mu;
        let x = (rs - gates.start_m) / gates.width_m;
        if x >= 0.0 && x as usize == g {
            return format!("gate {g} at {r:.0} m, the surface echo's");
        }
        if x < g as f64 {
            return format!(
                "gate {g} at {r:.0} m, beyond the surface (no single scattering; gates that end \
                 with the surface echo's let the rest be judged)"
            );
        }
    }
    let z = lidar.altitude_m + mu * r;
    let here: Vec<String> = scene
        .layers
        .iter()
        .enumerate()
        .filter(|(_, l)| l.base_m <= z && z <= l.top_m)
        .map(|(i, l)| layer_name(i, &l.name))
        .collect();
    if here.is_empty() {
        format!("gate {g} at {r:.0} m, in clear air")
    } else {
        format!("gate {g} at {r:.0} m, in {}", here.join(", "))
    }
}

/// The largest bound on any return: every channel, field of view and gate, the line returns
/// made of them, and with polarised light the co- and cross-polarised parts (multiple scattering
/// may put all of its light into the smaller part).
fn worst_return(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    bound: &MultipleScatteringBound,
    lb: &LineBounds,
) -> Worst {
    let fovs = &bound.fov_full_angle_mrad;
    let (nf, ng) = (fovs.len(), bound.range_m.len());
    let mut w = Worst {
        value: 0.0,
        order2: 0.0,
        fov_mrad: fovs.first().copied().unwrap_or(0.0),
        place: "every gate (all bounds 0)".into(),
    };
    for (k, name) in bound.channels.iter().enumerate() {
        for f in 0..nf {
            for g in 0..ng {
                let order2 = bound.ratio[f * ng + g];
                w.offer(bound.all_orders_at(k, f, g), order2, fovs[f], || {
                    format!(
                        "channel `{name}`, FOV {} mrad, {}",
                        fovs[f],
                        gate_place(scene, g)
                    )
                });
            }
        }
    }
    for (l, name) in lb.names.iter().enumerate() {
        for f in 0..nf {
            for g in 0..ng {
                let (up, down) = lb.at(l, f, g);
                w.offer(up.max(down), bound.ratio[f * ng + g], fovs[f], || {
                    format!(
                        "line `{name}`, FOV {} mrad, {}",
                        fovs[f],
                        gate_place(scene, g)
                    )
                });
            }
        }
    }
    if let Some((co, cross)) = lidar_eq::single_scatter_polarised(scene, atm) {
        let total = lidar_eq::single_scatter(scene, atm);
        for (part, label) in [(&co, "co"), (&cross, "cross")] {
            for (k, name) in bound.channels.iter().enumerate() {
                for f in 0..nf {
                    for g in 0..ng {
                        let i = total.index(k, f, g, 0);
                        let (e, p) = (total.energy_j[i], part.energy_j[i]);
                        let k_all = bound.all_orders_at(k, f, g);
                        // All of the multiply scattered light may be in this part.
                        let v = if k_all == 0.0 || e == 0.0 {
                            0.0
                        } else if p > 0.0 {
                            k_all * e / p
                        } else {
                            f64::INFINITY
                        };
                        w.offer(v, bound.ratio[f * ng + g], fovs[f], || {
                            format!(
                                "the {label}-polarised part of channel `{name}`, FOV {} mrad, {}",
                                fovs[f],
                                gate_place(scene, g)
                            )
                        });
                    }
                }
            }
        }
    }
    w
}

/// Per line, field of view and gate, how far multiple scattering may move the line's return,
/// relative to its single scattering: up by at most `up`, down by at most `down` (a line is a
/// combination of channels; with frequency jitter some coefficients are negative).
struct LineBounds {
    names: Vec<String>,
    n_fov: usize,
    n_gates: usize,
    /// (up, down), index `(line * n_fov + fov) * n_gates + gate`.
    moves: Vec<(f64, f64)>,
}

impl LineBounds {
    fn new(
        scene: &Scene,
        bound: &MultipleScatteringBound,
        returns: &Returns,
        lines: &LineReturns,
    ) -> Self {
        let (nf, ng) = (bound.fov_full_angle_mrad.len(), bound.range_m.len());
        let combos = &scene.sampling.mean;
        let mut moves = Vec::with_capacity(combos.len() * nf * ng);
        for (l, combo) in combos.iter().enumerate() {
            for f in 0..nf {
                for g in 0..ng {
                    let (mut up, mut down) = (0.0, 0.0);
                    for &(k, c) in &combo.terms {
                        let e = returns.energy_j[returns.index(k, f, g, 0)];
                        let ms = if e == 0.0 {
                            0.0
                        } else {
                            bound.all_orders_at(k, f, g) * e
                        };
                        if c > 0.0 {
                            up += c * ms;
                        } else {
                            down -= c * ms;
                        }
                    }
                    let p = lines.mean.energy_j[lines.mean.index(l, f, g, 0)];
                    let rel = |m: f64| {
                        if m == 0.0 {
                            0.0
                        } else if p > 0.0 {
                            m / p
                        } else {
                            f64::INFINITY
                        }
                    };
                    moves.push((rel(up), rel(down)));
                }
            }
        }
        LineBounds {
            names: combos.iter().map(|c| c.name.clone()).collect(),
            n_fov: nf,
            n_gates: ng,
            moves,
        }
    }

    fn at(&self, line: usize, fov: usize, gate: usize) -> (f64, f64) {
        self.moves[(line * self.n_fov + fov) * self.n_gates + gate]
    }
}

/// The largest relative change of any retrieved product that multiple scattering within the
/// returns' bounds allows, and which product (the module docs): the retrieval run on the line
/// returns moved to the corners that make each product's differential optical depth largest
/// and least.
fn retrieval_change(
    scene: &Scene,
    retrieval: &Retrieval,
    lines: &LineReturns,
    lb: &LineBounds,
) -> (f64, String) {
    let mut r = retrieval.clone();
    // The expected values are what is judged: no noisy realisations.
    r.config.realisations = 0;
    let (on, off) = (r.config.on, r.config.off);
    let ng = lb.n_gates;
    // Per gate: Some(true) = a far end (off-line up, on-line down), Some(false) = a near end
    // (on-line up, off-line down). Every gate one way raises every IPDA's D, the other lowers
    // it; a DIAL cell's D is largest with its far end up and its near end down, and cells share
    // ends, so alternate cells take the two ways in two more passes.
    let mut passes: Vec<Vec<Option<bool>>> = vec![vec![Some(true); ng], vec![Some(false); ng]];
    if let Some(d) = &r.config.dial {
        for parity in 0..2 {
            let mut roles = vec![None; ng];
            for c in 0..d.cells {
                let (a, b) = d.bounds(c);
                let rising = c % 2 == parity;
                if a < ng {
                    roles[a] = Some(!rising);
                }
                if b < ng {
                    roles[b] = Some(rising);
                }
            }
            passes.push(roles);
        }
    }
    let retrieve = |set: &LineReturns| -> Option<Vec<Product>> {
        let signals = super::signals_of(scene, set, Order::Exactly(1))?;
        let mut out = Vec::new();
        for fov in 0..lb.n_fov {
            out.extend(r.retrieve(set, &signals, fov).ok()?);
        }
        Some(out)
    };
    let Some(base) = retrieve(lines) else {
        return (f64::INFINITY, "the retrievals, which fail".into());
    };
    let mut worst = (0.0f64, "the retrievals".to_string());
    for roles in passes {
        let mut moved = lines.clone();
        let mean = &mut moved.mean;
        for (g, role) in roles.iter().enumerate() {
            let Some(far) = *role else { continue };
            for f in 0..lb.n_fov {
                // A far end raises the off-line and lowers the on-line; a near end the reverse.
                let (raised, lowered) = if far { (off, on) } else { (on, off) };
                let i = mean.index(raised, f, g, 0);
                mean.energy_j[i] *= 1.0 + lb.at(raised, f, g).0;
                let i = mean.index(lowered, f, g, 0);
                mean.energy_j[i] *= 1.0 - lb.at(lowered, f, g).1;
            }
        }
        let products = if mean.energy_j.iter().all(|e| e.is_finite() && *e >= 0.0) {
            retrieve(&moved)
        } else {
            None
        };
        let Some(products) = products else {
            return (
                f64::INFINITY,
                "the retrievals, which fail on returns within the bound".into(),
            );
        };
        for (p, b) in products.iter().zip(&base) {
            let change = if p.retrieved == b.retrieved {
                0.0
            } else if b.retrieved != 0.0 {
                ((p.retrieved - b.retrieved) / b.retrieved).abs()
            } else {
                f64::INFINITY
            };
            let change = if change.is_nan() {
                f64::INFINITY
            } else {
                change
            };
            if change > worst.0 {
                worst = (
                    change,
                    format!(
                        "{} {} (FOV {} mrad, {:.0}–{:.0} m)",
                        b.method.label(),
                        b.quantity.label(),
                        b.fov_full_angle_mrad,
                        b.range_m.0,
                        b.range_m.1
                    ),
                );
            }
        }
    }
    worst
}
