//! Attenuated backscatter and range-corrected signal of every returns bin: the quantities
//! aerosol and cloud lidar users work with, from the received energies of
//! [`crate::returns::Returns`] (`backscatter.csv` and `run.nc`; `docs/instrument.md`,
//! "Attenuated backscatter and the lidar constant").
//!
//! **The lidar constant** C = E₀ · η · A_tel \[J m²\]: the line's pulse energy, the receiver's
//! optical efficiency and the telescope's collecting area. It leaves out the geometric
//! overlap O (and, with a `[receiver]` filter or an impure `[laser]`, the filter's
//! transmission and the laser's spectral purity): those stay in β′ as they stay in the signal,
//! so that β′ is what a lidar calibrated for C alone would report.
//!
//! **Attenuated backscatter.** The single-scatter lidar equation (docs/design.md §3; Measures
//! 1984, *Laser Remote Sensing*, Eq. 7.7) for the energy of the gate [r₁, r₂] is
//!
//! ```text
//! E = C ∫_{r₁}^{r₂} β(r) T²(r) O(r) / r² dr,      T² = exp(−2 ∫₀ʳ α dr')
//! ```
//!
//! and the attenuated backscatter of the gate is defined as that energy over C times the
//! gate's ∫ dr/r² = 1/r₁ − 1/r₂ = Δr/(r₁ r₂):
//!
//! ```text
//! β′ = E · r₁ r₂ / (C · Δr)        [m⁻¹ sr⁻¹]                                        (B1)
//! ```
//!
//! i.e. the 1/r²-weighted mean over the gate of β T² O. Where β T² O is constant over a gate,
//! β′ is that constant exactly; in a homogeneous layer it is β O times the 1/r²-weighted mean
//! of T² over the gate, the point value at the 1/r²-weighted mean range r₁r₂ ln(r₂/r₁)/Δr to O((σ Δr)²). Applied to the
//! analytic single-scatter returns (which integrate the gate exactly, [`crate::lidar_eq`]),
//! order 1 is this mean of β T² O to rounding: the identity the tests check against formulas
//! worked by hand. This is the range-resolved quantity the Klett (1981) and Fernald (1984)
//! inversions start from (β′ = P r²/C in their notation, with the point range r² in place of
//! the gate's r₁ r₂: the two differ by Δr²/(4 r²), 1e-4 for 10 m gates at 500 m).
//!
//! **Range-corrected signal** RCS = E · r_c² \[J m²\], r_c the gate's centre: the energy
//! times the square of the gate's range, not divided by the gate's width (a 20 m gate has
//! twice the RCS of a 10 m one); the conventional P r² of lidar processing.
//!
//! Both are linear in E, so their standard errors are the energy's times the same factor.
//! A gate that holds a hard target's echo (a surface, or the gate cut short by it) gets the
//! same formulas: its β′ is the volume backscatter that would return the echo's energy, not a
//! property of the air. A value that cannot be computed (no lidar constant for a channel, a
//! gate starting at r₁ < 0, an overflow) is not finite and is written as an empty field or
//! `_FillValue`; a gate from r₁ = 0 has β′ = 0 (its ∫ dr/r² diverges).

use std::fmt::Write as _;

use crate::output::{csv_field, csv_number};
use crate::returns::{Order, Returns, Source};
use crate::scene::Gates;

/// The lidar constant C = E₀ · η · A_tel \[J m²\] (module documentation): pulse energy
/// \[J\], receiver optical efficiency and telescope collecting area \[m²\]. The overlap is not
/// in it.
pub fn lidar_constant_j_m2(pulse_energy_j: f64, optical_efficiency: f64, area_m2: f64) -> f64 {
    pulse_energy_j * optical_efficiency * area_m2
}

/// The factor f with β′ = f · E (Eq. B1) for the gate [r₁, r₂] \[m\] and lidar constant C:
/// f = r₁ r₂ / (C Δr) \[m⁻¹ sr⁻¹ J⁻¹\], Δr = r₂ − r₁; 0 for r₁ = 0 (∫ dr/r² diverges, the
/// limit of β′ is 0); NaN where it does not exist (r₁ < 0, r₂ ≤ r₁, C not positive, a value
/// not finite).
pub fn backscatter_factor(r1_m: f64, r2_m: f64, lidar_constant_j_m2: f64) -> f64 {
    let finite = r1_m.is_finite() && r2_m.is_finite() && lidar_constant_j_m2.is_finite();
    if !(finite && r1_m >= 0.0 && r2_m > r1_m && lidar_constant_j_m2 > 0.0) {
        return f64::NAN;
    }
    // r₁ (r₂/Δr) first, then /C: no product of two ranges (≤ 1e8 m) can overflow, and a
    // tiny r₁ (a gate starting at 1e-297 m) gives a tiny factor, not an underflow to NaN.
    r1_m * (r2_m / (r2_m - r1_m)) / lidar_constant_j_m2
}

