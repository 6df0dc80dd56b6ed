//! Particle and molecular scattering: phase functions, Rayleigh cross-sections, Mie.
//!
//! Consumes particle descriptions (Henyey-Greenstein parameters, phase-function tables, size
//! distributions with a refractive index); produces scattering coefficients, single-scattering
//! albedos and [`phase::PhaseFunction`]s that the transport can evaluate and sample.

pub mod cache;
pub mod distribution;
pub mod matrix;
pub mod matrix_table;
pub mod mie;
pub mod opac;
pub mod phase;
pub mod rayleigh;
pub mod table;
pub mod water_content;

use std::path::Path;

use table::PhaseTable;

/// The tables shipped in `phase_functions/`, compiled into the binary so scenes (and the
/// embedded default scene) can name them with `builtin = "..."` without a path.
const BUILTIN_TABLES: &[(&str, &str)] = &[
    (
        "bissonnette_c1_1064nm",
        include_str!("../../phase_functions/bissonnette_c1_1064nm.txt"),
    ),
    (
        "c1_cloud_532nm",
        include_str!("../../phase_functions/c1_cloud_532nm.txt"),
    ),
    (
        "c1_cloud_1064nm",
        include_str!("../../phase_functions/c1_cloud_1064nm.txt"),
    ),
    (
        "c1_cloud_1572nm",
        include_str!("../../phase_functions/c1_cloud_1572nm.txt"),
    ),
    (
        "continental_average_532nm",
        include_str!("../../phase_functions/continental_average_532nm.txt"),
    ),
    (
        "continental_average_1064nm",
        include_str!("../../phase_functions/continental_average_1064nm.txt"),
    ),
    (
        "continental_average_1572nm",
        include_str!("../../phase_functions/continental_average_1572nm.txt"),
    ),
    (
        "maritime_clean_532nm",
        include_str!("../../phase_functions/maritime_clean_532nm.txt"),
    ),
    (
        "maritime_clean_1064nm",
        include_str!("../../phase_functions/maritime_clean_1064nm.txt"),
    ),
    (
        "maritime_clean_1572nm",
        include_str!("../../phase_functions/maritime_clean_1572nm.txt"),
    ),
];

/// Names of the built-in tables.
pub fn builtin_table_names() -> Vec<&'static str> {
    BUILTIN_TABLES.iter().map(|(n, _)| *n).collect()
}

/// What to write instead of a phase-table `file` that is not found at `resolved` (the scene's
/// directory joined with it): where relative paths are anchored and, when the file is one of
/// the shipped tables (a scene copied out of `scenes/` keeps `file = "../phase_functions/…"`),
/// the built-in table of the same name. `None` when the file exists.
pub fn missing_table_hint(file: &str, resolved: &Path) -> Option<String> {
    if resolved.exists() {
        return None;
    }
    let stem = Path::new(file).file_stem()?.to_str()?;
    let anchor = if Path::new(file).is_relative() {
        format!(
            "`{file}` is relative to the scene's directory (or, for a scene read from standard input, the current directory)"
        )
    } else {
        format!("`{file}` does not exist")
    };
    Some(match BUILTIN_TABLES.iter().find(|(n, _)| *n == stem) {
        Some((name, _)) => format!(
            "{anchor}; the same table is built in: write `phase = {{ kind = \"table\", builtin = \"{name}\" }}`"
        ),
        None => format!(
            "{anchor}; built-in tables (`builtin = \"NAME\"`): {}",
            builtin_table_names().join(", ")
        ),
    })
}

/// A built-in table by name (the file name in `phase_functions/` without `.txt`).
pub fn builtin_table(name: &str) -> Result<PhaseTable, String> {
    let (_, text) = BUILTIN_TABLES
        .iter()
        .find(|(n, _)| *n == name)
        .ok_or_else(|| {
            format!(
                "no built-in phase-function table `{name}` (known: {})",
                builtin_table_names().join(", ")
            )
        })?;
    PhaseTable::parse(Path::new(&format!("phase_functions/{name}.txt")), text)
        .map_err(|e| e.to_string())
}
