//! Revolute joint about the common z axis: atpoint plus `x_i·z_j = 0` and
//! `y_i·z_j = 0` (z_i stays parallel to z_j).

use super::{atpoint, Condition, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    let mut c = atpoint::conditions(f);
    c.push(Condition::Perpendicular { a: f.x_i, b: f.z_j });
    c.push(Condition::Perpendicular { a: f.y_i, b: f.z_j });
    c
}