/// Attenuated backscatter and range-corrected signal on the grid of one set of returns
/// (module documentation), with their standard errors. Values are indexed as the returns'
/// ([`Returns::index`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Backscatter {
    /// Monte Carlo or analytic.
    pub source: Source,
    /// Channel names, as the returns'.
    pub channels: Vec<String>,
    /// Receiver fields of view, full angles \[mrad\].
    pub fov_full_angle_mrad: Vec<f64>,
    /// Gate centres \[m\].
    pub range_m: Vec<f64>,
    /// Order bins, as the returns'.
    pub orders: Vec<Order>,
    /// The lidar constant of each channel \[J m²\] (NaN where unknown).
    pub lidar_constant_j_m2: Vec<f64>,
    /// β′ \[m⁻¹ sr⁻¹\] (Eq. B1).
    pub attenuated_backscatter_per_m_sr: Vec<f64>,
    /// Standard error of β′ \[m⁻¹ sr⁻¹\] (0 for analytic returns).
    pub attenuated_backscatter_stderr_per_m_sr: Vec<f64>,
    /// E · r_c² \[J m²\].
    pub range_corrected_signal_j_m2: Vec<f64>,
    /// Standard error of the range-corrected signal \[J m²\].
    pub range_corrected_signal_stderr_j_m2: Vec<f64>,
}

impl Backscatter {
    /// β′ and the range-corrected signal of every bin of `returns`, whose gate g is
    /// [r₁, r₂] = [start + g w, r₁ + w] of `gates` (the edges the lidar equation integrates
    /// over, `crate::lidar_eq`), and the lidar constant of each of its channels
    /// (`lidar_constant_j_m2[k]` for channel k; a channel without one gets NaN β′).
    pub fn of(returns: &Returns, gates: &Gates, lidar_constant_j_m2: &[f64]) -> Backscatter {
        let nch = returns.channels.len();
        let constants: Vec<f64> = (0..nch)
            .map(|k| lidar_constant_j_m2.get(k).copied().unwrap_or(f64::NAN))
            .collect();
        let n = returns.energy_j.len();
        let mut out = Backscatter {
            source: returns.source,
            channels: returns.channels.clone(),
            fov_full_angle_mrad: returns.fov_full_angle_mrad.clone(),
            range_m: returns.range_m.clone(),
            orders: returns.orders.clone(),
            lidar_constant_j_m2: constants.clone(),
            attenuated_backscatter_per_m_sr: vec![f64::NAN; n],
            attenuated_backscatter_stderr_per_m_sr: vec![f64::NAN; n],
            range_corrected_signal_j_m2: vec![f64::NAN; n],
            range_corrected_signal_stderr_j_m2: vec![f64::NAN; n],
        };
        for (k, c) in constants.iter().enumerate() {
            for f in 0..returns.fov_full_angle_mrad.len() {
                for (g, r) in returns.range_m.iter().enumerate() {
                    let r1 = gates.start_m + g as f64 * gates.width_m;
                    let beta_factor = backscatter_factor(r1, r1 + gates.width_m, *c);
                    let rcs_factor = r * r;
                    for o in 0..returns.orders.len() {
                        let i = returns.index(k, f, g, o);
                        let (Some(e), Some(se)) =
                            (returns.energy_j.get(i), returns.stderr_j.get(i))
                        else {
                            continue;
                        };
                        // Linear in E: the errors scale by the same factor (no covariance term).
                        out.attenuated_backscatter_per_m_sr[i] = beta_factor * e;
                        out.attenuated_backscatter_stderr_per_m_sr[i] = beta_factor * se;
                        out.range_corrected_signal_j_m2[i] = rcs_factor * e;
                        out.range_corrected_signal_stderr_j_m2[i] = rcs_factor * se;
                    }
                }
            }
        }
        out
    }

