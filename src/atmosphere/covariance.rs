//! Covariances of the atmospheric state for perturbed ensembles.
//!
//! The state vector of a profile with n levels is `x = (T_1..T_n, ln x_H2O,1..n, CO2_1..n, p_s)`
//! in the units K, 1 (natural log of the H2O volume mixing ratio), ppmv (CO2 of moist air) and
//! hPa (surface pressure); levels bottom-up. A [`Covariance`] is a symmetric matrix over
//! [`StateElement`]s. It comes from
//! * (a) a file ([`Covariance::read`], the format of [`Covariance::to_csv`]), on any pressure
//!   grid, projected to a profile's levels with [`Covariance::on_profile`];
//! * (b) per-level standard deviations and vertical correlation lengths ([`ErrorModel`], default
//!   the representative 6-h NWP forecast error in `data/nwp_error`);
//! * (c) forecast-minus-analysis pairs ([`Covariance::from_pairs`], the NWP method).
//!
//! [`Covariance::factor`] gives L with S = L Lᵀ: Cholesky where S is positive definite; otherwise
//! the eigen-decomposition with negative eigenvalues set to zero (the nearest positive
//! semi-definite matrix in the Frobenius norm, Higham 1988), always reported.

use std::fmt;
use std::path::Path;

use nalgebra::{DMatrix, SymmetricEigen};

use super::interp::hybrid_shift_pa;
use super::set::ProfileSet;
use super::{AtmosphereError, Profile};
use crate::input::{CsvTable, InputError, parse_f64, read_to_string};

mod error_model;

pub use error_model::ErrorModel;

/// One variable of the state vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum StateVariable {
    /// Temperature \[K\].
    Temperature,
    /// Natural log of the H2O volume mixing ratio \[1\] (so σ = 0.2 is a 20 % error).
    LnH2o,
    /// CO2 volume mixing ratio of moist air \[ppmv\].
    Co2,
    /// Surface pressure \[hPa\].
    SurfacePressure,
}

impl StateVariable {
    /// All variables in state-vector order.
    pub const ALL: [StateVariable; 4] = [
        Self::Temperature,
        Self::LnH2o,
        Self::Co2,
        Self::SurfacePressure,
    ];

    /// Name in covariance files: `T_K`, `lnq`, `CO2_ppmv`, `ps_hPa`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Temperature => "T_K",
            Self::LnH2o => "lnq",
            Self::Co2 => "CO2_ppmv",
            Self::SurfacePressure => "ps_hPa",
        }
    }

    fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|v| v.name() == s)
    }
}

/// One element of the state vector: a variable at a pressure level (the surface pressure has
/// none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateElement {
    /// The variable.
    pub variable: StateVariable,
    /// The level's pressure \[Pa\]; `None` for the surface pressure.
    pub pressure_pa: Option<f64>,
}

/// A covariance matrix over state elements.
#[derive(Debug, Clone, PartialEq)]
pub struct Covariance {
    /// The elements, in matrix order.
    pub elements: Vec<StateElement>,
    /// The symmetric covariance matrix (units: products of the elements' units).
    pub matrix: DMatrix<f64>,
    /// What was done to build it (for reports and file headers).
    pub notes: Vec<String>,
}

/// The factor L of S = L Lᵀ and what repair, if any, was needed.
#[derive(Debug, Clone)]
pub struct Factor {
    /// L (dimension × dimension); rows of elements with zero variance are zero.
    pub l: DMatrix<f64>,
    /// Set when S was not positive definite and the eigenvalue clipping was used.
    pub repair: Option<RepairReport>,
}

/// How a covariance that was not positive definite was repaired.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RepairReport {
    /// Dimension of the factored part (elements with positive variance).
    pub dimension: usize,
    /// Number of eigenvalues ≤ 0 set to zero.
    pub clipped: usize,
    /// The smallest eigenvalue before repair.
    pub min_eigenvalue: f64,
    /// The largest eigenvalue.
    pub max_eigenvalue: f64,
    /// ‖S_repaired − S‖_F / ‖S‖_F.
    pub relative_change: f64,
}

