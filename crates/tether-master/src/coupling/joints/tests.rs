//! The joint math against itself: the velocity and acceleration levels are
//! the time derivatives of the position level along a rigid motion, and the
//! force law is the transpose of the velocity-level Jacobian (virtual work).

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::*;
use crate::coupling::rows::RowLevel;

/// A rigid motion with constant angular acceleration about a fixed axis and a
/// quadratic path: r(t), R(t) and their derivatives in closed form.
struct Motion {
    r0: Vector3<f64>,
    v0: Vector3<f64>,
    acc: Vector3<f64>,
    axis: Vector3<f64>,
    angle0: f64,
    rate0: f64,
    rate_dot: f64,
    offset: Vector3<f64>,
}

impl Motion {
    fn at(&self, t: f64) -> Kinematics {
        let angle = self.angle0 + self.rate0 * t + 0.5 * self.rate_dot * t * t;
        let rate = self.rate0 + self.rate_dot * t;
        let axis = nalgebra::Unit::new_normalize(self.axis);
        let rot: Matrix3<f64> = Rotation3::from_axis_angle(&axis, angle).into_inner();
        let w = axis.into_inner() * rate;
        let alpha = axis.into_inner() * self.rate_dot;
        let r = self.r0 + self.v0 * t + 0.5 * self.acc * t * t;
        let v = self.v0 + self.acc * t;
        let rho = rot * self.offset;
        let w_rho = w.cross(&rho);
        Kinematics {
            r,
            rot,
            w,
            alpha,
            c: r + rho,
            c_dot: v + w_rho,
            c_ddot: self.acc + alpha.cross(&rho) + w.cross(&w_rho),
            rho,
        }
    }

    fn velocity(&self, t: f64) -> Vector3<f64> {
        self.v0 + self.acc * t
    }
}

fn motions() -> (Motion, Motion) {
    (
        Motion {
            r0: Vector3::new(0.3, -0.2, 0.1),
            v0: Vector3::new(0.5, 1.0, -0.7),
            acc: Vector3::new(-0.4, 0.2, 0.9),
            axis: Vector3::new(1.0, 2.0, 0.5),
            angle0: 0.4,
            rate0: 1.3,
            rate_dot: -0.8,
            offset: Vector3::new(0.1, 0.2, -0.3),
        },
        Motion {
            r0: Vector3::new(-0.1, 0.4, 0.2),
            v0: Vector3::new(-0.3, 0.6, 0.2),
            acc: Vector3::new(0.7, -0.5, 0.1),
            axis: Vector3::new(-0.3, 0.4, 1.0),
            angle0: -0.9,
            rate0: -0.6,
            rate_dot: 1.1,
            offset: Vector3::new(-0.2, 0.05, 0.15),
        },
    )
}

fn all_conditions() -> Vec<(String, Condition)> {
    let frames = Frames::new(
        Vector3::new(0.2, 0.1, 1.0),
        Vector3::new(1.0, 0.3, 0.0),
        Vector3::new(-0.1, 0.3, 1.0),
        Vector3::new(1.0, -0.2, 0.1),
    )
    .unwrap();
    KINDS
        .iter()
        .flat_map(|kind| {
            conditions(kind, &frames)
                .unwrap()
                .into_iter()
                .enumerate()
                .map(move |(k, c)| (format!("{kind}[{}]", k + 1), c))
        })
        .collect()
}

#[test]
fn velocity_and_acceleration_levels_are_derivatives_of_the_position_level() {
    let (mi, mj) = motions();
    let h = 1e-4;
    for (name, c) in all_conditions() {
        let g = |t: f64| c.value(RowLevel::Position, &mi.at(t), &mj.at(t));
        let t = 0.37;
        let fd1 = (g(t + h) - g(t - h)) / (2.0 * h);
        let fd2 = (g(t + h) - 2.0 * g(t) + g(t - h)) / (h * h);
        let g1 = c.value(RowLevel::Velocity, &mi.at(t), &mj.at(t));
        let g2 = c.value(RowLevel::Acceleration, &mi.at(t), &mj.at(t));
        assert!((g1 - fd1).abs() < 1e-7, "{name}: ġ {g1} vs {fd1}");
        assert!((g2 - fd2).abs() < 1e-5, "{name}: g̈ {g2} vs {fd2}");
    }
}

