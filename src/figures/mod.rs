//! The figures the command line draws, one module per command; the data they show comes from
//! the library. Here the shared set-up: the embedded font and the legend style.
//!
//! plotters' default font features link the system's fontconfig and freetype; with its
//! `ab_glyph` feature and a TTF font compiled into the binary, labelled PNGs render on any machine
//! (DejaVu Sans, free licence in `assets/DejaVuSans.LICENSE`).

use std::sync::Once;

pub mod bench;
pub mod dial;
pub mod lbl;
pub mod profiles;
pub mod run;
pub mod select;

/// The result of drawing one figure.
pub type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Font family name to use in plotters text styles.
pub const FONT: &str = "sans-serif";

static REGISTER: Once = Once::new();

/// Register the embedded font under [`FONT`]; call before drawing any text (idempotent).
pub fn init_font() {
    REGISTER.call_once(|| {
        // The font is compiled in; failure to parse it is a build defect, not a user error.
        plotters::style::register_font(
            FONT,
            plotters::style::FontStyle::Normal,
            include_bytes!("../../assets/DejaVuSans.ttf"),
        )
        .map_err(|_| "embedded font")
        .expect("assets/DejaVuSans.ttf is a valid TTF font");
    });
}

/// The house palette's i-th colour (Okabe and Ito 2008, *Color Universal Design*: told apart
/// with every common colour-vision deficiency), repeating after eight.
pub fn palette(i: usize) -> plotters::style::RGBColor {
    use plotters::style::RGBColor;
    const C: [RGBColor; 8] = [
        RGBColor(0, 114, 178),
        RGBColor(213, 94, 0),
        RGBColor(0, 158, 115),
        RGBColor(204, 121, 167),
        RGBColor(230, 159, 0),
        RGBColor(86, 180, 233),
        RGBColor(240, 228, 66),
        RGBColor(0, 0, 0),
    ];
    C[i % C.len()]
}

/// Draw a chart's series legend in the house style (translucent white box, black border).
pub fn draw_legend<'a, DB, CT>(
    chart: &mut plotters::chart::ChartContext<'a, DB, CT>,
) -> Result<(), String>
where
    DB: plotters::prelude::DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    use plotters::prelude::*;
    chart
        .configure_series_labels()
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        // The backend's error borrows the drawing area; its words are what the caller needs.
        .map_err(|e| e.to_string())
}