impl fmt::Display for RepairReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the covariance was not positive definite: {} of {} eigenvalues ≤ 0 (smallest {:.3e}, \
             largest {:.3e}) were set to 0 (nearest positive semi-definite matrix, Higham 1988); \
             relative change of the matrix {:.2e}",
            self.clipped,
            self.dimension,
            self.min_eigenvalue,
            self.max_eigenvalue,
            self.relative_change
        )
    }
}

/// Negative eigenvalues down to this fraction of the largest are rounding, repaired without
/// asking.
pub const ROUNDING_EIGENVALUE_FRACTION: f64 = 1e-10;

impl Covariance {
    /// The state elements of a profile: T, ln H2O and CO2 at each level (bottom-up), then p_s.
    pub fn profile_elements(profile: &Profile) -> Vec<StateElement> {
        let mut e = Vec::with_capacity(3 * profile.len() + 1);
        for v in [
            StateVariable::Temperature,
            StateVariable::LnH2o,
            StateVariable::Co2,
        ] {
            e.extend(profile.pressure_pa.iter().map(|p| StateElement {
                variable: v,
                pressure_pa: Some(*p),
            }));
        }
        e.push(StateElement {
            variable: StateVariable::SurfacePressure,
            pressure_pa: None,
        });
        e
    }

    /// Dimension of the state.
    pub fn dimension(&self) -> usize {
        self.elements.len()
    }

    /// Standard deviation of each element.
    pub fn std_devs(&self) -> Vec<f64> {
        (0..self.dimension())
            .map(|i| self.matrix[(i, i)].max(0.0).sqrt())
            .collect()
    }

    /// True when the elements are exactly those of `profile` ([`Self::profile_elements`]).
    pub fn fits(&self, profile: &Profile) -> bool {
        let e = Self::profile_elements(profile);
        e.len() == self.elements.len()
            && e.iter().zip(&self.elements).all(|(a, b)| {
                a.variable == b.variable
                    && match (a.pressure_pa, b.pressure_pa) {
                        (Some(x), Some(y)) => (x / y - 1.0).abs() < 1e-9,
                        (None, None) => true,
                        _ => false,
                    }
            })
    }

    /// The covariance on `profile`'s state elements: S_p = W S Wᵀ, where each row of W
    /// interpolates a variable linearly in ln p between this covariance's levels of that variable
    /// (held at the end values beyond the first and last level). Variables absent here get zero
    /// rows (not perturbed; said in the notes). W S Wᵀ stays positive semi-definite.
    pub fn on_profile(&self, profile: &Profile) -> Covariance {
        let target = Self::profile_elements(profile);
        let mut w = DMatrix::<f64>::zeros(target.len(), self.dimension());
        let mut notes = self.notes.clone();
        for v in StateVariable::ALL {
            // This covariance's elements of v, sorted by −ln p (increasing).
            let mut src: Vec<(usize, f64)> = self
                .elements
                .iter()
                .enumerate()
                .filter(|(_, e)| e.variable == v)
                .map(|(i, e)| (i, e.pressure_pa.map_or(0.0, |p| -p.ln())))
                .collect();
            src.sort_by(|a, b| a.1.total_cmp(&b.1));
            let rows: Vec<(usize, &StateElement)> = target
                .iter()
                .enumerate()
                .filter(|(_, e)| e.variable == v)
                .collect();
            if src.is_empty() {
                notes.push(format!(
                    "{}: not in the covariance, not perturbed",
                    v.name()
                ));
                continue;
            }
            let mut clamped = false;
            for (r, e) in rows {
                let s = e.pressure_pa.map_or(0.0, |p| -p.ln());
                if src.len() == 1 || s <= src[0].1 {
                    clamped |= src.len() > 1 && s < src[0].1 - 1e-9;
                    w[(r, src[0].0)] = 1.0;
                } else if s >= src[src.len() - 1].1 {
                    clamped |= s > src[src.len() - 1].1 + 1e-9;
                    w[(r, src[src.len() - 1].0)] = 1.0;
                } else {
                    let k = src.partition_point(|x| x.1 <= s) - 1;
                    let t = (s - src[k].1) / (src[k + 1].1 - src[k].1);
                    w[(r, src[k].0)] = 1.0 - t;
                    w[(r, src[k + 1].0)] = t;
                }
            }
            if clamped {
                notes.push(format!(
                    "{}: profile levels outside the covariance's pressure range take the values of its end levels",
                    v.name()
                ));
            }
        }
        let matrix = &w * &self.matrix * w.transpose();
        Covariance {
            elements: target,
            matrix: symmetrize(matrix),
            notes,
        }
    }

