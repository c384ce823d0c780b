//! Universal (Cardan) joint: atpoint plus `x_i·y_j = 0` — the fork axes x_i
//! and y_j stay perpendicular, so the bodies turn freely about those two axes
//! and not about the shafts' common z axis relative to each other.

use super::{atpoint, Condition, Frames};

pub(super) fn conditions(f: &Frames) -> Vec<Condition> {
    let mut c = atpoint::conditions(f);
    c.push(Condition::Perpendicular { a: f.x_i, b: f.y_j });
    c
}
