//! The control loop through direct feedthrough (source → PI controller →
//! plant, the loop controller ↔ plant) and its monolithic closed form, for
//! the tests that run it (tests/master_signal_loops.rs,
//! tests/master_signal_iterations.rs).

use nalgebra::{Matrix4, RowVector4, Vector4};

/// The source: ẇ = A_S·w from w = 1.
pub const A_S: f64 = -2.0;
/// The controller's integral gain and set point.
pub const KI: f64 = 2.0;
pub const R: f64 = 1.0;
/// The plant: ẋ = A·x + B1·u1 + B2·u2, Y = C·x + D1·u1 + D2·u2.
pub const A: f64 = -1.0;
pub const B1: f64 = 1.0;
pub const B2: f64 = 1.0;
pub const C: f64 = 1.0;
pub const D1: f64 = 0.5;
pub const D2: f64 = 0.5;

/// The plant output Y of the monolithic loop at `t` for proportional gain
/// `kp` (loop gain d1·kp), from w = 1, z = x = 0.
pub fn monolithic(kp: f64, t: f64) -> f64 {
    let alpha = 1.0 / (1.0 + D1 * kp);
    // s = (w, z, x, 1): Y = y·s, U = u·s, ṡ = A s.
    let y = RowVector4::new(alpha * D2, alpha * D1 * KI, alpha * C, alpha * D1 * kp * R);
    let u = RowVector4::new(0.0, KI, 0.0, kp * R) - kp * y;
    #[rustfmt::skip]
    let a = Matrix4::new(
        A_S,                0.0,        0.0,            0.0,
        -y[0],              -y[1],      -y[2],          R - y[3],
        B2 + B1 * u[0],     B1 * u[1],  A + B1 * u[2],  B1 * u[3],
        0.0,                0.0,        0.0,            0.0,
    );
    (y * (a * t).exp() * Vector4::new(1.0, 0.0, 0.0, 1.0))[0]
}
