//! A 3D rigid body (6 DOF) with two marker ports `A` and `B` (docs/marker-ports.md),
//! optionally jointed to ground by a spherical or a revolute joint.
//!
//! States: CoM position `com[1..3]` (world), orientation quaternion `q[1..4]`
//! (scalar first, body → world), CoM velocity `vcom[1..3]` (world) and the angular
//! velocity in body coordinates `wb[1..3]`. The quaternion is normalised wherever it
//! is used (so the rotation matrices are orthonormal to rounding), and its derivative
//! carries a small term that pulls |q| back to 1.
//!
//! Free body: m a = Σ F + m g, J ω̇ + ω × J ω = Σ (ρ × F + T) (body frame at the CoM).
//! Grounded body: the body point `pivot` stays where it starts, and the body obeys
//! Euler's equations about that fixed point (inertia shifted by the parallel-axis
//! theorem); a revolute joint also keeps the body axis `axis` fixed, so ω = θ̇ n and
//! θ̈ = n·τ_O / (nᵀ J_O n). These are reduced equations: the ground joint is exact, the
//! CoM position and velocity follow from the orientation and the angular velocity.
//! See docs/fmus.md.

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use tether_fmu_kit::{
    export_fmu, Declaration, DefaultExperiment, Integer, Model, Output, Parameters, Real, State,
};

/// The states, in order (13).
const STATES: &[&str] = &[
    "com[1]", "com[2]", "com[3]", "q[1]", "q[2]", "q[3]", "q[4]", "vcom[1]", "vcom[2]", "vcom[3]",
    "wb[1]", "wb[2]", "wb[3]",
];

/// Every state and every input: what the accelerations depend on.
const STATES_AND_INPUTS: &[&str] = &[
    "com[1]", "com[2]", "com[3]", "q[1]", "q[2]", "q[3]", "q[4]", "vcom[1]", "vcom[2]", "vcom[3]",
    "wb[1]", "wb[2]", "wb[3]", "A.F[1]", "A.F[2]", "A.F[3]", "A.T[1]", "A.T[2]", "A.T[3]",
    "B.F[1]", "B.F[2]", "B.F[3]", "B.T[1]", "B.T[2]", "B.T[3]",
];

/// The markers, in the order of their inputs and outputs.
pub const MARKERS: [&str; 2] = ["A", "B"];

/// Outputs per marker (docs/marker-ports.md): r 3, R 9, v 3, w 3, a 3, alpha 3.
pub const OUTPUTS_PER_MARKER: usize = 24;

/// Control of the quaternion's norm: q̇ gets −κ (|q|² − 1) q, κ in 1/s.
const NORM_GAIN: f64 = 10.0;

macro_rules! vector3 {
    ($name:literal, $start:expr, $unit:literal, $description:literal) => {
        [
            Real::new(concat!($name, "[1]"), $start[0])
                .unit($unit)
                .description($description),
            Real::new(concat!($name, "[2]"), $start[1])
                .unit($unit)
                .description($description),
            Real::new(concat!($name, "[3]"), $start[2])
                .unit($unit)
                .description($description),
        ]
    };
}

