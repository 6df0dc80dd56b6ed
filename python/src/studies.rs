//! Profile ensembles and the studies over them (`dial`, `select-lines`).

use std::path::PathBuf;

use lidarsim::atmosphere::{
    GasProfile, LatitudeClass, Profile, ProfileMeta, ProfileSet, SetMember, StandardAtmosphere,
    read_profile_set,
};
use lidarsim::products::dial::DialRequest;
use lidarsim::products::profiles::GenerateRequest;
use lidarsim::products::select::SelectProducts;
use lidarsim::study::dial::{self as dial_study, BudgetSteps, ProfileSource};
use lidarsim::study::select::Uncertainties;
use lidarsim::study::select_study::{SelectOptions, SelectSource, SelectStudy};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

use crate::convert::dataset_to_py;
use crate::errors::{runtime_error, scene_error, value_error};
use crate::scene::PyScene;
use crate::watch::watch;

/// A profile set as a dict of flat arrays (profiles × levels, row-major; a profile with fewer
/// levels than the longest is padded with NaN): `name`, `notes`, `id`, `latitude_deg`,
/// `longitude_deg`, `time_utc`, `weight` (NaN: none), `levels`, `altitude_m`, `pressure_pa`,
/// `temperature_k`, and `vmr`, a dict gas → volume mixing ratio [mol/mol].
fn set_to_py<'py>(py: Python<'py>, set: &ProfileSet) -> PyResult<Bound<'py, PyDict>> {
    let levels = set
        .members
        .iter()
        .map(|m| m.profile.len())
        .max()
        .unwrap_or(0);
    let mut gases: Vec<String> = Vec::new();
    for m in &set.members {
        for g in &m.profile.gases {
            if !gases.contains(&g.name) {
                gases.push(g.name.clone());
            }
        }
    }
    let padded = |f: &dyn Fn(&Profile) -> Option<&[f64]>| -> Vec<f64> {
        let mut out = vec![f64::NAN; set.len() * levels];
        for (row, m) in out.chunks_mut(levels.max(1)).zip(&set.members) {
            if let Some(v) = f(&m.profile) {
                row[..v.len()].copy_from_slice(v);
            }
        }
        out
    };
    let d = PyDict::new(py);
    d.set_item("name", &set.name)?;
    d.set_item("notes", &set.notes)?;
    let meta = |f: fn(&ProfileMeta) -> f64| -> Vec<f64> {
        set.members.iter().map(|m| f(&m.meta)).collect()
    };
    d.set_item(
        "id",
        set.members
            .iter()
            .map(|m| m.meta.id.clone())
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "latitude_deg",
        PyArray1::from_vec(py, meta(|m| m.latitude_deg)),
    )?;
    d.set_item(
        "longitude_deg",
        PyArray1::from_vec(py, meta(|m| m.longitude_deg)),
    )?;
    d.set_item(
        "time_utc",
        set.members
            .iter()
            .map(|m| m.meta.time_utc.clone())
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "class",
        set.members
            .iter()
            .map(|m| m.meta.class().name())
            .collect::<Vec<_>>(),
    )?;
    d.set_item(
        "weight",
        PyArray1::from_vec(py, meta(|m| m.weight.unwrap_or(f64::NAN))),
    )?;
    d.set_item("levels", levels)?;
    d.set_item(
        "altitude_m",
        PyArray1::from_vec(py, padded(&|p| Some(&p.altitude_m))),
    )?;
    d.set_item(
        "pressure_pa",
        PyArray1::from_vec(py, padded(&|p| Some(&p.pressure_pa))),
    )?;
    d.set_item(
        "temperature_k",
        PyArray1::from_vec(py, padded(&|p| Some(&p.temperature_k))),
    )?;
    let vmr = PyDict::new(py);
    for g in &gases {
        vmr.set_item(g, PyArray1::from_vec(py, padded(&|p| p.gas(g))))?;
    }
    d.set_item("vmr", vmr)?;
    Ok(d)
}

