//! The link FMUs with the parameters of `examples/double_pendulum.toml` and
//! `examples/slider_crank.toml`, driven open-loop by the monolithic references' joint
//! forces, follow the references: the examples, the FMU and the references
//! (`tests/support/reference`) share their geometry, angle conventions, energy and
//! the sign of the multipliers. The forces are applied as the joint definitions say
//! (force ports): side i gets λe at its marker, side j gets −λe at the same point,
//! i.e. −λe plus the torque (C_i − r_j) × (−λe) at marker j.

use std::path::Path;

use tether_fmi::{Fmu, Instance, InstanceOptions};
use tether_tests::reference::{double_pendulum, slider_crank};

/// An instance initialized with the `parameters` of instance `name` in an example.
fn instance_from_example(fmu: &Fmu, example: &str, name: &str) -> Instance {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(example);
    let text = std::fs::read_to_string(&path).expect("read example");
    let file: toml::Table = text.parse().expect("example is TOML");
    let instance = file["instance"]
        .as_array()
        .expect("[[instance]]")
        .iter()
        .find(|i| i["name"].as_str() == Some(name))
        .expect("instance in example");
    let mut inst = fmu
        .instantiate(name, InstanceOptions::default())
        .expect("instantiate");
    inst.setup_experiment(None, 0.0, None).expect("setup");
    for (key, value) in instance["parameters"].as_table().expect("parameters") {
        let vr = inst
            .value_reference(key)
            .expect("parameter of the link FMU");
        match value {
            toml::Value::Boolean(b) => inst.set_boolean(&[vr], &[*b]).expect("set"),
            toml::Value::Float(x) => inst.set_real(&[vr], &[*x]).expect("set"),
            toml::Value::Integer(n) => inst.set_real(&[vr], &[*n as f64]).expect("set"),
            other => panic!("{key} = {other} in {example}"),
        }
    }
    inst.enter_initialization_mode().expect("enter init");
    inst.exit_initialization_mode().expect("exit init");
    inst
}

fn get(inst: &mut Instance, name: &str) -> f64 {
    let vr = inst.value_reference(name).expect("variable");
    let mut v = [0.0];
    inst.get_real(&[vr], &mut v).expect("get");
    v[0]
}

/// Sets port inputs to the quadratic through (τ = 0, H/2, H): value and derivatives.
fn set_quadratic(inst: &mut Instance, names: &[&str], samples: &[[f64; 3]], h: f64) {
    let vrs: Vec<u32> = names
        .iter()
        .map(|n| inst.value_reference(n).expect("input"))
        .collect();
    let value: Vec<f64> = samples.iter().map(|s| s[0]).collect();
    let d1: Vec<f64> = samples
        .iter()
        .map(|s| (-3.0 * s[0] + 4.0 * s[1] - s[2]) / h)
        .collect();
    let d2: Vec<f64> = samples
        .iter()
        .map(|s| 4.0 * (s[0] - 2.0 * s[1] + s[2]) / (h * h))
        .collect();
    inst.set_real(&vrs, &value).expect("inputs");
    let n = vrs.len();
    inst.set_real_input_derivatives(&vrs, &vec![1; n], &d1)
        .expect("d1");
    inst.set_real_input_derivatives(&vrs, &vec![2; n], &d2)
        .expect("d2");
}

/// (H, number of steps) of the open-loop runs: 0.5 s.
const H: f64 = 1e-3;
const STEPS: usize = 500;

fn half_step_grid() -> Vec<f64> {
    (0..=2 * STEPS).map(|k| k as f64 * H / 2.0).collect()
}

