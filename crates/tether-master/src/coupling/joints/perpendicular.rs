//! Perpendicular joint, paper eq. 47: the axes z_i and z_j stay
//! perpendicular, `z_i·z_j = 0`.

use super::{Condition, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    vec![Condition::Perpendicular { a: f.z_i, b: f.z_j }]
}