macro_rules! marker_outputs {
    ($($m:literal),*) => {
        &[
            $(
                Output::new(concat!($m, ".r[1]")).unit("m").description("Marker position (world)").depends_on(STATES),
                Output::new(concat!($m, ".r[2]")).unit("m").description("Marker position (world)").depends_on(STATES),
                Output::new(concat!($m, ".r[3]")).unit("m").description("Marker position (world)").depends_on(STATES),
                Output::new(concat!($m, ".R[1,1]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[1,2]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[1,3]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[2,1]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[2,2]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[2,3]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[3,1]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[3,2]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".R[3,3]")).description("Rotation marker -> world").depends_on(STATES),
                Output::new(concat!($m, ".v[1]")).unit("m/s").description("Marker velocity (world)").depends_on(STATES),
                Output::new(concat!($m, ".v[2]")).unit("m/s").description("Marker velocity (world)").depends_on(STATES),
                Output::new(concat!($m, ".v[3]")).unit("m/s").description("Marker velocity (world)").depends_on(STATES),
                Output::new(concat!($m, ".w[1]")).unit("rad/s").description("Angular velocity (world)").depends_on(STATES),
                Output::new(concat!($m, ".w[2]")).unit("rad/s").description("Angular velocity (world)").depends_on(STATES),
                Output::new(concat!($m, ".w[3]")).unit("rad/s").description("Angular velocity (world)").depends_on(STATES),
                Output::new(concat!($m, ".a[1]")).unit("m/s2").description("Marker acceleration (world)").depends_on(STATES_AND_INPUTS),
                Output::new(concat!($m, ".a[2]")).unit("m/s2").description("Marker acceleration (world)").depends_on(STATES_AND_INPUTS),
                Output::new(concat!($m, ".a[3]")).unit("m/s2").description("Marker acceleration (world)").depends_on(STATES_AND_INPUTS),
                Output::new(concat!($m, ".alpha[1]")).unit("rad/s2").description("Angular acceleration (world)").depends_on(STATES_AND_INPUTS),
                Output::new(concat!($m, ".alpha[2]")).unit("rad/s2").description("Angular acceleration (world)").depends_on(STATES_AND_INPUTS),
                Output::new(concat!($m, ".alpha[3]")).unit("rad/s2").description("Angular acceleration (world)").depends_on(STATES_AND_INPUTS),
            )*
            Output::new("E").unit("J").description("Kinetic plus potential energy (zero potential at the world origin)").depends_on(STATES),
        ]
    };
}

macro_rules! marker_inputs {
    ($($m:literal),*) => {
        &[
            $(
                Real::new(concat!($m, ".F[1]"), 0.0).unit("N").description("Force at the marker (world)"),
                Real::new(concat!($m, ".F[2]"), 0.0).unit("N").description("Force at the marker (world)"),
                Real::new(concat!($m, ".F[3]"), 0.0).unit("N").description("Force at the marker (world)"),
                Real::new(concat!($m, ".T[1]"), 0.0).unit("N.m").description("Torque on the body (world)"),
                Real::new(concat!($m, ".T[2]"), 0.0).unit("N.m").description("Torque on the body (world)"),
                Real::new(concat!($m, ".T[3]"), 0.0).unit("N.m").description("Torque on the body (world)"),
            )*
        ]
    };
}

const fn concat_reals<const N: usize>(groups: [&[Real]; N]) -> [Real; 32] {
    let mut out = [Real::new("", 0.0); 32];
    let mut k = 0;
    let mut g = 0;
    while g < N {
        let mut i = 0;
        while i < groups[g].len() {
            out[k] = groups[g][i];
            k += 1;
            i += 1;
        }
        g += 1;
    }
    assert!(k == 32, "the Real parameter count changed");
    out
}

const REAL_PARAMETERS: [Real; 32] = concat_reals([
    &[
        Real::new("m", 1.0)
            .unit("kg")
            .description("Mass (must be > 0)"),
        Real::new("Jxx", 0.1)
            .unit("kg.m2")
            .description("Principal moment of inertia about the body x axis, at the CoM (> 0)"),
        Real::new("Jyy", 0.1)
            .unit("kg.m2")
            .description("Principal moment of inertia about the body y axis, at the CoM (> 0)"),
        Real::new("Jzz", 0.1)
            .unit("kg.m2")
            .description("Principal moment of inertia about the body z axis, at the CoM (> 0)"),
        Real::new("gx", 0.0)
            .unit("m/s2")
            .description("Gravity, world x"),
        Real::new("gy", 0.0)
            .unit("m/s2")
            .description("Gravity, world y"),
        Real::new("gz", -9.81)
            .unit("m/s2")
            .description("Gravity, world z"),
    ],
    &vector3!("r0", [0.0; 3], "m", "Initial CoM position (world)"),
    &vector3!(
        "phi0",
        [0.0; 3],
        "rad",
        "Initial orientation as a rotation vector (axis times angle, world)"
    ),
    &vector3!(
        "v0",
        [0.0; 3],
        "m/s",
        "Initial CoM velocity (world); with a ground joint it must equal w0 x (r0 - pivot)"
    ),
    &vector3!(
        "w0",
        [0.0; 3],
        "rad/s",
        "Initial angular velocity (world); with a revolute ground joint parallel to the axis"
    ),
    &vector3!(
        "pivot",
        [0.0; 3],
        "m",
        "Ground joint: the body point (body frame, from the CoM) held at its initial world position"
    ),
    &vector3!(
        "axis",
        [0.0, 0.0, 1.0],
        "1",
        "Revolute ground joint: the body axis (body frame) kept fixed in the world"
    ),
    &vector3!(
        "A.offset",
        [0.0; 3],
        "m",
        "Origin of marker A (body frame, from the CoM)"
    ),
    &vector3!(
        "B.offset",
        [0.0; 3],
        "m",
        "Origin of marker B (body frame, from the CoM)"
    ),
    &[Real::new("max_step", 0.0)
        .min(0.0)
        .unit("s")
        .description("Largest internal integrator step (0: no limit), as in a model exported with a fixed-rate solver; makes a step costlier")],
]);

/// The ground joint (`joint` parameter: 0 none, 1 spherical, 2 revolute).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GroundJoint {
    Free,
    /// The body point `pivot` (body frame) is fixed at the world point `at`;
    /// `inertia` is the inertia about the pivot (body frame), `inverse` its inverse.
    Spherical {
        pivot: Vector3<f64>,
        at: Vector3<f64>,
        inertia: Matrix3<f64>,
        inverse: Matrix3<f64>,
    },
    /// Spherical, and the body turns only about the unit body axis `axis`;
    /// `inertia` is nᵀ J_O n.
    Revolute {
        pivot: Vector3<f64>,
        at: Vector3<f64>,
        axis: Vector3<f64>,
        inertia: f64,
    },
}

pub struct Body3d {
    m: f64,
    j: Vector3<f64>,
    g: Vector3<f64>,
    r0: Vector3<f64>,
    q0: UnitQuaternion<f64>,
    v0: Vector3<f64>,
    w0: Vector3<f64>,
    joint: GroundJoint,
    offsets: [Vector3<f64>; 2],
    max_step: f64,
}

/// The body's motion at one instant (world frame unless named body).
struct Motion {
    r: Vector3<f64>,
    rot: Matrix3<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
    a: Vector3<f64>,
    alpha: Vector3<f64>,
    /// Angular velocity and acceleration in body coordinates.
    wb: Vector3<f64>,
    wb_dot: Vector3<f64>,
}

fn vec3(x: &[f64]) -> Vector3<f64> {
    Vector3::new(x[0], x[1], x[2])
}

impl Body3d {
    fn read(p: &Parameters, name: &str) -> Result<Vector3<f64>, String> {
        Ok(Vector3::new(
            p.real(&format!("{name}[1]"))?,
            p.real(&format!("{name}[2]"))?,
            p.real(&format!("{name}[3]"))?,
        ))
    }

    /// Kinematics and accelerations from the states and the marker inputs.
    fn motion(&self, x: &[f64], u: &[f64]) -> Motion {
        let q = Quaternion::new(x[3], x[4], x[5], x[6]);
        let rot = UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .into_inner();
        let wb_state = vec3(&x[10..13]);
        // Sum of marker forces (world) and of their moments about the CoM (body frame).
        let mut force = Vector3::zeros();
        let mut torque_b = Vector3::zeros();
        let mut moment_of_forces_b = Vector3::zeros(); // Σ ρ_k × F_k (body)
        for (k, rho) in self.offsets.iter().enumerate() {
            let f = vec3(&u[6 * k..6 * k + 3]);
            let t = vec3(&u[6 * k + 3..6 * k + 6]);
            let fb = rot.transpose() * f;
            force += f;
            torque_b += rot.transpose() * t;
            moment_of_forces_b += rho.cross(&fb);
        }
        let jc = Matrix3::from_diagonal(&self.j);
        match self.joint {
            GroundJoint::Free => {
                let wb = wb_state;
                let tau = moment_of_forces_b + torque_b;
                let wb_dot = (tau - wb.cross(&(jc * wb))).component_div(&self.j);
                Motion {
                    r: vec3(&x[0..3]),
                    rot,
                    v: vec3(&x[7..10]),
                    w: rot * wb,
                    a: force / self.m + self.g,
                    alpha: rot * wb_dot,
                    wb,
                    wb_dot,
                }
            }
            GroundJoint::Spherical {
                pivot,
                at,
                inertia,
                inverse,
            } => {
                let tau = self.torque_about(pivot, rot, force, moment_of_forces_b, torque_b);
                let wb = wb_state;
                let wb_dot = inverse * (tau - wb.cross(&(inertia * wb)));
                self.about_pivot(pivot, at, rot, wb, wb_dot)
            }
            GroundJoint::Revolute {
                pivot,
                at,
                axis,
                inertia,
            } => {
                let tau = self.torque_about(pivot, rot, force, moment_of_forces_b, torque_b);
                let wb = axis * axis.dot(&wb_state);
                let wb_dot = axis * (axis.dot(&tau) / inertia);
                self.about_pivot(pivot, at, rot, wb, wb_dot)
            }
        }
    }

    /// τ_O (body frame): marker forces, torques and gravity about the body point `pivot`.
    fn torque_about(
        &self,
        pivot: Vector3<f64>,
        rot: Matrix3<f64>,
        force: Vector3<f64>,
        moment_of_forces_b: Vector3<f64>,
        torque_b: Vector3<f64>,
    ) -> Vector3<f64> {
        // Σ (ρ_k − p) × F_k + Σ T_k + (−p) × m g, all in body coordinates.
        let fb = rot.transpose() * force;
        let gravity_b = rot.transpose() * (self.m * self.g);
        moment_of_forces_b - pivot.cross(&fb) + torque_b - pivot.cross(&gravity_b)
    }

    fn about_pivot(
        &self,
        pivot: Vector3<f64>,
        at: Vector3<f64>,
        rot: Matrix3<f64>,
        wb: Vector3<f64>,
        wb_dot: Vector3<f64>,
    ) -> Motion {
        let s = -(rot * pivot); // CoM relative to the fixed point (world)
        let w = rot * wb;
        let alpha = rot * wb_dot;
        Motion {
            r: at + s,
            rot,
            v: w.cross(&s),
            w,
            a: alpha.cross(&s) + w.cross(&w.cross(&s)),
            alpha,
            wb,
            wb_dot,
        }
    }

    fn energy(&self, motion: &Motion) -> f64 {
        let jw = motion.wb.component_mul(&self.j);
        0.5 * self.m * motion.v.norm_squared() + 0.5 * motion.wb.dot(&jw)
            - self.m * self.g.dot(&motion.r)
    }
}

impl Model for Body3d {
    const DECLARATION: Declaration = Declaration {
        model_name: "body3d",
        model_identifier: "body3d",
        description: "3D rigid body (6 DOF) with markers A and B, optionally jointed to ground (spherical or revolute)",
        real_parameters: &REAL_PARAMETERS,
        integer_parameters: &[Integer::new("joint", 0)
            .min(0)
            .max(2)
            .description("Joint to ground: 0 none (free body), 1 spherical (pivot fixed), 2 revolute (pivot fixed, rotation about axis)")],
        inputs: marker_inputs!("A", "B"),
        outputs: marker_outputs!("A", "B"),
        states: &[
            State::new("com[1]").unit("m", "m/s").description("CoM position (world)"),
            State::new("com[2]").unit("m", "m/s").description("CoM position (world)"),
            State::new("com[3]").unit("m", "m/s").description("CoM position (world)"),
            State::new("q[1]").description("Orientation quaternion, scalar part (body -> world)"),
            State::new("q[2]").description("Orientation quaternion, x"),
            State::new("q[3]").description("Orientation quaternion, y"),
            State::new("q[4]").description("Orientation quaternion, z"),
            State::new("vcom[1]").unit("m/s", "m/s2").description("CoM velocity (world)"),
            State::new("vcom[2]").unit("m/s", "m/s2").description("CoM velocity (world)"),
            State::new("vcom[3]").unit("m/s", "m/s2").description("CoM velocity (world)"),
            State::new("wb[1]").unit("rad/s", "rad/s2").description("Angular velocity (body frame)"),
            State::new("wb[2]").unit("rad/s", "rad/s2").description("Angular velocity (body frame)"),
            State::new("wb[3]").unit("rad/s", "rad/s2").description("Angular velocity (body frame)"),
        ],
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 1e-3,
        },
        model_exchange: true,
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        let m = p.real("m")?;
        if !(m.is_finite() && m > 0.0) {
            return Err(format!("m must be > 0, got {m}"));
        }
        let j = Vector3::new(p.real("Jxx")?, p.real("Jyy")?, p.real("Jzz")?);
        for (name, value) in ["Jxx", "Jyy", "Jzz"].iter().zip(j.iter()) {
            if !(value.is_finite() && *value > 0.0) {
                return Err(format!("{name} must be > 0, got {value}"));
            }
        }
        let g = Vector3::new(p.real("gx")?, p.real("gy")?, p.real("gz")?);
        let r0 = Self::read(p, "r0")?;
        let q0 = UnitQuaternion::from_scaled_axis(Self::read(p, "phi0")?);
        let v0 = Self::read(p, "v0")?;
        let w0 = Self::read(p, "w0")?;
        let offsets = [Self::read(p, "A.offset")?, Self::read(p, "B.offset")?];
        let pivot = Self::read(p, "pivot")?;
        let rot0 = q0.to_rotation_matrix().into_inner();
        let at = r0 + rot0 * pivot;
        let kind = p.integer("joint")?;
        if kind != 0 {
            // The CoM moves on a sphere about the fixed point: its velocity is set by w0.
            let expected = w0.cross(&(r0 - at));
            if (v0 - expected).norm() > 1e-9 * (1.0 + expected.norm()) {
                return Err(format!(
                    "v0 = [{}, {}, {}] is inconsistent with the ground joint: it must be w0 x (r0 - pivot) = [{}, {}, {}]",
                    v0[0], v0[1], v0[2], expected[0], expected[1], expected[2]
                ));
            }
        }
        // Inertia about the pivot: J_O = J_C + m (|p|² I − p pᵀ) (body frame).
        let inertia = Matrix3::from_diagonal(&j)
            + m * (Matrix3::identity() * pivot.norm_squared() - pivot * pivot.transpose());
        let joint = match kind {
            0 => GroundJoint::Free,
            1 => GroundJoint::Spherical {
                pivot,
                at,
                inertia,
                inverse: inertia
                    .try_inverse()
                    .ok_or("the inertia about the pivot is singular")?,
            },
            2 => {
                let axis = Self::read(p, "axis")?;
                if !axis.norm().is_finite() || axis.norm() <= 1e-12 {
                    return Err(format!(
                        "axis must be a nonzero vector for the revolute ground joint, got [{}, {}, {}]",
                        axis[0], axis[1], axis[2]
                    ));
                }
                let axis = axis.normalize();
                let world_axis = rot0 * axis;
                let off_axis = w0 - world_axis * world_axis.dot(&w0);
                if off_axis.norm() > 1e-9 * (1.0 + w0.norm()) {
                    return Err(format!(
                        "w0 = [{}, {}, {}] is not parallel to the revolute axis, which starts at [{}, {}, {}] in the world",
                        w0[0], w0[1], w0[2], world_axis[0], world_axis[1], world_axis[2]
                    ));
                }
                GroundJoint::Revolute {
                    pivot,
                    at,
                    axis,
                    inertia: axis.dot(&(inertia * axis)),
                }
            }
            other => return Err(format!("joint must be 0, 1 or 2, got {other}")),
        };
        Ok(Body3d {
            m,
            j,
            g,
            r0,
            q0,
            v0,
            w0,
            joint,
            offsets,
            max_step: p.real("max_step")?,
        })
    }

    fn max_step(&self) -> Option<f64> {
        (self.max_step > 0.0).then_some(self.max_step)
    }

    fn initial_states(&self, x: &mut [f64]) {
        let wb = self.q0.inverse() * self.w0;
        let wb = match self.joint {
            GroundJoint::Revolute { axis, .. } => axis * axis.dot(&wb),
            _ => wb,
        };
        let q = self.q0.quaternion();
        x[0..3].copy_from_slice(self.r0.as_slice());
        x[3..7].copy_from_slice(&[q.w, q.i, q.j, q.k]);
        x[7..10].copy_from_slice(self.v0.as_slice());
        x[10..13].copy_from_slice(wb.as_slice());
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let motion = self.motion(x, u);
        let q = Quaternion::new(x[3], x[4], x[5], x[6]);
        // q̇ = ½ q ⊗ (0, ω_body), plus the pull of |q| towards 1.
        let omega = Quaternion::new(0.0, motion.wb[0], motion.wb[1], motion.wb[2]);
        let q_dot = q * omega * 0.5 - q * (NORM_GAIN * (q.norm_squared() - 1.0));
        dx[0..3].copy_from_slice(motion.v.as_slice());
        dx[3..7].copy_from_slice(&[q_dot.w, q_dot.i, q_dot.j, q_dot.k]);
        dx[7..10].copy_from_slice(motion.a.as_slice());
        dx[10..13].copy_from_slice(motion.wb_dot.as_slice());
    }

    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        let motion = self.motion(x, u);
        for (k, rho) in self.offsets.iter().enumerate() {
            let s = motion.rot * rho;
            let r = motion.r + s;
            let v = motion.v + motion.w.cross(&s);
            let a = motion.a + motion.alpha.cross(&s) + motion.w.cross(&motion.w.cross(&s));
            let out = &mut y[k * OUTPUTS_PER_MARKER..(k + 1) * OUTPUTS_PER_MARKER];
            out[0..3].copy_from_slice(r.as_slice());
            for i in 0..3 {
                for j in 0..3 {
                    out[3 + 3 * i + j] = motion.rot[(i, j)];
                }
            }
            out[12..15].copy_from_slice(v.as_slice());
            out[15..18].copy_from_slice(motion.w.as_slice());
            out[18..21].copy_from_slice(a.as_slice());
            out[21..24].copy_from_slice(motion.alpha.as_slice());
        }
        y[2 * OUTPUTS_PER_MARKER] = self.energy(&motion);
    }
}

export_fmu!(Body3d);
