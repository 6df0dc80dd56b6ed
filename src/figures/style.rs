//! The house style of every figure: one palette, one font and its sizes, one way to format ticks
//! and lengths, legends drawn beside the data (never over it), and the helpers that keep a
//! figure honest and quick (robust axis limits, min/max decimation of long series).
//!
//! The palette is Paul Tol's "muted" qualitative scheme (Tol 2021, *Colour Schemes*, SRON
//! technical note SRON/EPS/TN/09-002, issue 3.2): nine colours told apart with every common
//! colour-vision deficiency and readable on white. Black is kept for the reference curve of a
//! panel (the truth, the total); more than nine series repeat the colours with a dashed line
//! (and a hollow marker), so sixteen channels stay distinct.

use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

pub use super::{DrawResult, FONT, init_font};

/// A chart on two linear f64 axes (log axes are drawn as log10 of the data, [`Axis::Log10`]).
pub type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Tol's "muted" scheme (Tol 2021), the darker colours first so that two or three series
/// contrast most; the pale cyan and sand come last.
pub const PALETTE: [RGBColor; 9] = [
    RGBColor(0x33, 0x22, 0x88), // indigo
    RGBColor(0xCC, 0x66, 0x77), // rose
    RGBColor(0x44, 0xAA, 0x99), // teal
    RGBColor(0x99, 0x99, 0x33), // olive
    RGBColor(0xAA, 0x44, 0x99), // purple
    RGBColor(0x11, 0x77, 0x33), // green
    RGBColor(0x88, 0x22, 0x55), // wine
    RGBColor(0x88, 0xCC, 0xEE), // cyan
    RGBColor(0xDD, 0xCC, 0x77), // sand
];

/// The reference curve of a panel: the truth, the total.
pub const INK: RGBColor = RGBColor(0, 0, 0);
/// Secondary data drawn behind the rest (a noisy histogram, a band).
pub const GREY: RGBColor = RGBColor(0xBB, 0xBB, 0xBB);

/// Font sizes [px]: figure title, panel caption, axis description, tick labels, legend.
pub const TITLE: u32 = 22;
pub const CAPTION: u32 = 17;
pub const AXIS: u32 = 16;
pub const TICK: u32 = 14;
pub const LEGEND: u32 = 14;
/// Width of the legend column beside the panels [px].
pub const LEGEND_W: u32 = 300;

/// The i-th series colour (repeats after nine, see [`dashed`]).
pub fn colour(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// The colour of a latitude class, the same in every figure (warm for the tropics, dark for
/// high latitudes).
pub fn class_colour(class: &str) -> RGBColor {
    match class {
        "tropical" => PALETTE[1],
        "mid" => PALETTE[5],
        "high" => PALETTE[0],
        _ => INK,
    }
}

/// Whether the i-th series is drawn dashed (the second round of the palette).
pub fn dashed(i: usize) -> bool {
    (i / PALETTE.len()) % 2 == 1
}

/// A tick label with no spurious digits: "1000", "0.25", "1.5e-7", never "1000.0".
pub fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        let s = format!("{v:.3e}");
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        return format!("{}e{e}", trim(m));
    }
    // Six significant digits cover every tick step plotters picks; trailing zeros go.
    let decimals = (5 - a.log10().floor() as i32).clamp(0, 9) as usize;
    trim(&format!("{v:.decimals$}"))
}

fn trim(s: &str) -> String {
    if s.contains('.') {
        let t = s.trim_end_matches('0').trim_end_matches('.');
        if t == "-0" { "0".into() } else { t.into() }
    } else {
        s.into()
    }
}

/// A power of ten as "10⁻³" (superscripts are in the embedded font).
pub fn decade(e: i32) -> String {
    const SUP: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let digits: String = e
        .unsigned_abs()
        .to_string()
        .chars()
        .map(|c| SUP[c as usize - '0' as usize])
        .collect();
    format!("10{}{digits}", if e < 0 { "⁻" } else { "" })
}

