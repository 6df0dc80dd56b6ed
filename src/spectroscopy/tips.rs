//! Total internal partition sums Q(T) from TIPS-2021.
//!
//! Q(T) on the native TIPS-2021 temperature grids (1 K, then every 10 K) of Gamache et al.
//! (2021)[^1] for every isotopologue of H2O, CO2, O3, N2O, CO, CH4 and O2, as embedded in HAPI 1.3
//! and copied to `data/tips/tips2021_q.csv` by `validation/hapi_tips/make_tables.py`, up to
//! 1000 K and one grid point beyond. Between grid points Q is interpolated exactly as HAPI's
//! `partitionSum` does (4-point Lagrange, 3-point in the first and last interval of HAPI's grid;
//! HAPI `AtoB`), so lidarsim's Q(T) equals HAPI's to rounding up to 1000 K: the point beyond
//! 1000 K is there for the 4-point interpolation between 990 and 1000 K, which a table ending at
//! 1000 K would make through 3 points (2.5e-6 from HAPI's). Both Q(296 K) of the intensity
//! scaling and Q(T) come from this one table.
//!
//! [^1]: R. R. Gamache et al. (2021), "Total internal partition sums for the HITRAN2020 database",
//!     JQSRT 271, 107713, doi:10.1016/j.jqsrt.2021.107713.

use std::collections::HashMap;
use std::sync::OnceLock;

use super::SpectroscopyError;
use crate::input::{CsvTable, InputError};

const EMBEDDED: &str = include_str!("../../data/tips/tips2021_q.csv");
const EMBEDDED_NAME: &str = "<embedded data/tips/tips2021_q.csv>";
/// Upper end of the temperatures served: the embedded grids' last point lies beyond it.
const MAX_TEMPERATURE_K: f64 = 1000.0;

/// The TIPS grid of one isotopologue.
#[derive(Debug, Clone)]
pub struct TipsGrid {
    /// Temperatures \[K\], strictly increasing.
    pub temperature_k: Vec<f64>,
    /// Q at those temperatures.
    pub q: Vec<f64>,
}

fn parse(text: &str) -> Result<HashMap<(u8, u8), TipsGrid>, InputError> {
    let t = CsvTable::parse(EMBEDDED_NAME, text)?;
    let c_m = t.column("molecule_id")?;
    let c_i = t.column("local_iso_id")?;
    let c_t = t.column("T_K")?;
    let c_q = t.column("Q")?;
    let mut map: HashMap<(u8, u8), TipsGrid> = HashMap::new();
    for row in 0..t.len() {
        let m = t.f64_at(row, c_m)? as u8;
        let i = t.f64_at(row, c_i)? as u8;
        let g = map.entry((m, i)).or_insert(TipsGrid {
            temperature_k: vec![],
            q: vec![],
        });
        let temp = t.f64_at(row, c_t)?;
        if g.temperature_k.last().is_some_and(|&last| temp <= last) {
            return Err(InputError::at(
                EMBEDDED_NAME,
                t.line_of(row),
                "T_K",
                "temperatures must increase",
            ));
        }
        g.temperature_k.push(temp);
        g.q.push(t.f64_at(row, c_q)?);
    }
    Ok(map)
}

/// The embedded TIPS-2021 grids, by (molecule number, local isotopologue number).
pub fn grids() -> &'static HashMap<(u8, u8), TipsGrid> {
    static TABLE: OnceLock<HashMap<(u8, u8), TipsGrid>> = OnceLock::new();
    // Part of the build; checked by the unit tests below.
    TABLE.get_or_init(|| parse(EMBEDDED).expect("embedded TIPS table parses"))
}

/// Total internal partition sum Q(T) of an isotopologue (TIPS-2021, Gamache et al. 2021).
///
/// `temperature_k` must lie within 1–1000 K (or the isotopologue's grid, where it ends
/// sooner); outside, or for an isotopologue without a table, the error says so. Interpolation as
/// HAPI 1.3 `partitionSum`.
pub fn partition_sum(
    molecule_id: u8,
    iso_id: u8,
    temperature_k: f64,
) -> Result<f64, SpectroscopyError> {
    let err = |reason: String| SpectroscopyError::PartitionSum {
        molecule_id,
        iso_id,
        temperature_k,
        reason,
    };
    let g = grids()
        .get(&(molecule_id, iso_id))
        .ok_or_else(|| err("isotopologue not in the embedded table".into()))?;
    let (lo, hi) = (
        g.temperature_k[0],
        g.temperature_k
            .last()
            .unwrap_or(&0.0)
            .min(MAX_TEMPERATURE_K),
    );
    if !(temperature_k >= lo && temperature_k <= hi) {
        return Err(err(format!("outside the table's range {lo}–{hi} K")));
    }
    Ok(lagrange_like_hapi(temperature_k, &g.temperature_k, &g.q))
}

/// HAPI's `AtoB` interpolation: Lagrange through the 4 grid points around `x` (two on each
/// side), through 3 points in the first and last interval. `xs` strictly increasing, len ≥ 3,
/// `x` within `[xs[0], xs[last]]`.
pub fn lagrange_like_hapi(x: f64, xs: &[f64], ys: &[f64]) -> f64 {
    let n = xs.len();
    // First grid index i >= 1 with xs[i] >= x (HAPI scans from the second point).
    let i = (1..n).find(|&i| xs[i] >= x).unwrap_or(n - 1);
    let nodes: std::ops::Range<usize> = if i < 2 {
        0..3
    } else if i == n - 1 {
        n - 3..n
    } else {
        i - 2..i + 2
    };
    let mut sum = 0.0;
    for a in nodes.clone() {
        let mut w = 1.0;
        for b in nodes.clone() {
            if a != b {
                w *= (x - xs[b]) / (xs[a] - xs[b]);
            }
        }
        sum += w * ys[a];
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn q296_of_co2_626_is_the_published_tips2021_value() {
        // data/tips PROVENANCE: Q626(296 K) = 286.0938 (TIPS-2021); HAPI reference header:
        // 286.09384880000005.
        let q = partition_sum(2, 1, 296.0).unwrap();
        assert!((q - 286.0938488).abs() < 1e-6, "{q}");
    }

    #[test]
    fn grid_points_are_reproduced_and_out_of_range_is_an_error() {
        let g = &grids()[&(1, 1)];
        for (t, q) in g.temperature_k.iter().zip(&g.q) {
            if *t <= MAX_TEMPERATURE_K {
                assert_eq!(partition_sum(1, 1, *t).unwrap(), *q);
            }
        }
        assert!(partition_sum(1, 1, 1000.0).is_ok());
        assert!(partition_sum(1, 1, 1000.5).is_err());
        assert!(partition_sum(1, 1, 1.0).is_ok());
        assert!(partition_sum(1, 1, 0.5).is_err());
        assert!(partition_sum(9, 1, 296.0).is_err());
    }

    #[test]
    fn every_known_isotopologue_has_a_table() {
        for iso in super::super::isotopologues::all() {
            let q = partition_sum(iso.molecule_id, iso.iso_id, 296.0).unwrap();
            assert!(q > 1.0, "{} {}", iso.molecule, iso.afgl_code);
        }
    }
}