/// The inverse of [`set_to_py`]: NaN levels at the top of a profile are dropped; every
/// profile is checked as a file's would be.
fn set_from_py(d: &Bound<'_, PyDict>) -> PyResult<ProfileSet> {
    let item = |k: &str| -> PyResult<Bound<'_, PyAny>> {
        d.get_item(k)?
            .ok_or_else(|| value_error(format!("profiles: no `{k}`")))
    };
    let array = |k: &str| -> PyResult<Vec<f64>> {
        let a: PyReadonlyArray1<f64> = item(k)?.extract()?;
        Ok(a.as_slice()?.to_vec())
    };
    let ids: Vec<String> = item("id")?.extract()?;
    let levels: usize = item("levels")?.extract()?;
    let (lat, lon, weight) = (
        array("latitude_deg")?,
        array("longitude_deg")?,
        array("weight")?,
    );
    let time: Vec<String> = item("time_utc")?.extract()?;
    let (alt, p, t) = (
        array("altitude_m")?,
        array("pressure_pa")?,
        array("temperature_k")?,
    );
    let vmr_dict = item("vmr")?;
    let vmr_dict = vmr_dict.cast::<PyDict>()?;
    let mut gases: Vec<(String, Vec<f64>)> = Vec::new();
    for (k, v) in vmr_dict.iter() {
        let a: PyReadonlyArray1<f64> = v.extract()?;
        gases.push((k.extract()?, a.as_slice()?.to_vec()));
    }
    let n = ids.len();
    let full = n * levels;
    for (name, len) in [
        ("latitude_deg", lat.len()),
        ("longitude_deg", lon.len()),
        ("weight", weight.len()),
        ("time_utc", time.len()),
    ] {
        if len != n {
            return Err(value_error(format!(
                "profiles: `{name}` has {len} values for {n} profiles"
            )));
        }
    }
    for (name, len) in [
        ("altitude_m", alt.len()),
        ("pressure_pa", p.len()),
        ("temperature_k", t.len()),
    ]
    .into_iter()
    .chain(gases.iter().map(|(g, v)| (g.as_str(), v.len())))
    {
        if len != full {
            return Err(value_error(format!(
                "profiles: `{name}` has {len} values for {n} profiles of {levels} levels"
            )));
        }
    }
    let mut members = Vec::with_capacity(n);
    for (i, id) in ids.iter().enumerate() {
        let row = i * levels..(i + 1) * levels;
        let used = alt[row.clone()]
            .iter()
            .take_while(|a| a.is_finite())
            .count();
        let take = |v: &[f64]| v[row.start..row.start + used].to_vec();
        let profile = Profile {
            name: id.clone(),
            altitude_m: take(&alt),
            pressure_pa: take(&p),
            temperature_k: take(&t),
            gases: gases
                .iter()
                .map(|(g, v)| GasProfile {
                    name: g.clone(),
                    vmr: take(v),
                })
                .collect(),
        };
        profile
            .validate()
            .map_err(|e| value_error(format!("profile `{id}`: {e}")))?;
        members.push(SetMember {
            meta: ProfileMeta {
                id: id.clone(),
                latitude_deg: lat[i],
                longitude_deg: lon[i],
                time_utc: time[i].clone(),
                weight: weight[i].is_finite().then_some(weight[i]),
            },
            profile,
        });
    }
    Ok(ProfileSet {
        name: item("name")?.extract()?,
        members,
        notes: item("notes")?.extract()?,
    })
}

/// A profile-set file (lidarsim format) as the dict of [`set_to_py`].
#[pyfunction]
pub fn read_profiles<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let set = py
        .detach(|| read_profile_set(&path))
        .map_err(|e| scene_error(&e))?;
    set_to_py(py, &set)
}

/// `n` profiles drawn around a mean (an AFGL atmosphere, or a latitude class's AFGL mean)
/// with the representative NWP forecast-error covariance (or the error model given): the dict
/// of [`set_to_py`]; its notes say how it was made.
#[pyfunction]
#[pyo3(signature = (n, seed, latitude_class=None, atmosphere=None, co2_ppm=None, error_model=None, co2_std_ppm=None, ps_std_hpa=None, max_rh_percent=100.0, rh_over="water", co2_scaling="well_mixed"))]
#[allow(clippy::too_many_arguments)]
pub fn ensemble<'py>(
    py: Python<'py>,
    n: usize,
    seed: u64,
    latitude_class: Option<&str>,
    atmosphere: Option<&str>,
    co2_ppm: Option<f64>,
    error_model: Option<PathBuf>,
    co2_std_ppm: Option<f64>,
    ps_std_hpa: Option<f64>,
    max_rh_percent: f64,
    rh_over: &str,
    co2_scaling: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let co2_scaling = co2_scaling
        .parse::<lidarsim::atmosphere::Co2Scaling>()
        .map_err(|m| value_error(format!("co2_scaling: {m}")))?;
    let class = latitude_class
        .map(|c| {
            c.parse::<LatitudeClass>()
                .map_err(|m| value_error(format!("latitude_class: {m}")))
        })
        .transpose()?;
    let atmosphere = atmosphere
        .map(|a| {
            a.parse::<StandardAtmosphere>()
                .map_err(|m| value_error(format!("atmosphere: {m}")))
        })
        .transpose()?;
    let request = GenerateRequest {
        n,
        seed,
        class,
        atmosphere,
        set: None,
        mean_profile: None,
        profile_id: None,
        co2_ppm,
        co2_scaling,
        covariance: None,
        error_model,
        pairs: None,
        localization_lnp: None,
        t_corr_length: None,
        q_corr_length: None,
        ps_std_hpa,
        co2_std_ppm,
        co2_corr_length: 0.35,
        no_class_scaling: false,
        repair_covariance: false,
        max_rh_percent,
        rh_over: rh_over.to_string(),
    };
    let (set, _) = watch(py, None, |_| {
        lidarsim::products::profiles::generate(&request, &mut |_| Ok(()))
    })?
    .map_err(value_error)?;
    set_to_py(py, &set)
}

