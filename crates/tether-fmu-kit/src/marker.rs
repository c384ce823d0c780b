//! Marker ports (`docs/marker-ports.md`) without the repetition: the 24 outputs and
//! the force/torque inputs of a marker declared by name, and the kinematics written
//! into the output slice in the same order.
//!
//! ```
//! use tether_fmu_kit::{marker, marker_inputs, marker_outputs, Output, Real};
//!
//! const OUTPUTS: [Output; 25] = marker::concat(&[
//!     &marker_outputs!("tip", position: &["x"], velocity: &["x", "v"],
//!                      acceleration: &["x", "v", "tip.F[1]"]),
//!     &[Output::new("energy")],
//! ]);
//! const INPUTS: [Real; 3] = marker_inputs!("tip", planar);
//! assert_eq!(OUTPUTS[0].name, "tip.r[1]");
//! assert_eq!(OUTPUTS[23].name, "tip.alpha[3]");
//! assert_eq!(INPUTS[2].name, "tip.T[3]");
//! ```

/// Number of outputs of one marker: r (3), R (9), v, w, a, alpha (3 each).
pub const OUTPUTS_PER_MARKER: usize = 24;

/// The kinematics of a marker in world coordinates, as its 24 outputs report them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MarkerKinematics {
    /// Position of the marker origin.
    pub r: [f64; 3],
    /// Rotation marker → world, `rotation[i][j]` = `R[i+1,j+1]` (row i, column j).
    pub rotation: [[f64; 3]; 3],
    /// Velocity of the marker origin.
    pub v: [f64; 3],
    /// Angular velocity of the body.
    pub w: [f64; 3],
    /// Acceleration of the marker origin.
    pub a: [f64; 3],
    /// Angular acceleration of the body.
    pub alpha: [f64; 3],
}

impl MarkerKinematics {
    /// Writes the 24 outputs into `y[..24]` in the order of [`marker_outputs!`]:
    /// `r[1..3]`, `R[1,1], R[1,2], …, R[3,3]` (row by row), `v`, `w`, `a`, `alpha`.
    pub fn write_outputs(&self, y: &mut [f64]) {
        y[0..3].copy_from_slice(&self.r);
        for (i, row) in self.rotation.iter().enumerate() {
            y[3 + 3 * i..6 + 3 * i].copy_from_slice(row);
        }
        y[12..15].copy_from_slice(&self.v);
        y[15..18].copy_from_slice(&self.w);
        y[18..21].copy_from_slice(&self.a);
        y[21..24].copy_from_slice(&self.alpha);
    }
}

/// Concatenates slices into one array at compile time, e.g. the outputs of two
/// markers and a few more into one `const OUTPUTS: [Output; N]`. A length that does
/// not add up to `N`, or `N = 0`, is a compile-time error in a `const`.
pub const fn concat<T: Copy, const N: usize>(parts: &[&[T]]) -> [T; N] {
    let mut first = 0;
    while first < parts.len() && parts[first].is_empty() {
        first += 1;
    }
    assert!(first < parts.len(), "concat: nothing to concatenate");
    let mut out = [parts[first][0]; N];
    let mut n = 0;
    let mut p = 0;
    while p < parts.len() {
        let mut i = 0;
        while i < parts[p].len() {
            assert!(n < N, "concat: more items than the array length");
            out[n] = parts[p][i];
            n += 1;
            i += 1;
        }
        p += 1;
    }
    assert!(n == N, "concat: fewer items than the array length");
    out
}

