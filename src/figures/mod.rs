//! The figures the command line draws, one module per command; the data they show comes from
//! the library. Every figure takes its palette, fonts, tick labels and legend from [`style`],
//! the one house style; here the embedded font.
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
pub mod style;

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
