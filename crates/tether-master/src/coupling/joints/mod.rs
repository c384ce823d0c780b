//! The joint library: every joint is a list of scalar conditions of two
//! fundamental types (paper Sect. 3.1–3.2, `docs/joints.md`), evaluated from
//! the marker ports of the two sides (`docs/marker-ports.md`).
//!
//! - a *point* condition `d·e = 0`, with `d = C_i − C_j` the distance of the
//!   attachment points and `e` a world axis (atpoint) or a vector fixed on
//!   side j (inplane);
//! - a *perpendicular* condition `a·b = 0`, with `a` fixed on side i and `b`
//!   on side j.
//!
//! Each joint kind lives in its own file and only lists its conditions in
//! terms of the two joint frames; everything else (levels, force laws, planar
//! reduction) is here.

mod atpoint;
mod cylindrical;
mod inline;
mod inplane;
mod orientation;
mod perpendicular;
mod planar;
mod revolute;
mod translational;
mod universal;

use nalgebra::{Matrix3, Vector3};

use crate::coupling::rows::{RowLevel, View};

/// The joint kinds a system file may name.
pub(crate) const KINDS: [&str; 10] = [
    "atpoint",
    "inplane",
    "perpendicular",
    "universal",
    "revolute",
    "cylindrical",
    "translational",
    "planar",
    "inline",
    "orientation",
];

/// The two joint frames, as unit vectors in marker coordinates of their side.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frames {
    pub x_i: Vector3<f64>,
    pub y_i: Vector3<f64>,
    pub z_i: Vector3<f64>,
    pub x_j: Vector3<f64>,
    pub y_j: Vector3<f64>,
    pub z_j: Vector3<f64>,
}

impl Frames {
    /// Orthonormal frames from the z axis and a reference x axis of each side;
    /// an error naming the side if an axis is zero or the reference is
    /// parallel to it.
    pub fn new(
        axis_i: Vector3<f64>,
        ref_i: Vector3<f64>,
        axis_j: Vector3<f64>,
        ref_j: Vector3<f64>,
    ) -> Result<Frames, &'static str> {
        let side = |axis: Vector3<f64>, reference: Vector3<f64>, which| {
            let z = axis.try_normalize(1e-12).ok_or(if which {
                "axis_i is zero"
            } else {
                "axis_j is zero"
            })?;
            let x = (reference - z * reference.dot(&z))
                .try_normalize(1e-9)
                .ok_or(if which {
                    "ref_i is zero or parallel to axis_i"
                } else {
                    "ref_j is zero or parallel to axis_j"
                })?;
            Ok((x, z.cross(&x), z))
        };
        let (x_i, y_i, z_i) = side(axis_i, ref_i, true)?;
        let (x_j, y_j, z_j) = side(axis_j, ref_j, false)?;
        Ok(Frames {
            x_i,
            y_i,
            z_i,
            x_j,
            y_j,
            z_j,
        })
    }
}

/// Direction of a point condition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Direction {
    /// A fixed world axis (atpoint).
    World(Vector3<f64>),
    /// A vector fixed on side j, in marker-j coordinates (inplane).
    OnJ(Vector3<f64>),
}

/// One scalar condition of a joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Condition {
    /// `(C_i − C_j)·e = 0`.
    Point(Direction),
    /// `a·b = 0`, `a` in marker-i and `b` in marker-j coordinates.
    Perpendicular { a: Vector3<f64>, b: Vector3<f64> },
}

/// The conditions of a joint kind (before any planar reduction).
pub(crate) fn conditions(kind: &str, f: &Frames) -> Option<Vec<Condition>> {
    Some(match kind {
        "atpoint" => atpoint::conditions(f),
        "inplane" => inplane::conditions(f),
        "perpendicular" => perpendicular::conditions(f),
        "universal" => universal::conditions(f),
        "revolute" => revolute::conditions(f),
        "cylindrical" => cylindrical::conditions(f),
        "translational" => translational::conditions(f),
        "planar" => planar::conditions(f),
        "inline" => inline::conditions(f),
        "orientation" => orientation::conditions(f),
        _ => return None,
    })
}