#[test]
fn the_force_law_is_the_velocity_jacobian_transposed() {
    // ġ = F_i·v_i + T_i·ω_i + F_j·v_j + T_j·ω_j for a unit multiplier: the
    // law does no work on motions the joint allows.
    let (mi, mj) = motions();
    let t = 0.81;
    let (ki, kj) = (mi.at(t), mj.at(t));
    for (name, c) in all_conditions() {
        let law = c.law(&ki, &kj);
        let part = |k: usize| Vector3::new(law[k], law[k + 1], law[k + 2]);
        let power = part(0).dot(&mi.velocity(t))
            + part(3).dot(&ki.w)
            + part(6).dot(&mj.velocity(t))
            + part(9).dot(&kj.w);
        let g1 = c.value(RowLevel::Velocity, &ki, &kj);
        assert!((power - g1).abs() < 1e-13, "{name}: {power} vs {g1}");
        let active = c.active_components(&mi.offset, &mj.offset);
        for (k, on) in active.iter().enumerate() {
            if !on {
                assert!(part(3 * k).norm() == 0.0, "{name}: part {k} should vanish");
            }
        }
    }
}

#[test]
fn aligned_frames_at_one_point_satisfy_every_joint() {
    let frames = Frames::new(
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(1.0, 0.0, 0.0),
    )
    .unwrap();
    let rot = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
    let k = Kinematics {
        r: Vector3::new(1.0, 2.0, 3.0),
        rot,
        w: Vector3::zeros(),
        alpha: Vector3::zeros(),
        c: Vector3::new(1.0, 2.0, 3.0),
        c_dot: Vector3::zeros(),
        c_ddot: Vector3::zeros(),
        rho: Vector3::zeros(),
    };
    let counts = [3, 1, 1, 4, 5, 4, 5, 3, 2, 3];
    for (kind, count) in KINDS.iter().zip(counts) {
        let c = conditions(kind, &frames).unwrap();
        assert_eq!(c.len(), count, "{kind}");
        for cond in c {
            if let Condition::Perpendicular { a, b } = cond {
                if a == b {
                    continue; // the plain perpendicular joint needs crossed axes
                }
            }
            assert!(
                cond.value(RowLevel::Position, &k, &k).abs() < 1e-15,
                "{kind}"
            );
        }
    }
}

#[test]
fn planar_reduction_keeps_the_in_plane_conditions() {
    let frames = Frames::new(Vector3::z(), Vector3::x(), Vector3::z(), Vector3::x()).unwrap();
    let kept = |kind: &str| {
        conditions(kind, &frames)
            .unwrap()
            .iter()
            .filter(|c| c.acts_in_plane())
            .count()
    };
    assert_eq!(kept("atpoint"), 2);
    assert_eq!(kept("revolute"), 2);
    assert_eq!(kept("translational"), 1 + 2);
    assert_eq!(kept("orientation"), 1);
    // A rocker's axis line: inplane with the normal in the plane.
    let rocker = Frames::new(Vector3::z(), Vector3::x(), Vector3::y(), Vector3::x()).unwrap();
    assert_eq!(
        conditions("inplane", &rocker)
            .unwrap()
            .iter()
            .filter(|c| c.acts_in_plane())
            .count(),
        1
    );
}

#[test]
fn degenerate_frames_are_refused() {
    assert!(Frames::new(Vector3::zeros(), Vector3::x(), Vector3::z(), Vector3::x()).is_err());
    assert!(Frames::new(Vector3::z(), Vector3::z(), Vector3::z(), Vector3::x()).is_err());
}
