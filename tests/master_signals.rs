//! Signal connections (docs/algorithm.md, "Signal connections"): the paper's
//! two-mass oscillator under PI position control. The rigid link couples the
//! masses through its multiplier; the controller FMU, which declares no FMU
//! states, measures mass 1 and drives its second force input through signal
//! connections. The reference is the monolithic controlled system
//! (m1 + m2) ẍ = −(c1 + c2) x − (d1 + d2) ẋ + kp (r − x) + ki z, ż = r − x,
//! integrated exactly (matrix exponential of the affine system).

use nalgebra::{Matrix4, Vector4};
use tether_master::{MasterError, MemoryRecorder, Simulation, SystemSpec};
use tether_tests::signals::*;

/// The controller holds its measured input over a step and the plant sees
/// its command one step late: the co-simulation converges to the monolithic
/// system at first order in H, under both schemes; the controller steps
/// once per macro step and is never rolled back.
#[test]
fn controlled_pair_converges_to_the_monolithic_system_at_first_order() {
    for scheme in ["jacobi", "gauss_seidel"] {
        let (e1, stats) = run(&system(2e-3, 1, scheme, ""));
        let (e2, _) = run(&system(1e-3, 1, scheme, ""));
        let (e3, _) = run(&system(5e-4, 1, scheme, ""));
        let (r1, r2) = (e1 / e2, e2 / e3);
        println!(
            "{scheme}: max |x - x_ref| = {e1:.3e}, {e2:.3e}, {e3:.3e} (ratios {r1:.2}, {r2:.2})"
        );
        assert!(
            e2 < 0.02 * R,
            "{scheme}: error {e2} beyond 2 % of the set point"
        );
        for r in [r1, r2] {
            assert!(
                (1.8..2.2).contains(&r),
                "{scheme}: ratio {r} is not first order"
            );
        }
        let ctrl = &stats.instances[0];
        assert_eq!(ctrl.name, "ctrl");
        assert_eq!(
            ctrl.do_steps, 500,
            "{scheme}: one fmi2DoStep per macro step"
        );
        assert_eq!((ctrl.state_gets, ctrl.state_sets), (0, 0), "{scheme}");
    }
}

/// Gauss–Seidel hands the plant the command at T_{N+1} (the controller steps
/// first): closer to the monolithic system than Jacobi at the same step.
#[test]
fn gauss_seidel_is_more_accurate_than_jacobi_here() {
    let (jacobi, _) = run(&system(1e-3, 0, "jacobi", ""));
    let (gauss_seidel, _) = run(&system(1e-3, 0, "gauss_seidel", ""));
    println!("k = 0: Jacobi {jacobi:.3e}, Gauss-Seidel {gauss_seidel:.3e}");
    assert!(gauss_seidel < jacobi);
}

/// A gain and offset on a connection are the linear transformation
/// u = gain·y + offset: a controller measuring in mm with an offset of
/// −1000·r and a set point of 0 is the same controller.
#[test]
fn gain_and_offset_transform_the_value() {
    let plain = run(&system(1e-3, 1, "jacobi", "")).0;
    let mut spec = system(1e-3, 1, "jacobi", "");
    spec.connections[0].gain = Some(1000.0);
    spec.connections[0].offset = Some(-1000.0 * R);
    spec.instances[0]
        .parameters
        .insert("r".into(), tether_master::StartValue::Real(0.0));
    for k in ["kp", "ki"] {
        let v = match spec.instances[0].parameters[k] {
            tether_master::StartValue::Real(v) => v,
            tether_master::StartValue::Integer(v) => v as f64,
            ref other => panic!("{other:?}"),
        };
        spec.instances[0]
            .parameters
            .insert(k.into(), tether_master::StartValue::Real(v / 1000.0));
    }
    let transformed = run(&spec).0;
    assert!(
        (plain - transformed).abs() < 1e-9,
        "{plain} vs {transformed}"
    );
}

#[test]
fn bad_connections_are_one_clear_line() {
    let err = |extra: &str| setup_error(&system(1e-3, 0, "jacobi", extra));
    let cases = [
        // A second sender for the same input.
        (
            "[[connection]]\nfrom = \"mass2.x\"\nto = \"ctrl.y\"",
            "already receives",
        ),
        // Units differ: m into N.
        (
            "[[connection]]\nfrom = \"mass2.x\"\nto = \"mass2.F_ext\"",
            "units differ",
        ),
        // An input a constraint drives.
        (
            "[[connection]]\nfrom = \"ctrl.u\"\nto = \"mass2.F\"",
            "driven by a constraint",
        ),
        // An input as the sender.
        (
            "[[connection]]\nfrom = \"mass2.F_ext\"\nto = \"mass2.F_ext\"",
            "needs a Real, Integer, Boolean or String output",
        ),
        (
            "[[connection]]\nfrom = \"mass3.x\"\nto = \"ctrl.y\"",
            "unknown instance 'mass3'",
        ),
        ("[[connection]]\nfrom = \"mass2.xx\"\nto = \"ctrl.y\"", "xx"),
    ];
    for (extra, expected) in cases {
        let message = err(extra);
        assert!(message.contains(expected), "{extra}: {message}");
        assert!(!message.contains('\n'), "{message}");
    }
}

