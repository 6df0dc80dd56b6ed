//! Jacobians: derivatives of the Monte Carlo returns with respect to each layer's absorption,
//! scattering, extinction and gas amount, with their standard errors, and their CSV form
//! (`jacobians.csv`). Plain data: the transport fills it (`transport::jacobian`, where the
//! estimators are), the retrieval's weighting functions and the writers read it.

use crate::returns::Order;

/// Quantities per (layer, channel): [`JacobianQuantity::ALL`].
pub const QUANTITIES: usize = 5;
const QR: usize = QUANTITIES;

/// What a derivative is taken with respect to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JacobianQuantity {
    /// The layer's absorption coefficient (gas and particles alike) [1/m].
    Absorption,
    /// The layer's molecular (Rayleigh) scattering coefficient [1/m].
    MolecularScattering,
    /// The scattering coefficient of the layer's particles, all species in proportion [1/m].
    ParticleScattering,
    /// The particles' extinction coefficient at a fixed single-scattering albedo [1/m].
    ParticleExtinction,
    /// The amount of the line-by-line gases in the layer, relatively: ∂E/∂ln n_gas = the
    /// absorption derivative times the gases' absorption coefficient \[J\] (what a DIAL or
    /// IPDA weighting function is made of).
    GasAmount,
}

impl JacobianQuantity {
    /// Every quantity, in the order of [`Jacobians::index`].
    pub const ALL: [JacobianQuantity; 5] = [
        JacobianQuantity::Absorption,
        JacobianQuantity::MolecularScattering,
        JacobianQuantity::ParticleScattering,
        JacobianQuantity::ParticleExtinction,
        JacobianQuantity::GasAmount,
    ];

    /// The `quantity` column value.
    pub fn label(self) -> &'static str {
        match self {
            JacobianQuantity::Absorption => "absorption",
            JacobianQuantity::MolecularScattering => "molecular_scattering",
            JacobianQuantity::ParticleScattering => "particle_scattering",
            JacobianQuantity::ParticleExtinction => "particle_extinction",
            JacobianQuantity::GasAmount => "gas_amount",
        }
    }

    /// The unit of the derivative.
    pub fn unit(self) -> &'static str {
        match self {
            JacobianQuantity::GasAmount => "J",
            _ => "J m",
        }
    }

    /// The suffix of `jacobians.csv`'s value columns of this quantity (its unit):
    /// `j_m` for ∂E/∂θ with θ in 1/m, `j` for `gas_amount` (per relative change).
    pub fn column_suffix(self) -> &'static str {
        match self {
            JacobianQuantity::GasAmount => "j",
            _ => "j_m",
        }
    }
}

/// The units of `jacobians.csv`'s value columns, by their suffix, in column order.
pub const CSV_UNIT_SUFFIXES: [&str; 2] = ["j_m", "j"];

/// Derivatives of the Monte Carlo returns with respect to layer properties, with standard
/// errors from the same batches as the returns: ∂E/∂θ \[J·m\] (energy per unit coefficient
/// in 1/m) per channel, FOV, gate, order (total, 1, 2+), layer and quantity.
#[derive(Debug, Clone, PartialEq)]
pub struct Jacobians {
    /// Channel names.
    pub channels: Vec<String>,
    /// Fields of view (full angles) \[mrad\].
    pub fov_full_angle_mrad: Vec<f64>,
    /// Gate centres \[m\].
    pub range_m: Vec<f64>,
    /// Order bins: total, 1 and 2+.
    pub orders: Vec<Order>,
    /// Index in the optical atmosphere of the first layer reported: the layers are those a
    /// path can reach within the last gate's time (the others' derivatives are exactly 0).
    pub first_layer: usize,
    /// Bottom of each layer reported \[m\].
    pub layer_bottom_m: Vec<f64>,
    /// Top of each layer \[m\].
    pub layer_top_m: Vec<f64>,
    /// ∂E/∂θ \[J·m\], index [`Jacobians::index`].
    pub value: Vec<f64>,
    /// Standard error of `value` \[J·m\].
    pub stderr: Vec<f64>,
    /// Whether a derivative exists, index `(layer * 5 + quantity) * channels + channel`:
    /// absorption always; scattering and extinction where the layer has that scatterer, gas
    /// amount where it has line-by-line gas absorption.
    pub defined: Vec<bool>,
}

impl Jacobians {
    /// Flat index of (channel, FOV, gate, order bin, layer, quantity).
    pub fn index(
        &self,
        channel: usize,
        fov: usize,
        gate: usize,
        order: usize,
        layer: usize,
        quantity: usize,
    ) -> usize {
        ((((channel * self.fov_full_angle_mrad.len() + fov) * self.range_m.len() + gate)
            * self.orders.len()
            + order)
            * self.layer_bottom_m.len()
            + layer)
            * QR
            + quantity
    }

