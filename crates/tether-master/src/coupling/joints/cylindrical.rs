//! Cylindrical joint along and about z_j: z_i stays parallel to z_j
//! (`x_i·z_j = 0`, `y_i·z_j = 0`) and C_i stays on the line through C_j along
//! z_j (`d·x_j = 0`, `d·y_j = 0`).

use super::{Condition, Direction, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    vec![
        Condition::Perpendicular { a: f.x_i, b: f.z_j },
        Condition::Perpendicular { a: f.y_i, b: f.z_j },
        Condition::Point(Direction::OnJ(f.x_j)),
        Condition::Point(Direction::OnJ(f.y_j)),
    ]
}
