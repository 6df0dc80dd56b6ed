//! Where a value falls in a non-decreasing table (the layer edges, a scattering class's
//! cumulative optical depths) in a few comparisons instead of a binary search through hundreds
//! of entries: a space lidar's photon enters 800 layers from the top, and its first collision,
//! a flight cut by the last gate or a cone estimate's point far from the collision it starts
//! from each needed such a search (9 % of a 16-channel default scene's transport).

/// A uniform grid over a table's range whose cells hold the table's interval at their lower
/// end; a query starts there and steps to its interval (bucketed search).
#[derive(Debug, Clone)]
pub(crate) struct TableIndex {
    lo: f64,
    inv_h: f64,
    start: Vec<u32>,
}

/// Grid cells per table interval.
const CELLS_PER_INTERVAL: usize = 4;

impl TableIndex {
    /// The index of table `v` (non-decreasing, at least two entries: `v.len() − 1` intervals).
    pub(crate) fn new(v: &[f64]) -> Self {
        let n = v.len().saturating_sub(1).max(1);
        let (lo, hi) = (
            v.first().copied().unwrap_or(0.0),
            v.last().copied().unwrap_or(0.0),
        );
        let cells = n * CELLS_PER_INTERVAL;
        let h = (hi - lo) / cells as f64;
        if !(h > 0.0 && h.is_finite() && lo.is_finite()) {
            return TableIndex {
                lo: 0.0,
                inv_h: 0.0,
                start: vec![0],
            };
        }
        let start = (0..cells)
            .map(|i| {
                let x = lo + i as f64 * h;
                v.partition_point(|e| *e <= x).saturating_sub(1).min(n - 1) as u32
            })
            .collect();
        TableIndex {
            lo,
            inv_h: 1.0 / h,
            start,
        }
    }

    /// The interval l of `v` (the table it was built from) that `below` puts x in:
    /// `v.partition_point(below) − 1`, clamped to the intervals 0..n − 1, for a predicate
    /// `below(e)` true of the entries before x (e ≤ x or e < x), so monotone on the table. The
    /// same index as that binary search whatever cell the query starts from; the grid only
    /// makes the walk short.
    #[inline]
    pub(crate) fn find(&self, v: &[f64], x: f64, below: impl Fn(f64) -> bool) -> usize {
        let n = v.len().saturating_sub(1);
        if n <= 1 {
            return 0;
        }
        let mut l = self.start_of(x, n);
        while l > 0 && !below(v[l]) {
            l -= 1;
        }
        while l + 1 < n && below(v[l + 1]) {
            l += 1;
        }
        l
    }

    /// The interval a query for x starts from (of n): the one at the lower end of x's cell.
    #[inline]
    fn start_of(&self, x: f64, n: usize) -> usize {
        let c = (x - self.lo) * self.inv_h;
        // A float-to-integer cast saturates (NaN to 0): any cell is a correct start.
        let cell = (c as usize).min(self.start.len() - 1);
        // Never binding for the table the index was built from: a query against another one
        // stays in bounds.
        (self.start[cell] as usize).min(n - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid is sharp where the table is even: on 800 layers of 100 m (the default scene's,
    /// from sea level and from a ground 1.5 km up) every query starts in its own interval or the
    /// next one down, so the walk is one step at most; and a table's index covers its range
    /// with 4 cells an interval.
    #[test]
    fn queries_start_next_to_their_interval() {
        for bottom in [0.0, 1500.0] {
            let v: Vec<f64> = (0..=800).map(|i| bottom + 100.0 * i as f64).collect();
            let idx = TableIndex::new(&v);
            assert_eq!(idx.start.len(), 3200);
            assert_eq!((idx.lo, idx.inv_h), (bottom, 1.0 / 25.0));
            for i in 0..=160_000 {
                let z = bottom + 0.5 * i as f64;
                let want = v.partition_point(|e| *e <= z).saturating_sub(1).min(799);
                let start = idx.start_of(z, 800);
                assert!(
                    start <= want && want <= start + 1,
                    "z {z}: start {start}, interval {want}"
                );
            }
        }
    }

    /// The same interval as the binary search over the whole table, for both predicates, on
    /// tables with repeated entries (layers that do not scatter), very uneven intervals (thin
    /// air above a cloud), one interval, and values outside, on and between the entries.
    #[test]
    fn finds_what_a_binary_search_finds() {
        let tables: Vec<Vec<f64>> = vec![
            (0..=800).map(|i| 100.0 * i as f64).collect(),
            vec![0.0, 1e-9, 1e-9, 2e-9, 0.05, 0.05, 0.0750001, 0.076, 0.076],
            vec![3.0, 7.0],
            vec![0.0, 0.0, 0.0],
            (0..=50).map(|i| (i as f64 * 0.37).exp()).collect(),
        ];
        for v in &tables {
            let idx = TableIndex::new(v);
            let n = v.len() - 1;
            let mut xs: Vec<f64> = v
                .iter()
                .flat_map(|e| [*e, e.next_up(), e.next_down()])
                .collect();
            let (lo, hi) = (v[0], v[n]);
            xs.extend((0..=997).map(|i| lo - 1.0 + (hi - lo + 2.0) * i as f64 / 997.0));
            xs.extend([f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1e300, 1e300]);
            for x in xs {
                for strict in [false, true] {
                    let below = |e: f64| if strict { e < x } else { e <= x };
                    let want = v
                        .partition_point(|e| below(*e))
                        .saturating_sub(1)
                        .min(n - 1);
                    assert_eq!(
                        idx.find(v, x, below),
                        want,
                        "x = {x}, strict {strict}, {v:?}"
                    );
                }
            }
        }
    }
}
