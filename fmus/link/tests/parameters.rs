//! Invalid parameter combinations are refused with a message naming the parameter
//! (the kit turns it into fmi2Error at fmi2ExitInitializationMode).

use link::Link;
use tether_fmu_kit::{Model, Parameters};

/// `Link::new` with the declared defaults, overridden by `reals` and `pinned`.
fn build(reals: &[(&str, f64)], pinned: bool) -> Result<Link, String> {
    let d = &Link::DECLARATION;
    let mut values: Vec<f64> = d.all_real_parameters().iter().map(|p| p.start).collect();
    for (name, value) in reals {
        let i = d
            .real_parameters
            .iter()
            .position(|p| p.name == *name)
            .expect("known parameter");
        values[i] = *value;
    }
    Link::new(&Parameters::new(d, &values, &[], &[pinned]))
}

fn error(reals: &[(&str, f64)], pinned: bool) -> String {
    match build(reals, pinned) {
        Ok(_) => panic!("{reals:?} (pinned = {pinned}) was accepted"),
        Err(message) => message,
    }
}

#[test]
fn defaults_are_valid_free_and_pinned() {
    assert!(build(&[], false).is_ok());
    assert!(build(&[], true).is_ok());
    assert!(build(&[("c_phi", 500.0), ("d_phi", 50.0)], true).is_ok());
}

#[test]
fn non_positive_mass_inertia_or_length_is_refused() {
    for name in ["m", "J", "l"] {
        for value in [0.0, -1.0, f64::NAN] {
            let message = error(&[(name, value)], false);
            assert!(
                message.starts_with(&format!("{name} must be > 0")),
                "{message}"
            );
        }
    }
}

#[test]
fn non_finite_values_are_refused() {
    for name in ["g", "xA", "x0", "phi0", "vy0", "phi_ref"] {
        let message = error(&[(name, f64::INFINITY)], false);
        assert!(
            message.starts_with(&format!("{name} must be finite")),
            "{message}"
        );
    }
}

#[test]
fn a_spring_damper_needs_a_pivot_and_a_pivot_cannot_move() {
    let message = error(&[("c_phi", 500.0)], false);
    assert!(message.contains("need pinned = true"), "{message}");
    let message = error(&[("d_phi", 1.0)], false);
    assert!(message.contains("need pinned = true"), "{message}");
    let message = error(&[("vx0", 1.0)], true);
    assert!(message.contains("must be 0 for a pinned link"), "{message}");
}