    /// Read a covariance file (see `docs/atmosphere.md`): header `variable,p_hPa,c1,...,cN`, then
    /// one row per state element: its variable (`T_K`, `lnq`, `CO2_ppmv`, `ps_hPa`), its level
    /// in hPa (empty for `ps_hPa`) and row i of the matrix. The matrix must be square and
    /// symmetric (to 1e-8 of sqrt(S_ii S_jj)) with a non-negative diagonal.
    pub fn read(path: &Path) -> Result<Covariance, InputError> {
        Self::parse(path, &read_to_string(path)?)
    }

    /// Parse the text of a covariance file (`path` for messages).
    pub fn parse(path: &Path, text: &str) -> Result<Covariance, InputError> {
        let t = CsvTable::parse(path, text)?;
        let cv = t.column("variable")?;
        let cp = t.column("p_hPa")?;
        let n = t.len();
        let value_cols: Vec<usize> = (0..t.header().len())
            .filter(|c| *c != cv && *c != cp)
            .collect();
        if value_cols.len() != n {
            return Err(InputError::file(
                path,
                format!(
                    "{} matrix columns for {n} rows: the matrix must be square",
                    value_cols.len()
                ),
            ));
        }
        let mut elements = Vec::with_capacity(n);
        let mut m = DMatrix::<f64>::zeros(n, n);
        for (i, (line, f)) in t.rows().enumerate() {
            let variable = StateVariable::parse(&f[cv]).ok_or_else(|| {
                InputError::at(
                    path,
                    line,
                    "variable",
                    format!("`{}` is not one of T_K, lnq, CO2_ppmv, ps_hPa", f[cv]),
                )
            })?;
            let pressure_pa = if variable == StateVariable::SurfacePressure {
                None
            } else {
                let p = parse_f64(path, line, "p_hPa", &f[cp])?;
                if !(p > 0.0) {
                    return Err(InputError::at(
                        path,
                        line,
                        "p_hPa",
                        "pressure must be positive",
                    ));
                }
                Some(p * 100.0)
            };
            if elements.iter().any(|e: &StateElement| {
                e.variable == variable
                    && match (e.pressure_pa, pressure_pa) {
                        (Some(a), Some(b)) => a == b,
                        _ => true,
                    }
            }) {
                return Err(InputError::at(
                    path,
                    line,
                    "variable",
                    "this element appears twice",
                ));
            }
            elements.push(StateElement {
                variable,
                pressure_pa,
            });
            for (j, c) in value_cols.iter().enumerate() {
                m[(i, j)] = parse_f64(path, line, &t.header()[*c], &f[*c])?;
            }
            if m[(i, i)] < 0.0 {
                return Err(InputError::at(
                    path,
                    line,
                    &t.header()[value_cols[i]],
                    "negative variance",
                ));
            }
        }
        for i in 0..n {
            for j in 0..i {
                let tol = 1e-8 * (m[(i, i)] * m[(j, j)]).sqrt() + 1e-300;
                if (m[(i, j)] - m[(j, i)]).abs() > tol {
                    return Err(InputError::at(
                        path,
                        t.line_of(i),
                        &t.header()[value_cols[j]],
                        format!(
                            "the matrix is not symmetric: S[{}][{}] = {} but S[{}][{}] = {}",
                            i + 1,
                            j + 1,
                            m[(i, j)],
                            j + 1,
                            i + 1,
                            m[(j, i)]
                        ),
                    ));
                }
            }
        }
        Ok(Covariance {
            elements,
            matrix: symmetrize(m),
            notes: vec![format!("covariance from {}", path.display())],
        })
    }