impl Condition {
    /// Whether the condition's force or torque has a component in the world
    /// xy-plane motion (force x/y, torque z), for planar joints. Marker z axes
    /// of planar models are the world z axis.
    pub fn acts_in_plane(&self) -> bool {
        let in_plane = |v: &Vector3<f64>| v.x.hypot(v.y) > 1e-12;
        match self {
            Condition::Point(Direction::World(e)) | Condition::Point(Direction::OnJ(e)) => {
                in_plane(e)
            }
            Condition::Perpendicular { a, b } => in_plane(a) && in_plane(b),
        }
    }
}

/// Number of slots a marker occupies: r, R (row-major), v, w, a, alpha.
pub(crate) const MARKER_OUTPUTS: usize = 24;

/// The marker output names in slot order.
pub(crate) fn marker_output_names(marker: &str) -> Vec<String> {
    let mut names = Vec::with_capacity(MARKER_OUTPUTS);
    for k in 1..=3 {
        names.push(format!("{marker}.r[{k}]"));
    }
    for row in 1..=3 {
        for col in 1..=3 {
            names.push(format!("{marker}.R[{row},{col}]"));
        }
    }
    for quantity in ["v", "w", "a", "alpha"] {
        for k in 1..=3 {
            names.push(format!("{marker}.{quantity}[{k}]"));
        }
    }
    names
}

/// One side of a joint, resolved: the instance, the marker's output slots and
/// the attachment offset.
#[derive(Debug, Clone)]
pub(crate) struct Side {
    pub slave: usize,
    pub marker: String,
    pub slots: [usize; MARKER_OUTPUTS],
    pub offset: Vector3<f64>,
}

/// Kinematics of an attachment point and its body, in world coordinates.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Kinematics {
    /// Marker origin.
    pub r: Vector3<f64>,
    /// Marker → world.
    pub rot: Matrix3<f64>,
    pub w: Vector3<f64>,
    pub alpha: Vector3<f64>,
    /// Attachment point C, its velocity and acceleration.
    pub c: Vector3<f64>,
    pub c_dot: Vector3<f64>,
    pub c_ddot: Vector3<f64>,
    /// C − r (world).
    pub rho: Vector3<f64>,
}

impl Side {
    pub fn kinematics(&self, view: &View) -> Kinematics {
        let s = |k: usize| view.value(self.slave, self.slots[k]);
        let vec = |k: usize| Vector3::new(s(k), s(k + 1), s(k + 2));
        let r = vec(0);
        let rot = Matrix3::new(s(3), s(4), s(5), s(6), s(7), s(8), s(9), s(10), s(11));
        let (v, w, a, alpha) = (vec(12), vec(15), vec(18), vec(21));
        let rho = rot * self.offset;
        let w_rho = w.cross(&rho);
        Kinematics {
            r,
            rot,
            w,
            alpha,
            c: r + rho,
            c_dot: v + w_rho,
            c_ddot: a + alpha.cross(&rho) + w.cross(&w_rho),
            rho,
        }
    }
}

/// A body-fixed vector `ê` seen in the world: e, ė, ë.
fn body_vector(k: &Kinematics, local: &Vector3<f64>) -> [Vector3<f64>; 3] {
    let e = k.rot * local;
    let e_dot = k.w.cross(&e);
    let e_ddot = k.alpha.cross(&e) + k.w.cross(&e_dot);
    [e, e_dot, e_ddot]
}

/// Generalised force of a unit multiplier: force and torque (about the marker
/// origin) on side i, then on side j, as 12 numbers `[F_i, T_i, F_j, T_j]`.
pub(crate) type Law = [f64; 12];

