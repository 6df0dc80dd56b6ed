//! Scenes (a TOML file or text, or the values of a dict) and their runs.

use std::path::PathBuf;
use std::sync::Arc;

use lidarsim::pipeline;
use lidarsim::scene::{Scene, SceneDescription};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use crate::convert::dataset_to_py;
use crate::errors::{run_error, runtime_error, scene_error, value_error};
use crate::watch::watch;

/// A resolved scene (Python: `lidarsim.Scene`, which wraps this).
#[pyclass(module = "lidarsim._lidarsim", name = "Scene", frozen)]
pub struct PyScene {
    pub scene: Arc<Scene>,
}

impl PyScene {
    fn new(scene: Scene) -> Self {
        PyScene {
            scene: Arc::new(scene),
        }
    }
}

/// A description from JSON text (a dict's values), its bad key named by its path.
fn description_from_json(json: &str) -> PyResult<SceneDescription> {
    let de = &mut serde_json::Deserializer::from_str(json);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        // serde_json appends " at line 1 column 80" of the JSON text, which the user never saw.
        let message = inner.to_string();
        let message = match message.rfind(" at line ") {
            Some(i) => message[..i].to_string(),
            None => message,
        };
        scene_error(&lidarsim::input::InputError {
            path: lidarsim::scene::DESCRIPTION_NAME.into(),
            line: None,
            field: (path != ".").then_some(path),
            message,
        })
    })
}

#[pymethods]
impl PyScene {
    /// The scene in TOML text `text`; `path` names it in errors and anchors its relative paths.
    #[staticmethod]
    fn from_toml_text(py: Python<'_>, text: &str, path: PathBuf) -> PyResult<Self> {
        let scene = py
            .detach(|| Scene::from_toml(&path, text))
            .map_err(|e| scene_error(&e))?;
        Ok(Self::new(scene))
    }

    /// The scene file at `path`.
    #[staticmethod]
    fn read(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let scene = py
            .detach(|| Scene::read(&path))
            .map_err(|e| scene_error(&e))?;
        Ok(Self::new(scene))
    }

    /// The embedded default scene.
    #[staticmethod]
    fn default_scene(py: Python<'_>) -> PyResult<Self> {
        let scene = py
            .detach(Scene::default_scene)
            .map_err(|e| scene_error(&e))?;
        Ok(Self::new(scene))
    }

    /// The scene a description (JSON text of the TOML's keys) makes, its relative paths
    /// anchored at `base_dir`.
    #[staticmethod]
    fn from_json(py: Python<'_>, json: &str, base_dir: PathBuf) -> PyResult<Self> {
        let d = description_from_json(json)?;
        let scene = py
            .detach(|| d.resolve(&base_dir))
            .map_err(|e| scene_error(&e))?;
        Ok(Self::new(scene))
    }

    /// Another description (JSON) resolved at this scene's directory, keeping what this
    /// scene resolved that the edit leaves unchanged (layer optics, line lists).
    fn edited(&self, py: Python<'_>, json: &str) -> PyResult<Self> {
        let d = description_from_json(json)?;
        let previous = &self.scene;
        let scene = py
            .detach(|| d.resolve_reusing(previous.base_dir(), previous))
            .map_err(|e| scene_error(&e))?;
        Ok(Self::new(scene))
    }

    /// The scene with another atmospheric profile (levels bottom up; `gases` maps a formula
    /// to its volume mixing ratio per level [mol/mol]), keeping the layers' optics, the line
    /// lists and the run settings; errors name the scene key the profile does not fit.
    #[pyo3(signature = (name, altitude_m, pressure_pa, temperature_k, gases))]
    fn with_profile(
        &self,
        py: Python<'_>,
        name: String,
        altitude_m: Vec<f64>,
        pressure_pa: Vec<f64>,
        temperature_k: Vec<f64>,
        gases: Vec<(String, Vec<f64>)>,
    ) -> PyResult<Self> {
        let profile = lidarsim::atmosphere::Profile {
            name,
            altitude_m,
            pressure_pa,
            temperature_k,
            gases: gases
                .into_iter()
                .map(|(name, vmr)| lidarsim::atmosphere::GasProfile { name, vmr })
                .collect(),
        };
        let scene = py
            .detach(|| self.scene.with_profile(profile))
            .map_err(|e| scene_error(&e))?;
        Ok(Self::new(scene))
    }

