//! Tests of the kit through a small model: ẋ = u − k·x, outputs y = x + u (direct
//! feedthrough) and z = x.

use std::cell::RefCell;
use std::rc::Rc;

use crate::declaration::{Declaration, Output, Parameters, Real, State};
use crate::input::InputJet;
use crate::instance::{Instance, Status};
use crate::machine::{Call, MachineState};
use crate::model::Model;
use crate::snapshot::Snapshot;
use crate::xml;

pub(crate) struct Decay {
    k: f64,
    x0: f64,
}

impl Model for Decay {
    const DECLARATION: Declaration = Declaration {
        model_name: "decay",
        model_identifier: "decay",
        description: "x' = u - k x",
        real_parameters: &[
            Real::new("k", 1.0).min(0.0).unit("1/s").description("rate"),
            Real::new("x0", 1.0),
        ],
        inputs: &[Real::new("u", 0.0)],
        outputs: &[
            Output::new("y").depends_on(&["x", "u"]),
            Output::new("z").depends_on(&["x"]),
        ],
        states: &[State::new("x")],
        max_output_derivative_order: 1,
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        let k = p.real("k")?;
        if k > 1e6 {
            return Err(format!("k = {k} is too large"));
        }
        Ok(Decay {
            k,
            x0: p.real("x0")?,
        })
    }
    fn initial_states(&self, x: &mut [f64]) {
        x[0] = self.x0;
    }
    fn derivatives(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        assert!(self.k != 123.0, "k = 123 makes the test model panic");
        dx[0] = u[0] - self.k * x[0];
    }
    fn outputs(&self, _t: f64, x: &[f64], u: &[f64], y: &mut [f64]) {
        y[0] = x[0] + u[0];
        y[1] = x[0];
    }
    fn output_derivatives(
        &self,
        _t: f64,
        x: &[f64],
        u: &[InputJet],
        order: u32,
        dy: &mut [f64],
    ) -> bool {
        let dx = u[0].value - self.k * x[0];
        order == 1 && {
            dy.copy_from_slice(&[dx + u[0].d1, dx]);
            true
        }
    }
}

// Value references: k 0, x0 1, tolerance 2, u 3, y 4, z 5, x 6, der(x) 7.
const K: u32 = 0;
const X0: u32 = 1;
const U: u32 = 3;
const Y: u32 = 4;
const Z: u32 = 5;
const DER_X: u32 = 7;

type Log = Rc<RefCell<Vec<String>>>;

fn instance() -> (Instance<Decay>, Log) {
    let log: Log = Rc::default();
    let sink = log.clone();
    let logger = Box::new(move |status: Status, category: &str, message: &str| {
        sink.borrow_mut()
            .push(format!("{status:?} {category} {message}"));
    });
    (Instance::new("test", Some(logger), false), log)
}

fn initialized(k: f64) -> Instance<Decay> {
    let (mut inst, _) = instance();
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[K], &[k])),
        Status::Ok
    );
    assert_eq!(
        inst.call(Call::SetupExperiment, |i| i
            .setup_experiment(None, 0.0, None)),
        Status::Ok
    );
    assert_eq!(
        inst.call(
            Call::EnterInitializationMode,
            Instance::enter_initialization_mode
        ),
        Status::Ok
    );
    assert_eq!(
        inst.call(
            Call::ExitInitializationMode,
            Instance::exit_initialization_mode
        ),
        Status::Ok
    );
    inst
}

fn get(inst: &mut Instance<Decay>, vr: u32) -> f64 {
    let mut v = [f64::NAN];
    assert_eq!(
        inst.call(Call::GetReal, |i| i.get_real(&[vr], &mut v)),
        Status::Ok
    );
    v[0]
}

fn step(inst: &mut Instance<Decay>, t: f64, h: f64) -> Status {
    inst.call(Call::DoStep, |i| {
        i.do_step(t, h).inspect_err(|f| eprintln!("{}", f.message))
    })
}

