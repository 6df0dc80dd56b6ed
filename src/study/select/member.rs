//! One member of the set: its four shifted profiles, the weighting function and the
//! sensitivities of every on-line position ([`super`] module docs).

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::{
    GHZ_PER_CM1, SelectError, Steps, StudyConfig, invalid, layer_edges, set_co2_column_average,
};
use crate::atmosphere::hydrostatic::HydrostaticProfile;
use crate::atmosphere::{LatitudeClass, Profile, SetMember, StateShift, shift_member};
use crate::instrument::laser::{Filter, Laser, Line};
use crate::instrument::line_shape::MHZ_PER_CM1;
use crate::retrieval::{AssumedInstrument, ReferenceState};
use crate::spectroscopy::{LayerDepthMemo, LblOptions, LineList, layer_optical_depths_at};

/// The results of one on-line position for one profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionResult {
    /// One-way differential absorption optical depth, all gases, top to surface.
    pub daod_one_way: f64,
    /// Peak of the weighting function per unit pressure \[hPa\].
    pub wf_peak_hpa: f64,
    /// XCO2 error for a true temperature 1 K higher \[ppm\].
    pub dxco2_per_k_ppm: f64,
    /// XCO2 error for a true on-line frequency 1 MHz higher \[ppm\].
    pub dxco2_per_mhz_ppm: f64,
    /// XCO2 error for an assumed surface pressure 1 hPa higher \[ppm\].
    pub dxco2_per_hpa_ppm: f64,
    /// XCO2 error for a true humidity 10 % higher \[ppm\].
    pub dxco2_per_10pct_h2o_ppm: f64,
    /// Two-way gas transmission of the on-line, top to surface.
    pub t2_on: f64,
    /// Random error of one averaged measurement \[ppm\] (NaN without a noise model).
    pub random_error_ppm: f64,
}

/// The results for one profile.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberResult {
    /// Profile id.
    pub id: String,
    /// Its latitude class.
    pub class: LatitudeClass,
    /// The layer edges used \[m\] (surface to top).
    pub edges_m: Vec<f64>,
    /// XCO2 of the unperturbed (shifted by nothing) profile over the grid \[ppm\].
    pub xco2_ppm: f64,
    /// One result per [`StudyConfig::positions`].
    pub positions: Vec<PositionResult>,
}

/// A profile that could not be studied, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberFailure {
    /// Profile id.
    pub id: String,
    /// The reason.
    pub reason: String,
}

/// The four shifted profiles of a member: none, temperature, water vapour, surface pressure.
fn shifted(member: &SetMember, steps: &Steps) -> Result<[Profile; 4], SelectError> {
    let none = shift_member(member, &StateShift::NONE)?;
    let t = shift_member(
        member,
        &StateShift {
            temperature_k: steps.temperature_k,
            ..StateShift::NONE
        },
    )?;
    // A profile without water vapour has none to change: the truth is the unshifted one.
    let q = if member.profile.gas("H2O").is_some() {
        shift_member(
            member,
            &StateShift {
                h2o_factor: steps.h2o_factor,
                ..StateShift::NONE
            },
        )?
    } else {
        none.clone()
    };
    let p = shift_member(
        member,
        &StateShift {
            surface_pressure_hpa: steps.surface_pressure_hpa,
            ..StateShift::NONE
        },
    )?;
    Ok([none.profile, t.profile, q.profile, p.profile])
}

/// The IPDA weighting function per unit pressure of one on/off pair on the layers of a
/// reference state (module docs): WF_l = Δτ_CO2,l/(x_l Δp_l).
#[derive(Debug, Clone, PartialEq)]
pub struct WeightingFunction {
    /// Centre of each layer, the mean of ln p \[Pa\] at its edges.
    pub ln_p_centre: Vec<f64>,
    /// Pressure thickness of each layer \[hPa\].
    pub dp_hpa: Vec<f64>,
    /// WF_l \[1/hPa\].
    pub per_hpa: Vec<f64>,
}

impl WeightingFunction {
    /// Pressure \[hPa\] where it peaks ([`peak_pressure_hpa`]'s parabola in ln p).
    pub fn peak_hpa(&self) -> f64 {
        peak_pressure_hpa(&self.ln_p_centre, &self.per_hpa)
    }
}

