//! The statistics of a study per class and line pair.

use super::*;

/// Bias and spread of one budget row over a group of profiles \[ppm\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceStats {
    /// Mean error (0 for the random row).
    pub bias_ppm: f64,
    /// Standard deviation over the profiles (the random row: the rms of each profile's 1σ).
    pub sd_ppm: f64,
    /// √(bias² + sd²).
    pub rms_ppm: f64,
    /// rms² over the sum of every row's rms²: the row's share of the total error variance.
    pub share: f64,
}

/// Statistics of one retrieved quantity over a group of profiles.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// A latitude class, or `all`.
    pub class: String,
    /// `on/off`.
    pub pair: String,
    /// IPDA or DIAL.
    pub method: Method,
    /// Altitude interval \[m\].
    pub altitude_m: (f64, f64),
    /// Profiles in the group (failed ones excluded).
    pub profiles: usize,
    /// Of those, the profiles whose noise-free values could all be computed
    /// ([`Record::is_defined`]): the members of `bias_ppm`, `sd_ppm`, the budget rows and
    /// `total_ppm`. `profiles` from the analytic lidar equation; from Monte Carlo returns the
    /// profiles with energy in the quantity's windows.
    pub retrieved_profiles: usize,
    /// Of those, the profiles whose noisy measurement could be retrieved too: the members of
    /// `noisy_bias_ppm`, `noisy_sd_ppm` and `noise_ratio`.
    pub noisy_profiles: usize,
    /// Mean truth \[ppm\].
    pub truth_mean_ppm: f64,
    /// Mean and standard deviation of retrieved − truth, noise-free, over the
    /// `retrieved_profiles` \[ppm\] (NaN, an empty field, for none; the standard deviation
    /// also for one).
    pub bias_ppm: f64,
    /// See `bias_ppm`.
    pub sd_ppm: f64,
    /// The same with one noisy measurement per profile, over the `noisy_profiles` whose
    /// measurement could be retrieved \[ppm\] (NaN, an empty field, for none; the standard
    /// deviation also for one).
    pub noisy_bias_ppm: f64,
    /// See `noisy_bias_ppm`.
    pub noisy_sd_ppm: f64,
    /// Standard deviation of noisy − noise-free over the `noisy_profiles`, divided by the rms
    /// analytic random error over the same profiles: 1 within sampling error (√(1/(2n))
    /// relative) if the analytic error is right (NaN, an empty field, for fewer than 2).
    pub noise_ratio: f64,
    /// The budget rows in [`Source::ALL`] order.
    pub sources: [SourceStats; N_SOURCES],
    /// √ of the sum of every row's rms² \[ppm\].
    pub total_ppm: f64,
}

/// Root mean square (NaN for none).
fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// Mean and sample standard deviation; NaN where undefined (no value; one, for the standard
/// deviation), which the writers make empty fields and `_FillValue`.
fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0)
    } else {
        f64::NAN
    };
    (m, var.sqrt())
}

/// Statistics per class (and over all classes when there are several), pair, method and
/// altitude interval, in class, pair and record order. Failed profiles are left out.
pub fn summarise(outcomes: &[ProfileOutcome]) -> Vec<Summary> {
    let mut groups: Vec<(String, Vec<&ProfileOutcome>)> = LatitudeClass::ALL
        .iter()
        .map(|c| {
            let members: Vec<&ProfileOutcome> = outcomes.iter().filter(|o| o.class == *c).collect();
            (c.name().to_string(), members)
        })
        .filter(|(_, m)| !m.is_empty())
        .collect();
    if groups.len() > 1 {
        groups.push(("all".into(), outcomes.iter().collect()));
    }
    let mut out = Vec::new();
    for (class, members) in groups {
        let ok: Vec<&Vec<Record>> = members
            .iter()
            .filter_map(|o| o.records.as_ref().ok())
            .collect();
        let Some(first) = ok.first() else {
            continue;
        };
        // Records of every profile come in the same order (same scene, same pairs).
        for (k, r0) in first.iter().enumerate() {
            let recs: Vec<&Record> = ok.iter().filter_map(|rs| rs.get(k)).collect();
            let col =
                |f: &dyn Fn(&Record) -> f64| -> Vec<f64> { recs.iter().map(|r| f(r)).collect() };
            let (truth_mean_ppm, _) = mean_sd(&col(&|r| r.truth_ppm));
            // The noise-free statistics over the profiles whose noise-free values are all
            // defined (always from the analytic lidar equation; from a Monte Carlo with few
            // photons a window may hold none), so that every budget row and the total are
            // over the same profiles.
            let defined: Vec<&Record> = recs.iter().copied().filter(|r| r.is_defined()).collect();
            let col =
                |f: &dyn Fn(&Record) -> f64| -> Vec<f64> { defined.iter().map(|r| f(r)).collect() };
            let (bias_ppm, sd_ppm) = mean_sd(&col(&|r| r.error_ppm()));
            // The noisy statistics over those whose noisy measurement was retrieved too (a
            // far DIAL cell from space often has no positive noisy signal).
            let noisy: Vec<&Record> = defined
                .iter()
                .copied()
                .filter(|r| r.retrieved_noisy_ppm.is_finite())
                .collect();
            let noisy_col =
                |f: &dyn Fn(&Record) -> f64| -> Vec<f64> { noisy.iter().map(|r| f(r)).collect() };
            let (noisy_bias_ppm, noisy_sd_ppm) = mean_sd(&noisy_col(&|r| r.error_noisy_ppm()));
            let (_, noise_sd) = mean_sd(&noisy_col(&|r| r.retrieved_noisy_ppm - r.retrieved_ppm));
            let noisy_random = rms(&noisy_col(&|r| r.budget_ppm[0]));
            let mut sources = [SourceStats {
                bias_ppm: 0.0,
                sd_ppm: 0.0,
                rms_ppm: 0.0,
                share: 0.0,
            }; N_SOURCES];
            for (j, s) in sources.iter_mut().enumerate() {
                let v = col(&|r| r.budget_ppm[j]);
                if j == 0 {
                    let rms = rms(&v);
                    *s = SourceStats {
                        bias_ppm: if v.is_empty() { f64::NAN } else { 0.0 },
                        sd_ppm: rms,
                        rms_ppm: rms,
                        share: 0.0,
                    };
                } else {
                    let (m, sd) = mean_sd(&v);
                    // One profile: no spread (none: nothing, NaN, empty fields).
                    let sd = if v.len() == 1 { 0.0 } else { sd };
                    *s = SourceStats {
                        bias_ppm: m,
                        sd_ppm: sd,
                        rms_ppm: (m * m + sd * sd).sqrt(),
                        share: 0.0,
                    };
                }
            }
            let total2: f64 = sources.iter().map(|s| s.rms_ppm * s.rms_ppm).sum();
            for s in &mut sources {
                s.share = if total2 > 0.0 {
                    s.rms_ppm * s.rms_ppm / total2
                } else if defined.is_empty() {
                    f64::NAN
                } else {
                    0.0
                };
            }
            out.push(Summary {
                class: class.clone(),
                pair: r0.pair.clone(),
                method: r0.method,
                altitude_m: r0.altitude_m,
                profiles: recs.len(),
                retrieved_profiles: defined.len(),
                noisy_profiles: noisy.len(),
                truth_mean_ppm,
                bias_ppm,
                sd_ppm,
                noisy_bias_ppm,
                noisy_sd_ppm,
                noise_ratio: noise_sd / noisy_random,
                sources,
                total_ppm: total2.sqrt(),
            });
        }
    }
    out
}