    /// Flat index of (channel, fov, gate, order bin), as [`Returns::index`].
    #[inline]
    pub fn index(&self, channel: usize, fov: usize, gate: usize, order: usize) -> usize {
        ((channel * self.fov_full_angle_mrad.len() + fov) * self.range_m.len() + gate)
            * self.orders.len()
            + order
    }

    /// β′ of one bin, its order looked up by value; `None` where the returns have no such bin.
    pub fn attenuated_backscatter(
        &self,
        channel: usize,
        fov: usize,
        gate: usize,
        order: Order,
    ) -> Option<f64> {
        let o = self.orders.iter().position(|x| *x == order)?;
        if channel >= self.channels.len()
            || fov >= self.fov_full_angle_mrad.len()
            || gate >= self.range_m.len()
        {
            return None;
        }
        self.attenuated_backscatter_per_m_sr
            .get(self.index(channel, fov, gate, o))
            .copied()
    }

    /// The CSV rows (no header) of `backscatter.csv`, one per bin, ordered as `returns.csv`'s
    /// (channel, FOV, gate, order), with `polarisation` in the last column ([`CSV_HEADER`]).
    pub fn csv_rows(&self, out: &mut String, polarisation: &str) {
        let src = self.source.label();
        let labels: Vec<String> = self.orders.iter().map(|o| o.label()).collect();
        for (c, ch) in self.channels.iter().enumerate() {
            let name = csv_field(ch);
            let constant = self.lidar_constant_j_m2[c];
            for (f, fov) in self.fov_full_angle_mrad.iter().enumerate() {
                for (g, r) in self.range_m.iter().enumerate() {
                    for (o, label) in labels.iter().enumerate() {
                        let i = self.index(c, f, g, o);
                        let _ = writeln!(
                            out,
                            "{src},{name},{fov},{r},{label},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{polarisation}",
                            csv_number(self.attenuated_backscatter_per_m_sr[i]),
                            csv_number(self.attenuated_backscatter_stderr_per_m_sr[i]),
                            csv_number(self.range_corrected_signal_j_m2[i]),
                            csv_number(self.range_corrected_signal_stderr_j_m2[i]),
                            csv_number(constant),
                        );
                    }
                }
            }
        }
    }
}

/// The header line of `backscatter.csv`: the grid columns of `returns.csv`, then β′ and the
/// range-corrected signal with their standard errors, the lidar constant, and `polarisation`.
pub const CSV_HEADER: &str = "source,channel,fov_full_angle_mrad,range_m,order,\
attenuated_backscatter_per_m_sr,attenuated_backscatter_stderr_per_m_sr,\
range_corrected_signal_j_m2,range_corrected_signal_stderr_j_m2,lidar_constant_j_m2,polarisation";