/// The weighting function of lines `on` and `off` (their first quadrature node: a
/// monochromatic laser) of `state`, computed on `profile` (the state's profile). The pressure
/// thickness Δp_l comes from the same hydrostatic integration as the state's columns
/// ([`HydrostaticProfile`]), so that x_l Δp_l is the layer's CO2 column times m g: within a
/// level interval the column per unit pressure is then constant up to humidity, and WF_l is
/// Δσ_l U_dry,l/Δp_l = Δσ_l (1 − x_w)/(m g) as the hydrostatic equation has it. (With Δp from
/// ln p linear in z it varied by ΔT/T across each interval, ±1 % in the tropics, and that
/// sawtooth set the peak where the weighting function is flat.)
pub fn weighting_function(
    profile: &Profile,
    state: &ReferenceState,
    on: usize,
    off: usize,
) -> WeightingFunction {
    let edges = &state.columns.edges_m;
    let hydro = HydrostaticProfile::new(profile);
    let p: Vec<f64> = edges.iter().map(|z| hydro.pressure_pa(*z)).collect();
    let n = edges.len().saturating_sub(1);
    let mut wf = WeightingFunction {
        ln_p_centre: Vec::with_capacity(n),
        dp_hpa: Vec::with_capacity(n),
        per_hpa: Vec::with_capacity(n),
    };
    for l in 0..n {
        let dp = (p[l] - p[l + 1]) / 100.0;
        let x = state.columns.gas_per_m2[l] / state.columns.dry_air_per_m2[l];
        let dt = state.target_tau[state.tau_index(l, on, 0)]
            - state.target_tau[state.tau_index(l, off, 0)];
        wf.ln_p_centre.push(0.5 * (p[l].ln() + p[l + 1].ln()));
        wf.dp_hpa.push(dp);
        wf.per_hpa.push(dt / (x * dp));
    }
    wf
}

/// Pressure \[hPa\] where `wf` (per layer, centres at ln p `x`) peaks: the largest layer,
/// refined by a parabola through it and its neighbours when it has two.
pub(super) fn peak_pressure_hpa(x: &[f64], wf: &[f64]) -> f64 {
    let Some((k, _)) = wf
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .max_by(|a, b| a.1.total_cmp(b.1))
    else {
        return f64::NAN;
    };
    let mut ln_p = x[k];
    if k > 0 && k + 1 < wf.len() {
        let (x0, x1, x2) = (x[k - 1], x[k], x[k + 1]);
        let (y0, y1, y2) = (wf[k - 1], wf[k], wf[k + 1]);
        let num = (x1 - x0).powi(2) * (y1 - y2) - (x1 - x2).powi(2) * (y1 - y0);
        let den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0);
        if den != 0.0 {
            let v = x1 - 0.5 * num / den;
            ln_p = v.clamp(x0.min(x2), x0.max(x2));
        }
    }
    ln_p.exp() / 100.0
}