/// How an axis is labelled.
#[derive(Clone, Copy)]
pub enum Axis<'s> {
    /// Linear, ticks by [`tick`].
    Linear(&'s str),
    /// The coordinate is log10 of the value: ticks at whole decades as "10ⁿ" (all ticks, by
    /// value, when the axis spans less than two decades).
    Log10(&'s str),
    /// The coordinate is −log10 of the value (pressure, so that up is up): ticks at whole
    /// decades, by value ("1000", "100").
    NegLog10(&'s str),
    /// Whole counts (a histogram's height): integer ticks only.
    Count(&'s str),
    /// Category i at coordinate i, named by the list.
    Names(&'s str, &'s [String]),
}

impl Axis<'_> {
    fn desc(&self) -> &str {
        match self {
            Axis::Linear(d)
            | Axis::Log10(d)
            | Axis::NegLog10(d)
            | Axis::Count(d)
            | Axis::Names(d, _) => d,
        }
    }
}

fn label(axis: &Axis, span: f64, v: f64) -> String {
    match axis {
        Axis::Linear(_) => tick(v),
        // Less than two decades: every tick, by value, to two significant digits.
        Axis::Log10(_) if span < 2.0 => {
            let s = format!("{:.1e}", 10f64.powf(v));
            let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
            let m = trim(m);
            match e {
                "0" => m,
                _ => format!("{m}e{e}"),
            }
        }
        Axis::Log10(_) => {
            if (v - v.round()).abs() < 1e-6 {
                decade(v.round() as i32)
            } else {
                String::new()
            }
        }
        Axis::NegLog10(_) => {
            if (v - v.round()).abs() < 1e-6 || span < 2.0 {
                tick(10f64.powf(-v))
            } else {
                String::new()
            }
        }
        Axis::Count(_) => {
            if (v - v.round()).abs() < 1e-6 && v >= 0.0 {
                format!("{}", v.round() as i64)
            } else {
                String::new()
            }
        }
        Axis::Names(_, names) => {
            let i = v.round();
            if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
                names[i as usize].clone()
            } else {
                String::new()
            }
        }
    }
}

fn n_labels(axis: &Axis, lo: f64, hi: f64, default: usize) -> usize {
    match axis {
        // One label per decade (plotters puts ticks on round numbers of its step).
        Axis::Log10(_) | Axis::NegLog10(_) if hi - lo >= 2.0 => {
            ((hi - lo).floor() as usize + 1).min(default * 2)
        }
        Axis::Count(_) => ((hi - lo).floor() as usize + 1).clamp(2, default),
        Axis::Names(_, n) => n.len().max(1),
        _ => default,
    }
}

/// Draw the grid, ticks and axis descriptions of `chart` in the house style.
pub fn mesh(chart: &mut Chart, x: Axis, y: Axis) -> DrawResult {
    let xr = chart.x_range();
    let yr = chart.y_range();
    let (xs, ys) = (xr.end - xr.start, yr.end - yr.start);
    let fx = |v: &f64| label(&x, xs, *v);
    let fy = |v: &f64| label(&y, ys, *v);
    chart
        .configure_mesh()
        .x_desc(x.desc())
        .y_desc(y.desc())
        .x_labels(n_labels(&x, xr.start, xr.end, 8))
        .y_labels(n_labels(&y, yr.start, yr.end, 8))
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .label_style((FONT, TICK))
        .axis_desc_style((FONT, AXIS))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;
    Ok(())
}

/// A panel's chart on `area`, with the house margins and label areas.
pub fn chart<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    caption: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<Chart<'a, 'b>, Box<dyn std::error::Error>> {
    chart_with_y_labels(area, caption, x, y, 75)
}

/// The same with a y label area `y_label_w` pixels wide (names on the y axis).
pub fn chart_with_y_labels<'a, 'b>(
    area: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    caption: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    y_label_w: u32,
) -> Result<Chart<'a, 'b>, Box<dyn std::error::Error>> {
    let mut b = ChartBuilder::on(area);
    b.margin(10)
        .x_label_area_size(50)
        .y_label_area_size(y_label_w);
    if !caption.is_empty() {
        b.caption(caption, (FONT, CAPTION));
    }
    Ok(b.build_cartesian_2d(x, y)?)
}

/// A drawing area of a figure.
pub type Area<'b> = DrawingArea<BitMapBackend<'b>, Shift>;

/// A white canvas of `size` at `path` with the figure's `title` on top, split into the area
/// for the panels and the legend column on the right (None: no legend column).
pub fn canvas<'b>(
    path: &'b Path,
    size: (u32, u32),
    title: &str,
    legend: bool,
) -> Result<(Area<'b>, Option<Area<'b>>), Box<dyn std::error::Error>> {
    init_font();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, (FONT, TITLE))?;
    if !legend {
        return Ok((root, None));
    }
    let (w, _) = root.dim_in_pixel();
    let (plots, key) = root.split_horizontally(w.saturating_sub(LEGEND_W));
    Ok((plots, Some(key)))
}