    /// The covariance as a file readable by [`Self::read`] (full precision).
    pub fn to_csv(&self) -> String {
        let mut out = String::from("# lidarsim covariance (format: docs/atmosphere.md)\n");
        for n in &self.notes {
            out.push_str(&format!("# {n}\n"));
        }
        out.push_str("variable,p_hPa");
        for j in 0..self.dimension() {
            out.push_str(&format!(",c{}", j + 1));
        }
        out.push('\n');
        for (i, e) in self.elements.iter().enumerate() {
            out.push_str(e.variable.name());
            out.push(',');
            if let Some(p) = e.pressure_pa {
                out.push_str(&format!("{}", p / 100.0));
            }
            for j in 0..self.dimension() {
                out.push_str(&format!(",{:e}", self.matrix[(i, j)]));
            }
            out.push('\n');
        }
        out
    }

    /// Estimate the covariance from forecast-minus-analysis pairs (the NWP method: 6-h forecasts
    /// checked against the analysis valid at the same time), on the levels of `grid` (usually
    /// the mean profile the ensemble will perturb).
    ///
    /// Pairs are matched by profile id. Each profile is interpolated (ln p) to `grid`'s levels
    /// moved to its own surface pressure ([`hybrid_shift_pa`]), so differences are taken
    /// level-following; `d = x_f − x_a` in (T, ln H2O, CO2 ppmv, p_s hPa). The mean difference
    /// (the bias) is removed: S = Σ (d − d̄)(d − d̄)ᵀ / (N − 1). A variable missing from the
    /// profiles gets zero rows. With `localization_lnp`, S is multiplied element-wise by
    /// exp(−(ln p_i − ln p_j)²/(2 L²)) (Schur product; keeps S positive semi-definite and
    /// damps spurious long-range sample correlations). With fewer pairs than state elements S is
    /// singular; [`Self::factor`] then repairs it (reported).
    ///
    /// Returns the covariance and the bias d̄.
    pub fn from_pairs(
        forecast: &ProfileSet,
        analysis: &ProfileSet,
        grid: &Profile,
        localization_lnp: Option<f64>,
    ) -> Result<(Covariance, Vec<f64>), AtmosphereError> {
        grid.validate()?;
        let elements = Self::profile_elements(grid);
        let dim = elements.len();
        let has = |s: &ProfileSet, g: &str| s.members.iter().all(|m| m.profile.gas(g).is_some());
        let use_h2o = has(forecast, "H2O") && has(analysis, "H2O");
        let use_co2 = has(forecast, "CO2") && has(analysis, "CO2");
        let mut diffs: Vec<Vec<f64>> = Vec::new();
        for f in &forecast.members {
            let a = analysis.member(&f.meta.id).ok_or_else(|| {
                AtmosphereError::Covariance(format!(
                    "forecast profile `{}` has no analysis with the same id in `{}`",
                    f.meta.id, analysis.name
                ))
            })?;
            let sf = state_on(grid, &f.profile, use_h2o, use_co2)?;
            let sa = state_on(grid, &a.profile, use_h2o, use_co2)?;
            diffs.push(sf.iter().zip(&sa).map(|(x, y)| x - y).collect());
        }
        let n = diffs.len();
        if n < 2 {
            return Err(AtmosphereError::Covariance(format!(
                "{n} forecast-analysis pairs; at least 2 are needed"
            )));
        }
        let mut bias = vec![0.0; dim];
        for d in &diffs {
            bias.iter_mut().zip(d).for_each(|(b, x)| *b += x / n as f64);
        }
        let mut s = DMatrix::<f64>::zeros(dim, dim);
        for d in &diffs {
            let c = nalgebra::DVector::from_iterator(dim, d.iter().zip(&bias).map(|(x, b)| x - b));
            s.ger(1.0 / (n as f64 - 1.0), &c, &c, 1.0);
        }
        let mut notes = vec![format!(
            "covariance estimated from {n} forecast-minus-analysis pairs ({} vs {}), bias removed",
            forecast.name, analysis.name
        )];
        if !use_h2o {
            notes.push("lnq: the pairs have no H2O, not perturbed".into());
        }
        if !use_co2 {
            notes.push("CO2_ppmv: the pairs have no CO2, not perturbed".into());
        }
        if let Some(l) = localization_lnp {
            if !(l.is_finite() && l > 0.0) {
                return Err(AtmosphereError::InvalidArgument(format!(
                    "localization length {l} (ln p) must be positive"
                )));
            }
            let lnp: Vec<f64> = elements
                .iter()
                .map(|e| e.pressure_pa.unwrap_or(grid.pressure_pa[0]).ln())
                .collect();
            for i in 0..dim {
                for j in 0..dim {
                    s[(i, j)] *= (-(lnp[i] - lnp[j]).powi(2) / (2.0 * l * l)).exp();
                }
            }
            notes.push(format!("localized with a Gaussian of length {l} in ln p"));
        }
        Ok((
            Covariance {
                elements,
                matrix: symmetrize(s),
                notes,
            },
            bias,
        ))
    }

