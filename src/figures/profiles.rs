//! The figure of `lidarsim profiles plot`: temperature, humidity and CO2 against pressure, one
//! column of panels per latitude class.

use std::path::Path;

use plotters::prelude::*;

use lidarsim::atmosphere::{LatitudeClass, ProfileSet, SetMember};

use super::{DrawResult, FONT, init_font};

/// −log10(p/hPa): increases upward, so the surface is at the bottom of a panel.
fn y_of(p_pa: f64) -> f64 {
    -(p_pa / 100.0).log10()
}

/// Draw the set `set`, read from `set_path`, showing pressures down to `top_hpa`, to `tmp`.
pub fn draw(tmp: &Path, set: &ProfileSet, set_path: &Path, top_hpa: f64) -> DrawResult {
    let classes: Vec<LatitudeClass> = LatitudeClass::ALL
        .into_iter()
        .filter(|c| set.members.iter().any(|m| m.meta.class() == *c))
        .collect();
    let subsets: Vec<ProfileSet> = classes.iter().map(|c| set.class(*c)).collect();
    let means: Vec<Option<SetMember>> = subsets.iter().map(|s| s.mean_member().ok()).collect();
    let (w, h) = (420 * classes.len() as u32 + 40, 1260);
    init_font();
    let root = BitMapBackend::new(tmp, (w, h)).into_drawing_area();
    root.fill(&WHITE)?;
    let title = format!(
        "Profile set {}: temperature, H2O and CO2 against pressure, by latitude class ({} profiles)",
        set_path
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        set.len()
    );
    let root = root.titled(&title, (FONT, super::style::TITLE))?;
    let panels = root.split_evenly((3, classes.len()));
    let p_max = set
        .members
        .iter()
        .map(|m| m.profile.surface_pressure_pa())
        .fold(0.0, f64::max)
        * 1.02;
    let y_range = y_of(p_max)..y_of(top_hpa * 100.0);
    let decades = (p_max / (top_hpa * 100.0)).log10().ceil().max(1.0) as usize;
    let keep = |p: f64| p >= top_hpa * 100.0 * 0.999;
    for (ci, (c, sub)) in classes.iter().zip(&subsets).enumerate() {
        let color = super::style::class_colour(c.name());
        for row in 0..3 {
            let area = &panels[row * classes.len() + ci];
            // x data per member.
            let xs = |m: &SetMember| -> Option<Vec<(f64, f64)>> {
                let p = &m.profile;
                let v: Vec<f64> = match row {
                    0 => p.temperature_k.clone(),
                    1 => p.gas("H2O")?.iter().map(|x| x * 1e6).collect(),
                    // CO2 per dry air: what a well-mixed gas keeps constant.
                    _ => {
                        let w = p.gas("H2O");
                        p.gas("CO2")?
                            .iter()
                            .enumerate()
                            .map(|(k, x)| x * 1e6 / (1.0 - w.map_or(0.0, |w| w[k])))
                            .collect()
                    }
                };
                Some(
                    p.pressure_pa
                        .iter()
                        .zip(v)
                        .filter(|(pp, _)| keep(**pp))
                        .map(|(pp, x)| (x, y_of(*pp)))
                        .collect(),
                )
            };
            let lines: Vec<Vec<(f64, f64)>> = sub.members.iter().filter_map(xs).collect();
            let label = ["temperature [K]", "H2O [ppmv]", "CO2 [ppmv of dry air]"][row];
            let caption = if row == 0 {
                format!("{c} (n = {})", sub.len())
            } else {
                String::new()
            };
            if lines.is_empty() {
                area.draw(&Text::new(
                    format!("no {}", ["T", "H2O", "CO2"][row]),
                    (150, 200),
                    (FONT, 20).into_font(),
                ))?;
                continue;
            }
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for l in &lines {
                for (x, _) in l {
                    if *x > 0.0 || row != 1 {
                        lo = lo.min(*x);
                    }
                    hi = hi.max(*x);
                }
            }
            let pad = match row {
                0 => 0.05 * (hi - lo).max(1.0),
                _ => 0.05 * (hi - lo).max(10.0),
            };
            let mut builder = ChartBuilder::on(area);
            builder
                .margin(10)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .caption(caption, (FONT, super::style::CAPTION));
            let y_fmt = |v: &f64| super::style::tick(10f64.powf(-v));
            let x_fmt = |v: &f64| super::style::tick(*v);
            let style = ShapeStyle::from(&color.mix(0.25)).stroke_width(1);
            let mean_line = means[ci].as_ref().and_then(xs);
            macro_rules! draw_panel {
                ($chart:expr) => {{
                    let mut chart = $chart;
                    chart
                        .configure_mesh()
                        .x_desc(label)
                        .y_desc("pressure [hPa]")
                        .y_label_formatter(&y_fmt)
                        .x_label_formatter(&x_fmt)
                        .label_style((FONT, super::style::TICK))
                        .axis_desc_style((FONT, super::style::AXIS))
                        .x_labels(6)
                        .y_labels(decades + 1)
                        .draw()?;
                    for l in &lines {
                        chart.draw_series(LineSeries::new(l.iter().copied(), style))?;
                    }
                    if let Some(l) = &mean_line {
                        chart.draw_series(LineSeries::new(
                            l.iter().copied(),
                            ShapeStyle::from(&BLACK).stroke_width(2),
                        ))?;
                    }
                }};
            }
            if row == 1 {
                let lo = lo.max(1e-3) / 1.5;
                draw_panel!(
                    builder.build_cartesian_2d((lo..hi * 1.5).log_scale(), y_range.clone())?
                );
            } else {
                draw_panel!(builder.build_cartesian_2d((lo - pad)..(hi + pad), y_range.clone())?);
            }
        }
    }
    root.present()?;
    Ok(())
}
