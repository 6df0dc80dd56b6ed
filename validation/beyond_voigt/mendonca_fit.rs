//! The instrument (FTS line shape by FFT), the least-squares fit and the residual statistics of
//! the `mendonca_30012` example.

use anyhow::{Result, bail};
use nalgebra::{Matrix4, Vector4};
use num_complex::Complex64;

use lidarsim::constants::STANDARD_ATMOSPHERE_PA;
use lidarsim::spectroscopy::{GasState, LineList, WavenumberGrid};

/// The measured spectrum.
pub struct Measurement {
    /// Wavenumbers [cm⁻¹].
    pub nu: Vec<f64>,
    /// Transmission.
    pub t: Vec<f64>,
}

/// The FTS instrument line shape.
#[derive(Debug, Clone, Copy)]
pub struct Ils {
    /// Maximum optical path difference L [cm] (unapodised: ILS(δ) = 2L sinc(2πLδ)); infinite
    /// for no ILS.
    pub max_opd_cm: f64,
    /// Width of the self-apodisation boxcar ν Ω/(2π) [cm⁻¹] (0: a point aperture). Its shift
    /// −ν Ω/(4π) is proportional to ν, so the fitted wavenumber scale absorbs it.
    pub aperture_width_cm1: f64,
}

impl Ils {
    /// The Fourier transform of the ILS at optical path difference x [cm]: the boxcar
    /// |x| ≤ L times the aperture's sinc(π x w).
    fn transfer(&self, x: f64) -> f64 {
        if x.abs() > self.max_opd_cm {
            return 0.0;
        }
        let u = std::f64::consts::PI * x * self.aperture_width_cm1;
        if u == 0.0 { 1.0 } else { u.sin() / u }
    }
}

/// In-place radix-2 complex FFT; `inverse` uses e^{+2πi jk/N} and divides by N.
fn fft(a: &mut [Complex64], inverse: bool) {
    let n = a.len();
    assert!(n.is_power_of_two());
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            a.swap(i, j);
        }
    }
    let sign = if inverse { 1.0 } else { -1.0 };
    let mut len = 2;
    while len <= n {
        let ang = sign * 2.0 * std::f64::consts::PI / len as f64;
        let half = len / 2;
        // Twiddles computed directly (not by recurrence) to keep rounding at 1e-16.
        let tw: Vec<Complex64> = (0..half)
            .map(|k| Complex64::from_polar(1.0, ang * k as f64))
            .collect();
        for start in (0..n).step_by(len) {
            for k in 0..half {
                let u = a[start + k];
                let v = a[start + k + half] * tw[k];
                a[start + k] = u + v;
                a[start + k + half] = u - v;
            }
        }
        len <<= 1;
    }
    if inverse {
        let s = 1.0 / n as f64;
        for x in a.iter_mut() {
            *x *= s;
        }
    }
}

/// A model's monochromatic optical depth on the fine grid and the instrument.
pub struct ModelSpectrum {
    grid: WavenumberGrid,
    tau: Vec<f64>,
    ils: Ils,
}

impl ModelSpectrum {
    pub fn new(grid: WavenumberGrid, tau: Vec<f64>, ils: Ils) -> Self {
        assert!(grid.len.is_power_of_two() && tau.len() == grid.len);
        ModelSpectrum { grid, tau, ils }
    }

    /// The transmission exp(−s τ) convolved with the ILS on the fine grid. The absorption
    /// 1 − exp(−s τ) minus the straight line joining its end values is convolved by FFT
    /// (continuous when extended periodically, so no wrap-around jump), and the line, which
    /// the unit-area symmetric ILS leaves unchanged, is added back.
    pub fn convolved(&self, s: f64) -> Vec<f64> {
        let n = self.grid.len;
        let a: Vec<f64> = self.tau.iter().map(|t| 1.0 - (-s * t).exp()).collect();
        if self.ils.max_opd_cm.is_infinite() && self.ils.aperture_width_cm1 == 0.0 {
            return a.iter().map(|x| 1.0 - x).collect();
        }
        let (a0, a1) = (a[0], a[n - 1]);
        let ramp = |i: usize| a0 + (a1 - a0) * i as f64 / (n - 1) as f64;
        let mut c: Vec<Complex64> = a
            .iter()
            .enumerate()
            .map(|(i, x)| Complex64::new(x - ramp(i), 0.0))
            .collect();
        fft(&mut c, false);
        let span = n as f64 * self.grid.step_cm1;
        for (k, v) in c.iter_mut().enumerate() {
            let kk = if k <= n / 2 {
                k as f64
            } else {
                k as f64 - n as f64
            };
            *v *= self.ils.transfer(kk / span);
        }
        fft(&mut c, true);
        c.iter()
            .enumerate()
            .map(|(i, v)| 1.0 - (v.re + ramp(i)))
            .collect()
    }