#[test]
fn model_description_declares_the_model_as_fmpy_expects() {
    let text = xml::model_description(&Decay::DECLARATION).unwrap();
    assert!(text.contains(r#"fmiVersion="2.0""#));
    assert!(text.contains(r#"canInterpolateInputs="true" maxOutputDerivativeOrder="1""#));
    assert!(text.contains(r#"<ScalarVariable name="der(x)" valueReference="7""#));
    assert!(text.contains(r#"<Real derivative="7"/>"#));
    assert!(
        text.contains(r#"<Unknown index="5" dependencies="4 7"/>"#),
        "y depends on u and x"
    );
    assert!(
        text.contains(r#"<Unknown index="6" dependencies="7"/>"#),
        "z depends on x only"
    );
    assert!(text.contains(r#"<Unit name="1/s"/>"#));
    assert!(text.contains(r#"name="tolerance" valueReference="2""#));
    let initial: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.contains("<InitialUnknowns>"))
        .collect();
    assert_eq!(
        initial[1..5].join("").matches("<Unknown index=").count(),
        4,
        "y, z, x, der(x)"
    );
}

#[test]
fn guid_is_a_deterministic_hash_of_the_declaration() {
    let guid = xml::guid(&Decay::DECLARATION);
    assert_eq!(guid, xml::guid(&Decay::DECLARATION));
    assert_eq!(guid.len(), 38);
    let other = Declaration {
        description: "changed",
        ..Decay::DECLARATION
    };
    assert_ne!(guid, xml::guid(&other));
}

#[test]
fn the_cached_guid_is_rendered_once_per_model() {
    let first = xml::model_guid::<Decay>();
    assert_eq!(first, xml::guid(&Decay::DECLARATION));
    // The second call returns the same string, not a new rendering.
    assert!(std::ptr::eq(first, xml::model_guid::<Decay>()));
    // Each model type has its own entry.
    assert_eq!(
        xml::model_guid::<Limited>(),
        xml::guid(&Limited::DECLARATION)
    );
    assert_ne!(xml::model_guid::<Limited>(), first);
}

#[test]
fn invalid_declarations_are_refused() {
    const DUPLICATE_INPUTS: &[Real] = &[Real::new("k", 0.0)];
    const UNKNOWN_DEPENDENCY: &[Output] = &[Output::new("y").depends_on(&["w"])];
    let duplicate = Declaration {
        inputs: DUPLICATE_INPUTS,
        ..Decay::DECLARATION
    };
    assert!(xml::model_description(&duplicate)
        .unwrap_err()
        .contains("twice"));
    let unknown = Declaration {
        outputs: UNKNOWN_DEPENDENCY,
        ..Decay::DECLARATION
    };
    assert!(xml::model_description(&unknown)
        .unwrap_err()
        .contains("neither a state nor an input"));
    let bad_id = Declaration {
        model_identifier: "a-b",
        ..Decay::DECLARATION
    };
    assert!(xml::model_description(&bad_id).is_err());
    assert_eq!(
        xml::escape(r#"a<"b">&'"#),
        "a&lt;&quot;b&quot;&gt;&amp;&apos;"
    );
}

#[test]
fn wrong_state_calls_return_error_and_change_nothing() {
    let (mut inst, log) = instance();
    assert_eq!(step(&mut inst, 0.0, 0.1), Status::Error);
    let mut v = [0.0];
    assert_eq!(
        inst.call(Call::GetReal, |i| i.get_real(&[Z], &mut v)),
        Status::Error
    );
    assert_eq!(inst.data.machine, MachineState::Instantiated);
    assert!(
        log.borrow()[0].contains("fmi2DoStep: not allowed in state Instantiated"),
        "{:?}",
        log.borrow()
    );
    assert_eq!(
        inst.call(
            Call::ExitInitializationMode,
            Instance::exit_initialization_mode
        ),
        Status::Error
    );
}

#[test]
fn parameters_are_fixed_after_initialization_and_range_checked() {
    let (mut inst, log) = instance();
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[K], &[-1.0])),
        Status::Error,
        "below min"
    );
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[K, X0], &[2.0, f64::NAN])),
        Status::Error
    );
    assert_eq!(inst.data.reals[0], 1.0, "a refused call changes nothing");
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[Y], &[1.0])),
        Status::Error,
        "outputs cannot be set"
    );
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[99], &[1.0])),
        Status::Error
    );
    assert!(log
        .borrow()
        .iter()
        .any(|m| m.contains("unknown value reference 99")));
    let mut inst = initialized(2.0);
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[K], &[3.0])),
        Status::Error
    );
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[U], &[3.0])),
        Status::Ok,
        "inputs can"
    );
}

