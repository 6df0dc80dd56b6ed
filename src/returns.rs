//! Received energy by channel, field of view, range gate and scattering order: the common
//! output of the Monte Carlo transport and the analytic lidar equation, and its CSV form.
//!
//! **contract** (DESIGN §4): `returns.csv` has the columns
//! `source,channel,fov_full_angle_mrad,range_m,order,energy_j,stderr_j`.

use std::fmt::Write as _;
use std::io;
use std::path::Path;

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
    /// The `order` column value: `total`, `1`, `2`, …, `N+`.
    pub fn label(self) -> String {
        match self {
            Order::Total => "total".into(),
            Order::Exactly(n) => n.to_string(),
            Order::AtLeast(n) => format!("{n}+"),
        }
    }
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
        }
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

    /// The CSV rows (no header), one per bin, ordered by channel, FOV, gate, order.
    pub fn csv_rows(&self, out: &mut String) {
        let src = self.source.label();
        let labels: Vec<String> = self.orders.iter().map(|o| o.label()).collect();
        for (c, ch) in self.channels.iter().enumerate() {
            for (f, fov) in self.fov_full_angle_mrad.iter().enumerate() {
                for (g, r) in self.range_m.iter().enumerate() {
                    for (o, label) in labels.iter().enumerate() {
                        let i = self.index(c, f, g, o);
                        let _ = writeln!(
                            out,
                            "{src},{ch},{fov},{r},{label},{:.9e},{:.9e}",
                            self.energy_j[i], self.stderr_j[i]
                        );
                    }
                }
            }
        }
    }
}

/// The header line of `returns.csv`.
pub const CSV_HEADER: &str = "source,channel,fov_full_angle_mrad,range_m,order,energy_j,stderr_j";

/// Write several sets of returns to one CSV file, through a temporary file and a rename so that
/// a failed run never leaves a half-written file.
pub fn write_csv(path: &Path, sets: &[&Returns]) -> io::Result<()> {
    let mut s = String::with_capacity(1 << 20);
    s.push_str(CSV_HEADER);
    s.push('\n');
    for r in sets {
        r.csv_rows(&mut s);
    }
    let tmp = path.with_extension("csv.tmp");
    std::fs::write(&tmp, s)?;
    std::fs::rename(&tmp, path)
}
