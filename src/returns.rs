//! Received energy by channel, field of view, range gate and scattering order: the common
//! output of the Monte Carlo transport and the analytic lidar equation, and its CSV form.
//!
//! **contract** (docs/design.md §4): `returns.csv` has the columns
//! `source,channel,fov_full_angle_mrad,range_m,order,energy_j,stderr_j`, then `polarisation`:
//! `total` on every row of an unpolarised run; with polarised light also `co` and `cross`
//! rows (what a sphere's single backscatter returns, and the rest; `docs/transport.md`,
//! "Polarisation").

use std::fmt::Write as _;

use crate::output::{csv_field, csv_number};

/// Where a set of returns comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Monte Carlo transport.
    MonteCarlo,
    /// Analytic single-scatter lidar equation.
    Analytic,
}

impl Source {
    /// The `source` column value.
    pub fn label(self) -> &'static str {
        match self {
            Source::MonteCarlo => "mc",
            Source::Analytic => "analytic",
        }
    }
}

/// A scattering-order bin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// All orders together.
    Total,
    /// Exactly this many scattering events (surface reflections count as events).
    Exactly(u32),
    /// This many events or more (the last bin, `N+`).
    AtLeast(u32),
}

impl Order {
    /// The `order` column value (and the NetCDF files' `order` coordinate): `total`, then the
    /// ordinals `1st`, `2nd`, `3rd`, `4th`, …, and `N+` as `2nd+`, `6th+`. A bin is named as
    /// one says it ("first-order scattering") and never as a bare number: a reader (pandas, R,
    /// a spreadsheet) would load a column of `1`, `2`, `3+` as numbers in a run that has only
    /// order 1 (`--photons 0`) and as text in every other, where `1st` is text in every run.
    pub fn label(self) -> String {
        match self {
            Order::Total => "total".into(),
            Order::Exactly(n) => ordinal(n),
            Order::AtLeast(n) => format!("{}+", ordinal(n)),
        }
    }
}