/// How a legend entry is drawn.
#[derive(Clone, Copy)]
pub enum Mark {
    /// A line of this width, dashed or not.
    Line(u32, bool),
    /// A filled (true) or hollow marker with an error bar.
    Point(bool),
    /// A filled box (a histogram, a band).
    Box,
    /// No symbol: a heading in the legend.
    Heading,
}

/// One legend row.
pub struct Entry {
    pub label: String,
    pub colour: RGBColor,
    pub mark: Mark,
}

impl Entry {
    pub fn new(label: impl Into<String>, colour: RGBColor, mark: Mark) -> Self {
        Entry {
            label: label.into(),
            colour,
            mark,
        }
    }
    /// A heading row (no symbol).
    pub fn heading(label: impl Into<String>) -> Self {
        Entry::new(label, INK, Mark::Heading)
    }
}

/// Draw the legend rows into `area` (the column beside the panels), top down, wrapping long
/// labels.
pub fn legend(area: &DrawingArea<BitMapBackend, Shift>, entries: &[Entry]) -> DrawResult {
    let x0 = 8;
    let mut y = 60;
    let text = TextStyle::from((FONT, LEGEND).into_font()).color(&INK);
    let line_h = LEGEND as i32 + 8;
    for e in entries {
        let c = e.colour;
        let ym = y + LEGEND as i32 / 2;
        let tx = match e.mark {
            Mark::Heading => x0,
            _ => x0 + 34,
        };
        match e.mark {
            Mark::Line(w, false) => area.draw(&PathElement::new(
                vec![(x0, ym), (x0 + 26, ym)],
                c.stroke_width(w),
            ))?,
            Mark::Line(w, true) => {
                for k in 0..3 {
                    let a = x0 + 10 * k;
                    area.draw(&PathElement::new(
                        vec![(a, ym), (a + 6, ym)],
                        c.stroke_width(w),
                    ))?;
                }
            }
            Mark::Point(filled) => {
                area.draw(&PathElement::new(
                    vec![(x0 + 13, ym - 7), (x0 + 13, ym + 7)],
                    c.stroke_width(1),
                ))?;
                let style = if filled {
                    c.filled()
                } else {
                    c.stroke_width(2)
                };
                area.draw(&Circle::new((x0 + 13, ym), 4, style))?;
            }
            Mark::Box => area.draw(&Rectangle::new(
                [(x0, ym - 6), (x0 + 26, ym + 6)],
                c.mix(0.7).filled(),
            ))?,
            Mark::Heading => {}
        }
        let font = match e.mark {
            Mark::Heading => TextStyle::from((FONT, LEGEND).into_font().style(FontStyle::Bold)),
            _ => text.clone(),
        };
        // Wrap at ~34 characters on spaces so long labels stay in the column.
        for part in wrap(&e.label, 32) {
            area.draw(&Text::new(part, (tx, y), font.clone()))?;
            y += line_h;
        }
        y += 2;
    }
    Ok(())
}