    /// The description as JSON text (the TOML's keys and values).
    fn description_json(&self) -> PyResult<String> {
        serde_json::to_string(self.scene.as_description()).map_err(runtime_error)
    }

    /// The description as TOML text.
    fn to_toml(&self) -> PyResult<String> {
        self.scene
            .as_description()
            .to_toml()
            .map_err(|e| scene_error(&e))
    }

    /// The file (or pseudo-path) the scene came from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.scene.path.clone()
    }

    /// The directory its relative paths are anchored at.
    #[getter]
    fn base_dir(&self) -> PathBuf {
        self.scene.base_dir().to_path_buf()
    }

    /// The laser lines: (name, vacuum wavenumber [cm⁻¹]).
    #[getter]
    fn lines(&self) -> Vec<(String, f64)> {
        self.scene
            .lines
            .iter()
            .map(|c| (c.name.clone(), c.wavenumber_cm1))
            .collect()
    }

    /// The monochromatic channels the transport follows: (name, vacuum wavenumber [cm⁻¹]).
    #[getter]
    fn channels(&self) -> Vec<(String, f64)> {
        self.scene
            .channels
            .iter()
            .map(|c| (c.name.clone(), c.wavenumber_cm1))
            .collect()
    }

    /// Receiver fields of view, full angles [mrad].
    #[getter]
    fn fov_full_angle_mrad(&self) -> Vec<f64> {
        self.scene.lidar.fov_full_angle_mrad.clone()
    }

    /// Gate centres [m].
    #[getter]
    fn range_m(&self) -> Vec<f64> {
        (0..self.scene.gates.count)
            .map(|i| self.scene.gates.centre_m(i))
            .collect()
    }

    /// The run settings: (photons, seed, batches, threads).
    #[getter]
    fn simulation(&self) -> (u64, u64, usize, usize) {
        let s = &self.scene.simulation;
        (s.photons, s.seed, s.batches, s.threads)
    }
}

/// Run a scene: returns (the data set of `run.nc`, a note on long work or None).
#[pyfunction]
#[pyo3(signature = (scene, photons=None, seed=None, threads=None, progress=None, history=String::new()))]
pub fn run<'py>(
    py: Python<'py>,
    scene: &PyScene,
    photons: Option<u64>,
    seed: Option<u64>,
    threads: Option<usize>,
    progress: Option<&Bound<'py, PyAny>>,
    history: String,
) -> PyResult<Bound<'py, PyTuple>> {
    let mut scene: Scene = (*scene.scene).clone();
    scene
        .override_simulation(photons, seed, threads)
        .map_err(value_error)?;
    enum Failed {
        Run(pipeline::RunError),
        Netcdf(lidarsim::netcdf::NetcdfError),
    }
    let outcome = watch(py, progress, |control| {
        let prepared = pipeline::prepare(&scene).map_err(Failed::Run)?;
        let note = prepared.warning();
        let mc = prepared
            .trace_until(&|done, total| control.report(done, total), control.stop())
            .map_err(Failed::Run)?;
        let run = prepared.finish(mc).map_err(Failed::Run)?;
        let ds =
            lidarsim::products::run::dataset(&scene, &run, &history).map_err(Failed::Netcdf)?;
        Ok((ds, note))
    })?;
    let (ds, note) = outcome.map_err(|e| match e {
        Failed::Run(e) => run_error(&e),
        Failed::Netcdf(e) => runtime_error(e),
    })?;
    let ds = dataset_to_py(py, ds)?;
    PyTuple::new(py, [ds.into_any(), note.into_pyobject(py)?.into_any()])
}
