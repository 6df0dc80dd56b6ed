//! Physical constants (CODATA 2018 exact SI values where exact), in SI unless the name says otherwise.

/// Speed of light in vacuum [m/s].
pub const SPEED_OF_LIGHT_M_PER_S: f64 = 299_792_458.0;
/// Boltzmann constant [J/K].
pub const BOLTZMANN_J_PER_K: f64 = 1.380_649e-23;
/// Avogadro constant [1/mol].
pub const AVOGADRO_PER_MOL: f64 = 6.022_140_76e23;
/// Planck constant [J s].
pub const PLANCK_J_S: f64 = 6.626_070_15e-34;
/// Elementary charge \[C\] (exact in the 2019 SI).
pub const ELEMENTARY_CHARGE_C: f64 = 1.602_176_634e-19;
/// Atomic mass constant \[kg\].
pub const ATOMIC_MASS_KG: f64 = 1.660_539_066_60e-27;
/// Second radiation constant c2 = h c / k [cm K], as HITRAN uses it.
pub const C2_CM_K: f64 = 1.438_776_877;
/// Standard gravity [m/s²].
pub const STANDARD_GRAVITY_M_PER_S2: f64 = 9.806_65;
/// One standard atmosphere \[Pa\].
pub const STANDARD_ATMOSPHERE_PA: f64 = 101_325.0;
/// Molar mass of dry air [kg/mol] (US Standard Atmosphere 1976).
pub const MOLAR_MASS_DRY_AIR_KG_PER_MOL: f64 = 0.028_964_4;
/// Molar mass of water [kg/mol].
pub const MOLAR_MASS_WATER_KG_PER_MOL: f64 = 0.018_015_28;
/// Loschmidt number density at 273.15 K and 1 atm [1/m³].
pub const LOSCHMIDT_PER_M3: f64 = 2.686_780_111e25;
/// Molar gas constant R = N_A k [J/(mol K)].
pub const MOLAR_GAS_CONSTANT_J_PER_MOL_K: f64 = 8.314_462_618;
/// One Dobson unit [molecules/m²] (2.686 780 111e20, the Loschmidt number times 10 µm).
pub const DOBSON_UNIT_PER_M2: f64 = 2.686_780_111e20;