    /// The factor L with S = L Lᵀ.
    ///
    /// Elements with zero variance are left out (zero rows in L). The rest is factored by
    /// Cholesky (nalgebra); if that fails, by the symmetric eigen-decomposition S = V Λ Vᵀ,
    /// L = V max(Λ, 0)^½. Negative eigenvalues no larger in magnitude than
    /// [`ROUNDING_EIGENVALUE_FRACTION`] of the largest are rounding and always repaired; larger
    /// ones give [`AtmosphereError::NotPositiveDefinite`] unless `allow_repair`. Any repair is
    /// returned in [`Factor::repair`].
    pub fn factor(&self, allow_repair: bool) -> Result<Factor, AtmosphereError> {
        let n = self.dimension();
        if self.matrix.iter().any(|v| !v.is_finite()) {
            return Err(AtmosphereError::Covariance(
                "the matrix has non-finite values".into(),
            ));
        }
        let active: Vec<usize> = (0..n).filter(|&i| self.matrix[(i, i)] > 0.0).collect();
        let m = active.len();
        let mut l = DMatrix::<f64>::zeros(n, n);
        if m == 0 {
            return Ok(Factor { l, repair: None });
        }
        let sub = DMatrix::from_fn(m, m, |i, j| self.matrix[(active[i], active[j])]);
        if let Some(ch) = sub.clone().cholesky() {
            let lf = ch.l();
            for i in 0..m {
                for j in 0..m {
                    l[(active[i], active[j])] = lf[(i, j)];
                }
            }
            return Ok(Factor { l, repair: None });
        }
        let eig = SymmetricEigen::new(sub.clone());
        let max = eig.eigenvalues.max();
        let min = eig.eigenvalues.min();
        let beyond = eig
            .eigenvalues
            .iter()
            .filter(|&&v| v < -ROUNDING_EIGENVALUE_FRACTION * max.abs())
            .count();
        if beyond > 0 && !allow_repair {
            return Err(AtmosphereError::NotPositiveDefinite {
                negative: beyond,
                dimension: m,
                min_eigenvalue: min,
                max_eigenvalue: max,
            });
        }
        let clipped = eig.eigenvalues.iter().filter(|&&v| v <= 0.0).count();
        let sqrt_l = eig.eigenvalues.map(|v| v.max(0.0).sqrt());
        let lf = &eig.eigenvectors * DMatrix::from_diagonal(&sqrt_l);
        let repaired = &lf * lf.transpose();
        let relative_change = (&repaired - &sub).norm() / sub.norm();
        for i in 0..m {
            for j in 0..m {
                l[(active[i], active[j])] = lf[(i, j)];
            }
        }
        Ok(Factor {
            l,
            repair: Some(RepairReport {
                dimension: m,
                clipped,
                min_eigenvalue: min,
                max_eigenvalue: max,
                relative_change,
            }),
        })
    }
}

