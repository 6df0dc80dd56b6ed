//! The work of a Mie computation before it runs: how many size points and terms, for
//! estimates and progress.

use std::f64::consts::PI;

use super::fingerprint::fingerprint;
use super::integrate::{max_intervals, mode_range_um};
use super::options::{BulkOptions, Component, check_inputs, default_angle_grid};
use crate::particles::mie::{MieError, n_terms};

/// The cost of Mie size integrations, bounded before any of them is done (README, "Limits").
///
/// Time goes in two places: the Mie coefficients of every radius of a mode's grid (Wiscombe's
/// N(x) = x + 4.05 x^(1/3) + 2 terms each), and the matrix products that turn them into the
/// phase function and scattering matrix on K angles (N(x)·K multiply-adds a radius). The grid is
/// the finest the refinement can reach (every panel halved down to `min_step_x` or up to its
/// share of `max_points`): the refinement stops sooner on convergence, so the count is an upper
/// bound, often a loose one (the panels in a mode's tails stop early). The work is
/// `terms × (angles + c)`, `terms` the sum of N(x) over the grids' radii and `c` the cost of the
/// coefficients in angles ([`crate::limits::MIE_COEFFICIENT_ANGLES`]; the matrix products use
/// the same coefficients as the efficiencies); its unit, a "term-angle", takes
/// [`crate::limits::MIE_SECONDS_PER_WORK`] on one core of the reference machine.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MieWork {
    /// Size integrations: modes × wavelengths.
    pub integrations: u64,
    /// Radii of the finest grids, summed over the integrations.
    pub radii: u64,
    /// Mie terms summed over those radii (an upper bound: N(x) is concave, and is evaluated
    /// at each grid's middle).
    pub terms: f64,
    /// Angles of the phase function (0: none asked for), the largest of the integrations.
    pub angles: u64,
    /// Values of the largest angle table (angles × terms at the largest radius), held twice.
    pub angle_table_values: u64,
    /// `terms × (angles + c)` summed over the integrations \[term-angles\].
    pub work: f64,
}

impl MieWork {
    /// The work of two sets of integrations (the angle table is the larger one's: tables are
    /// made one integration at a time).
    pub fn add(&mut self, o: &MieWork) {
        self.integrations += o.integrations;
        self.radii += o.radii;
        self.terms += o.terms;
        self.angles = self.angles.max(o.angles);
        self.angle_table_values = self.angle_table_values.max(o.angle_table_values);
        self.work += o.work;
    }

    /// The coefficients' cost in angles, `c` (see the type's documentation).
    fn coefficient_angles(&self) -> u64 {
        crate::limits::MIE_COEFFICIENT_ANGLES
    }

    /// Seconds on one core of the reference machine (README, "Limits").
    pub fn seconds(&self) -> f64 {
        self.work * crate::limits::MIE_SECONDS_PER_WORK
    }

    /// The work as a product of its factors, for messages.
    fn describe(&self) -> String {
        // Three significant digits: an order of magnitude is what a reader needs here.
        let f = |v: f64| {
            if v >= 1e5 {
                format!("{v:.2e}")
            } else {
                format!("{}", v.round())
            }
        };
        let c = self.coefficient_angles();
        format!(
            "{} size integration{} (modes × wavelengths) over up to {} radii: {} Mie terms × ({} angles + {c} for the coefficients) = {} term-angles, up to about {} on one core",
            self.integrations,
            if self.integrations == 1 { "" } else { "s" },
            self.radii,
            f(self.terms),
            self.angles,
            f(self.work),
            crate::limits::fmt_seconds(self.seconds()),
        )
    }

    /// Ok below the limits, else the message naming the product and the limit.
    pub fn check(&self) -> Result<(), String> {
        use crate::limits::{MAX_MIE_ANGLE_TABLE_VALUES, MAX_MIE_WORK, check_product};
        if self.work > MAX_MIE_WORK {
            return Err(format!(
                "Mie work: {}, more than the limit of {} (about {}; README, \"Limits\")",
                self.describe(),
                crate::input::fmt_bound(MAX_MIE_WORK),
                crate::limits::fmt_seconds(MAX_MIE_WORK * crate::limits::MIE_SECONDS_PER_WORK),
            ));
        }
        let n_max = self
            .angle_table_values
            .checked_div(self.angles)
            .unwrap_or(0);
        check_product(
            "Mie angle tables",
            &[("angles", self.angles), ("Mie terms", n_max)],
            MAX_MIE_ANGLE_TABLE_VALUES,
        )
        .map(|_| ())
    }

    /// A note when the work is allowed but long (above [`crate::limits::MIE_WORK_WARN`]).
    pub fn warning(&self) -> Option<String> {
        (self.work > crate::limits::MIE_WORK_WARN).then(|| format!("Mie work: {}", self.describe()))
    }
}

/// The cost of [`bulk_optics_mixture`] for these inputs ([`MieWork`]), from the radius ranges
/// alone: milliseconds. Errors are those of the inputs (as [`bulk_optics_mixture`] gives them).
pub fn mie_work(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<MieWork, MieError> {
    check_inputs(components, wavelength_m, opts)?;
    let k = 2.0 * PI / (wavelength_m * 1e6);
    let n_terms_f = |x: f64| x + 4.05 * x.cbrt() + 2.0;
    let mut w = MieWork::default();
    let (mut area, mut vol, mut x_max) = (0.0, 0.0, 0.0f64);
    for c in components {
        let n = c.distribution.number_density_per_cm3();
        area += n * c.distribution.moment(2.0);
        vol += n * c.distribution.moment(3.0);
        for mode in c.distribution.modes() {
            let (r_lo, r_hi) = mode_range_um(&mode, k, opts)?;
            let (x_lo, x_hi) = (k * r_lo, k * r_hi);
            // Per panel of the refinement, its finest grid: the points (the panels share their
            // ends: one point more than the intervals in all), and N(x) at the panel's middle
            // times its points with both ends, a bound by concavity.
            let finest = max_intervals(x_lo, x_hi, opts);
            let radii = finest.iter().map(|p| p.2).sum::<usize>() + 1;
            w.integrations += 1;
            w.radii += radii as u64;
            for (a, b, intervals) in finest {
                w.terms += (intervals + 1) as f64 * n_terms_f(0.5 * (a + b));
            }
            x_max = x_max.max(x_hi);
        }
    }
    // The angles bulk_optics_mixture will use: its default grid depends on the effective size
    // parameter (here of the untruncated distributions, within the integrated range).
    w.angles = match &opts.angles_deg {
        Some(a) => a.len() as u64,
        None => default_angle_grid((k * vol / area).min(x_max)).len() as u64,
    };
    w.angle_table_values = w.angles.saturating_mul(n_terms(x_max) as u64);
    w.work = w.terms * (w.angles + w.coefficient_angles()) as f64;
    Ok(w)
}

/// The cost of the size integrations of several (components, wavelength) sets, each counted
/// once however often it appears (equal inputs are computed once: the cache of
/// [`super::cache`]).
pub fn mie_work_of<'a>(
    sets: impl IntoIterator<Item = (&'a [Component], f64)>,
    opts: &BulkOptions,
) -> Result<MieWork, MieError> {
    let mut seen = std::collections::HashSet::new();
    let mut total = MieWork::default();
    for (components, wavelength_m) in sets {
        if seen.insert(fingerprint(components, wavelength_m, opts)) {
            total.add(&mie_work(components, wavelength_m, opts)?);
        }
    }
    Ok(total)
}