/// A DIAL/IPDA study of `scene` over profiles (a dict of [`set_to_py`], a file, or an
/// ensemble of `ensemble` members per class): (the data set of `profiles.nc`, that of
/// `summary.nc`, the failed profiles as (id, reason)). A data set is None without rows.
#[pyfunction]
#[pyo3(signature = (scene, profiles=None, profiles_path=None, ensemble=None, seed=None, latitude_class="all", on=Vec::new(), photons=None, threads=0, steps=None, progress=None, history=String::new(), strict=false))]
#[allow(clippy::too_many_arguments)]
pub fn dial<'py>(
    py: Python<'py>,
    scene: &PyScene,
    profiles: Option<&Bound<'py, PyDict>>,
    profiles_path: Option<PathBuf>,
    ensemble: Option<usize>,
    seed: Option<u64>,
    latitude_class: &str,
    on: Vec<String>,
    photons: Option<u64>,
    threads: usize,
    steps: Option<(f64, f64, f64, f64, f64)>,
    progress: Option<&Bound<'py, PyAny>>,
    history: String,
    strict: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let source = match (profiles, profiles_path, ensemble) {
        (Some(d), None, None) => ProfileSource::Given(set_from_py(d)?),
        (None, Some(p), None) => ProfileSource::Set(p),
        (None, None, Some(n)) if n >= 2 => ProfileSource::Ensemble(n),
        (None, None, Some(n)) => {
            return Err(value_error(format!(
                "ensemble: {n} members per class; at least 2"
            )));
        }
        _ => {
            return Err(value_error(
                "give one of profiles (a Dataset or a file) and ensemble",
            ));
        }
    };
    dial_study::classes(latitude_class).map_err(value_error)?;
    let steps = steps.map_or(BudgetSteps::default(), |s| BudgetSteps {
        temperature_k: s.0,
        humidity_fraction: s.1,
        surface_pressure_hpa: s.2,
        frequency_offset_mhz: s.3,
        linewidth_fraction: s.4,
    });
    let request = DialRequest {
        scene: None,
        overrides: Vec::new(),
        profiles: None,
        ensemble: None,
        seed,
        class: latitude_class.to_string(),
        on,
        photons,
        steps,
        shard: false,
    };
    let scene = (*scene.scene).clone();
    let inputs = py
        .detach(|| request.resolve_with(scene, source))
        .map_err(value_error)?;
    // `--strict` of the command line: a profile that cannot be run is refused before the
    // work, any failed one after it.
    let policy = lidarsim::study::FailurePolicy::strict_if(strict);
    lidarsim::products::dial::check_before_run(&inputs, policy).map_err(runtime_error)?;
    let pool = lidarsim::study::thread_pool(threads).map_err(value_error)?;
    let result = watch(py, progress, |control| {
        control.report(0, inputs.set.len());
        pool.install(|| {
            dial_study::run_until(
                &inputs.scene,
                &inputs.set,
                &inputs.options,
                &|| control.tick(),
                control.stop(),
            )
        })
    })?
    .map_err(runtime_error)?;
    let products = lidarsim::products::dial::DialProducts::with_policy(&inputs, &result, policy)
        .map_err(runtime_error)?;
    let title = format!("lidarsim dial: retrievals over {}", inputs.set.name);
    let records = if result
        .outcomes
        .iter()
        .any(|o| o.records.as_ref().is_ok_and(|r| !r.is_empty()))
    {
        let ds = lidarsim::products::dial::profiles_nc(
            &result.outcomes,
            &title,
            &history,
            &inputs.scene,
            &inputs.set,
            inputs.options.seed,
        )
        .map_err(runtime_error)?;
        dataset_to_py(py, ds)?.into_any()
    } else {
        py.None().into_bound(py)
    };
    let summary = if products.summaries.is_empty() {
        py.None().into_bound(py)
    } else {
        let ds = lidarsim::products::dial::summary_nc(
            &products.summaries,
            &title,
            &history,
            &inputs.scene,
            &inputs.set,
            inputs.options.seed,
        )
        .map_err(runtime_error)?;
        dataset_to_py(py, ds)?.into_any()
    };
    let failed = PyList::empty(py);
    for o in &result.outcomes {
        if let Err(reason) = &o.records {
            failed.append((o.id.clone(), reason.clone()))?;
        }
    }
    PyTuple::new(py, [records, summary, failed.into_any()])
}