    /// Cubic (4-point Lagrange) interpolation of a fine-grid series at ν.
    pub fn at(&self, series: &[f64], nu: f64) -> f64 {
        let u = (nu - self.grid.start_cm1) / self.grid.step_cm1;
        let i = (u.floor() as usize).clamp(1, self.grid.len - 3);
        let f = u - i as f64;
        let (p0, p1, p2, p3) = (series[i - 1], series[i], series[i + 1], series[i + 2]);
        -f * (f - 1.0) * (f - 2.0) / 6.0 * p0 + (f + 1.0) * (f - 1.0) * (f - 2.0) / 2.0 * p1
            - (f + 1.0) * f * (f - 2.0) / 2.0 * p2
            + (f + 1.0) * f * (f - 1.0) / 6.0 * p3
    }
}

/// A fit's parameters and its model at the measured wavenumbers.
pub struct FitResult {
    /// CO2 amount scale s (τ → s τ).
    pub amount_scale: f64,
    /// Wavenumber scale ε: the model is evaluated at ν_meas (1 + ε).
    pub epsilon: f64,
    /// Baseline b₀ + b₁ (ν − ν_mid) (b₁ per cm⁻¹).
    pub baseline: [f64; 2],
    /// RMS residual in transmission.
    pub rms: f64,
    pub iterations: usize,
    /// Fitted model at the measured wavenumbers.
    pub model: Vec<f64>,
    /// Measurement − model.
    pub residual: Vec<f64>,
    /// The convolved gas transmission (without baseline) at the measured wavenumbers.
    pub gas: Vec<f64>,
}

fn evaluate(
    meas: &Measurement,
    model: &ModelSpectrum,
    conv: &[f64],
    p: &Vector4<f64>,
    nu_mid: f64,
) -> (Vec<f64>, Vec<f64>) {
    let gas: Vec<f64> = meas
        .nu
        .iter()
        .map(|&nu| model.at(conv, nu * (1.0 + p[2])))
        .collect();
    let m = meas
        .nu
        .iter()
        .zip(&gas)
        .map(|(&nu, g)| (p[0] + p[1] * (nu - nu_mid)) * g)
        .collect();
    (m, gas)
}

fn cost(meas: &Measurement, m: &[f64]) -> f64 {
    meas.t.iter().zip(m).map(|(y, x)| (y - x).powi(2)).sum()
}

