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

/// Total reflectance and transmittance of a slab of thickness `d` under the multipole (Donner
/// and Jensen 2005, "Light Diffusion in Multi-Layered Translucent Materials", the pole pairs):
/// real poles at z_r,i = 2i(d + z_b0 + z_bd) + l (weight +1), virtual ones at z_v,i =
/// 2i(d + z_b0 + z_bd) − l − 2 z_b0 (weight −1), i = −n..n, with l = 1/σt′, z_b = 2AD and
/// D = 1/(3σt′), `a_top` and `a_bottom` the faces' mismatch terms A. Each pole integrates over
/// the plane to sgn(z) e^(−σtr |z|), z its depth below the top face for the reflectance and
/// above the bottom face (d − z) for the transmittance: R = α′/2 Σ w sgn(z) e^(−σtr |z|).
pub fn slab_totals(
    sigma_a: f64,
    sigma_s_prime: f64,
    d: f64,
    a_top: f64,
    a_bottom: f64,
) -> (f64, f64) {
    let st = sigma_a + sigma_s_prime;
    let a = sigma_s_prime / st;
    let l = 1.0 / st;
    let (zb0, zbd) = (2.0 * a_top / (3.0 * st), 2.0 * a_bottom / (3.0 * st));
    let tr = (3.0 * sigma_a * st).sqrt();
    let term = |z: f64| z.signum() * (-tr * z.abs()).exp();
    if d.is_infinite() {
        return (0.5 * a * (term(l) - term(-l - 2.0 * zb0)), 0.0);
    }
    let (mut r, mut t) = (0.0, 0.0);
    for i in -2000..=2000 {
        let shift = 2.0 * f64::from(i) * (d + zb0 + zbd);
        let (zr, zv) = (shift + l, shift - l - 2.0 * zb0);
        r += term(zr) - term(zv);
        t += term(d - zr) - term(d - zv);
    }
    (0.5 * a * r, 0.5 * a * t)
}

/// A = (1 + F_dr) / (1 − F_dr) with Xu 2007 Table 1's fit of F_dr.
fn mismatch(eta: f64) -> f64 {
    let f_dr = -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta;
    (1.0 + f_dr) / (1.0 - f_dr)
}

/// Total diffuse reflectance of a slab of thickness `d` in the open under the multipole
/// (`slab_totals` with both faces against the outside). At d → ∞: `rd_total`.
pub fn slab_rd_total(sigma_a: f64, sigma_s_prime: f64, eta: f64, d: f64) -> f64 {
    let a = mismatch(eta);
    slab_totals(sigma_a, sigma_s_prime, d, a, a).0
}

/// Total diffuse reflectance of a layer (`top`: σa, σs′, thickness) over a base (σa, σs′,
/// thickness, infinite for a half-space), Donner and Jensen 2005's Kubelka–Munk sum at zero
/// spatial frequency: R = R1 + T1 T1′ R2 / (1 − R1′ R2), primes for the top layer lit from
/// below; the face between the layers index-matched (A = 1), the outer faces at `eta`.
pub fn layered_rd_total(top: (f64, f64, f64), base: (f64, f64, f64), eta: f64) -> f64 {
    let a = mismatch(eta);
    let (r1, t1) = slab_totals(top.0, top.1, top.2, a, 1.0);
    let (r1_up, t1_up) = slab_totals(top.0, top.1, top.2, 1.0, a);
    let (r2, _) = slab_totals(base.0, base.1, base.2, 1.0, a);
    r1 + t1 * t1_up * r2 / (1.0 - r1_up * r2)
}
