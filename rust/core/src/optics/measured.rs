//! Measured materials: Jensen et al. 2001's table of reduced scattering and absorption.

/// Jensen 2001, Table (also pbrt's subsurface table): reduced scattering sigma_s' and absorption
/// sigma_a in mm^-1, measured with eta = 1.3.
pub const MEASURED: [(&str, [f64; 3], [f64; 3]); 12] = [
    ("apple", [2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046]),
    ("chicken1", [0.15, 0.21, 0.38], [0.015, 0.077, 0.19]),
    ("chicken2", [0.19, 0.25, 0.32], [0.018, 0.088, 0.20]),
    ("cream", [7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163]),
    ("ketchup", [0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
    ("marble", [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
    ("potato", [0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12]),
    ("skimmilk", [0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
    ("skin1", [0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
    ("skin2", [1.09, 1.59, 1.79], [0.013, 0.070, 0.145]),
    ("spectralon", [11.6, 20.4, 14.9], [0.00, 0.00, 0.00]),
    ("wholemilk", [2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014]),
];

/// The relative index of refraction Jensen 2001 measured the presets with.
pub const MEASURED_ETA: f64 = 1.3;