/// The 24 outputs of marker `$m` (a string literal) as `[Output; 24]`, in the order
/// [`marker::MarkerKinematics::write_outputs`](crate::marker::MarkerKinematics::write_outputs)
/// fills them. The three dependency lists (names of states and inputs) go to the
/// position-level outputs (`r`, `R`), the velocity-level ones (`v`, `w`) and the
/// acceleration-level ones (`a`, `alpha`; name the force inputs there for direct
/// feedthrough).
#[macro_export]
macro_rules! marker_outputs {
    ($m:literal, position: $p:expr, velocity: $v:expr, acceleration: $a:expr $(,)?) => {
        [
            $crate::marker_outputs!(@one $m, "r", "1", "m", "Position of marker ", $p),
            $crate::marker_outputs!(@one $m, "r", "2", "m", "Position of marker ", $p),
            $crate::marker_outputs!(@one $m, "r", "3", "m", "Position of marker ", $p),
            $crate::marker_outputs!(@rot $m, "1,1", $p),
            $crate::marker_outputs!(@rot $m, "1,2", $p),
            $crate::marker_outputs!(@rot $m, "1,3", $p),
            $crate::marker_outputs!(@rot $m, "2,1", $p),
            $crate::marker_outputs!(@rot $m, "2,2", $p),
            $crate::marker_outputs!(@rot $m, "2,3", $p),
            $crate::marker_outputs!(@rot $m, "3,1", $p),
            $crate::marker_outputs!(@rot $m, "3,2", $p),
            $crate::marker_outputs!(@rot $m, "3,3", $p),
            $crate::marker_outputs!(@one $m, "v", "1", "m/s", "Velocity of marker ", $v),
            $crate::marker_outputs!(@one $m, "v", "2", "m/s", "Velocity of marker ", $v),
            $crate::marker_outputs!(@one $m, "v", "3", "m/s", "Velocity of marker ", $v),
            $crate::marker_outputs!(@one $m, "w", "1", "rad/s", "Angular velocity of the body of marker ", $v),
            $crate::marker_outputs!(@one $m, "w", "2", "rad/s", "Angular velocity of the body of marker ", $v),
            $crate::marker_outputs!(@one $m, "w", "3", "rad/s", "Angular velocity of the body of marker ", $v),
            $crate::marker_outputs!(@one $m, "a", "1", "m/s2", "Acceleration of marker ", $a),
            $crate::marker_outputs!(@one $m, "a", "2", "m/s2", "Acceleration of marker ", $a),
            $crate::marker_outputs!(@one $m, "a", "3", "m/s2", "Acceleration of marker ", $a),
            $crate::marker_outputs!(@one $m, "alpha", "1", "rad/s2", "Angular acceleration of the body of marker ", $a),
            $crate::marker_outputs!(@one $m, "alpha", "2", "rad/s2", "Angular acceleration of the body of marker ", $a),
            $crate::marker_outputs!(@one $m, "alpha", "3", "rad/s2", "Angular acceleration of the body of marker ", $a),
        ]
    };

    (@one $m:literal, $q:literal, $k:literal, $unit:literal, $what:literal, $deps:expr) => {
        $crate::Output::new(concat!($m, ".", $q, "[", $k, "]"))
            .unit($unit)
            .description(concat!($what, $m, ", world component ", $k))
            .depends_on($deps)
    };
    (@rot $m:literal, $ij:literal, $deps:expr) => {
        $crate::Output::new(concat!($m, ".R[", $ij, "]"))
            .description(concat!("Rotation marker ", $m, " to world, element (", $ij, ")"))
            .depends_on($deps)
    };
}