/// mass2.a depends directly on mass2.F_ext, and ctrl2.u on ctrl2.y: feeding
/// the acceleration to a controller whose command pushes the same mass is a
/// direct-feedthrough loop, closed at macro points
/// (tests/master_signal_loops.rs runs such loops); its connections are still
/// checked, here the units, which differ.
#[test]
fn a_direct_feedthrough_loop_is_checked_at_setup() {
    let ctrl = tether_fmu_build::workspace_fmu("controller").unwrap();
    let mut spec = system(1e-3, 0, "jacobi", "");
    spec.instances.push(tether_master::InstanceSpec {
        name: "ctrl2".into(),
        fmu: ctrl,
        ..Default::default()
    });
    for (from, to) in [("mass2.a", "ctrl2.y"), ("ctrl2.u", "mass2.F_ext")] {
        spec.connections.push(tether_master::ConnectionSpec {
            from: from.into(),
            to: to.into(),
            gain: None,
            offset: None,
        });
    }
    let message = setup_error(&spec);
    assert_eq!(
        message,
        "connection mass2.a → ctrl2.y: mass2.a is in 'm/s2' and ctrl2.y in 'm': units differ; \
         set gain (and offset) on the connection to convert (to = gain·from + offset)"
    );
}

/// An FMU that cannot roll back is refused where a constraint would need to
/// repeat its step, with a message naming the capability.
#[test]
fn an_fmu_without_states_cannot_be_constraint_coupled() {
    let mut spec = system(1e-3, 0, "jacobi", "");
    spec.connections.clear();
    // ctrl.y is in m: a coefficient converts the multiplier (N) for it.
    spec.constraints[0].drives = "mass1.F - mass2.F + 1e-3*ctrl.y".into();
    let message = setup_error(&spec);
    assert!(message.contains("canGetAndSetFMUstate"), "{message}");
}

/// Without constraints there is nothing to solve: every method steps each
/// instance once per macro step, and they give the same results.
#[test]
fn a_system_of_signals_only_runs_without_constraints() -> Result<(), MasterError> {
    let mut results = Vec::new();
    for method in ["baumgarte", "explicit"] {
        let mut spec = system(1e-3, 0, "jacobi", "");
        spec.instances.truncate(2);
        spec.constraints.clear();
        if method == "explicit" {
            spec.method = tether_master::Method::Explicit { mu: 1e-3 };
        }
        let mut sim = Simulation::new(&spec)?;
        let mut rec = MemoryRecorder::default();
        let stats = sim.run(&mut [&mut rec], &mut |_, _| {})?;
        assert_eq!(stats.instances[1].do_steps, 1000, "{method}");
        assert_eq!(stats.instances[1].state_gets, 0, "{method}");
        results.push(rec.rows);
    }
    assert_eq!(results[0], results[1]);
    Ok(())
}

/// A free oscillator A pushes oscillator B through a one-way spring
/// (`B.F_ext = 1000·A.x`, a connection with a gain). B interpolates inputs,
/// so it receives A's position as the polynomial of degree k through A's
/// last values: the error of B against the exact solution (matrix
/// exponential of both, A unaffected by B) falls as H^(k+1), under both
/// schemes. A starts at rest (x0 = 0.1, v0 = 0), so that the start-up steps
/// of lower degree (docs/algorithm.md) do not cap the order.
#[test]
fn interpolating_receivers_get_polynomials_of_degree_k() {
    const G: f64 = 1000.0;
    let osc = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let exact = |t: f64| {
        #[rustfmt::skip]
        let a = Matrix4::new(
            0.0,     1.0,     0.0,          0.0,
            -C / M1, -D / M1, 0.0,          0.0,
            0.0,     0.0,     0.0,          1.0,
            G / M2,  0.0,     -C / M2,      -D / M2,
        );
        ((a * t).exp() * Vector4::new(0.1, 0.0, 0.0, 0.0))[2]
    };
    let error = |h: f64, order: usize, scheme: &str| {
        let text = format!(
            r#"
            [experiment]
            stop = 0.2
            step = {h}
            [coupling]
            order = {order}
            [signals]
            scheme = "{scheme}"
            [[instance]]
            name = "a"
            fmu = "{osc}"
            parameters = {{ m = {M1}, c = {C}, d = {D}, x0 = 0.1, v0 = 0.0, exact = true }}
            [[instance]]
            name = "b"
            fmu = "{osc}"
            parameters = {{ m = {M2}, c = {C}, d = {D}, x0 = 0.0, v0 = 0.0, exact = true }}
            [[connection]]
            from = "a.x"
            to = "b.F_ext"
            gain = {G}
            "#,
            osc = osc.display()
        );
        let spec = SystemSpec::from_toml(&text).unwrap();
        let mut sim = Simulation::new(&spec).unwrap();
        let mut rec = MemoryRecorder::default();
        sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
        let x = rec.columns.iter().position(|c| c == "b.x").unwrap();
        rec.times
            .iter()
            .zip(&rec.rows)
            .map(|(t, row)| (row[x] - exact(*t)).abs())
            .fold(0.0, f64::max)
    };
    for scheme in ["jacobi", "gauss_seidel"] {
        for order in 0..=2 {
            let (e1, e2) = (error(2e-3, order, scheme), error(1e-3, order, scheme));
            let expected = f64::powi(2.0, order as i32 + 1);
            let ratio = e1 / e2;
            println!("{scheme}, k = {order}: {e1:.3e} -> {e2:.3e}, ratio {ratio:.2} (expected {expected})");
            assert!(
                (0.8 * expected..1.25 * expected).contains(&ratio),
                "{scheme}, k = {order}: ratio {ratio}"
            );
        }
    }
}

