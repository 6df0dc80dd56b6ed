//! What `lidarsim profiles info` prints: a table of a profile set's members.

use std::fmt::Write as _;

use crate::atmosphere::ProfileSet;
use crate::output::csv_field;

/// One CSV row per member: id, latitude, class, levels, surface pressure, top, air column,
/// precipitable water and XCO2 (empty where the profile has no H2O or CO2).
pub fn info_csv(set: &ProfileSet) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "id,latitude_deg,class,levels,surface_p_hPa,top_altitude_km,air_column_per_cm2,precipitable_water_mm,xco2_ppm"
    );
    for m in &set.members {
        let p = &m.profile;
        let pw = p
            .precipitable_water_kg_per_m2()
            .map(|v| format!("{v:.3}"))
            .unwrap_or_default();
        let xco2 = p
            .column_average_dry_vmr("CO2")
            .map(|v| format!("{:.3}", v * 1e6))
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "{},{},{},{},{:.2},{:.2},{:.5e},{pw},{xco2}",
            csv_field(&m.meta.id),
            m.meta.latitude_deg,
            m.meta.class(),
            p.len(),
            p.surface_pressure_pa() / 100.0,
            p.altitude_m[p.len() - 1] / 1e3,
            p.air_column_per_m2() * 1e-4
        );
    }
    s
}
