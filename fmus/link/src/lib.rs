//! A planar rigid link (a bar) in the world xy-plane, gravity g in −y, with two marker
//! ports `A` and `B` (docs/marker-ports.md). Either free (3 DOF) or pinned to ground
//! by a revolute joint at a body point P, with an optional torsional spring-damper
//! (1 DOF). See docs/fmus.md for the parameters and conventions.
//!
//! Body frame: origin at the centre of mass, x along the link axis (from end A to
//! end B), y across it. Body points are given in units of the length `l`, so the
//! defaults (−½, 0) and (½, 0) are the two ends whatever `l` is. φ is the angle of the
//! link axis from world x; the rotation body → world is R(φ) about world z.

use tether_fmu_kit::marker::{concat, MarkerKinematics, OUTPUTS_PER_MARKER};
use tether_fmu_kit::{
    export_fmu, marker_inputs, marker_outputs, Boolean, Declaration, DefaultExperiment, Model,
    Output, Parameters, Real, State,
};

/// States: centre of mass position, angle, centre of mass velocity, angular velocity.
const STATES: [&str; 6] = [
    "x_cm",
    "y_cm",
    "angle",
    "vx_cm",
    "vy_cm",
    "angular_velocity",
];
const POSITION_STATES: &[&str] = &["x_cm", "y_cm", "angle"];
const VELOCITY_STATES: &[&str] = &STATES;
/// Accelerations read every state and every force input (direct feedthrough).
const ACCELERATION_DEPENDENCIES: &[&str] = &[
    "x_cm",
    "y_cm",
    "angle",
    "vx_cm",
    "vy_cm",
    "angular_velocity",
    "A.F[1]",
    "A.F[2]",
    "A.T[3]",
    "B.F[1]",
    "B.F[2]",
    "B.T[3]",
];

const INPUTS: [Real; 6] = concat(&[&marker_inputs!("A", planar), &marker_inputs!("B", planar)]);

const OUTPUTS: [Output; 2 * OUTPUTS_PER_MARKER + 3] = concat(&[
    &marker_outputs!("A", position: POSITION_STATES, velocity: VELOCITY_STATES,
                     acceleration: ACCELERATION_DEPENDENCIES),
    &marker_outputs!("B", position: POSITION_STATES, velocity: VELOCITY_STATES,
                     acceleration: ACCELERATION_DEPENDENCIES),
    &[
        Output::new("phi")
            .unit("rad")
            .description("Angle of the link axis from world x")
            .depends_on(&["angle"]),
        Output::new("omega")
            .unit("rad/s")
            .description("Angular velocity")
            .depends_on(&["angular_velocity"]),
        Output::new("E")
            .unit("J")
            .description("Kinetic + gravity (zero at y = 0) + spring energy")
            .depends_on(&STATES),
    ],
]);

/// A 2-vector of the world xy-plane.
type V2 = [f64; 2];

fn rotate(phi: f64, p: V2) -> V2 {
    let (s, c) = phi.sin_cos();
    [c * p[0] - s * p[1], s * p[0] + c * p[1]]
}

