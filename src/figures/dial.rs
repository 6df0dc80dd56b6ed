//! Figures of `lidarsim dial`: the ensemble's spread (`ensemble.png`), the IPDA errors per
//! class (`errors.png`) and the error budget per line pair (`budget.png`, the reference study's
//! Figure 5 in kind).

use std::path::Path;

use plotters::prelude::*;

use super::{FONT, draw_legend, init_font};
use lidarsim::atmosphere::{LatitudeClass, ProfileSet};
use lidarsim::output::{OutputError, OutputSet};
use lidarsim::retrieval::Method;
use lidarsim::study::dial::{N_SOURCES, Source, StudyResult, Summary};

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn class_colour(c: &str) -> RGBColor {
    match c {
        "tropical" => RGBColor(200, 60, 30),
        "mid" => RGBColor(30, 120, 60),
        "high" => RGBColor(30, 70, 190),
        _ => RGBColor(0, 0, 0),
    }
}

/// Draw every figure into `files`, for the directory `dir`.
pub fn draw(
    files: &mut OutputSet,
    dir: &Path,
    set: &ProfileSet,
    result: &StudyResult,
    summaries: &[Summary],
) -> Result<(), OutputError> {
    init_font();
    files.write_via(dir.join("ensemble.png"), |p| ensemble_figure(p, set))?;
    if result
        .outcomes
        .iter()
        .any(|o| o.records.as_ref().is_ok_and(|r| !r.is_empty()))
    {
        files.write_via(dir.join("errors.png"), |p| errors_figure(p, result))?;
    }
    if summaries.iter().any(|m| m.method == Method::Ipda) {
        files.write_via(dir.join("budget.png"), |p| budget_figure(p, summaries))?;
    }
    Ok(())
}

/// (mean pressure \[Pa\], T standard deviation \[K\], relative H2O standard deviation \[%\]).
type LevelSpread = (f64, f64, f64);

/// Per class and level: mean pressure, standard deviation of T \[K\] and of H2O relative to
/// its mean \[%\], over members with the class's most common number of levels.
fn spread(set: &ProfileSet, c: LatitudeClass) -> Vec<LevelSpread> {
    let sub = set.class(c);
    let Some(n) = sub.members.first().map(|m| m.profile.len()) else {
        return Vec::new();
    };
    let ms: Vec<_> = sub
        .members
        .iter()
        .filter(|m| m.profile.len() == n)
        .collect();
    if ms.len() < 2 {
        return Vec::new();
    }
    let k = ms.len() as f64;
    (0..n)
        .map(|l| {
            let p = ms.iter().map(|m| m.profile.pressure_pa[l]).sum::<f64>() / k;
            let sd = |v: Vec<f64>| {
                let mean = v.iter().sum::<f64>() / k;
                let var = v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (k - 1.0);
                (mean, var.sqrt())
            };
            let (_, t_sd) = sd(ms.iter().map(|m| m.profile.temperature_k[l]).collect());
            let q: Vec<f64> = ms
                .iter()
                .map(|m| m.profile.gas("H2O").map_or(0.0, |h| h[l]))
                .collect();
            let (q_mean, q_sd) = sd(q);
            let q_rel = if q_mean > 0.0 {
                100.0 * q_sd / q_mean
            } else {
                0.0
            };
            (p, t_sd, q_rel)
        })
        .collect()
}

/// −log10(p/hPa): up is up.
fn y_of(p_pa: f64) -> f64 {
    -(p_pa / 100.0).log10()
}