/// Study one profile (module docs). The member's CO2 is used as it is: set it first with
/// [`set_co2_column_average`].
pub fn study_member(member: &SetMember, cfg: &StudyConfig) -> Result<MemberResult, SelectError> {
    let n = cfg.positions.len();
    if n == 0 {
        return Err(invalid(
            "--on-cm1",
            "(none)",
            "no on-line position to study",
        ));
    }
    let profiles = shifted(member, &cfg.steps)?;
    let surface_m = profiles[0].altitude_m[0];
    let top_m = profiles
        .iter()
        .map(|p| p.altitude_m[p.len() - 1])
        .fold(cfg.grid.top_m, f64::min);
    let edges = layer_edges(surface_m, top_m, cfg.grid.layer_m)?;
    let z_top = edges[edges.len() - 1];

    let dnu = cfg.steps.frequency_mhz / MHZ_PER_CM1;
    let (base, all) = study_lines(cfg, dnu);
    let off = n;
    let state = |profile: &Profile, lines: &[Line]| -> Result<ReferenceState, SelectError> {
        Ok(ReferenceState::new(
            profile,
            &edges,
            "CO2",
            &cfg.lines,
            &cfg.options,
            AssumedInstrument {
                laser: &Laser::ideal(1.0, lines.len()),
                lines,
                filter: &Filter::none(),
            },
        )?)
    };
    let mut memo = LayerDepthMemo::new();
    let s0 = ReferenceState::new_with(
        &profiles[0],
        &edges,
        "CO2",
        &cfg.lines,
        &cfg.options,
        AssumedInstrument {
            laser: &Laser::ideal(1.0, all.len()),
            lines: &all,
            filter: &Filter::none(),
        },
        &mut memo,
    )?;
    let s_t = state(&profiles[1], &base)?;
    let s_q = if member.profile.gas("H2O").is_some() {
        Some(state(&profiles[2], &base)?)
    } else {
        None
    };
    let s_p = state(&profiles[3], &base)?;
    let s_q = s_q.as_ref().unwrap_or(&s0);

    let path = |s: &ReferenceState| s.path(z_top, surface_m, -1.0);
    let xco2 = |s: &ReferenceState| {
        let (g, d) = s.columns.between(z_top, surface_m);
        g / d
    };
    let (p0, p_t, p_q, p_p) = (path(&s0), path(&s_t), path(s_q), path(&s_p));
    let (x0, x_t, x_q, x_p) = (xco2(&s0), xco2(&s_t), xco2(s_q), xco2(&s_p));
    let tau = |p: &crate::retrieval::PathDepths, line: usize| {
        let k = line * p.nodes;
        p.target_scaled[k] + p.target_fixed[k] + p.other[k]
    };
    // The error of a retrieval whose reference is (state, path, X) given the true DAOD.
    let error_ppm =
        |s: &ReferenceState,
         p: &crate::retrieval::PathDepths,
         x_assumed: f64,
         on: usize,
         d_true: f64,
         x_true: f64| { (s.solve_scale(p, on, off, d_true) * x_assumed - x_true) * 1e6 };

    let rayleigh_tau = rayleigh_optical_depth(cfg, &profiles[0], &edges)?;
    let tau_off = tau(&p0, off);
    let slope_off = tau(&p0, 2 * n + 1) - tau_off;

    let mut positions = Vec::with_capacity(n);
    for (i, pos) in cfg.positions.iter().enumerate() {
        let d0 = tau(&p0, i) - tau_off;
        // Weighting function per unit pressure of the unshifted profile.
        let wf = weighting_function(&profiles[0], &s0, i, off);
        let d_of = |s: &ReferenceState, p: &crate::retrieval::PathDepths| s.daod(p, i, off, 1.0).0;
        let d_f = s0.daod(&p0, n + 1 + i, off, 1.0).0;
        let t2_on = (-2.0 * tau(&p0, i)).exp();
        let random_error_ppm = match &cfg.noise {
            Some(m) => {
                let range = m.lidar_altitude_m - surface_m;
                let extra = 2.0 * (rayleigh_tau + m.particle_optical_depth);
                let t2 = |t: f64| (-2.0 * t - extra).exp();
                let snr_on = m.snr(0, pos.nu_cm1, range, t2(tau(&p0, i)));
                let snr_off = m.snr(1, cfg.off_cm1, range, t2(tau_off));
                // ∂ln E/∂ν = −2 ∂τ/∂ν per MHz, from the lines shifted by the step.
                let per_mhz = 1.0 / cfg.steps.frequency_mhz;
                let slope_on = -2.0 * (tau(&p0, n + 1 + i) - tau(&p0, i)) * per_mhz;
                let slope_off = -2.0 * slope_off * per_mhz;
                let inv2 = |snr: f64| {
                    if snr > 0.0 {
                        1.0 / (snr * snr)
                    } else {
                        f64::INFINITY
                    }
                };
                let sj = m.frequency_jitter_rms_mhz;
                let var = inv2(snr_on)
                    + inv2(snr_off)
                    + 2.0 * m.energy_monitor_error_fraction.powi(2)
                    + (sj * slope_on).powi(2)
                    + (sj * slope_off).powi(2);
                x0 * 1e6 * var.sqrt() / (2.0 * d0 * (m.averaging_shots as f64).sqrt())
            }
            None => f64::NAN,
        };
        positions.push(PositionResult {
            daod_one_way: d0,
            wf_peak_hpa: wf.peak_hpa(),
            dxco2_per_k_ppm: error_ppm(&s0, &p0, x0, i, d_of(&s_t, &p_t), x_t),
            dxco2_per_mhz_ppm: error_ppm(&s0, &p0, x0, i, d_f, x0),
            dxco2_per_hpa_ppm: error_ppm(&s_p, &p_p, x_p, i, d_of(&s0, &p0), x0),
            dxco2_per_10pct_h2o_ppm: error_ppm(&s0, &p0, x0, i, d_of(s_q, &p_q), x_q),
            t2_on,
            random_error_ppm,
        });
    }

    Ok(MemberResult {
        id: member.meta.id.clone(),
        class: member.meta.class(),
        edges_m: edges,
        xco2_ppm: x0 * 1e6,
        positions,
    })
}

