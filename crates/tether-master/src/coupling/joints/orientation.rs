//! Orientation joint: the relative rotation is locked by three perpendicular
//! conditions `x_i·z_j`, `y_i·z_j`, `x_i·y_j` = 0; the points move freely.

use super::{Condition, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    vec![
        Condition::Perpendicular { a: f.x_i, b: f.z_j },
        Condition::Perpendicular { a: f.y_i, b: f.z_j },
        Condition::Perpendicular { a: f.x_i, b: f.y_j },
    ]
}