/// A line-selection study (`lidarsim select-lines`): (the data set of `sensitivities.nc`,
/// the failed profiles as (id, reason)).
#[pyfunction]
#[pyo3(signature = (scene, off_cm1, co2_ppm, on_cm1=Vec::new(), atmospheres=Vec::new(), profiles_path=None, ensemble=None, seed=1, latitude_class="all", lines=Vec::new(), max_j=40, offsets_ghz=vec![-3.0, -2.5, -2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0], layer_m=250.0, top_km=60.0, wing_cm1=25.0, uncertainties=(1.0, 1.0, 1.0, 10.0), per_profile=false, threads=0, progress=None, history=String::new(), strict=false))]
#[allow(clippy::too_many_arguments)]
pub fn select_lines<'py>(
    py: Python<'py>,
    scene: &PyScene,
    off_cm1: f64,
    co2_ppm: f64,
    on_cm1: Vec<f64>,
    atmospheres: Vec<String>,
    profiles_path: Option<PathBuf>,
    ensemble: Option<usize>,
    seed: u64,
    latitude_class: &str,
    lines: Vec<PathBuf>,
    max_j: u32,
    offsets_ghz: Vec<f64>,
    layer_m: f64,
    top_km: f64,
    wing_cm1: f64,
    uncertainties: (f64, f64, f64, f64),
    per_profile: bool,
    threads: usize,
    progress: Option<&Bound<'py, PyAny>>,
    history: String,
    strict: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let source = match (profiles_path, ensemble) {
        (Some(p), None) => SelectSource::Set(p),
        (None, Some(n)) => SelectSource::Ensemble(n),
        (None, None) => {
            let names = if atmospheres.is_empty() {
                vec!["us_standard".to_string()]
            } else {
                atmospheres
            };
            SelectSource::Atmospheres(
                names
                    .iter()
                    .map(|a| {
                        a.parse::<StandardAtmosphere>()
                            .map_err(|m| value_error(format!("atmospheres: {m}")))
                    })
                    .collect::<PyResult<_>>()?,
            )
        }
        _ => {
            return Err(value_error(
                "give at most one of profiles_path and ensemble",
            ));
        }
    };
    let options = SelectOptions {
        source,
        seed,
        class: latitude_class.to_string(),
        per_profile,
        lines,
        on_cm1,
        off_cm1,
        co2_ppm,
        max_j,
        offsets_ghz,
        layer_m,
        top_km,
        wing_cm1,
        uncertainties: Uncertainties {
            temperature_k: uncertainties.0,
            frequency_mhz: uncertainties.1,
            surface_pressure_hpa: uncertainties.2,
            h2o_percent: uncertainties.3,
        },
        figure_lines: Vec::new(),
        plots: false,
    };
    let scene = (*scene.scene).clone();
    let study = py
        .detach(|| SelectStudy::build(options, scene))
        .map_err(value_error)?;
    let pool = lidarsim::study::thread_pool(threads).map_err(value_error)?;
    let outcomes = watch(py, progress, |control| {
        control.report(0, study.len());
        pool.install(|| study.study_until(&|| control.tick(), control.stop()))
    })?
    .ok_or_else(|| runtime_error("the study was stopped before its end"))?;
    let products = SelectProducts::with_policy(
        &study,
        &outcomes,
        lidarsim::study::FailurePolicy::strict_if(strict),
    )
    .map_err(runtime_error)?;
    let table = if products.rows.is_empty() {
        py.None().into_bound(py)
    } else {
        let ds = products.dataset(&history).map_err(runtime_error)?;
        dataset_to_py(py, ds)?.into_any()
    };
    let failed = PyList::empty(py);
    for o in &outcomes {
        if let Err(f) = o {
            failed.append((f.id.clone(), f.reason.clone()))?;
        }
    }
    PyTuple::new(py, [table, failed.into_any()])
}