/// `n` as an English ordinal: `1st`, `2nd`, `3rd`, `4th`, `11th`, `12th`, `13th`, `21st`, ….
fn ordinal(n: u32) -> String {
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

/// Returns on a grid of channel × FOV × gate × order, with standard errors.
#[derive(Debug, Clone, PartialEq)]
pub struct Returns {
    /// Monte Carlo or analytic.
    pub source: Source,
    /// Channel names, in scene order.
    pub channels: Vec<String>,
    /// Receiver fields of view (full angles) \[mrad\], in scene order.
    pub fov_full_angle_mrad: Vec<f64>,
    /// Gate centres \[m\].
    pub range_m: Vec<f64>,
    /// Order bins.
    pub orders: Vec<Order>,
    /// Expected received energy per pulse \[J\], index [`Returns::index`].
    pub energy_j: Vec<f64>,
    /// Standard error of `energy_j` \[J\] (0 for analytic returns).
    pub stderr_j: Vec<f64>,
    /// Covariances between the means of channel pairs, where the producer knows them (Monte
    /// Carlo channels share photon paths, so on- and off-line errors are strongly correlated).
    pub covariance: Option<Covariance>,
}

/// A linear combination of channels, Σ cᵢ · channelᵢ: a laser line's return from those of its
/// line-shape quadrature nodes, or a derivative with respect to frequency by finite differences.
#[derive(Debug, Clone, PartialEq)]
pub struct Combination {
    /// Name of the combined channel.
    pub name: String,
    /// (channel index, coefficient) pairs.
    pub terms: Vec<(usize, f64)>,
}

/// Covariances of the means of channel pairs, bin by bin.
#[derive(Debug, Clone, PartialEq)]
pub struct Covariance {
    /// Channel pairs (a, b), a < b.
    pub pairs: Vec<(usize, usize)>,
    /// Covariance of the two means \[J²\], index `pair * bins + bin`, where `bin` is
    /// [`Returns::index`] of channel 0 and `bins` the number of bins per channel.
    pub cov_j2: Vec<f64>,
}

impl Returns {
    /// All-zero returns on the given grid.
    pub fn zeros(
        source: Source,
        channels: Vec<String>,
        fov_full_angle_mrad: Vec<f64>,
        range_m: Vec<f64>,
        orders: Vec<Order>,
    ) -> Self {
        let n = channels.len() * fov_full_angle_mrad.len() * range_m.len() * orders.len();
        Returns {
            source,
            channels,
            fov_full_angle_mrad,
            range_m,
            orders,
            energy_j: vec![0.0; n],
            stderr_j: vec![0.0; n],
            covariance: None,
        }
    }

    /// Number of bins of one channel (FOV × gate × order).
    pub fn bins_per_channel(&self) -> usize {
        self.fov_full_angle_mrad.len() * self.range_m.len() * self.orders.len()
    }

    /// Covariance of the means of channels a and b in one bin \[J²\]: the variance when a = b;
    /// 0 when both have zero error (analytic returns); `None` where it is not known.
    pub fn covariance_j2(
        &self,
        a: usize,
        b: usize,
        fov: usize,
        gate: usize,
        order: usize,
    ) -> Option<f64> {
        let (ia, ib) = (
            self.index(a, fov, gate, order),
            self.index(b, fov, gate, order),
        );
        if a == b {
            return Some(self.stderr_j[ia].powi(2));
        }
        if self.stderr_j[ia] == 0.0 && self.stderr_j[ib] == 0.0 {
            return Some(0.0);
        }
        let c = self.covariance.as_ref()?;
        let key = (a.min(b), a.max(b));
        let p = c.pairs.iter().position(|q| *q == key)?;
        Some(c.cov_j2[p * self.bins_per_channel() + self.index(0, fov, gate, order)])
    }

    /// The returns of some channels only, in the given order (with their covariances).
    pub fn channel_subset(&self, channels: &[usize]) -> Returns {
        let bins = self.bins_per_channel();
        // Copied channel by channel (no zeroing first: these are large).
        let pick = |v: &[f64]| -> Vec<f64> {
            let mut out = Vec::with_capacity(channels.len() * bins);
            for k in channels {
                out.extend_from_slice(&v[k * bins..(k + 1) * bins]);
            }
            out
        };
        let mut out = Returns {
            source: self.source,
            channels: channels.iter().map(|k| self.channels[*k].clone()).collect(),
            fov_full_angle_mrad: self.fov_full_angle_mrad.clone(),
            range_m: self.range_m.clone(),
            orders: self.orders.clone(),
            energy_j: pick(&self.energy_j),
            stderr_j: pick(&self.stderr_j),
            covariance: None,
        };
        out.covariance = self.covariance.as_ref().map(|c| {
            let mut pairs = Vec::new();
            let mut cov_j2 = Vec::new();
            for a in 0..channels.len() {
                for b in a + 1..channels.len() {
                    let key = (channels[a].min(channels[b]), channels[a].max(channels[b]));
                    if let Some(p) = c.pairs.iter().position(|q| *q == key) {
                        pairs.push((a, b));
                        cov_j2.extend_from_slice(&c.cov_j2[p * bins..(p + 1) * bins]);
                    }
                }
            }
            Covariance { pairs, cov_j2 }
        });
        out
    }

    /// The returns of linear combinations of channels (deterministic combination, bin by bin).
    ///
    /// Energies combine exactly. Standard errors combine through the covariances where they are
    /// known (σ² = Σ_ab c_a c_b cov_ab); they are 0 where every term has zero error and NaN where
    /// a needed covariance is unknown. A Monte Carlo run that should report combined channels
    /// with proper errors combines batch by batch instead (`transport::TallyLayout::combinations`).
    pub fn combine(&self, combos: &[Combination]) -> Returns {
        let mut out = Returns::zeros(
            self.source,
            combos.iter().map(|c| c.name.clone()).collect(),
            self.fov_full_angle_mrad.clone(),
            self.range_m.clone(),
            self.orders.clone(),
        );
        let bins = self.bins_per_channel();
        for (j, c) in combos.iter().enumerate() {
            // Term by term over the channel's bins: each bin's sum in term order, from 0.
            let e = &mut out.energy_j[j * bins..(j + 1) * bins];
            for (a, ca) in &c.terms {
                for (e, v) in e.iter_mut().zip(&self.energy_j[a * bins..(a + 1) * bins]) {
                    *e += ca * v;
                }
            }
            // Every term without error in every bin (analytic returns): every covariance is 0,
            // so the variance below is +0 and the error 0, as `zeros` left it.
            if c.terms.iter().all(|(_, ca)| ca.is_finite())
                && c.terms.iter().all(|(a, _)| {
                    self.stderr_j[a * bins..(a + 1) * bins]
                        .iter()
                        .all(|s| *s == 0.0)
                })
            {
                continue;
            }
            for f in 0..self.fov_full_angle_mrad.len() {
                for g in 0..self.range_m.len() {
                    for o in 0..self.orders.len() {
                        let mut var = 0.0;
                        for (a, ca) in &c.terms {
                            for (b, cb) in &c.terms {
                                var += ca
                                    * cb
                                    * self.covariance_j2(*a, *b, f, g, o).unwrap_or(f64::NAN);
                            }
                        }
                        let i = out.index(j, f, g, o);
                        out.stderr_j[i] = var.max(0.0).sqrt();
                        if var.is_nan() {
                            out.stderr_j[i] = f64::NAN;
                        }
                    }
                }
            }
        }
        out
    }

    /// Flat index of (channel, fov, gate, order bin).
    #[inline]
    pub fn index(&self, channel: usize, fov: usize, gate: usize, order: usize) -> usize {
        ((channel * self.fov_full_angle_mrad.len() + fov) * self.range_m.len() + gate)
            * self.orders.len()
            + order
    }

    /// Position of an order bin.
    pub fn order_index(&self, order: Order) -> Option<usize> {
        self.orders.iter().position(|o| *o == order)
    }

    /// Energy of one bin.
    pub fn energy(&self, channel: usize, fov: usize, gate: usize, order: Order) -> Option<f64> {
        let o = self.order_index(order)?;
        Some(self.energy_j[self.index(channel, fov, gate, o)])
    }

    /// Standard error of one bin.
    pub fn stderr(&self, channel: usize, fov: usize, gate: usize, order: Order) -> Option<f64> {
        let o = self.order_index(order)?;
        Some(self.stderr_j[self.index(channel, fov, gate, o)])
    }

    /// The CSV rows (no header), one per bin, ordered by channel, FOV, gate, order, with
    /// `polarisation` in the last column.
    pub fn csv_rows(&self, out: &mut String, polarisation: &str) {
        let src = self.source.label();
        let labels: Vec<String> = self.orders.iter().map(|o| o.label()).collect();
        for (c, ch) in self.channels.iter().enumerate() {
            let ch = csv_field(ch);
            for (f, fov) in self.fov_full_angle_mrad.iter().enumerate() {
                for (g, r) in self.range_m.iter().enumerate() {
                    for (o, label) in labels.iter().enumerate() {
                        let i = self.index(c, f, g, o);
                        let _ = writeln!(
                            out,
                            "{src},{ch},{fov},{r},{label},{:.9e},{:.9e},{polarisation}",
                            csv_number(self.energy_j[i]),
                            csv_number(self.stderr_j[i])
                        );
                    }
                }
            }
        }
    }
}

/// The header line of `returns.csv`.
pub const CSV_HEADER: &str =
    "source,channel,fov_full_angle_mrad,range_m,order,energy_j,stderr_j,polarisation";

/// Several sets of returns, each with its `polarisation` label (`total`, `co`, `cross`), as the
/// text of one CSV file (header and rows).
pub fn to_csv(sets: &[(&Returns, &str)]) -> String {
    let mut s = String::with_capacity(1 << 20);
    s.push_str(CSV_HEADER);
    s.push('\n');
    for (r, label) in sets {
        r.csv_rows(&mut s, label);
    }
    s
}

/// The header line of `depolarisation.csv`.
pub const DEPOLARISATION_HEADER: &str =
    "source,channel,fov_full_angle_mrad,range_m,order,delta,delta_stderr";

/// The depolarisation ratio δ = cross/co of every bin of a pair of co- and cross-polarised
/// returns (same grid), with its standard error from the two errors and the covariance of the
/// two means (`cov_j2`, index [`Returns::index`]; `None` for analytic returns, whose error is
/// 0), by the first-order propagation
/// σ²_δ = δ² (σ²_x/x² + σ²_c/c² − 2 cov/(x c)). A bin whose co-polarised return is 0 has no
/// ratio: both fields are empty.
pub fn depolarisation_rows(
    out: &mut String,
    co: &Returns,
    cross: &Returns,
    cov_j2: Option<&[f64]>,
) {
    let src = co.source.label();
    let labels: Vec<String> = co.orders.iter().map(|o| o.label()).collect();
    for (c, ch) in co.channels.iter().enumerate() {
        let ch = csv_field(ch);
        for (f, fov) in co.fov_full_angle_mrad.iter().enumerate() {
            for (g, r) in co.range_m.iter().enumerate() {
                for (o, label) in labels.iter().enumerate() {
                    let (delta, se) = depolarisation_ratio(co, cross, cov_j2, co.index(c, f, g, o));
                    let _ = writeln!(
                        out,
                        "{src},{ch},{fov},{r},{label},{:.9e},{:.9e}",
                        csv_number(delta),
                        csv_number(se)
                    );
                }
            }
        }
    }
}

/// The depolarisation ratio δ = cross/co of bin `i` ([`Returns::index`]) and its standard
/// error, as [`depolarisation_rows`] writes them: both NaN where the co-polarised return is 0.
pub fn depolarisation_ratio(
    co: &Returns,
    cross: &Returns,
    cov_j2: Option<&[f64]>,
    i: usize,
) -> (f64, f64) {
    let (a, x) = (co.energy_j[i], cross.energy_j[i]);
    if !(a > 0.0) {
        return (f64::NAN, f64::NAN);
    }
    let delta = x / a;
    let se = match cov_j2 {
        None => 0.0,
        Some(cov) => {
            let (sa, sx) = (co.stderr_j[i], cross.stderr_j[i]);
            if x == 0.0 {
                // δ = 0: its error is that of the cross-polarised return alone.
                sx / a
            } else {
                let rel = (sa / a).powi(2) + (sx / x).powi(2) - 2.0 * cov[i] / (a * x);
                // Rounding can leave a nearly perfectly correlated pair's variance a hair below
                // 0; an unknown error (NaN) stays unknown (`f64::max` would make it 0).
                delta.abs() * if rel < 0.0 { 0.0 } else { rel.sqrt() }
            }
        }
    };
    (delta, se)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_bin(source: Source, energy_j: f64, stderr_j: f64) -> Returns {
        let mut r = Returns::zeros(
            source,
            vec!["c".into()],
            vec![1.0],
            vec![100.0],
            vec![Order::Total],
        );
        r.energy_j[0] = energy_j;
        r.stderr_j[0] = stderr_j;
        r
    }

    /// Order bins are English ordinals, never a text a CSV reader loads as a number.
    #[test]
    fn order_labels_are_ordinals_that_never_read_as_numbers() {
        let cases = [
            (Order::Total, "total"),
            (Order::Exactly(1), "1st"),
            (Order::Exactly(2), "2nd"),
            (Order::Exactly(3), "3rd"),
            (Order::Exactly(4), "4th"),
            (Order::Exactly(11), "11th"),
            (Order::Exactly(12), "12th"),
            (Order::Exactly(13), "13th"),
            (Order::Exactly(21), "21st"),
            (Order::Exactly(102), "102nd"),
            (Order::AtLeast(2), "2nd+"),
            (Order::AtLeast(6), "6th+"),
        ];
        for (o, want) in cases {
            assert_eq!(o.label(), want);
            assert!(want.parse::<f64>().is_err());
            // Written as they are: no apostrophe, no quotes.
            assert_eq!(crate::output::csv_field(want), want);
        }
    }

    /// δ = cross/co with σ²_δ = δ²(σ²_x/x² + σ²_c/c² − 2 cov/(x c)) (first-order
    /// propagation), against values worked by hand: uncorrelated, correlated ½ (σ_δ = δ r for
    /// equal relative errors r), a covariance past the Cauchy–Schwarz bound by rounding (the
    /// variance a hair below 0: error 0, not NaN), an unknown error (NaN stays NaN), no cross
    /// return (the cross error over co), no co return (no ratio), analytic (error 0).
    #[test]
    fn depolarisation_ratio_and_its_error_by_hand() {
        let mc = Source::MonteCarlo;
        let (co, cross) = (one_bin(mc, 4.0, 0.4), one_bin(mc, 1.0, 0.2));
        let (d, se) = depolarisation_ratio(&co, &cross, Some(&[0.0]), 0);
        assert_eq!(d, 0.25);
        assert!((se - 0.25 * (0.01f64 + 0.04).sqrt()).abs() < 1e-15);
        let same = one_bin(mc, 1.0, 0.1);
        let (d, se) = depolarisation_ratio(&co, &same, Some(&[0.5 * 0.4 * 0.1]), 0);
        assert!((se - d * 0.1).abs() < 1e-15);
        let (_, se) = depolarisation_ratio(&co, &same, Some(&[1.000001 * 0.4 * 0.1]), 0);
        assert_eq!(se, 0.0);
        let unknown = one_bin(mc, 1.0, f64::NAN);
        assert!(
            depolarisation_ratio(&co, &unknown, Some(&[0.0]), 0)
                .1
                .is_nan()
        );
        let none = one_bin(mc, 0.0, 0.0);
        assert_eq!(
            depolarisation_ratio(&co, &none, Some(&[0.0]), 0),
            (0.0, 0.0)
        );
        let (d, se) = depolarisation_ratio(&none, &cross, Some(&[0.0]), 0);
        assert!(d.is_nan() && se.is_nan());
        assert_eq!(depolarisation_ratio(&co, &cross, None, 0), (0.25, 0.0));
    }
}