#[test]
fn invalid_parameters_fail_initialization_with_a_message() {
    let (mut inst, log) = instance();
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[K], &[1e7])),
        Status::Ok
    );
    inst.call(
        Call::EnterInitializationMode,
        Instance::enter_initialization_mode,
    );
    assert_eq!(
        inst.call(
            Call::ExitInitializationMode,
            Instance::exit_initialization_mode
        ),
        Status::Error
    );
    assert_eq!(inst.data.machine, MachineState::Error);
    assert!(
        log.borrow()
            .iter()
            .any(|m| m.contains("invalid parameters: k = 10000000 is too large")),
        "{:?}",
        log.borrow()
    );
    assert_eq!(inst.call(Call::Reset, Instance::reset), Status::Ok);
    assert_eq!(inst.data.machine, MachineState::Instantiated);
}

#[test]
fn dop853_meets_the_tolerance_on_exponential_decay() {
    let mut inst = initialized(3.0);
    for n in 0..10 {
        assert_eq!(step(&mut inst, n as f64 * 0.1, 0.1), Status::Ok);
    }
    assert!((get(&mut inst, Z) - (-3.0f64).exp()).abs() < 1e-10);
}

/// An input value or derivative set as a subnormal number is stored as 0, and a
/// state that is subnormal at the end of a step is 0: arithmetic on subnormals
/// would slow every later step (docs/fmu-kit.md). Normal values are left as they are.
#[test]
fn subnormal_states_and_inputs_are_zero_in_a_step() {
    let tiny = f64::MIN_POSITIVE / 8.0;
    assert!(tiny.is_subnormal());
    let mut inst = initialized(0.0);
    inst.data.states[0] = tiny;
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[U], &[tiny])),
        Status::Ok
    );
    let set = inst.call(Call::SetRealInputDerivatives, |i| {
        i.set_real_input_derivatives(&[U, U], &[1, 2], &[-tiny, 1.0])
    });
    assert_eq!(set, Status::Ok);
    let jet = inst.data.inputs[0];
    assert_eq!(
        [jet.value, jet.d1, jet.d2].map(f64::to_bits),
        [0.0, -0.0, 1.0].map(f64::to_bits)
    );
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[U], &[0.0])),
        Status::Ok
    );
    assert_eq!(step(&mut inst, 0.0, 0.1), Status::Ok);
    assert_eq!(get(&mut inst, Z).to_bits(), 0.0f64.to_bits());
    // x' = -1e3 x decays through every normal magnitude, never subnormal, to 0.
    let mut inst = initialized(1e3);
    let mut smallest = 1.0f64;
    let mut n = 0;
    while get(&mut inst, Z) != 0.0 && n < 10_000 {
        assert_eq!(step(&mut inst, n as f64 * 0.01, 0.01), Status::Ok);
        let x = get(&mut inst, Z);
        assert!(x == 0.0 || x.is_normal(), "{x:e} after {n} steps");
        if x != 0.0 {
            smallest = smallest.min(x.abs());
        }
        n += 1;
    }
    assert_eq!(get(&mut inst, Z), 0.0, "after {n} steps");
    assert!(smallest < 1e-300, "{smallest:e}");
}

#[test]
fn communication_points_are_start_plus_n_h_and_checked() {
    let mut inst = initialized(1.0);
    let mut accumulated = 0.0;
    for n in 0..10 {
        assert_eq!(step(&mut inst, n as f64 * 0.1, 0.1), Status::Ok);
        accumulated += 0.1;
    }
    assert_ne!(accumulated, 1.0);
    assert_eq!(inst.data.time, 1.0, "10 · 0.1, not a sum of ten 0.1");
    assert_eq!(
        step(&mut inst, 0.9, 0.1),
        Status::Error,
        "not the FMU's time"
    );
    assert_eq!(inst.data.machine, MachineState::StepComplete);
    assert_eq!(step(&mut inst, 1.0, 0.0), Status::Error);
    assert_eq!(
        step(&mut inst, 1.0 + 1e-12, 0.25),
        Status::Ok,
        "within the relative tolerance"
    );
    assert_eq!(
        inst.data.time,
        1.0 + 1e-12 + 0.25,
        "a new step size restarts the count at t_c"
    );
}