fn ensemble_figure(path: &Path, set: &ProfileSet) -> DrawResult {
    let root = BitMapBackend::new(path, (1000, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        &format!("Ensemble spread by class ({} profiles)", set.len()),
        (FONT, 22),
    )?;
    let panels = root.split_evenly((1, 2));
    let data: Vec<(LatitudeClass, Vec<LevelSpread>)> = LatitudeClass::ALL
        .iter()
        .map(|c| (*c, spread(set, *c)))
        .filter(|(_, v)| !v.is_empty())
        .collect();
    for (i, panel) in panels.iter().enumerate() {
        let pick = |v: &LevelSpread| if i == 0 { v.1 } else { v.2 };
        let x_max = data
            .iter()
            .flat_map(|(_, v)| v.iter().filter(|v| v.0 >= 100.0).map(pick))
            .fold(0.0, f64::max)
            * 1.1;
        let mut chart = ChartBuilder::on(panel)
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..x_max.max(1e-9), y_of(110_000.0)..y_of(100.0))?;
        chart
            .configure_mesh()
            .x_desc(if i == 0 {
                "temperature standard deviation [K]"
            } else {
                "water vapour standard deviation [% of mean]"
            })
            .y_desc("pressure [hPa]")
            .y_label_formatter(&|y| format!("{:.0}", 10f64.powf(-*y)))
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()?;
        for (c, v) in &data {
            let colour = class_colour(c.name());
            chart
                .draw_series(LineSeries::new(
                    v.iter()
                        .filter(|v| v.0 >= 100.0)
                        .map(|v| (pick(v), y_of(v.0))),
                    colour.stroke_width(2),
                ))?
                .label(c.name())
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour));
        }
        draw_legend(&mut chart)?;
    }
    root.present()?;
    Ok(())
}

fn errors_figure(path: &Path, result: &StudyResult) -> DrawResult {
    // The IPDA errors of the first pair, per class: noise-free and noisy.
    let first_pair = result
        .outcomes
        .iter()
        .find_map(|o| o.records.as_ref().ok().and_then(|r| r.first()))
        .map(|r| r.pair.clone())
        .unwrap_or_default();
    let classes: Vec<LatitudeClass> = LatitudeClass::ALL
        .into_iter()
        .filter(|c| result.outcomes.iter().any(|o| o.class == *c))
        .collect();
    let errors = |c: LatitudeClass, noisy: bool| -> Vec<f64> {
        result
            .outcomes
            .iter()
            .filter(|o| o.class == c)
            .filter_map(|o| o.records.as_ref().ok())
            .flat_map(|rs| {
                rs.iter()
                    .filter(|r| r.method == Method::Ipda && r.pair == first_pair)
                    .map(|r| {
                        if noisy {
                            r.error_noisy_ppm()
                        } else {
                            r.error_ppm()
                        }
                    })
            })
            .filter(|x| x.is_finite())
            .collect()
    };
    let root =
        BitMapBackend::new(path, (1000, 360 * classes.len() as u32 + 60)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        &format!("IPDA XCO2 error, {first_pair} (class-mean virtual σ)"),
        (FONT, 22),
    )?;
    let panels = root.split_evenly((classes.len(), 1));
    for (c, panel) in classes.iter().zip(panels.iter()) {
        let clean = errors(*c, false);
        let noisy = errors(*c, true);
        let all: Vec<f64> = clean.iter().chain(&noisy).copied().collect();
        if all.is_empty() {
            continue;
        }
        let (lo, hi) = all
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(*x), b.max(*x))
            });
        let pad = 0.05 * (hi - lo).max(1e-6);
        let (lo, hi) = (lo - pad, hi + pad);
        let bins = 40;
        let w = (hi - lo) / bins as f64;
        let hist = |v: &[f64]| -> Vec<usize> {
            let mut h = vec![0usize; bins];
            for x in v {
                let i = (((x - lo) / w) as usize).min(bins - 1);
                h[i] += 1;
            }
            h
        };
        let (hc, hn) = (hist(&clean), hist(&noisy));
        let top = hc.iter().chain(&hn).copied().max().unwrap_or(1) as f64 * 1.15;
        let mut chart = ChartBuilder::on(panel)
            .margin(12)
            .caption(format!("{c} ({} profiles)", clean.len()), (FONT, 17))
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(lo..hi, 0.0..top)?;
        chart
            .configure_mesh()
            .x_desc("retrieved − true XCO2 [ppm]")
            .y_desc("profiles")
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 15))
            .draw()?;
        for (h, colour, label) in [
            (&hn, RGBColor(150, 150, 150), "one noisy measurement"),
            (&hc, class_colour(c.name()), "noise-free"),
        ] {
            chart
                .draw_series(h.iter().enumerate().map(|(i, n)| {
                    let x0 = lo + i as f64 * w;
                    Rectangle::new([(x0, 0.0), (x0 + w, *n as f64)], colour.mix(0.6).filled())
                }))?
                .label(label)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 15, y + 5)], colour.mix(0.6).filled())
                });
        }
        draw_legend(&mut chart)?;
    }
    root.present()?;
    Ok(())
}