fn wrap(s: &str, width: usize) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut cur = String::new();
    for w in s.split(' ') {
        if !cur.is_empty() && cur.chars().count() + 1 + w.chars().count() > width {
            out.push(std::mem::take(&mut cur));
        }
        if !cur.is_empty() {
            cur.push(' ');
        }
        cur.push_str(w);
    }
    out.push(cur);
    out
}

/// Draw a line series in the style of series `i` (solid, or dashed in the palette's second
/// round).
pub fn line(
    chart: &mut Chart,
    pts: Vec<(f64, f64)>,
    c: RGBColor,
    width: u32,
    dash: bool,
) -> DrawResult {
    if dash {
        chart.draw_series(DashedLineSeries::new(pts, 8, 5, c.stroke_width(width)))?;
    } else {
        chart.draw_series(LineSeries::new(pts, c.stroke_width(width)))?;
    }
    Ok(())
}

/// Markers with vertical error bars (value, low, high), filled or hollow, clamped to the
/// chart's y range so a huge error bar does not leave the panel.
pub fn points_with_errors(
    chart: &mut Chart,
    pts: &[(f64, f64, f64, f64)],
    c: RGBColor,
    filled: bool,
) -> DrawResult {
    let yr = chart.y_range();
    let xr = chart.x_range();
    let cl = |v: f64| v.clamp(yr.start, yr.end);
    let inside: Vec<_> = pts
        .iter()
        .filter(|p| p.1 >= yr.start && p.1 <= yr.end && p.0 >= xr.start && p.0 <= xr.end)
        .collect();
    // Bars half transparent and markers small, so that many gates do not hide the lines.
    chart.draw_series(inside.iter().map(|&&(x, _, lo, hi)| {
        PathElement::new(vec![(x, cl(lo)), (x, cl(hi))], c.mix(0.45).stroke_width(1))
    }))?;
    let style = if filled {
        c.filled()
    } else {
        c.stroke_width(1)
    };
    let r = if inside.len() > 150 { 2 } else { 3 };
    chart.draw_series(
        inside
            .iter()
            .map(|&&(x, y, _, _)| Circle::new((x, y), r, style)),
    )?;
    Ok(())
}

/// The same with horizontal error bars (x, y, x low, x high), clamped to the x range.
pub fn points_with_x_errors(
    chart: &mut Chart,
    pts: &[(f64, f64, f64, f64)],
    c: RGBColor,
    filled: bool,
) -> DrawResult {
    let xr = chart.x_range();
    let cl = |v: f64| v.clamp(xr.start, xr.end);
    let inside: Vec<_> = pts
        .iter()
        .filter(|p| p.0 >= xr.start && p.0 <= xr.end)
        .collect();
    chart.draw_series(inside.iter().map(|&&(_, y, lo, hi)| {
        PathElement::new(vec![(cl(lo), y), (cl(hi), y)], c.stroke_width(1))
    }))?;
    let style = if filled {
        c.filled()
    } else {
        c.stroke_width(1)
    };
    chart.draw_series(
        inside
            .iter()
            .map(|&&(x, y, _, _)| Circle::new((x, y), 3, style)),
    )?;
    Ok(())
}

/// The q-th quantile (0..=1) of finite values (linear interpolation), None if there are none.
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos.fract());
    Some(if i + 1 < v.len() {
        v[i] * (1.0 - f) + v[i + 1] * f
    } else {
        v[i]
    })
}

/// Axis limits that show the bulk of `values` (the 2nd to 98th percentile, widened by the
/// `always` values that must be seen, e.g. the truth, and padded by 8 %): a few wild values
/// (a retrieval in a cell with no signal) do not squash the rest to a line.
pub fn robust_range(values: &[f64], always: &[f64]) -> std::ops::Range<f64> {
    let (mut lo, mut hi) = match (quantile(values, 0.02), quantile(values, 0.98)) {
        (Some(a), Some(b)) => (a, b),
        _ => (f64::INFINITY, f64::NEG_INFINITY),
    };
    for &a in always.iter().filter(|a| a.is_finite()) {
        lo = lo.min(a);
        hi = hi.max(a);
    }
    padded(lo, hi)
}