/// z component of a × b.
fn cross(a: V2, b: V2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// ω k × p.
fn spin(omega: f64, p: V2) -> V2 {
    [-omega * p[1], omega * p[0]]
}

/// Forces and torques of the two ports, world components.
struct Loads {
    force: [V2; 2],
    torque: [f64; 2],
}

impl Loads {
    fn from_inputs(u: &[f64]) -> Self {
        Loads {
            force: [[u[0], u[1]], [u[3], u[4]]],
            torque: [u[2], u[5]],
        }
    }
}

/// Motion of the centre of mass and rotation at one instant.
struct Motion {
    phi: f64,
    omega: f64,
    alpha: f64,
    r_cm: V2,
    v_cm: V2,
    a_cm: V2,
}

pub struct Link {
    m: f64,
    j: f64,
    g: f64,
    pinned: bool,
    c_phi: f64,
    d_phi: f64,
    phi_ref: f64,
    /// Body points (metres, body frame, from the centre of mass): A, B, P.
    marker: [V2; 2],
    point_p: V2,
    /// World position of P at t = 0 (the fixed pivot when pinned).
    p0: V2,
    phi0: f64,
    omega0: f64,
    vp0: V2,
}

impl Link {
    /// Centre of mass relative to the pivot, in world coordinates: −R(φ)·s_P.
    fn cm_from_pivot(&self, phi: f64) -> V2 {
        let rp = rotate(phi, self.point_p);
        [-rp[0], -rp[1]]
    }

    /// Angular acceleration and the resultant force on the body (gravity included).
    fn motion(&self, x: &[f64], loads: &Loads) -> Motion {
        let (phi, omega) = (x[2], x[5]);
        let arms = [rotate(phi, self.marker[0]), rotate(phi, self.marker[1])];
        let gravity = [0.0, -self.m * self.g];
        let port_torque: f64 = (0..2)
            .map(|k| loads.torque[k] + cross(arms[k], loads.force[k]))
            .sum();
        let force = [
            loads.force[0][0] + loads.force[1][0] + gravity[0],
            loads.force[0][1] + loads.force[1][1] + gravity[1],
        ];
        if self.pinned {
            // J_P φ̈ = Σ moments about P (ports, gravity at the CoM, spring-damper).
            let d = self.cm_from_pivot(phi);
            let j_p = self.j + self.m * (d[0] * d[0] + d[1] * d[1]);
            let moment = port_torque + cross(d, force)
                - self.c_phi * (phi - self.phi_ref)
                - self.d_phi * omega;
            let alpha = moment / j_p;
            let v = spin(omega, d);
            let at = spin(alpha, d);
            Motion {
                phi,
                omega,
                alpha,
                r_cm: [self.p0[0] + d[0], self.p0[1] + d[1]],
                v_cm: v,
                a_cm: [at[0] - omega * omega * d[0], at[1] - omega * omega * d[1]],
            }
        } else {
            Motion {
                phi,
                omega,
                alpha: port_torque / self.j,
                r_cm: [x[0], x[1]],
                v_cm: [x[3], x[4]],
                a_cm: [force[0] / self.m, force[1] / self.m],
            }
        }
    }

    fn marker_kinematics(&self, motion: &Motion, point: V2) -> MarkerKinematics {
        let Motion {
            phi,
            omega,
            alpha,
            r_cm,
            v_cm,
            a_cm,
        } = *motion;
        let rho = rotate(phi, point);
        let w_rho = spin(omega, rho);
        let al_rho = spin(alpha, rho);
        let (s, c) = phi.sin_cos();
        MarkerKinematics {
            r: [r_cm[0] + rho[0], r_cm[1] + rho[1], 0.0],
            rotation: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
            v: [v_cm[0] + w_rho[0], v_cm[1] + w_rho[1], 0.0],
            w: [0.0, 0.0, omega],
            a: [
                a_cm[0] + al_rho[0] - omega * omega * rho[0],
                a_cm[1] + al_rho[1] - omega * omega * rho[1],
                0.0,
            ],
            alpha: [0.0, 0.0, alpha],
        }
    }

    fn energy(&self, motion: &Motion) -> f64 {
        let v2 = motion.v_cm[0] * motion.v_cm[0] + motion.v_cm[1] * motion.v_cm[1];
        let spring = if self.pinned {
            0.5 * self.c_phi * (motion.phi - self.phi_ref).powi(2)
        } else {
            0.0
        };
        0.5 * self.m * v2
            + 0.5 * self.j * motion.omega * motion.omega
            + self.m * self.g * motion.r_cm[1]
            + spring
    }
}

fn positive(p: &Parameters, name: &str) -> Result<f64, String> {
    let value = p.real(name)?;
    if value.is_nan() || value <= 0.0 {
        return Err(format!("{name} must be > 0, got {value}"));
    }
    Ok(value)
}

impl Model for Link {
    const DECLARATION: Declaration = Declaration {
        model_name: "link",
        model_identifier: "link",
        description: "Planar rigid link in the world xy-plane (gravity in -y), free or pinned to \
                      ground with a torsional spring-damper, with marker ports A and B",
        real_parameters: &[
            Real::new("m", 1.0).unit("kg").description("Mass (> 0)"),
            Real::new("J", 1.0 / 12.0)
                .unit("kg.m2")
                .description("Moment of inertia about the centre of mass (> 0)"),
            Real::new("l", 1.0)
                .unit("m")
                .description("Length (> 0); body points are given in units of l"),
            Real::new("g", 9.81)
                .unit("m/s2")
                .description("Gravity, acting in -y"),
            Real::new("xA", -0.5)
                .description("Marker A along the axis from the centre of mass, in units of l"),
            Real::new("yA", 0.0)
                .description("Marker A across the axis from the centre of mass, in units of l"),
            Real::new("xB", 0.5)
                .description("Marker B along the axis from the centre of mass, in units of l"),
            Real::new("yB", 0.0)
                .description("Marker B across the axis from the centre of mass, in units of l"),
            Real::new("xP", -0.5).description(
                "Point P (pivot, or where x0, y0 place a free link) along the axis, in units of l",
            ),
            Real::new("yP", 0.0).description("Point P across the axis, in units of l"),
            Real::new("x0", 0.0)
                .unit("m")
                .description("World x of P at t = 0 (the fixed pivot if pinned)"),
            Real::new("y0", 0.0)
                .unit("m")
                .description("World y of P at t = 0 (the fixed pivot if pinned)"),
            Real::new("phi0", 0.0)
                .unit("rad")
                .description("Initial angle of the link axis from world x"),
            Real::new("omega0", 0.0)
                .unit("rad/s")
                .description("Initial angular velocity"),
            Real::new("vx0", 0.0)
                .unit("m/s")
                .description("Initial world x velocity of P (free link only)"),
            Real::new("vy0", 0.0)
                .unit("m/s")
                .description("Initial world y velocity of P (free link only)"),
            Real::new("c_phi", 0.0)
                .min(0.0)
                .unit("N.m/rad")
                .description("Torsional spring at the pivot (pinned only)"),
            Real::new("d_phi", 0.0)
                .min(0.0)
                .unit("N.m.s/rad")
                .description("Torsional damper at the pivot (pinned only)"),
            Real::new("phi_ref", 0.0)
                .unit("rad")
                .description("Angle at which the torsional spring is stress-free"),
        ],
        boolean_parameters: &[Boolean::new("pinned", false)
            .description("Pinned to ground by a revolute joint at P (else a free body)")],
        inputs: &INPUTS,
        outputs: &OUTPUTS,
        states: &[
            State::new("x_cm")
                .unit("m", "m/s")
                .description("Centre of mass, world x"),
            State::new("y_cm")
                .unit("m", "m/s")
                .description("Centre of mass, world y"),
            State::new("angle")
                .unit("rad", "rad/s")
                .description("Angle of the link axis from world x"),
            State::new("vx_cm")
                .unit("m/s", "m/s2")
                .description("Centre of mass velocity, world x"),
            State::new("vy_cm")
                .unit("m/s", "m/s2")
                .description("Centre of mass velocity, world y"),
            State::new("angular_velocity")
                .unit("rad/s", "rad/s2")
                .description("Angular velocity"),
        ],
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 2.0,
            step_size: 1e-3,
        },
        model_exchange: true,
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        let m = positive(p, "m")?;
        let j = positive(p, "J")?;
        let l = positive(p, "l")?;
        let mut values = Vec::new();
        for name in [
            "g", "xA", "yA", "xB", "yB", "xP", "yP", "x0", "y0", "phi0", "omega0", "vx0", "vy0",
            "c_phi", "d_phi", "phi_ref",
        ] {
            let value = p.real(name)?;
            if !value.is_finite() {
                return Err(format!("{name} must be finite, got {value}"));
            }
            values.push(value);
        }
        let [g, xa, ya, xb, yb, xp, yp, x0, y0, phi0, omega0, vx0, vy0, c_phi, d_phi, phi_ref] =
            values[..]
        else {
            unreachable!("sixteen names, sixteen values")
        };
        let pinned = p.boolean("pinned")?;
        if pinned && (vx0 != 0.0 || vy0 != 0.0) {
            return Err(format!(
                "vx0, vy0 must be 0 for a pinned link (P is the fixed pivot), got {vx0}, {vy0}"
            ));
        }
        if !pinned && (c_phi != 0.0 || d_phi != 0.0) {
            return Err(format!(
                "c_phi, d_phi act at the pivot and need pinned = true, got {c_phi}, {d_phi}"
            ));
        }
        Ok(Link {
            m,
            j,
            g,
            pinned,
            c_phi,
            d_phi,
            phi_ref,
            marker: [[xa * l, ya * l], [xb * l, yb * l]],
            point_p: [xp * l, yp * l],
            p0: [x0, y0],
            phi0,
            omega0,
            vp0: [vx0, vy0],
        })
    }

    fn initial_states(&self, x: &mut [f64]) {
        let d = self.cm_from_pivot(self.phi0);
        let w_d = spin(self.omega0, d);
        x.copy_from_slice(&[
            self.p0[0] + d[0],
            self.p0[1] + d[1],
            self.phi0,
            self.vp0[0] + w_d[0],
            self.vp0[1] + w_d[1],
            self.omega0,
        ]);
    }

    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let motion = self.motion(x, &Loads::from_inputs(u));
        // Pinned: the CoM states follow the pivot kinematics (they are not read back).
        dx.copy_from_slice(&[
            motion.v_cm[0],
            motion.v_cm[1],
            motion.omega,
            motion.a_cm[0],
            motion.a_cm[1],
            motion.alpha,
        ]);
    }

    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        let motion = self.motion(x, &Loads::from_inputs(u));
        let n = OUTPUTS_PER_MARKER;
        for (k, point) in self.marker.iter().enumerate() {
            self.marker_kinematics(&motion, *point)
                .write_outputs(&mut y[k * n..(k + 1) * n]);
        }
        y[2 * n..].copy_from_slice(&[motion.phi, motion.omega, self.energy(&motion)]);
    }
}

export_fmu!(Link);