/// Several sets, each with its `polarisation` label (`total`, `co`, `cross`), as the text of
/// `backscatter.csv` (header and rows).
pub fn to_csv(sets: &[(&Backscatter, &str)]) -> String {
    let mut s = String::with_capacity(1 << 20);
    s.push_str(CSV_HEADER);
    s.push('\n');
    for (b, label) in sets {
        b.csv_rows(&mut s, label);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const GATES: Gates = Gates {
        start_m: 1000.0,
        width_m: 10.0,
        count: 2,
    };

    fn returns(orders: Vec<Order>) -> Returns {
        let mut r = Returns::zeros(
            Source::MonteCarlo,
            vec!["a".into(), "b".into()],
            vec![1.0],
            vec![1005.0, 1015.0],
            orders,
        );
        for (i, e) in r.energy_j.iter_mut().enumerate() {
            *e = 1e-12 * (i + 1) as f64;
        }
        for (i, s) in r.stderr_j.iter_mut().enumerate() {
            *s = 1e-14 * (i + 1) as f64;
        }
        r
    }

    /// Eq. B1 against numbers worked by hand: gate [1000, 1010] m, C = 2 J m² → f =
    /// 1000 · 1010 / (10 · 2) = 50 500; the gate [1010, 1020], f = 1010 · 1020 / 20 = 51 510.
    /// RCS = E · 1005², E · 1015². Errors scale by the same factors. Orders found by value,
    /// wherever they sit in the list (a `2+` bin between others).
    #[test]
    fn backscatter_and_rcs_by_hand() {
        let orders = vec![
            Order::Total,
            Order::Exactly(1),
            Order::AtLeast(2),
            Order::Exactly(2),
        ];
        let r = returns(orders);
        let b = Backscatter::of(&r, &GATES, &[2.0, 4.0]);
        for (k, c) in [2.0, 4.0].iter().enumerate() {
            for (g, (r1, r2, rc)) in [(1000.0, 1010.0, 1005.0), (1010.0, 1020.0, 1015.0)]
                .iter()
                .enumerate()
            {
                for (o, order) in r.orders.iter().enumerate() {
                    let i = r.index(k, 0, g, o);
                    let f = r1 * r2 / (10.0 * c);
                    let near = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-15;
                    assert!(near(
                        b.attenuated_backscatter_per_m_sr[i],
                        f * r.energy_j[i]
                    ));
                    assert!(near(
                        b.attenuated_backscatter_stderr_per_m_sr[i],
                        f * r.stderr_j[i]
                    ));
                    assert!(near(
                        b.range_corrected_signal_j_m2[i],
                        rc * rc * r.energy_j[i]
                    ));
                    assert!(near(
                        b.range_corrected_signal_stderr_j_m2[i],
                        rc * rc * r.stderr_j[i]
                    ));
                    assert_eq!(
                        b.attenuated_backscatter(k, 0, g, *order),
                        Some(b.attenuated_backscatter_per_m_sr[i])
                    );
                }
            }
        }
        assert_eq!(b.attenuated_backscatter(0, 0, 0, Order::AtLeast(3)), None);
        assert_eq!(b.attenuated_backscatter(2, 0, 0, Order::Total), None);
        assert_eq!(b.attenuated_backscatter(0, 0, 2, Order::Total), None);
    }

    /// No value where none exists: a channel without a lidar constant, a gate reaching r < 0,
    /// an empty gate, a zero or infinite constant: NaN (an empty field), never ±inf; the CSV
    /// has no `NaN`. A gate starting at r₁ = 0 has β′ = 0 (∫ dr/r² diverges), one starting at
    /// 1e-297 m a factor of about 1e-297 (found by the scene fuzzer: r_c − Δr/2 rounds to 0).
    #[test]
    fn values_that_do_not_exist_are_nan_and_empty_fields() {
        assert!(backscatter_factor(-1.0, 10.0, 1.0).is_nan());
        assert!(backscatter_factor(10.0, 10.0, 1.0).is_nan());
        assert!(backscatter_factor(100.0, 110.0, 0.0).is_nan());
        assert!(backscatter_factor(100.0, 110.0, f64::INFINITY).is_nan());
        assert!(backscatter_factor(f64::NAN, 110.0, 1.0).is_nan());
        assert_eq!(backscatter_factor(0.0, 10.0, 1.0), 0.0);
        let tiny = backscatter_factor(1e-297, 10.0 + 1e-297, 2.0);
        assert!((tiny / 0.5e-297 - 1.0).abs() < 1e-12, "{tiny}");
        assert_eq!(backscatter_factor(5.0, 15.0, 1.0), 5.0 * 15.0 / 10.0);
        let r = returns(vec![Order::Total]);
        let b = Backscatter::of(&r, &GATES, &[1.0]);
        for (i, v) in b.attenuated_backscatter_per_m_sr.iter().enumerate() {
            assert_eq!(v.is_nan(), i >= 2, "{i}: {v}");
            assert!(b.range_corrected_signal_j_m2[i].is_finite());
        }
        let text = to_csv(&[(&b, "total")]);
        assert_eq!(text.lines().count(), 5);
        assert!(!text.to_ascii_lowercase().contains("nan"), "{text}");
        let fields: Vec<&str> = text.lines().nth(3).unwrap().split(',').collect();
        assert_eq!(fields.len(), CSV_HEADER.split(',').count());
        assert_eq!(fields[1], "b");
        // No constant for `b`: no β′ (nor C); its range-corrected signal needs none.
        assert_eq!([fields[5], fields[6], fields[9]], ["", "", ""]);
        let rcs: f64 = fields[7].parse().unwrap();
        assert!(
            (rcs / (3e-12 * 1005.0 * 1005.0) - 1.0).abs() < 1e-9,
            "{rcs}"
        );
        assert_eq!(fields[10], "total");
        assert_eq!(lidar_constant_j_m2(2.0, 0.5, 3.0), 3.0);
    }
}