/// `lo..hi` padded by 8 % (a degenerate or empty range becomes a unit one around its value).
pub fn padded(lo: f64, hi: f64) -> std::ops::Range<f64> {
    if !(lo.is_finite() && hi.is_finite()) {
        return 0.0..1.0;
    }
    let span = hi - lo;
    if span <= 1e-12 * lo.abs().max(hi.abs()).max(1e-300) {
        let d = if lo == 0.0 { 1.0 } else { 0.05 * lo.abs() };
        return (lo - d)..(hi + d);
    }
    (lo - 0.08 * span)..(hi + 0.08 * span)
}

/// A length axis for values in metres: km when they reach beyond 10 km. Returns (scale to
/// multiply metres by, unit name).
pub fn length_unit(max_m: f64) -> (f64, &'static str) {
    if max_m.abs() > 10_000.0 {
        (1e-3, "km")
    } else {
        (1.0, "m")
    }
}

/// Decimate a series sorted by x to at most ~2·`buckets` points, keeping each bucket's minimum
/// and maximum (in x order): the drawn envelope is the same at the figure's resolution, and a
/// spectrum of 10⁵–10⁶ points is drawn in milliseconds instead of minutes.
pub fn decimate(pts: &[(f64, f64)], buckets: usize) -> Vec<(f64, f64)> {
    if pts.len() <= 2 * buckets || buckets == 0 {
        return pts.to_vec();
    }
    let (x0, x1) = (pts[0].0, pts[pts.len() - 1].0);
    let w = (x1 - x0) / buckets as f64;
    if w.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return pts.to_vec();
    }
    let mut out = Vec::with_capacity(2 * buckets + 2);
    let mut i = 0;
    while i < pts.len() {
        let b = (((pts[i].0 - x0) / w) as usize).min(buckets - 1);
        let mut j = i;
        let (mut lo, mut hi) = (i, i);
        while j < pts.len() && (((pts[j].0 - x0) / w) as usize).min(buckets - 1) == b {
            if pts[j].1 < pts[lo].1 {
                lo = j;
            }
            if pts[j].1 > pts[hi].1 {
                hi = j;
            }
            j += 1;
        }
        let (a, c) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push(pts[a]);
        if c != a {
            out.push(pts[c]);
        }
        i = j;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_have_no_spurious_digits() {
        assert_eq!(tick(1000.0), "1000");
        assert_eq!(tick(0.25), "0.25");
        assert_eq!(tick(0.1 + 0.2), "0.3");
        assert_eq!(tick(-2.0), "-2");
        assert_eq!(tick(440.0), "440");
        assert_eq!(tick(1.5e-7), "1.5e-7");
        assert_eq!(tick(2.0e6), "2e6");
        assert_eq!(decade(-12), "10⁻¹²");
        assert_eq!(decade(3), "10³");
    }

    #[test]
    fn decimation_keeps_the_envelope() {
        let pts: Vec<(f64, f64)> = (0..100_000)
            .map(|i| (i as f64, ((i * 7919) % 1000) as f64))
            .collect();
        let d = decimate(&pts, 500);
        assert!(d.len() <= 1000);
        let max = d.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        let min = d.iter().map(|p| p.1).fold(f64::MAX, f64::min);
        assert_eq!((min, max), (0.0, 999.0));
        assert!(d.windows(2).all(|w| w[0].0 <= w[1].0));
    }

    #[test]
    fn robust_range_ignores_wild_values_but_keeps_the_truth() {
        let mut v: Vec<f64> = (0..100).map(|i| 400.0 + 0.01 * i as f64).collect();
        v.push(450_000.0);
        v.push(-450_000.0);
        let r = robust_range(&v, &[395.0]);
        assert!(r.start < 395.0 && r.start > 390.0, "{r:?}");
        assert!(r.end < 402.0, "{r:?}");
    }
}