/// The counter FMU of tests/fixtures/fmi/counter.c, compiled and packaged
/// into `dir`.
fn counter_fmu(dir: &std::path::Path) -> std::path::PathBuf {
    use tether_tests::fmi::{compile_shared_library, zip_directory};
    let root = dir.join("counter-unpacked");
    let binaries = root.join("binaries").join("linux64");
    std::fs::create_dir_all(&binaries).unwrap();
    let source = include_str!("fixtures/fmi/counter.c");
    compile_shared_library(&binaries, "counter", source, &[]);
    std::fs::remove_file(binaries.join("counter.c")).unwrap();
    let var = |name: &str, vr: u32, causality: &str, ty: &str| {
        let variability = if ty == "Real" {
            "continuous"
        } else {
            "discrete"
        };
        let start = if causality == "input" {
            r#" start="0""#
        } else {
            ""
        };
        let start = if ty == "Boolean" && causality == "input" {
            r#" start="false""#
        } else {
            start
        };
        format!(
            r#"<ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" variability="{variability}"><{ty}{start}/></ScalarVariable>"#
        )
    };
    let xml = format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="counter" guid="{{counter}}" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="counter" canHandleVariableCommunicationStepSize="true" canGetAndSetFMUstate="false"/>
  <ModelVariables>
    {}
    {}
    {}
    {}
    {}
    {}
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1" dependencies=""/><Unknown index="2" dependencies=""/><Unknown index="5" dependencies="3"/><Unknown index="6" dependencies="4"/></Outputs>
  </ModelStructure>
</fmiModelDescription>
"#,
        var("count", 0, "output", "Integer"),
        var("odd", 1, "output", "Boolean"),
        var("in_i", 2, "input", "Integer"),
        var("in_b", 3, "input", "Boolean"),
        var("got_i", 4, "output", "Real"),
        var("got_b", 5, "output", "Real"),
    );
    std::fs::write(root.join("modelDescription.xml"), xml).unwrap();
    let archive = dir.join("counter.fmu");
    zip_directory(&root, &archive);
    archive
}

fn counters(fmu: &std::path::Path, scheme: &str, extra: &str) -> SystemSpec {
    let text = format!(
        r#"
        [experiment]
        stop = 0.01
        step = 1e-3
        [signals]
        scheme = "{scheme}"
        [[instance]]
        name = "a"
        fmu = "{fmu}"
        [[instance]]
        name = "b"
        fmu = "{fmu}"
        [[connection]]
        from = "a.count"
        to = "b.in_i"
        [[connection]]
        from = "a.odd"
        to = "b.in_b"
        {extra}
        "#,
        fmu = fmu.display()
    );
    SystemSpec::from_toml(&text).unwrap()
}

/// Integer and Boolean outputs reach Integer and Boolean inputs, held over
/// the step: b sees a's count at T_N (Jacobi) or at T_{N+1} (Gauss–Seidel,
/// a steps first). Mixing the types, or a gain on an Integer, is refused.
#[test]
fn integer_and_boolean_connections_pass_values_at_macro_points() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = counter_fmu(dir.path());
    for (scheme, lag) in [("jacobi", 1.0), ("gauss_seidel", 0.0)] {
        let mut sim = Simulation::new(&counters(&fmu, scheme, "")).unwrap();
        let mut rec = MemoryRecorder::default();
        sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
        let col = |name: &str| rec.columns.iter().position(|c| c == name).unwrap();
        let (got_i, got_b) = (col("b.got_i"), col("b.got_b"));
        for (n, row) in rec.rows.iter().enumerate().skip(1) {
            let count = n as f64 - lag;
            assert_eq!(row[got_i], count, "{scheme}, step {n}");
            assert_eq!(row[got_b], count % 2.0, "{scheme}, step {n}");
        }
    }
    let message = setup_error(&counters(
        &fmu,
        "jacobi",
        "[[connection]]\nfrom = \"a.odd\"\nto = \"a.in_i\"",
    ));
    assert!(
        message.contains("a connection joins variables of one type"),
        "{message}"
    );
    let message = setup_error(&counters(
        &fmu,
        "jacobi",
        "[[connection]]\nfrom = \"b.count\"\nto = \"a.in_i\"\ngain = 2.0",
    ));
    assert!(
        message.contains("gain and offset apply to Real connections only"),
        "{message}"
    );
}