/// The lines of a member's study: the on positions and the off-line (`base`), and `all`: those
/// followed by the same shifted by `dnu` \[cm⁻¹\].
fn study_lines(cfg: &StudyConfig, dnu: f64) -> (Vec<Line>, Vec<Line>) {
    // Lines: on positions, off, on + δν, off + δν (the last two only for the unshifted state).
    let named = |name: String, nu: f64| Line {
        name,
        wavenumber_cm1: nu,
    };
    let mut base: Vec<Line> = cfg
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| named(format!("on{i}"), p.nu_cm1))
        .collect();
    base.push(named("off".into(), cfg.off_cm1));
    let mut all = base.clone();
    all.extend(
        cfg.positions
            .iter()
            .enumerate()
            .map(|(i, p)| named(format!("on{i}+"), p.nu_cm1 + dnu)),
    );
    all.push(named("off+".into(), cfg.off_cm1 + dnu));
    (base, all)
}

/// The Rayleigh optical depth of the air column of `profile` over `edges` at the off-line, for
/// the noise model (0 without one).
fn rayleigh_optical_depth(
    cfg: &StudyConfig,
    profile: &Profile,
    edges: &[f64],
) -> Result<f64, SelectError> {
    // Rayleigh optical depth of the air column over the grid (Bucholtz 1995).
    let tau = match &cfg.noise {
        Some(_) => {
            let wavelength_nm = 1e7 / cfg.off_cm1;
            let sigma = crate::particles::rayleigh::cross_section_m2(wavelength_nm)
                .map_err(|e| invalid("--off-cm1", cfg.off_cm1, e.to_string()))?;
            let air: f64 = crate::spectroscopy::layers::curtis_godson_layers(profile, edges)?
                .iter()
                .map(|l| l.air_column_per_cm2 * 1e4)
                .sum();
            sigma * air
        }
        None => 0.0,
    };
    Ok(tau)
}

/// The fine spectra of `cfg.spectra` for `profile` (a group's mean profile, its CO2 set: the
/// figures'): the two-way gas transmission, top to surface over the layers a member's study
/// would use ([`layer_edges`] from the surface to the grid's top), at every offset of each
/// window ([`column_depths_two_grid`]). Computed once per group, not per member: every
/// member's spectra made the figures a third of `select-lines`' CPU time.
pub fn transmission_spectra(
    cfg: &StudyConfig,
    profile: &Profile,
) -> Result<Vec<Vec<f64>>, SelectError> {
    if cfg.spectra.is_empty() {
        return Ok(Vec::new());
    }
    let top_m = profile.altitude_m[profile.len() - 1].min(cfg.grid.top_m);
    let edges = layer_edges(profile.altitude_m[0], top_m, cfg.grid.layer_m)?;
    let memo = &mut LayerDepthMemo::new();
    let windows: Vec<Vec<f64>> = cfg
        .spectra
        .iter()
        .map(|w| {
            w.offsets_ghz
                .iter()
                .map(|o| w.centre_cm1 + o / GHZ_PER_CM1)
                .collect()
        })
        .collect();
    let columns =
        column_depths_two_grid(profile, &cfg.lines, &edges, &windows, &cfg.options, memo)?;
    Ok(columns
        .iter()
        .map(|c| c.iter().map(|tau| (-2.0 * tau).exp()).collect())
        .collect())
}