#[test]
fn inputs_follow_their_taylor_polynomial_during_a_step() {
    // k = 0: x(h) = x0 + ∫ u = 1 + a h + b h²/2 + c h³/6, exact for Dop853.
    let mut inst = initialized(0.0);
    let (a, b, c, h) = (2.0, -3.0, 4.0, 0.5);
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[U], &[a])),
        Status::Ok
    );
    let set = inst.call(Call::SetRealInputDerivatives, |i| {
        i.set_real_input_derivatives(&[U, U], &[1, 2], &[b, c])
    });
    assert_eq!(set, Status::Ok);
    assert_eq!(step(&mut inst, 0.0, h), Status::Ok);
    let x = 1.0 + a * h + b * h * h / 2.0 + c * h * h * h / 6.0;
    assert!((get(&mut inst, Z) - x).abs() < 1e-13);
    // Outputs at the end of the step see the input polynomial at the end time.
    let u_end = a + b * h + c * h * h / 2.0;
    assert!((get(&mut inst, U) - u_end).abs() < 1e-14);
    assert!((get(&mut inst, Y) - (x + u_end)).abs() < 1e-13);
    assert!((get(&mut inst, DER_X) - u_end).abs() < 1e-13);
    let mut dy = [0.0; 2];
    let got = inst.call(Call::GetRealOutputDerivatives, |i| {
        i.get_real_output_derivatives(&[Y, Z], &[1, 1], &mut dy)
    });
    assert_eq!(got, Status::Ok);
    assert!((dy[0] - (u_end + b + c * h)).abs() < 1e-13 && (dy[1] - u_end).abs() < 1e-13);
    let too_high = inst.call(Call::GetRealOutputDerivatives, |i| {
        i.get_real_output_derivatives(&[Y], &[2], &mut dy)
    });
    assert_eq!(too_high, Status::Error);
    // Setting the value resets the derivatives: the input is constant again.
    assert_eq!(
        inst.call(Call::SetReal, |i| i.set_real(&[U], &[1.0])),
        Status::Ok
    );
    assert_eq!(inst.data.inputs[0], InputJet::constant(1.0));
    let bad = inst.call(Call::SetRealInputDerivatives, |i| {
        i.set_real_input_derivatives(&[U], &[3], &[1.0])
    });
    assert_eq!(bad, Status::Error);
}

#[test]
fn value_access_checks_every_reference_before_it_touches_anything() {
    let mut inst = initialized(2.0);
    let message = |outcome: crate::instance::Outcome| outcome.unwrap_err().message;
    // One call may mix every kind of Real; outputs and derivatives are
    // evaluated for it (x = x0 = 1, u = 0, ẋ = u − k x = −2).
    let mut all = [f64::NAN; 7];
    inst.get_real(&[K, X0, U, Y, Z, 6, DER_X], &mut all)
        .unwrap();
    assert_eq!(all, [2.0, 1.0, 0.0, 1.0, 1.0, 1.0, -2.0]);
    // A bad reference anywhere in a get writes no value at all.
    let mut out = [f64::NAN; 2];
    let bad = message(inst.get_real(&[Y, 42], &mut out));
    assert_eq!(bad, "unknown value reference 42");
    assert!(out.iter().all(|v| v.is_nan()), "{out:?}");
    // Real references through the Integer and Boolean functions name the type.
    let wrong = message(inst.get_integer(&[K], &mut [0]));
    assert_eq!(
        wrong,
        "value reference 0 (k) is a Real variable, not Integer"
    );
    let wrong = message(inst.set_boolean(&[U], &[true]));
    assert_eq!(
        wrong,
        "value reference 3 (u) is a Real variable, not Boolean"
    );
    // A set refused at its last value changes none of the others.
    assert!(inst.set_real(&[U, Y], &[5.0, 1.0]).is_err());
    assert_eq!(inst.data.inputs[0], InputJet::constant(0.0));
    let not_input =
        message(inst.set_real_input_derivatives(&[U, U, Z], &[1, 2, 1], &[4.0, 5.0, 6.0]));
    assert_eq!(not_input, "z is not an input");
    assert!(inst
        .set_real_input_derivatives(&[U, U], &[1, 2], &[4.0, f64::INFINITY])
        .is_err());
    assert_eq!(inst.data.inputs[0], InputJet::constant(0.0));
    inst.set_real_input_derivatives(&[U, U], &[2, 1], &[5.0, 4.0])
        .unwrap();
    let jet = inst.data.inputs[0];
    assert_eq!((jet.value, jet.d1, jet.d2), (0.0, 4.0, 5.0));
}

