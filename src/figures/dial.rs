//! Figures of `lidarsim dial`: the ensemble's spread (`ensemble.png`), the IPDA errors per
//! line pair and class (`errors.png`) and the error budget per line pair (`budget.png`, the
//! reference study's Figure 5 in kind).

use std::path::Path;

use plotters::prelude::*;

use super::style::{self, Axis, Entry, Mark, class_colour, colour};
use super::{DrawResult, FONT, init_font};
use lidarsim::atmosphere::{LatitudeClass, ProfileSet};
use lidarsim::output::{OutputError, OutputSet};
use lidarsim::retrieval::Method;
use lidarsim::study::dial::{N_SOURCES, Source, StudyResult, Summary};
use plotters::style::text_anchor::{HPos, Pos, VPos};

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
    let (plots, key) = style::canvas(
        path,
        (1100 + style::LEGEND_W, 650),
        &format!(
            "Spread of the profile ensemble by latitude class ({} profiles)",
            set.len()
        ),
        true,
    )?;
    let panels = plots.split_evenly((1, 2));
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
        let mut chart = style::chart(
            panel,
            "",
            0.0..x_max.max(1e-9),
            y_of(110_000.0)..y_of(100.0),
        )?;
        style::mesh(
            &mut chart,
            Axis::Linear(if i == 0 {
                "temperature standard deviation [K]"
            } else {
                "water vapour standard deviation [% of mean]"
            }),
            Axis::NegLog10("pressure [hPa]"),
        )?;
        for (c, v) in &data {
            let pts = v
                .iter()
                .filter(|v| v.0 >= 100.0)
                .map(|v| (pick(v), y_of(v.0)))
                .collect();
            style::line(&mut chart, pts, class_colour(c.name()), 2, false)?;
        }
    }
    let mut entries = vec![Entry::heading("latitude class")];
    for (c, _) in &data {
        entries.push(Entry::new(
            c.name(),
            class_colour(c.name()),
            Mark::Line(2, false),
        ));
    }
    if data.is_empty() {
        entries.push(Entry::heading("no class has two profiles of one length"));
    }
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}