/// Distance beyond a window within which a line counts as near [cm⁻¹]: some 7 pressure
/// half-widths at the surface, so that every far line's wing is smooth over the window.
const NEAR_CM1: f64 = 0.5;
/// Nodes at which the far lines are evaluated, per window.
const FAR_NODES: usize = 9;

/// The column optical depth (summed over the layers) at the sorted wavenumbers of each
/// window, on two grids, the way LBL codes treat far wings on a coarse grid (Clough, Kneizys
/// and Davies 1989, "Line shape and the water vapor continuum", Atmos. Res. 23, 229–241; LBLRTM
/// after it): the lines within [`NEAR_CM1`] of a window at each of its wavenumbers (the
/// multigrid on a uniform window, [`GasOpticalDepthTable`]), the rest (every line that can reach
/// the window minus the near ones) at [`FAR_NODES`] of them, by cubic Lagrange in between. A
/// far line's wing is at least 0.5 cm⁻¹ away, where a Lorentz wing's fourth derivative bounds
/// the interpolation error to ~1e-5 of the far part; a far line's 25 cm⁻¹ cutoff falling inside
/// a window is a step of ~1e-5 of its peak, smeared over one node interval. The line-by-line
/// sum of every line at each of the ~400 wavenumbers made these spectra, drawn only in the
/// figures, take most of `select-lines`' time.
fn column_depths_two_grid(
    profile: &Profile,
    lines: &LineList,
    edges: &[f64],
    windows: &[Vec<f64>],
    opts: &LblOptions,
    memo: &mut LayerDepthMemo,
) -> Result<Vec<Vec<f64>>, SelectError> {
    let column = |t: &[Vec<f64>], k: usize| -> f64 { t.iter().map(|row| row[k]).sum() };
    let sorted = |nus: &[f64]| nus.windows(2).all(|p| p[1] > p[0]);
    if windows.is_empty() {
        return Ok(Vec::new());
    }
    if windows
        .iter()
        .any(|w| w.len() <= 2 * FAR_NODES || !sorted(w))
    {
        return windows
            .iter()
            .map(|nus| {
                let t = layer_optical_depths_at(profile, lines, edges, nus, opts)?;
                Ok((0..nus.len()).map(|k| column(&t, k)).collect())
            })
            .collect();
    }
    let within = |lo: f64, hi: f64| LineList {
        source: lines.source.clone(),
        lines: lines
            .lines
            .iter()
            .filter(|l| l.nu_cm1 >= lo && l.nu_cm1 <= hi)
            .cloned()
            .collect(),
    };
    // Every line at the nodes of all windows at once, from the lines prepared for the study.
    let nodes = |n: usize| -> Vec<usize> {
        (0..FAR_NODES)
            .map(|j| j * (n - 1) / (FAR_NODES - 1))
            .collect()
    };
    let node_nus: Vec<f64> = windows
        .iter()
        .flat_map(|w| nodes(w.len()).into_iter().map(|k| w[k]))
        .collect();
    let t = memo.layer_optical_depths_at(profile, lines, edges, &node_nus, opts)?;
    let all_at_nodes: Vec<f64> = (0..node_nus.len()).map(|k| column(&t, k)).collect();
    let mut out = Vec::with_capacity(windows.len());
    for (i, nus) in windows.iter().enumerate() {
        let n = nus.len();
        let near = within(nus[0] - NEAR_CM1, nus[n - 1] + NEAR_CM1);
        let near_fine: Vec<f64> = if near.is_empty() {
            vec![0.0; n]
        } else {
            let t = layer_optical_depths_at(profile, &near, edges, nus, opts)?;
            (0..n).map(|k| column(&t, k)).collect()
        };
        let idx = nodes(n);
        let x: Vec<f64> = idx.iter().map(|&k| nus[k]).collect();
        // The far part at the nodes: everything minus the near lines, at the same wavenumbers.
        let far: Vec<f64> = idx
            .iter()
            .zip(&all_at_nodes[i * FAR_NODES..(i + 1) * FAR_NODES])
            .map(|(&k, all)| all - near_fine[k])
            .collect();
        out.push(
            nus.iter()
                .zip(&near_fine)
                .map(|(&nu, near)| near + lagrange4(&x, &far, nu))
                .collect(),
        );
    }
    Ok(out)
}