fn budget_figure(path: &Path, summaries: &[Summary]) -> DrawResult {
    // IPDA rows of the pooled group (`all`) if there is one, else of the one class.
    let group = if summaries.iter().any(|m| m.class == "all") {
        "all".to_string()
    } else {
        summaries
            .first()
            .map(|m| m.class.clone())
            .unwrap_or_default()
    };
    let rows: Vec<&Summary> = summaries
        .iter()
        .filter(|m| m.method == Method::Ipda && m.class == group)
        .collect();
    let n = rows.len();
    let vals = |j: Option<usize>| -> Vec<(f64, f64)> {
        rows.iter()
            .enumerate()
            .filter_map(|(i, m)| {
                let v = match j {
                    Some(j) => m.sources[j].rms_ppm,
                    None => m.total_ppm,
                };
                (v > 0.0 && v.is_finite()).then(|| (i as f64, v.log10()))
            })
            .collect()
    };
    let all: Vec<f64> = (0..N_SOURCES)
        .map(Some)
        .chain([None])
        .flat_map(|j| vals(j).into_iter().map(|p| p.1))
        .collect();
    let (lo, hi) = all
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(*x), b.max(*x))
        });
    let (lo, hi) = if lo.is_finite() {
        ((lo - 0.2).max(hi - 5.0), hi + 0.3)
    } else {
        (-3.0, 1.0)
    };
    // Rows far below the largest (e.g. a jitter's second-order bias) are left off the panel.
    let vals = |j: Option<usize>| -> Vec<(f64, f64)> {
        vals(j).into_iter().filter(|p| p.1 >= lo).collect()
    };
    let root = BitMapBackend::new(path, (1100, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .margin(15)
        .caption(
            format!("IPDA XCO2 error budget by line pair (class {group}; rms over profiles)"),
            (FONT, 20),
        )
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), lo..hi)?;
    // Pair names without the off-line when all pairs share it.
    let offs: Vec<&str> = rows
        .iter()
        .map(|m| m.pair.rsplit('/').next().unwrap_or(""))
        .collect();
    let same_off = offs.windows(2).all(|w| w[0] == w[1]);
    let names: Vec<String> = rows
        .iter()
        .map(|m| match (same_off, m.pair.rsplit_once('/')) {
            (true, Some((on, _))) => on.to_string(),
            _ => m.pair.clone(),
        })
        .collect();
    let x_desc = match (same_off, offs.first()) {
        (true, Some(off)) => format!("on-line (off-line `{off}`)"),
        _ => "on-line / off-line".to_string(),
    };
    chart
        .configure_mesh()
        .x_labels(n.max(1))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                names[i as usize].clone()
            } else {
                String::new()
            }
        })
        .x_label_style((FONT, 12))
        .x_desc(x_desc)
        .y_labels(((hi - lo).ceil() as usize * 2).max(2))
        .y_desc("error [ppm] (rms over profiles; random: 1σ)")
        .y_label_formatter(&|y| {
            // Label the decades only, with no more digits than they need.
            if (y - y.round()).abs() > 1e-6 {
                return String::new();
            }
            let e = y.round() as i32;
            if e >= 0 {
                format!("{}", 10f64.powi(e))
            } else {
                format!("{:.*}", (-e) as usize, 10f64.powi(e))
            }
        })
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .draw()?;
    let palette = [
        RGBColor(0, 0, 0),
        RGBColor(200, 60, 30),
        RGBColor(30, 120, 200),
        RGBColor(120, 80, 20),
        RGBColor(150, 30, 150),
        RGBColor(230, 150, 0),
        RGBColor(0, 150, 140),
        RGBColor(120, 120, 120),
        RGBColor(30, 160, 60),
    ];
    for (j, src) in Source::ALL.iter().enumerate() {
        let colour = palette[j % palette.len()];
        let pts = vals(Some(j));
        if pts.is_empty() {
            continue;
        }
        for w in pts.windows(2).filter(|w| w[1].0 - w[0].0 == 1.0) {
            chart.draw_series(LineSeries::new(w.to_vec(), colour.stroke_width(1)))?;
        }
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label(src.label())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour));
        chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, colour.filled())))?;
    }
    chart
        .draw_series(LineSeries::new(vals(None), BLACK.stroke_width(3)))?
        .label("total (root sum of squares)")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.stroke_width(3)));
    draw_legend(&mut chart)?;
    root.present()?;
    Ok(())
}
