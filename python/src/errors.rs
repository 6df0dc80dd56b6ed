//! The library's errors as Python exceptions: a problem with the input is a `ValueError` (a
//! scene's a [`SceneError`], which carries the file, line and key), anything else a
//! `RuntimeError`; a run stopped by Ctrl-C is the `KeyboardInterrupt` the watcher raised.

use lidarsim::input::InputError;
use lidarsim::scene::DESCRIPTION_NAME;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(
    _lidarsim,
    SceneError,
    PyValueError,
    "A scene that cannot be used: its message names the file, line and key (a TOML scene) or \
     the key path (a scene built from a dict, `layer[0].extinction_per_km`); the attributes \
     `path`, `line` and `key` hold them (None where they do not apply)."
);

/// A scene problem as a [`SceneError`]. A description built from values is named by its key
/// path alone (`layer[0].top_m: …`); a file by `file:line: key: …`, as the command line says it.
pub fn scene_error(e: &InputError) -> PyErr {
    let from_values = e.path.as_os_str() == DESCRIPTION_NAME && e.line.is_none();
    let message = match (&e.field, from_values) {
        (Some(field), true) => format!("{field}: {}", e.message),
        (None, true) => e.message.clone(),
        _ => e.to_string(),
    };
    let err = SceneError::new_err(message);
    Python::attach(|py| {
        let value = err.value(py);
        let path = (!from_values).then(|| e.path.display().to_string());
        // Attributes for code that wants to point at the key; failing to set them is not
        // worth hiding the error for.
        let _ = value.setattr("path", path);
        let _ = value.setattr("line", e.line);
        let _ = value.setattr("key", e.field.clone());
    });
    err
}

/// A request that cannot be done (bad arguments, a study that cannot start).
pub fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Anything else: the work failed.
pub fn runtime_error(e: impl std::fmt::Display) -> PyErr {
    PyRuntimeError::new_err(e.to_string())
}

/// A run's error: a scene problem found while running is a [`SceneError`], the rest
/// `RuntimeError`s.
pub fn run_error(e: &lidarsim::pipeline::RunError) -> PyErr {
    match e {
        lidarsim::pipeline::RunError::Input(i) => scene_error(i),
        other => runtime_error(other),
    }
}
