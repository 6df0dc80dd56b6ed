//! Rust values to Python ones without copying large arrays: a `Vec<f64>` becomes a numpy array
//! that owns the vector's buffer ([`numpy::PyArray1::from_vec`]).

use lidarsim::netcdf::{Attr, Dataset, FILL_F64, Values};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};

/// A data set as `(dims, variables, attributes)`: `dims` a list of (name, length), each variable
/// `(name, dims, values, attributes)` with doubles as a flat numpy array (row-major over
/// `dims`; a missing value, `_FillValue` in the file, is NaN here) or text as a flat list of
/// str over every dimension but the last (the string length), attributes as lists of
/// (name, value). `python/lidarsim/_data.py` builds the `xarray.Dataset`.
pub fn dataset_to_py(py: Python<'_>, ds: Dataset) -> PyResult<Bound<'_, PyTuple>> {
    let dims = PyList::empty(py);
    for (name, len) in &ds.dims {
        dims.append((name, *len))?;
    }
    let vars = PyList::empty(py);
    for v in ds.vars {
        let attrs = attrs_to_py(py, &v.attrs)?;
        let values = match v.values {
            Values::F64(mut x) => {
                if v.attrs.iter().any(|(k, _)| k == "_FillValue") {
                    for value in x.iter_mut().filter(|value| **value == FILL_F64) {
                        *value = f64::NAN;
                    }
                }
                PyArray1::from_vec(py, x).into_any()
            }
            Values::Char(bytes) => {
                let strlen = v
                    .dims
                    .last()
                    .and_then(|d| ds.dims.iter().find(|(n, _)| n == d))
                    .map_or(1, |(_, len)| (*len).max(1));
                let strings: Vec<String> = bytes
                    .chunks(strlen)
                    .map(|row| {
                        let end = row.iter().position(|b| *b == 0).unwrap_or(row.len());
                        String::from_utf8_lossy(&row[..end]).into_owned()
                    })
                    .collect();
                PyList::new(py, strings)?.into_any()
            }
        };
        vars.append((v.name, v.dims, values, attrs))?;
    }
    let globals = attrs_to_py(py, &ds.globals)?;
    PyTuple::new(py, [dims.into_any(), vars.into_any(), globals.into_any()])
}

fn attrs_to_py<'py>(py: Python<'py>, attrs: &[(String, Attr)]) -> PyResult<Bound<'py, PyList>> {
    let list = PyList::empty(py);
    for (name, a) in attrs {
        match a {
            Attr::Text(s) => list.append((name, s))?,
            Attr::F64(x) if x.len() == 1 => list.append((name, x[0]))?,
            Attr::F64(x) => list.append((name, PyArray1::from_slice(py, x)))?,
        }
    }
    Ok(list)
}