    /// Whether the derivative of `quantity` in `layer` exists for `channel`.
    pub fn is_defined(&self, channel: usize, layer: usize, quantity: usize) -> bool {
        self.defined[(layer * QR + quantity) * self.channels.len() + channel]
    }

    /// One derivative and its standard error, if defined.
    pub fn get(
        &self,
        channel: usize,
        fov: usize,
        gate: usize,
        order: Order,
        layer: usize,
        quantity: JacobianQuantity,
    ) -> Option<(f64, f64)> {
        let o = self.orders.iter().position(|x| *x == order)?;
        let q = JacobianQuantity::ALL.iter().position(|x| *x == quantity)?;
        if !self.is_defined(channel, layer, q) {
            return None;
        }
        let i = self.index(channel, fov, gate, o, layer, q);
        Some((self.value[i], self.stderr[i]))
    }
}

/// The header line of `jacobians.csv`: each row's derivative and error in the two columns of
/// its quantity's unit (`derivative_j_m`, `stderr_j_m`; `gas_amount`: `derivative_j`,
/// `stderr_j`), the other unit's columns empty, so that no column holds two units.
pub const CSV_HEADER: &str = "source,channel,fov_full_angle_mrad,range_m,order,layer,\
layer_bottom_m,layer_top_m,quantity,derivative_j_m,stderr_j_m,derivative_j,stderr_j";

impl Jacobians {
    /// `jacobians.csv`: one row per defined, nonzero derivative (a layer the gate's photons
    /// cannot reach in time has none), ordered by channel, FOV, gate, order,
    /// layer and quantity; ∂E/∂θ in J per (1/m), i.e. J·m, in the `_j_m` columns
    /// (`gas_amount`: J per unit relative change, in the `_j` columns).
    pub fn to_csv(&self) -> String {
        use crate::output::{csv_field, csv_number};
        use std::fmt::Write as _;
        let mut out = String::with_capacity(1 << 16);
        out.push_str(CSV_HEADER);
        out.push('\n');
        let labels: Vec<String> = self.orders.iter().map(|o| o.label()).collect();
        for (c, ch) in self.channels.iter().enumerate() {
            let ch = csv_field(ch);
            for (f, fov) in self.fov_full_angle_mrad.iter().enumerate() {
                for (g, r) in self.range_m.iter().enumerate() {
                    for (o, label) in labels.iter().enumerate() {
                        for l in 0..self.layer_bottom_m.len() {
                            for (q, quantity) in JacobianQuantity::ALL.iter().enumerate() {
                                if !self.is_defined(c, l, q) {
                                    continue;
                                }
                                let i = self.index(c, f, g, o, l, q);
                                // Paths that cannot reach the gate in time: exactly zero.
                                if self.value[i] == 0.0 && self.stderr[i] == 0.0 {
                                    continue;
                                }
                                let _ = write!(
                                    out,
                                    "mc,{ch},{fov},{r},{label},{},{},{},{}",
                                    self.first_layer + l,
                                    self.layer_bottom_m[l],
                                    self.layer_top_m[l],
                                    quantity.label(),
                                );
                                for suffix in CSV_UNIT_SUFFIXES {
                                    if suffix == quantity.column_suffix() {
                                        let _ = write!(
                                            out,
                                            ",{:.9e},{:.9e}",
                                            csv_number(self.value[i]),
                                            csv_number(self.stderr[i])
                                        );
                                    } else {
                                        out.push_str(",,");
                                    }
                                }
                                out.push('\n');
                            }
                        }
                    }
                }
            }
        }
        out
    }
}

impl Jacobians {
    /// The first `n` channels (a run's laser lines, which come before the combinations that
    /// differentiate them in frequency).
    pub fn first_channels(&self, n: usize) -> Jacobians {
        let n = n.min(self.channels.len());
        let per = self.value.len() / self.channels.len().max(1);
        let m = self.channels.len();
        let nl = self.layer_bottom_m.len();
        let mut defined = Vec::with_capacity(nl * QR * n);
        for lq in 0..nl * QR {
            defined.extend_from_slice(&self.defined[lq * m..lq * m + n]);
        }
        Jacobians {
            channels: self.channels[..n].to_vec(),
            value: self.value[..n * per].to_vec(),
            stderr: self.stderr[..n * per].to_vec(),
            defined,
            ..self.clone()
        }
    }
}
