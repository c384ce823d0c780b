//! Inline joint: C_i stays on the line through C_j along z_j, two inplane
//! conditions `d·x_j = 0`, `d·y_j = 0`.

use super::{Condition, Direction, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    vec![
        Condition::Point(Direction::OnJ(f.x_j)),
        Condition::Point(Direction::OnJ(f.y_j)),
    ]
}
