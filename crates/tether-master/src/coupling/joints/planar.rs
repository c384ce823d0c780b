//! Planar joint: z_i stays parallel to the plane normal z_j (`x_i·z_j = 0`,
//! `y_i·z_j = 0`) and C_i stays in the plane through C_j (`d·z_j = 0`).

use super::{Condition, Direction, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    vec![
        Condition::Perpendicular { a: f.x_i, b: f.z_j },
        Condition::Perpendicular { a: f.y_i, b: f.z_j },
        Condition::Point(Direction::OnJ(f.z_j)),
    ]
}