impl Condition {
    /// g, ġ or g̈ of the condition (or the stabilised combination).
    pub fn value(&self, level: RowLevel, i: &Kinematics, j: &Kinematics) -> f64 {
        let levels = |g: f64, g_dot: f64, g_ddot: f64| level.combine(g, g_dot, g_ddot);
        match self {
            Condition::Point(direction) => {
                let d = i.c - j.c;
                let d_dot = i.c_dot - j.c_dot;
                let d_ddot = i.c_ddot - j.c_ddot;
                match direction {
                    Direction::World(e) => levels(d.dot(e), d_dot.dot(e), d_ddot.dot(e)),
                    Direction::OnJ(local) => {
                        let [e, e1, e2] = body_vector(j, local);
                        levels(
                            d.dot(&e),
                            d_dot.dot(&e) + d.dot(&e1),
                            d_ddot.dot(&e) + 2.0 * d_dot.dot(&e1) + d.dot(&e2),
                        )
                    }
                }
            }
            Condition::Perpendicular { a, b } => {
                let [a, a1, a2] = body_vector(i, a);
                let [b, b1, b2] = body_vector(j, b);
                levels(
                    a.dot(&b),
                    a1.dot(&b) + a.dot(&b1),
                    a2.dot(&b) + 2.0 * a1.dot(&b1) + a.dot(&b2),
                )
            }
        }
    }

    /// Force law per unit multiplier (`docs/joints.md`, "How the force
    /// reaches the FMUs"): a point condition pushes i with `e` at C_i and j
    /// with `−e` (at C_j for a world axis, at C_i for a vector fixed on j); a
    /// perpendicular condition turns i with `a × b` and j with `−a × b`.
    pub fn law(&self, i: &Kinematics, j: &Kinematics) -> Law {
        let (f_i, t_i, f_j, t_j) = match self {
            Condition::Point(direction) => {
                let (e, arm_j) = match direction {
                    Direction::World(e) => (*e, j.rho),
                    Direction::OnJ(local) => (j.rot * local, i.c - j.r),
                };
                (e, i.rho.cross(&e), -e, arm_j.cross(&-e))
            }
            Condition::Perpendicular { a, b } => {
                let t = (i.rot * a).cross(&(j.rot * b));
                (Vector3::zeros(), t, Vector3::zeros(), -t)
            }
        };
        let mut law = [0.0; 12];
        for (chunk, v) in law.chunks_mut(3).zip([f_i, t_i, f_j, t_j]) {
            chunk.copy_from_slice(v.as_slice());
        }
        law
    }

    /// Which of the 12 law components can be non-zero, given the offsets.
    pub fn active_components(&self, offset_i: &Vector3<f64>, offset_j: &Vector3<f64>) -> [bool; 4] {
        let nonzero = |o: &Vector3<f64>| o.norm() > 0.0;
        match self {
            // [F_i, T_i, F_j, T_j]
            Condition::Point(Direction::World(_)) => {
                [true, nonzero(offset_i), true, nonzero(offset_j)]
            }
            Condition::Point(Direction::OnJ(_)) => [true, nonzero(offset_i), true, true],
            Condition::Perpendicular { .. } => [false, true, false, true],
        }
    }
}

/// A joint resolved against the instances.
#[derive(Debug, Clone)]
pub(crate) struct Joint {
    pub sides: [Side; 2],
    pub conditions: Vec<Condition>,
    /// Index of the first multiplier among the unknowns (one per condition).
    pub first_unknown: usize,
    /// Force-port rows its conditions load: (condition, law component, row),
    /// sorted by condition.
    pub targets: Vec<(usize, usize, usize)>,
}

impl Joint {
    pub fn kinematics(&self, view: &View) -> (Kinematics, Kinematics) {
        (
            self.sides[0].kinematics(view),
            self.sides[1].kinematics(view),
        )
    }
}

#[cfg(test)]
mod tests;