#[test]
fn restoring_a_state_repeats_the_same_steps_bit_exactly() {
    let mut inst = initialized(2.0);
    step(&mut inst, 0.0, 0.1);
    let saved: Snapshot = inst.data.clone();
    step(&mut inst, 0.1, 0.1);
    let after = inst.data.clone();
    assert_eq!(
        inst.call(Call::SetFMUstate, |i| i.restore(&saved)),
        Status::Ok
    );
    assert_eq!(inst.data.time, 0.1);
    step(&mut inst, 0.1, 0.1);
    assert_eq!(inst.data, after);
    let bytes = saved.serialize(inst.fingerprint());
    let back =
        Snapshot::deserialize(&bytes, inst.fingerprint(), Instance::<Decay>::shape()).unwrap();
    assert_eq!(back, saved);
}

#[test]
fn logging_honours_logging_on_and_categories_but_always_reports_errors() {
    let (mut inst, log) = instance();
    inst.log(Status::Ok, "quiet");
    assert!(log.borrow().is_empty());
    let on = inst.call(Call::SetDebugLogging, |i| {
        i.set_debug_logging(true, &["logEvents"])
    });
    assert_eq!(on, Status::Ok);
    inst.log(Status::Ok, "loud");
    inst.log(Status::Warning, "filtered");
    assert_eq!(log.borrow().as_slice(), ["Ok logEvents loud"]);
    let bad = inst.call(Call::SetDebugLogging, |i| {
        i.set_debug_logging(true, &["logNothing"])
    });
    assert_eq!(bad, Status::Error);
    assert!(log.borrow()[1]
        .starts_with("Error logStatusError fmi2SetDebugLogging: unknown log category"));
}

/// ẋ = 1 with a parameter-set limit on the integrator's step; counts right-hand
/// side evaluations.
struct Limited {
    max_step: f64,
    evaluations: std::cell::Cell<u32>,
}

impl Model for Limited {
    const DECLARATION: Declaration = Declaration {
        model_name: "limited",
        model_identifier: "limited",
        description: "x' = 1",
        real_parameters: &[Real::new("max_step", 0.0).min(0.0)],
        outputs: &[Output::new("x").depends_on(&["x"])],
        states: &[State::new("x")],
        ..Declaration::EMPTY
    };

    fn new(p: &Parameters) -> Result<Self, String> {
        Ok(Limited {
            max_step: p.real("max_step")?,
            evaluations: Default::default(),
        })
    }
    fn initial_states(&self, x: &mut [f64]) {
        x[0] = 0.0;
    }
    fn derivatives(&self, _t: f64, _x: &[f64], _u: &[f64], dx: &mut [f64]) {
        self.evaluations.set(self.evaluations.get() + 1);
        dx[0] = 1.0;
    }
    fn outputs(&self, _t: f64, x: &[f64], _u: &[f64], y: &mut [f64]) {
        y[0] = x[0];
    }
    fn max_step(&self) -> Option<f64> {
        (self.max_step > 0.0).then_some(self.max_step)
    }
}

#[test]
fn max_step_limits_the_integrators_internal_step() {
    let evaluations = |max_step: f64| {
        let mut inst = Instance::<Limited>::new("limited", None, false);
        let ok = |s| assert_eq!(s, Status::Ok);
        ok(inst.call(Call::SetReal, |i| i.set_real(&[0], &[max_step])));
        ok(inst.call(
            Call::EnterInitializationMode,
            Instance::enter_initialization_mode,
        ));
        ok(inst.call(
            Call::ExitInitializationMode,
            Instance::exit_initialization_mode,
        ));
        let before = inst.model.as_ref().unwrap().evaluations.get();
        ok(inst.call(Call::DoStep, |i| i.do_step(0.0, 0.1)));
        assert!((inst.data.states[0] - 0.1).abs() < 1e-15);
        inst.model.as_ref().unwrap().evaluations.get() - before
    };
    let free = evaluations(0.0);
    let limited = evaluations(1e-3);
    // Dop853 takes 12 evaluations per step: at most 0.1 / 1e-3 = 100 steps' worth
    // are forced, while x' = 1 alone is integrated in a few steps.
    assert!(free < 200, "unlimited: {free} evaluations");
    assert!(limited >= 100 * 11, "max_step 1e-3: {limited} evaluations");
}