/// Cubic Lagrange interpolation of (x, y) at `x0`, through the four nodes around it (the
/// first or last four at the ends); `x` sorted, at least four nodes.
fn lagrange4(x: &[f64], y: &[f64], x0: f64) -> f64 {
    let j = x.partition_point(|v| *v <= x0).clamp(2, x.len() - 2) - 2;
    let (xs, ys) = (&x[j..j + 4], &y[j..j + 4]);
    (0..4)
        .map(|a| {
            let w: f64 = (0..4)
                .filter(|b| *b != a)
                .map(|b| (x0 - xs[b]) / (xs[a] - xs[b]))
                .product();
            w * ys[a]
        })
        .sum()
}

/// Study every member with its CO2 set to a dry-air column average of `co2_ppm` first
/// ([`set_co2_column_average`]), in parallel (rayon) and in member order; the numbers do not
/// depend on the thread count (each member is computed alone). `progress` is called once per
/// member.
pub fn study_members(
    members: &[&SetMember],
    cfg: &StudyConfig,
    co2_ppm: f64,
    progress: &(dyn Fn() + Sync),
    stop: Option<&AtomicBool>,
) -> Vec<Result<MemberResult, MemberFailure>> {
    members
        .par_iter()
        .map(|m| {
            if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
                return Err(MemberFailure {
                    id: m.meta.id.clone(),
                    reason: "stopped".into(),
                });
            }
            let mut m = (*m).clone();
            let r = set_co2_column_average(&mut m.profile, co2_ppm)
                .map_err(SelectError::from)
                .and_then(|()| study_member(&m, cfg))
                .map_err(|e| MemberFailure {
                    id: m.meta.id.clone(),
                    reason: e.to_string(),
                });
            progress();
            r
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::StandardAtmosphere;
    use crate::spectroscopy::LineFilter;

    /// The two-grid column depths against the line-by-line sum at every wavenumber, over the
    /// study's windows (±4 GHz by 0.02 GHz around R16e and R26e): the built-in band model, and
    /// with the HITRAN CO2 and H2O files when `../shared` has them (read in place).
    #[test]
    fn two_grid_spectra_match_the_line_by_line_sum() {
        let mut profile = StandardAtmosphere::Tropical.profile();
        set_co2_column_average(&mut profile, 420.0).unwrap();
        let edges = layer_edges(profile.altitude_m[0], 60_000.0, 1000.0).unwrap();
        let windows: Vec<Vec<f64>> = [6359.967244, 6366.086989]
            .iter()
            .map(|c| {
                (0..=400)
                    .map(|k| c + (-4.0 + 0.02 * k as f64) / GHZ_PER_CM1)
                    .collect()
            })
            .collect();
        let opts = LblOptions::default();
        let mut lists = vec![LineList::co2_30012_band_model()];
        let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/hitran");
        let files = [
            "CO2_626_6000-6400_HITRAN2016.par",
            "H2O_161_6000-6400_HITRAN2016.par",
        ];
        if files.iter().all(|f| shared.join(f).is_file()) {
            let mut all = LineList {
                source: "HITRAN".into(),
                lines: Vec::new(),
            };
            for f in files {
                let l = LineList::read_par(&shared.join(f), &LineFilter::default()).unwrap();
                all.lines.extend(l.lines);
            }
            all.lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
            lists.push(all);
        }
        for lines in &lists {
            let fast = column_depths_two_grid(
                &profile,
                lines,
                &edges,
                &windows,
                &opts,
                &mut LayerDepthMemo::new(),
            )
            .unwrap();
            for (w, nus) in windows.iter().enumerate() {
                let t = layer_optical_depths_at(&profile, lines, &edges, nus, &opts).unwrap();
                for (k, f) in fast[w].iter().enumerate() {
                    let exact: f64 = t.iter().map(|row| row[k]).sum();
                    // 1e-5 of τ, and 1e-5 in the two-way transmission e^(−2τ) the figure draws.
                    let (t2, t2_exact) = ((-2.0 * f).exp(), (-2.0 * exact).exp());
                    assert!(
                        (f - exact).abs() <= 1e-5 * exact && (t2 - t2_exact).abs() <= 1e-5,
                        "{}: window {w}, point {k}: {f} against {exact}",
                        lines.source
                    );
                }
            }
        }
    }
}