#[test]
fn double_pendulum_example_links_follow_the_reference_under_its_joint_force() {
    let fmu = Fmu::open(tether_fmu_build::workspace_fmu("link").expect("link FMU")).unwrap();
    let mut links = [
        instance_from_example(&fmu, "double_pendulum.toml", "link1"),
        instance_from_example(&fmu, "double_pendulum.toml", "link2"),
    ];
    let reference = double_pendulum::reference(&half_step_grid());
    let columns = [
        "link1.phi",
        "link1.omega",
        "link1.B.r[1]",
        "link1.B.r[2]",
        "link2.phi",
        "link2.omega",
        "link2.A.r[1]",
        "link2.A.r[2]",
        "link2.B.r[1]",
        "link2.B.v[2]",
        "link1.E",
        "link2.E",
    ];
    let mut worst = 0.0f64;
    for n in 0..=STEPS {
        let now = &reference[2 * n];
        for column in columns {
            let (link, variable) = column.split_once('.').unwrap();
            let k = usize::from(link == "link2");
            let got = get(&mut links[k], variable);
            let expected = now.column(column).unwrap();
            worst = worst.max((got - expected).abs());
            assert!(
                (got - expected).abs() < 1e-8,
                "{column} at t = {}: FMU {got}, reference {expected}",
                now.t
            );
        }
        if n == STEPS {
            break;
        }
        let window = &reference[2 * n..=2 * n + 2];
        let lambda = |c: usize| {
            [
                window[0].lambda[c],
                window[1].lambda[c],
                window[2].lambda[c],
            ]
        };
        let minus = |s: [f64; 3]| s.map(|x| -x);
        set_quadratic(
            &mut links[0],
            &["B.F[1]", "B.F[2]"],
            &[lambda(0), lambda(1)],
            H,
        );
        set_quadratic(
            &mut links[1],
            &["A.F[1]", "A.F[2]"],
            &[minus(lambda(0)), minus(lambda(1))],
            H,
        );
        for link in &mut links {
            link.do_step(n as f64 * H, H, true).expect("step");
        }
    }
    eprintln!("double pendulum open loop: largest deviation {worst:e} over 0.5 s");
}

#[test]
fn slider_crank_example_links_follow_the_reference_under_its_joint_force() {
    let fmu = Fmu::open(tether_fmu_build::workspace_fmu("link").expect("link FMU")).unwrap();
    let mut links = [
        instance_from_example(&fmu, "slider_crank.toml", "crank"),
        instance_from_example(&fmu, "slider_crank.toml", "rocker"),
    ];
    let reference = slider_crank::reference(&half_step_grid());
    let columns = [
        "crank.phi",
        "crank.omega",
        "crank.B.r[1]",
        "crank.B.r[2]",
        "rocker.phi",
        "rocker.omega",
        "rocker.B.r[1]",
        "rocker.A.r[1]",
        "crank.E",
        "rocker.E",
    ];
    let mut worst = 0.0f64;
    for n in 0..=STEPS {
        let now = &reference[2 * n];
        for column in columns {
            let (link, variable) = column.split_once('.').unwrap();
            let k = usize::from(link == "rocker");
            let got = get(&mut links[k], variable);
            let expected = now.column(column).unwrap();
            worst = worst.max((got - expected).abs());
            assert!(
                (got - expected).abs() < 1e-8,
                "{column} at t = {}: FMU {got}, reference {expected}",
                now.t
            );
        }
        if n == STEPS {
            break;
        }
        // Side i (crank.B): λ n2. Side j (rocker.A): −λ n2 and the torque
        // (C_i − r_A) × (−λ n2) = −λ·slide, since C_i − r_A = slide·e2 and e2 × n2 = 1.
        let window = &reference[2 * n..=2 * n + 2];
        let sample = |f: &dyn Fn(&slider_crank::SliderCrankState) -> f64| {
            [f(&window[0]), f(&window[1]), f(&window[2])]
        };
        let fx = sample(&|s| -s.lambda * s.phi[1].sin());
        let fy = sample(&|s| s.lambda * s.phi[1].cos());
        let torque = sample(&|s| -s.lambda * s.slide);
        set_quadratic(&mut links[0], &["B.F[1]", "B.F[2]"], &[fx, fy], H);
        let minus = |s: [f64; 3]| s.map(|x| -x);
        set_quadratic(
            &mut links[1],
            &["A.F[1]", "A.F[2]", "A.T[3]"],
            &[minus(fx), minus(fy), torque],
            H,
        );
        for link in &mut links {
            link.do_step(n as f64 * H, H, true).expect("step");
        }
    }
    eprintln!("slider-crank open loop: largest deviation {worst:e} over 0.5 s");
}
