//! A model-exchange-only FMU (no co-simulation functions in its library),
//! compiled from `tests/fixtures/fmi/me_sawtooth.c`: it opens and runs as a
//! model-exchange instance, is refused as co-simulation in one line, and its
//! faults (an error status, a chattering event, a request to terminate) each
//! end a step with one line naming the instance, the time and the cause.

use tether_fmi::{instantiate, Error, Fmu, FmuInstance, Integrator, MeInstance, Placement};
use tether_tests::fmi::me_sawtooth_fmu as sawtooth;

/// A model-exchange instance with `mode` set, initialized at t = 0.
fn started(fmu: &Fmu, mode: i128) -> MeInstance {
    let mut a = MeInstance::new(fmu, "saw", Default::default(), Integrator::default()).unwrap();
    a.setup(Some(1e-8), 0.0, Some(5.0)).unwrap();
    a.enter_initialization().unwrap();
    a.set_integers(&[2], &[mode]).unwrap();
    a.exit_initialization().unwrap();
    a
}

/// Steps of 0.25 until an error or t = 5: the last time reached and the error.
fn run(a: &mut MeInstance) -> (f64, Option<Error>) {
    let mut t = 0.0;
    for n in 0..20 {
        if let Err(e) = a.step(t, 0.25) {
            return (t, Some(e));
        }
        t = (n + 1) as f64 * 0.25;
    }
    (t, None)
}

#[test]
fn a_model_exchange_only_fmu_runs_its_state_events() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    assert!(fmu.model_description().co_simulation.is_none());
    let mut a = started(&fmu, 0);
    let mut worst: f64 = 0.0;
    let mut t = 0.0;
    for n in 0..13 {
        a.step(t, 0.35).unwrap();
        t = (n + 1) as f64 * 0.35;
        let mut x = [0.0];
        a.get_reals(&[0], &mut x).unwrap();
        // x(t) = 1 − (t − ⌊t⌋) between the events at whole seconds (the grid
        // points are off the events).
        let expected = 1.0 - (t - t.floor());
        worst = worst.max((x[0] - expected).abs());
    }
    let mut events = [0];
    a.get_integers(&[3], &mut events).unwrap();
    assert_eq!(events[0], 4, "events at t = 1, 2, 3, 4 (t = 4.55 reached)");
    assert_eq!(a.events(), (4, a.events().1));
    // Each event is located just after its crossing, to 100·ε·max(|t|, h); the
    // sawtooth restarts from it, so the fourth is late by at most the sum of
    // the four resolutions (measured 8.5e-14 s).
    let last = a.events().1.unwrap();
    let late = last - 4.0;
    assert!(
        (0.0..=100.0 * f64::EPSILON * (1.0 + 2.0 + 3.0 + 4.0)).contains(&late),
        "{last}"
    );
    // x' = −1 is integrated exactly; the events are located to 100·ε·t
    // (measured 8.6e-14).
    assert!(worst < 1e-12, "{worst:e}");
    a.terminate().unwrap();
}

#[test]
fn a_model_exchange_only_fmu_is_refused_as_co_simulation() {
    let dir = tempfile::tempdir().unwrap();
    let path = sawtooth(dir.path());
    let fmu = Fmu::open(&path).unwrap();
    let e = instantiate(&fmu, "saw", Default::default(), Placement::InProcess).unwrap_err();
    assert!(matches!(e, Error::NotCoSimulation { .. }), "{e:?}");
    let line = e.to_string();
    assert!(
        line.contains("model-exchange-only")
            && line.contains("--fmi-type model-exchange")
            && !line.contains('\n'),
        "{line}"
    );
}

#[test]
fn a_chattering_event_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    // Mode 1 asks for new discrete states forever, from the initialization on.
    let mut a = MeInstance::new(&fmu, "saw", Default::default(), Integrator::default()).unwrap();
    a.setup(None, 0.0, Some(5.0)).unwrap();
    a.enter_initialization().unwrap();
    a.set_integers(&[2], &[1]).unwrap();
    let e = a.exit_initialization().unwrap_err();
    let line = e.to_string();
    assert!(
        matches!(e, Error::ModelExchange { time, .. } if time == 0.0),
        "{e:?}"
    );
    assert!(
        line.contains("'saw'")
            && line.contains("t = 0")
            && line.contains("more than 100 event iterations")
            && line.contains("chatters")
            && !line.contains('\n'),
        "{line}"
    );
}

#[test]
fn an_error_status_of_the_derivatives_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    let mut a = started(&fmu, 2);
    let (t, e) = run(&mut a);
    let e = e.expect("an error after t = 0.5");
    assert_eq!(t, 0.5, "the step from 0.5 fails");
    let line = e.to_string();
    assert!(matches!(e, Error::Failed { .. }), "{e:?}");
    assert!(
        line.contains("fmi2GetDerivatives")
            && line.contains("'saw'")
            && line.contains("the derivative fails")
            && !line.contains('\n'),
        "{line}"
    );
}

#[test]
fn a_request_to_terminate_ends_at_the_event() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    let mut a = started(&fmu, 3);
    let (_, e) = run(&mut a);
    match e {
        Some(Error::TerminationRequested { time, how, .. }) => {
            // The state event at t = 1, located to 100·ε·max(|t|, h).
            assert!((time - 1.0).abs() <= 100.0 * f64::EPSILON, "{time}");
            assert_eq!(
                how.as_deref(),
                Some("fmi2NewDiscreteStates, terminateSimulation")
            );
        }
        other => panic!("{other:?}"),
    }
}

/// Without FMU states (the sawtooth declares none) a saved state is the
/// instance's own: time, continuous states, indicators. Going back repeats a
/// step bit for bit while no event fell inside it (the FMU declares
/// `completedIntegratorStepNotNeeded`); after the event at t = 1 the FMU's
/// discrete state has moved and going back is one error line naming the
/// instance, the times and the cause. No serialized state.
#[test]
fn without_fmu_states_a_step_is_repeated_until_an_event() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = Fmu::open(sawtooth(dir.path())).unwrap();
    let mut a = started(&fmu, 0);
    assert!(a.capabilities().rollback && !a.capabilities().serialization);
    let x = |a: &mut MeInstance| {
        let mut out = [0.0];
        a.get_reals(&[1], &mut out).unwrap();
        out[0].to_bits()
    };
    a.step(0.0, 0.5).unwrap();
    a.save(0).unwrap();
    a.step(0.5, 0.25).unwrap();
    let first = x(&mut a);
    a.restore(0).unwrap();
    a.step(0.5, 0.25).unwrap();
    assert_eq!(x(&mut a), first);
    a.save(0).unwrap();
    a.step(0.75, 0.5).unwrap();
    let e = a.restore(0).unwrap_err();
    let line = e.to_string();
    assert!(matches!(e, Error::ModelExchange { .. }), "{e:?}");
    assert!(
        line.contains("'saw'")
            && line.contains("cannot go back to t = 0.75")
            && line.contains("an event at t = 1")
            && line.contains("canGetAndSetFMUstate")
            && !line.contains('\n'),
        "{line}"
    );
    let mut bytes = Vec::new();
    assert!(a.serialize(0, &mut bytes).is_err());
}