/// Histograms of the IPDA XCO2 error over the profiles, noise-free and with one noisy
/// measurement, one row of panels per line pair and one column per class. The panels of a
/// pair share their x range (the 2nd–98th percentiles of its errors, with zero; the few
/// beyond are counted in the edge bins) so the classes compare.
fn errors_figure(path: &Path, result: &StudyResult) -> DrawResult {
    let mut pairs: Vec<String> = Vec::new();
    for r in result
        .outcomes
        .iter()
        .filter_map(|o| o.records.as_ref().ok())
        .flatten()
        .filter(|r| r.method == Method::Ipda)
    {
        if !pairs.contains(&r.pair) {
            pairs.push(r.pair.clone());
        }
    }
    let classes: Vec<LatitudeClass> = LatitudeClass::ALL
        .into_iter()
        .filter(|c| result.outcomes.iter().any(|o| o.class == *c))
        .collect();
    let errors = |pair: &str, c: LatitudeClass, noisy: bool| -> Vec<f64> {
        result
            .outcomes
            .iter()
            .filter(|o| o.class == c)
            .filter_map(|o| o.records.as_ref().ok())
            .flat_map(|rs| {
                rs.iter()
                    .filter(|r| r.method == Method::Ipda && r.pair == pair)
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
    let (rows, cols) = (pairs.len().max(1), classes.len().max(1));
    let (plots, key) = style::canvas(
        path,
        (440 * cols as u32 + style::LEGEND_W, 330 * rows as u32 + 50),
        "IPDA XCO2 error (retrieved − true) over the profiles, per line pair and latitude class",
        true,
    )?;
    let panels = plots.split_evenly((rows, cols));
    let bins = 30;
    for (i, pair) in pairs.iter().enumerate() {
        let all: Vec<f64> = classes
            .iter()
            .flat_map(|c| {
                let mut v = errors(pair, *c, false);
                v.extend(errors(pair, *c, true));
                v
            })
            .collect();
        let x = style::robust_range(&all, &[0.0]);
        let w = (x.end - x.start) / bins as f64;
        let hist = |v: &[f64]| -> Vec<usize> {
            let mut h = vec![0usize; bins];
            for e in v {
                let k = ((e - x.start) / w).floor().clamp(0.0, (bins - 1) as f64) as usize;
                h[k] += 1;
            }
            h
        };
        let data: Vec<(Vec<usize>, Vec<usize>, usize)> = classes
            .iter()
            .map(|c| {
                let (clean, noisy) = (errors(pair, *c, false), errors(pair, *c, true));
                (hist(&clean), hist(&noisy), clean.len())
            })
            .collect();
        for (j, (c, (hc, hn, n))) in classes.iter().zip(&data).enumerate() {
            let top = hc.iter().chain(hn).copied().max().unwrap_or(1).max(1) as f64 * 1.15;
            let mut chart = style::chart(
                &panels[i * cols + j],
                &format!("{pair}, {c} ({n} profiles)"),
                x.clone(),
                0.0..top,
            )?;
            style::mesh(
                &mut chart,
                Axis::Linear("retrieved − true XCO2 [ppm]"),
                Axis::Count("profiles"),
            )?;
            if *n == 0 {
                // An empty panel would read as a drawing fault: say why it is empty.
                let text = TextStyle::from((FONT, style::LEGEND).into_font())
                    .color(&style::INK)
                    .pos(Pos::new(HPos::Center, VPos::Center));
                let mid = 0.5 * (x.start + x.end);
                for (k, line) in empty_panel_note(result, *c).iter().enumerate() {
                    chart.draw_series(std::iter::once(Text::new(
                        line.clone(),
                        (mid, top * (0.62 - 0.12 * k as f64)),
                        text.clone(),
                    )))?;
                }
                continue;
            }
            for (h, fill) in [(hn, style::GREY), (hc, class_colour(c.name()))] {
                chart.draw_series(h.iter().enumerate().filter(|(_, k)| **k > 0).map(
                    |(b, k)| {
                        let x0 = x.start + b as f64 * w;
                        Rectangle::new([(x0, 0.0), (x0 + w, *k as f64)], fill.mix(0.7).filled())
                    },
                ))?;
            }
        }
    }
    let mut entries = vec![Entry::heading("noise-free retrieval, by class")];
    for c in &classes {
        entries.push(Entry::new(c.name(), class_colour(c.name()), Mark::Box));
    }
    entries.push(Entry::heading("with noise"));
    entries.push(Entry::new(
        "one noisy measurement per profile",
        style::GREY,
        Mark::Box,
    ));
    entries.push(Entry::heading(
        "x range: 2nd–98th percentile of the pair's errors; the rest in the edge bins",
    ));
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}

/// Why a panel of class `c` of `errors.png` has no profile: all of them failed (how many,
/// and where they are listed), or none retrieved an IPDA product.
fn empty_panel_note(result: &StudyResult, c: LatitudeClass) -> Vec<String> {
    let of_class = result.outcomes.iter().filter(|o| o.class == c);
    let failed = of_class.clone().filter(|o| o.records.is_err()).count();
    let mut note = if failed > 0 && failed == of_class.count() {
        vec![format!("no profile of class {c} succeeded:")]
    } else {
        vec![format!("no IPDA retrieval in class {c}")]
    };
    if failed > 0 {
        let s = if failed == 1 { "" } else { "s" };
        note.push(format!("{failed} profile{s} failed, see failed.csv"));
    }
    note
}

/// The colour and line of error source `j` in the budget: random in rose (the total is
/// black and thick).
fn source_style(j: usize) -> (RGBColor, bool) {
    (
        colour((j + 1) % style::PALETTE.len()),
        j + 1 >= style::PALETTE.len(),
    )
}

/// The IPDA error budget: rms over the profiles of each source and the total, on a log axis.
/// With one line pair a bar per source; with several, one line per source across the pairs.
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
    let value = |m: &Summary, j: Option<usize>| -> Option<f64> {
        let v = match j {
            Some(j) => m.sources[j].rms_ppm,
            None => m.total_ppm,
        };
        (v > 0.0 && v.is_finite()).then(|| v.log10())
    };
    let all: Vec<f64> = rows
        .iter()
        .flat_map(|m| {
            (0..N_SOURCES)
                .map(Some)
                .chain([None])
                .filter_map(|j| value(m, j))
        })
        .collect();
    let (lo, hi) = all
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(*x), b.max(*x))
        });
    // Sources far below the largest (a jitter's second-order bias) are left off the axis.
    let (lo, hi) = if lo.is_finite() {
        ((lo - 0.2).max(hi - 5.0).floor(), (hi + 0.3).ceil())
    } else {
        (-3.0, 1.0)
    };
    let title =
        format!("IPDA XCO2 error budget (class {group}; rms over the profiles; random: 1σ)");
    let mut entries = Vec::new();
    if n == 1 {
        let m = rows[0];
        let (plots, key) = style::canvas(path, (1000 + style::LEGEND_W, 650), &title, true)?;
        let mut names: Vec<String> = Source::ALL
            .iter()
            .map(|s| s.label().replace('_', " "))
            .collect();
        names.push("total (root sum of squares)".into());
        let mut chart = style::chart_with_y_labels(
            &plots,
            &format!("line pair {}", m.pair),
            lo..hi,
            -0.6..(names.len() as f64 - 0.4),
            230,
        )?;
        style::mesh(
            &mut chart,
            Axis::Log10("error [ppm]"),
            Axis::Names("", &names),
        )?;
        for (j, _) in names.iter().enumerate() {
            let (c, v) = match j < N_SOURCES {
                true => (source_style(j).0, value(m, Some(j))),
                false => (style::INK, value(m, None)),
            };
            // A source below the axis (or zero) has no bar; the legend says so.
            if let Some(v) = v.filter(|v| *v > lo) {
                let y = j as f64;
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(lo, y - 0.35), (v.min(hi), y + 0.35)],
                    c.filled(),
                )))?;
            }
        }
        entries.push(Entry::heading(format!(
            "sources below {} ppm or zero have no bar",
            style::tick(10f64.powf(lo))
        )));
        style::legend(&key.expect("legend column"), &entries)?;
        return Ok(());
    }
    let (plots, key) = style::canvas(path, (1100 + style::LEGEND_W, 700), &title, true)?;
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
    let mut chart = style::chart(&plots, "", -0.5..(n as f64 - 0.5), lo..hi)?;
    style::mesh(
        &mut chart,
        Axis::Names(&x_desc, &names),
        Axis::Log10("error [ppm]"),
    )?;
    let mut series = |j: Option<usize>, c: RGBColor, dash: bool, width: u32| -> DrawResult {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .enumerate()
            .filter_map(|(i, m)| value(m, j).filter(|v| *v >= lo).map(|v| (i as f64, v)))
            .collect();
        // Lines only between neighbouring pairs that both have a value.
        for w in pts.windows(2).filter(|w| w[1].0 - w[0].0 == 1.0) {
            style::line(&mut chart, w.to_vec(), c, width, dash)?;
        }
        chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, c.filled())))?;
        Ok(())
    };
    for (j, src) in Source::ALL.iter().enumerate() {
        let (c, dash) = source_style(j);
        if rows
            .iter()
            .any(|m| value(m, Some(j)).is_some_and(|v| v >= lo))
        {
            series(Some(j), c, dash, 2)?;
            entries.push(Entry::new(
                src.label().replace('_', " "),
                c,
                Mark::Line(2, dash),
            ));
        }
    }
    series(None, style::INK, false, 3)?;
    entries.push(Entry::new(
        "total (root sum of squares)",
        style::INK,
        Mark::Line(3, false),
    ));
    entries.push(Entry::heading(format!(
        "sources below {} ppm are left off",
        style::tick(10f64.powf(lo))
    )));
    style::legend(&key.expect("legend column"), &entries)?;
    Ok(())
}