/// The state (T, ln H2O, CO2 ppmv, p_s hPa) of `p` on `grid`'s levels moved to `p`'s surface
/// pressure (level-following).
pub(crate) fn state_on(
    grid: &Profile,
    p: &Profile,
    h2o: bool,
    co2: bool,
) -> Result<Vec<f64>, AtmosphereError> {
    let ps_grid = grid.surface_pressure_pa();
    let ps = p.surface_pressure_pa();
    let top = *p
        .pressure_pa
        .last()
        .ok_or_else(|| AtmosphereError::InvalidProfile {
            profile: p.name.clone(),
            message: "no levels".into(),
        })?;
    let targets: Vec<f64> = grid
        .pressure_pa
        .iter()
        .map(|&q| hybrid_shift_pa(q, ps_grid, ps).clamp(top, ps))
        .collect();
    if targets.windows(2).any(|w| w[1] >= w[0]) {
        return Err(AtmosphereError::InvalidProfile {
            profile: p.name.clone(),
            message: format!(
                "its top ({top} Pa) is below levels of `{}`; it cannot be compared level by level",
                grid.name
            ),
        });
    }
    let at = p.interpolate_to_pressures(&targets)?;
    let n = grid.len();
    let mut s = Vec::with_capacity(3 * n + 1);
    s.extend_from_slice(&at.temperature_k);
    if h2o {
        for x in at.require_gas("H2O")? {
            if !(*x > 0.0) {
                return Err(AtmosphereError::InvalidProfile {
                    profile: p.name.clone(),
                    message: "H2O is zero at a level; ln H2O is undefined".into(),
                });
            }
            s.push(x.ln());
        }
    } else {
        s.extend(std::iter::repeat_n(0.0, n));
    }
    if co2 {
        s.extend(at.require_gas("CO2")?.iter().map(|x| x * 1e6));
    } else {
        s.extend(std::iter::repeat_n(0.0, n));
    }
    s.push(ps / 100.0);
    Ok(s)
}

fn symmetrize(m: DMatrix<f64>) -> DMatrix<f64> {
    let t = m.transpose();
    (m + t) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn not_positive_definite_is_an_error_or_repaired() {
        let c = Covariance {
            elements: vec![
                StateElement {
                    variable: StateVariable::Temperature,
                    pressure_pa: Some(1e5),
                },
                StateElement {
                    variable: StateVariable::Temperature,
                    pressure_pa: Some(5e4),
                },
            ],
            matrix: DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]),
            notes: vec![],
        };
        let e = c.factor(false).unwrap_err();
        assert!(
            matches!(e, AtmosphereError::NotPositiveDefinite { negative: 1, .. }),
            "{e}"
        );
        let f = c.factor(true).unwrap();
        let r = f.repair.unwrap();
        assert_eq!(r.clipped, 1);
        // Nearest PSD of [[1,2],[2,1]] (eigenvalues 3, −1) is 1.5·[[1,1],[1,1]].
        let s = &f.l * f.l.transpose();
        for v in s.iter() {
            assert!((v - 1.5).abs() < 1e-12);
        }
    }

    #[test]
    fn covariance_file_round_trips_and_rejects_asymmetry() {
        let p = crate::atmosphere::StandardAtmosphere::Tropical.profile();
        let c = ErrorModel::representative().covariance(&p).unwrap();
        let text = c.to_csv();
        let back = Covariance::parse(Path::new("c.csv"), &text).unwrap();
        assert!(back.fits(&p));
        assert!((&back.matrix - &c.matrix).norm() <= 1e-12 * c.matrix.norm());
        let bad = "variable,p_hPa,c1,c2\nT_K,1000,1,0.5\nT_K,500,0.4,1\n";
        let e = Covariance::parse(Path::new("b.csv"), bad).unwrap_err();
        assert!(e.to_string().contains("not symmetric"), "{e}");
        assert_eq!(e.line, Some(3));
    }
}
