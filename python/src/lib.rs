//! `lidarsim._lidarsim`: the Rust side of the Python package.
//!
//! A thin layer over the `lidarsim` library: scenes (parse → validate → resolve), runs, line
//! by line, Mie and the studies, each handing back plain values, numpy arrays (moved, not
//! copied, from the Rust vectors) and the data sets of the NetCDF products
//! ([`lidarsim::netcdf::Dataset`]), which `python/lidarsim/_data.py` turns into
//! `xarray.Dataset`s. Long work runs with the GIL released on a worker thread while the calling
//! thread watches for Ctrl-C and reports progress ([`watch`]). Nothing is printed.

use pyo3::prelude::*;

mod convert;
mod errors;
mod scene;
mod studies;
mod tools;
mod watch;

/// The extension module.
#[pymodule]
fn _lidarsim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SceneError", m.py().get_type::<errors::SceneError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<scene::PyScene>()?;
    m.add_class::<tools::PyLines>()?;
    m.add_function(wrap_pyfunction!(scene::run, m)?)?;
    m.add_function(wrap_pyfunction!(tools::cross_section, m)?)?;
    m.add_function(wrap_pyfunction!(tools::mie, m)?)?;
    m.add_function(wrap_pyfunction!(studies::ensemble, m)?)?;
    m.add_function(wrap_pyfunction!(studies::read_profiles, m)?)?;
    m.add_function(wrap_pyfunction!(studies::dial, m)?)?;
    m.add_function(wrap_pyfunction!(studies::select_lines, m)?)?;
    Ok(())
}