/// Levenberg-Marquardt (Marquardt's diagonal scaling) over (b₀, b₁, ε, s), with numerical
/// derivatives for ε (central, ±1e-9) and s (forward, 1e-5).
pub fn fit(meas: &Measurement, model: &ModelSpectrum) -> Result<FitResult> {
    let nu_mid = 0.5 * (meas.nu[0] + meas.nu[meas.nu.len() - 1]);
    let mut p = Vector4::new(1.0, 0.0, 0.0, 1.0);
    let mut conv = model.convolved(p[3]);
    let (mut m, _) = evaluate(meas, model, &conv, &p, nu_mid);
    let mut c = cost(meas, &m);
    let mut lambda = 1e-3;
    for it in 0..100 {
        let iterations = it + 1;
        let ds = 1e-5;
        let de = 1e-9;
        let conv_s = model.convolved(p[3] + ds);
        let mut jtj = Matrix4::<f64>::zeros();
        let mut jtr = Vector4::<f64>::zeros();
        for (i, &nu) in meas.nu.iter().enumerate() {
            let b = p[0] + p[1] * (nu - nu_mid);
            let g = model.at(&conv, nu * (1.0 + p[2]));
            let dg_de = (model.at(&conv, nu * (1.0 + p[2] + de))
                - model.at(&conv, nu * (1.0 + p[2] - de)))
                / (2.0 * de);
            let dg_ds = (model.at(&conv_s, nu * (1.0 + p[2])) - g) / ds;
            let j = Vector4::new(g, (nu - nu_mid) * g, b * dg_de, b * dg_ds);
            jtj += j * j.transpose();
            jtr += j * (meas.t[i] - m[i]);
        }
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj;
            for k in 0..4 {
                a[(k, k)] *= 1.0 + lambda;
            }
            let Some(step) = a.lu().solve(&jtr) else {
                lambda *= 10.0;
                continue;
            };
            let q = p + step;
            let conv_q = model.convolved(q[3]);
            let (m_q, _) = evaluate(meas, model, &conv_q, &q, nu_mid);
            let c_q = cost(meas, &m_q);
            if c_q < c {
                let rel = (c - c_q) / c;
                p = q;
                conv = conv_q;
                m = m_q;
                c = c_q;
                lambda = (lambda / 10.0).max(1e-12);
                improved = true;
                if rel < 1e-12 {
                    return finish(meas, model, &conv, p, nu_mid, iterations);
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            // No step lowers the cost: converged to rounding.
            return finish(meas, model, &conv, p, nu_mid, iterations);
        }
    }
    bail!("the fit did not converge in 100 iterations")
}

fn finish(
    meas: &Measurement,
    model: &ModelSpectrum,
    conv: &[f64],
    p: Vector4<f64>,
    nu_mid: f64,
    iterations: usize,
) -> Result<FitResult> {
    let (m, gas) = evaluate(meas, model, conv, &p, nu_mid);
    let residual: Vec<f64> = meas.t.iter().zip(&m).map(|(y, x)| y - x).collect();
    let rms = (residual.iter().map(|r| r * r).sum::<f64>() / residual.len() as f64).sqrt();
    Ok(FitResult {
        amount_scale: p[3],
        epsilon: p[2],
        baseline: [p[0], p[1]],
        rms,
        iterations,
        model: m,
        residual,
        gas,
    })
}

/// RMS of `r` where `mask` is true.
pub fn rms_on(r: &[f64], mask: &[bool]) -> f64 {
    let (s, n) = r
        .iter()
        .zip(mask)
        .filter(|(_, m)| **m)
        .fold((0.0, 0usize), |(s, n), (x, _)| (s + x * x, n + 1));
    (s / n.max(1) as f64).sqrt()
}

/// The measurement's noise estimated in line-free stretches.
pub struct Noise {
    /// Absorption threshold of "line-free" (fitted gas absorption below it).
    pub threshold: f64,
    pub mask: Vec<bool>,
    pub points: usize,
    /// RMS of point-to-point differences of the residual /√2 (pairs inside the mask).
    pub diff_rms: f64,
    /// Lag-1 autocorrelation of the residual inside the mask.
    pub lag1: f64,
    /// RMS residual of the beyond-Voigt fit inside the mask.
    pub residual_rms_beyond: f64,
}

/// Line-free: the fitted gas absorption 1 − T_gas is below `THRESHOLD` at the point and its
/// neighbours. Differences of the residual (not of the measurement) remove the smooth wings
/// that remain there.
pub fn noise_floor(meas: &Measurement, f: &FitResult) -> Noise {
    const THRESHOLD: f64 = 5e-3;
    let n = meas.nu.len();
    let free: Vec<bool> = f.gas.iter().map(|g| 1.0 - g < THRESHOLD).collect();
    let mask: Vec<bool> = (0..n)
        .map(|i| i > 0 && i + 1 < n && free[i - 1] && free[i] && free[i + 1])
        .collect();
    let r = &f.residual;
    let (mut sd, mut nd, mut c1, mut c0) = (0.0, 0usize, 0.0, 0.0);
    let mean = {
        let (s, k) = (0..n)
            .filter(|&i| mask[i])
            .fold((0.0, 0usize), |(s, k), i| (s + r[i], k + 1));
        s / k.max(1) as f64
    };
    for i in 0..n - 1 {
        if mask[i] && mask[i + 1] {
            sd += (r[i + 1] - r[i]).powi(2);
            nd += 1;
            c1 += (r[i] - mean) * (r[i + 1] - mean);
        }
        if mask[i] {
            c0 += (r[i] - mean).powi(2);
        }
    }
    let points = mask.iter().filter(|m| **m).count();
    Noise {
        threshold: THRESHOLD,
        diff_rms: (sd / nd.max(1) as f64 / 2.0).sqrt(),
        lag1: c1 / nd.max(1) as f64 / (c0 / points.max(1) as f64),
        residual_rms_beyond: rms_on(r, &mask),
        points,
        mask,
    }
}

/// One band line's residuals under each model.
pub struct LineResidual {
    pub label: String,
    pub nu0: f64,
    /// The measured line centre [cm⁻¹, measurement scale].
    pub nu_centre: f64,
    /// Residual at the centre, per model.
    pub centre: Vec<f64>,
    /// Largest |residual| within ±0.1 cm⁻¹ of the centre, per model.
    pub max_abs: Vec<f64>,
}

/// For each line of `lines`: the measured centre is the minimum of the measurement (5-point
/// running mean) within ±0.02 cm⁻¹ of the pressure-shifted centre ν₀ + Δ₀ in the measurement's
/// scale (ν/(1 + ε) of `reference`).
pub fn per_line(
    meas: &Measurement,
    lines: &LineList,
    state: &GasState,
    reference: &FitResult,
    fits: &[&FitResult],
) -> Vec<LineResidual> {
    let p_atm = state.pressure_pa / STANDARD_ATMOSPHERE_PA;
    let x = state.self_vmr;
    let n = meas.nu.len();
    let smooth = |i: usize| -> f64 {
        let lo = i.saturating_sub(2);
        let hi = (i + 2).min(n - 1);
        meas.t[lo..=hi].iter().sum::<f64>() / (hi - lo + 1) as f64
    };
    let range = |lo: f64, hi: f64| -> std::ops::Range<usize> {
        meas.nu.partition_point(|&v| v < lo)..meas.nu.partition_point(|&v| v <= hi)
    };
    lines
        .lines
        .iter()
        .map(|l| {
            let sp = l.shape.as_ref().expect("CSV lines carry shape parameters");
            let dt = state.temperature_k - 296.0;
            let delta0 = p_atm
                * ((1.0 - x) * (sp.air.delta0 + sp.air.n_delta0 * dt)
                    + x * (sp.self_broadening.delta0 + sp.self_broadening.n_delta0 * dt));
            let guess = (l.nu_cm1 + delta0) / (1.0 + reference.epsilon);
            let ic = range(guess - 0.02, guess + 0.02)
                .min_by(|&a, &b| smooth(a).total_cmp(&smooth(b)))
                .expect("the line lies inside the measured window");
            let nu_c = meas.nu[ic];
            let win = range(nu_c - 0.1, nu_c + 0.1);
            LineResidual {
                label: l.local_lower_quanta().split_whitespace().collect(),
                nu0: l.nu_cm1,
                nu_centre: nu_c,
                centre: fits.iter().map(|f| f.residual[ic]).collect(),
                max_abs: fits
                    .iter()
                    .map(|f| {
                        f.residual[win.clone()]
                            .iter()
                            .fold(0.0f64, |a, r| a.max(r.abs()))
                    })
                    .collect(),
            }
        })
        .collect()
}

/// Autocorrelation of `r` (mean removed) at lags 1..=`max_lag`.
pub fn autocorrelation(r: &[f64], max_lag: usize) -> Vec<f64> {
    let n = r.len();
    let mean = r.iter().sum::<f64>() / n as f64;
    let c0: f64 = r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
    (1..=max_lag)
        .map(|k| {
            (0..n - k)
                .map(|i| (r[i] - mean) * (r[i + k] - mean))
                .sum::<f64>()
                / (n - k) as f64
                / c0
        })
        .collect()
}

/// The residual's variance by optical path difference band, from its periodogram: returns
/// (variance in |x| ∈ [x_lo, x_hi), variance in |x| ≥ x_hi) with x_k = k/(N_pad h) [cm].
/// White noise band-limited to |x| ≤ L has variance σ² (x_hi − x_lo)/L in the first band
/// and none in the second.
pub fn band_variance(r: &[f64], step_cm1: f64, x_lo: f64, x_hi: f64) -> (f64, f64) {
    let n = r.len();
    let npad = n.next_power_of_two();
    let mean = r.iter().sum::<f64>() / n as f64;
    let mut c: Vec<Complex64> = (0..npad)
        .map(|i| Complex64::new(if i < n { r[i] - mean } else { 0.0 }, 0.0))
        .collect();
    fft(&mut c, false);
    let span = npad as f64 * step_cm1;
    let (mut inside, mut beyond) = (0.0, 0.0);
    for (k, v) in c.iter().enumerate() {
        let kk = if k <= npad / 2 { k } else { npad - k };
        let x = kk as f64 / span;
        let p = v.norm_sqr() / (n as f64 * npad as f64);
        if x >= x_hi {
            beyond += p;
        } else if x >= x_lo {
            inside += p;
        }
    }
    (inside, beyond)
}
