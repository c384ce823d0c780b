//! Atpoint (spherical) joint, paper eq. 29: the attachment points coincide,
//! `C_i − C_j = 0`, one condition per world axis (x, y, z).

use nalgebra::Vector3;

use super::{Condition, Direction, Frames};

pub(super) fn conditions(_: &Frames) -> Vec<Condition> {
    [Vector3::x(), Vector3::y(), Vector3::z()]
        .into_iter()
        .map(|e| Condition::Point(Direction::World(e)))
        .collect()
}
