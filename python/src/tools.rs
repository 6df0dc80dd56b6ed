//! Line by line and Mie theory on their own.

use std::path::PathBuf;
use std::sync::Arc;

use lidarsim::particles::mie::MieCoefficients;
use lidarsim::spectroscopy::isotopologues::molecule_name;
use lidarsim::spectroscopy::xsec::GasState;
use lidarsim::spectroscopy::{
    Conventions, LblOptions, LineFilter, LineList, LineShapeModel, WavenumberGrid, WingCentre,
    cross_section as lbl_cross_section, cross_section_at,
};
use num_complex::Complex64;
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::value_error;
use crate::watch::watch;

/// A line list (Python: `lidarsim.Lines`, which wraps this).
#[pyclass(module = "lidarsim._lidarsim", name = "Lines", frozen)]
pub struct PyLines {
    lines: Arc<LineList>,
}

#[pymethods]
impl PyLines {
    /// The lines of a HITRAN `.par` (or lidarsim CSV) file between `min_cm1` and `max_cm1`
    /// (all without them).
    #[staticmethod]
    #[pyo3(signature = (path, min_cm1=None, max_cm1=None))]
    fn read(
        py: Python<'_>,
        path: PathBuf,
        min_cm1: Option<f64>,
        max_cm1: Option<f64>,
    ) -> PyResult<Self> {
        let filter = match (min_cm1, max_cm1) {
            (None, None) => LineFilter::default(),
            (lo, hi) => LineFilter::window(lo.unwrap_or(0.0), hi.unwrap_or(f64::MAX)),
        };
        let lines = py
            .detach(|| LineList::read(&path, &filter))
            .map_err(value_error)?;
        Ok(PyLines {
            lines: Arc::new(lines),
        })
    }

    /// The built-in CO2 30012←00001 band model (the lines the default scene uses).
    #[staticmethod]
    fn co2_band_model() -> Self {
        PyLines {
            lines: Arc::new(LineList::co2_30012_band_model()),
        }
    }

    /// Number of lines.
    fn __len__(&self) -> usize {
        self.lines.lines.len()
    }

    /// Where the lines came from.
    #[getter]
    fn source(&self) -> String {
        self.lines.source.clone()
    }

    /// The molecules of the list, by name (`CO2`, `H2O`, …).
    #[getter]
    fn molecules(&self) -> Vec<String> {
        self.lines
            .molecules()
            .iter()
            .map(|m| molecule_name(*m).unwrap_or("?").to_string())
            .collect()
    }
}

fn line_shape(name: &str) -> PyResult<LineShapeModel> {
    name.parse::<LineShapeModel>()
        .map_err(|m| value_error(format!("line_shape: {m}")))
}

/// Absorption cross-sections [cm² molecule⁻¹] of every molecule of `lines` at the wavenumbers
/// given: a dict molecule → numpy array (moved, not copied, from Rust). An evenly spaced grid
/// goes through the multigrid (as `lidarsim lbl`), any other point by point.
#[pyfunction]
#[pyo3(signature = (lines, pressure_pa, temperature_k, wavenumbers_cm1, line_shape_name="voigt", line_mixing=false, vmr=0.0, wing_cm1=25.0, shifted_wing=false, exact=false, conventions="codata2018", self_broadening=true))]
#[allow(clippy::too_many_arguments)]
pub fn cross_section<'py>(
    py: Python<'py>,
    lines: &PyLines,
    pressure_pa: f64,
    temperature_k: f64,
    wavenumbers_cm1: PyReadonlyArray1<'py, f64>,
    line_shape_name: &str,
    line_mixing: bool,
    vmr: f64,
    wing_cm1: f64,
    shifted_wing: bool,
    exact: bool,
    conventions: &str,
    self_broadening: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let nu = wavenumbers_cm1.as_slice()?.to_vec();
    if nu.is_empty() {
        return Err(value_error("no wavenumbers"));
    }
    if let Some(bad) = nu.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        return Err(value_error(format!(
            "wavenumbers must be finite and positive, not {bad}"
        )));
    }
    let mut opts = LblOptions {
        wing_cm1,
        line_shape: line_shape(line_shape_name)?,
        line_mixing,
        ..Default::default()
    };
    if shifted_wing {
        opts.wing_centre = WingCentre::Shifted;
    }
    opts.self_broadening = self_broadening;
    opts.conventions = match conventions {
        "codata2018" => Conventions::CODATA_2018,
        "hapi" => Conventions::HAPI_1_3,
        other => {
            return Err(value_error(format!(
                "conventions `{other}` (known: codata2018, hapi)"
            )));
        }
    };
    if exact {
        opts.voigt = lidarsim::spectroscopy::VoigtMethod::Exact;
        opts.multigrid = false;
    }
    let state = GasState {
        pressure_pa,
        temperature_k,
        self_vmr: vmr,
    };
    let grid = even_grid(&nu);
    let list = lines.lines.clone();
    let columns = watch(py, None, |_| {
        list.molecules()
            .into_iter()
            .map(|m| {
                let sigma = match &grid {
                    Some(g) => lbl_cross_section(&list, m, &state, g, &opts),
                    None => cross_section_at(&list, m, &state, &nu, &opts),
                };
                sigma.map(|s| (molecule_name(m).unwrap_or("?").to_string(), s))
            })
            .collect::<Result<Vec<_>, _>>()
    })?
    .map_err(value_error)?;
    let out = PyDict::new(py);
    for (name, sigma) in columns {
        out.set_item(name, PyArray1::from_vec(py, sigma))?;
    }
    Ok(out)
}

/// The grid `nu` is, if it is start + i·step bit for bit (what the multigrid evaluates) for a
/// step found from its ends (numpy's `linspace`) or from its first two points (`start +
/// arange(n) * step`, `lidarsim lbl`'s grid); `None` sends it point by point.
fn even_grid(nu: &[f64]) -> Option<WavenumberGrid> {
    if nu.len() < 2 {
        return None;
    }
    let n = nu.len();
    [(nu[n - 1] - nu[0]) / (n - 1) as f64, nu[1] - nu[0]]
        .into_iter()
        .filter(|step| *step > 0.0)
        .map(|step_cm1| WavenumberGrid {
            start_cm1: nu[0],
            step_cm1,
            len: n,
        })
        .find(|g| (0..n).all(|i| g.at(i) == nu[i]))
}

/// Mie theory for spheres of refractive index `m` (imaginary part ≥ 0 absorbs) at every size
/// parameter of `x`: a dict of numpy arrays qext, qsca, qback, g, ssa.
#[pyfunction]
pub fn mie<'py>(
    py: Python<'py>,
    m: Complex64,
    x: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let x = x.as_slice()?.to_vec();
    let results = watch(py, None, |_| {
        use rayon::prelude::*;
        x.par_iter()
            .map(|&xi| MieCoefficients::compute(m, xi).map(|k| k.efficiencies()))
            .collect::<Result<Vec<_>, _>>()
    })?
    .map_err(value_error)?;
    let out = PyDict::new(py);
    let column = |f: fn(&lidarsim::particles::mie::MieResult) -> f64| {
        PyArray1::from_vec(py, results.iter().map(f).collect())
    };
    out.set_item("qext", column(|r| r.qext))?;
    out.set_item("qsca", column(|r| r.qsca))?;
    out.set_item("qback", column(|r| r.qback))?;
    out.set_item("g", column(|r| r.g))?;
    out.set_item("ssa", column(|r| r.ssa))?;
    Ok(out)
}
