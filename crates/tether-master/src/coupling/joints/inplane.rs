//! Inplane joint, paper eq. 38: C_i stays in the plane through C_j with
//! normal z_j, `(C_i − C_j)·z_j = 0`.

use super::{Condition, Direction, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    vec![Condition::Point(Direction::OnJ(f.z_j))]
}
