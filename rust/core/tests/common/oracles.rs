//! Closed forms the tests check against, written out apart from the crate's own code (shared
//! by the integration tests through `common` and by the unit tests through
//! `mesh::test_meshes`).

/// Total diffuse reflectance R_d,total of a semi-infinite medium under the dipole (Jensen,
/// Marschner, Levoy, Hanrahan 2001, "A Practical Model for Subsurface Light Transport": the
/// dipole's R_d(r), Xu 2007 eq. 4, integrated over the plane):
/// R_d,total = α′/2 (1 + e^(−(4/3) A √(3(1 − α′)))) e^(−√(3(1 − α′))), with the reduced
/// albedo α′ = σs′ / (σa + σs′), A = (1 + F_dr) / (1 − F_dr) and F_dr = −1.440/η² + 0.710/η +
/// 0.668 + 0.0636 η (Xu 2007 Table 1); docs/design.md, "The profile".
pub fn rd_total(sigma_a: f64, sigma_s_prime: f64, eta: f64) -> f64 {
    let a = sigma_s_prime / (sigma_a + sigma_s_prime);
    let f_dr = -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta;
    let big_a = (1.0 + f_dr) / (1.0 - f_dr);
    let s = (3.0 * (1.0 - a)).sqrt();
    0.5 * a * (1.0 + (-4.0 / 3.0 * big_a * s).exp()) * (-s).exp()
}