/// The force and torque inputs of marker `$m` (a string literal), start 0:
/// `marker_inputs!("A")` is all six (`F[1..3]`, `T[1..3]`, `[Real; 6]`);
/// `marker_inputs!("A", planar)` is the in-plane three of a model moving in the world
/// xy-plane (`F[1]`, `F[2]`, `T[3]`, `[Real; 3]`).
#[macro_export]
macro_rules! marker_inputs {
    ($m:literal) => {
        [
            $crate::marker_inputs!(@f $m, "1"),
            $crate::marker_inputs!(@f $m, "2"),
            $crate::marker_inputs!(@f $m, "3"),
            $crate::marker_inputs!(@t $m, "1"),
            $crate::marker_inputs!(@t $m, "2"),
            $crate::marker_inputs!(@t $m, "3"),
        ]
    };
    ($m:literal, planar) => {
        [
            $crate::marker_inputs!(@f $m, "1"),
            $crate::marker_inputs!(@f $m, "2"),
            $crate::marker_inputs!(@t $m, "3"),
        ]
    };
    (@f $m:literal, $k:literal) => {
        $crate::Real::new(concat!($m, ".F[", $k, "]"), 0.0)
            .unit("N")
            .description(concat!("Force at marker ", $m, ", world component ", $k))
    };
    (@t $m:literal, $k:literal) => {
        $crate::Real::new(concat!($m, ".T[", $k, "]"), 0.0)
            .unit("N.m")
            .description(concat!("Torque on the body at marker ", $m, ", world component ", $k))
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Declaration, Output, Real, State};

    const OUTPUTS: [Output; 2 * OUTPUTS_PER_MARKER + 1] = concat(&[
        &marker_outputs!("A", position: &["q"], velocity: &["q", "u"],
                         acceleration: &["q", "u", "A.F[1]"]),
        &[],
        &marker_outputs!("B", position: &["q"], velocity: &["q", "u"],
                         acceleration: &["q", "u"]),
        &[Output::new("E")],
    ]);
    const INPUTS: [Real; 9] = concat(&[&marker_inputs!("A"), &marker_inputs!("B", planar)]);

    #[test]
    fn marker_outputs_follow_the_port_convention_in_write_order() {
        let names: Vec<&str> = OUTPUTS[..24].iter().map(|o| o.name).collect();
        let expected = [
            "A.r[1]",
            "A.r[2]",
            "A.r[3]",
            "A.R[1,1]",
            "A.R[1,2]",
            "A.R[1,3]",
            "A.R[2,1]",
            "A.R[2,2]",
            "A.R[2,3]",
            "A.R[3,1]",
            "A.R[3,2]",
            "A.R[3,3]",
            "A.v[1]",
            "A.v[2]",
            "A.v[3]",
            "A.w[1]",
            "A.w[2]",
            "A.w[3]",
            "A.a[1]",
            "A.a[2]",
            "A.a[3]",
            "A.alpha[1]",
            "A.alpha[2]",
            "A.alpha[3]",
        ];
        assert_eq!(names, expected);
        assert_eq!(OUTPUTS[24].name, "B.r[1]");
        assert_eq!(OUTPUTS[48].name, "E");
        assert_eq!(OUTPUTS[11].depends_on, &["q"]);
        assert_eq!(OUTPUTS[14].depends_on, &["q", "u"]);
        assert_eq!(OUTPUTS[23].depends_on, &["q", "u", "A.F[1]"]);
        assert_eq!(OUTPUTS[23].unit, Some("rad/s2"));

        // write_outputs puts every quantity where its name says.
        let k = MarkerKinematics {
            r: [1.0, 2.0, 3.0],
            rotation: [[4.0, 5.0, 6.0], [7.0, 8.0, 9.0], [10.0, 11.0, 12.0]],
            v: [13.0, 14.0, 15.0],
            w: [16.0, 17.0, 18.0],
            a: [19.0, 20.0, 21.0],
            alpha: [22.0, 23.0, 24.0],
        };
        let mut y = [0.0; 24];
        k.write_outputs(&mut y);
        let expected: Vec<f64> = (1..=24).map(f64::from).collect();
        assert_eq!(y.to_vec(), expected);
    }

    #[test]
    fn marker_inputs_are_all_six_or_the_planar_three() {
        let names: Vec<&str> = INPUTS.iter().map(|u| u.name).collect();
        assert_eq!(
            names,
            [
                "A.F[1]", "A.F[2]", "A.F[3]", "A.T[1]", "A.T[2]", "A.T[3]", "B.F[1]", "B.F[2]",
                "B.T[3]"
            ]
        );
        assert!(INPUTS.iter().all(|u| u.start == 0.0));
        assert_eq!(INPUTS[3].unit, Some("N.m"));
    }

    #[test]
    fn a_declaration_built_from_marker_helpers_passes_the_checks() {
        const STATES: [State; 2] = [State::new("q"), State::new("u")];
        let d = Declaration {
            model_name: "m",
            model_identifier: "m",
            inputs: &INPUTS,
            outputs: &OUTPUTS,
            states: &STATES,
            ..Declaration::EMPTY
        };
        d.check().unwrap();
    }
}
