//! FMU states of the oscillator: restoring reproduces the run bit for bit, a serialized
//! state continues bit for bit in another instance, and get/free/update cycles do not
//! leak.

use tether_fmi::{Error, Fmu, Instance, InstanceOptions, ValueReference};
use tether_tests::fmi::{assert_one_line_naming, oscillator_fmu, rss_bytes};

const H: f64 = 1e-3;

/// The tests of this file run one at a time: the memory test measures the whole
/// process's RSS, which concurrent tests (loading FMUs) would disturb.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

struct Rig {
    inst: Instance,
    f: ValueReference,
    outputs: [ValueReference; 3],
}

/// An initialized oscillator instance (Dop853 unless `exact`).
fn rig(fmu: &Fmu, name: &str, exact: bool) -> Rig {
    let md = fmu.model_description();
    let vr = |n: &str| md.value_reference(n).expect("oscillator variable");
    let mut inst = fmu
        .instantiate(name, InstanceOptions::default())
        .expect("instantiate");
    inst.setup_experiment(None, 0.0, Some(10.0)).expect("setup");
    inst.set_real(&[vr("x0"), vr("v0"), vr("d")], &[0.3, -2.0, 3.0])
        .expect("parameters");
    inst.set_boolean(&[vr("exact")], &[exact]).expect("exact");
    inst.enter_initialization_mode().expect("enter init");
    inst.exit_initialization_mode().expect("exit init");
    Rig {
        inst,
        f: vr("F"),
        outputs: [vr("x"), vr("v"), vr("a")],
    }
}

impl Rig {
    /// Steps n macro steps from step index k0 with a polynomial force, returning the
    /// bit patterns of every output after every step.
    fn run(&mut self, k0: usize, n: usize) -> Vec<u64> {
        let mut bits = Vec::with_capacity(3 * n);
        let mut y = [0.0; 3];
        for k in k0..k0 + n {
            let t = k as f64 * H;
            let force = 10.0 * (1.0 + t - 2.0 * t * t);
            self.inst.set_real(&[self.f], &[force]).expect("F");
            self.inst
                .set_real_input_derivatives(&[self.f, self.f], &[1, 2], &[10.0 - 40.0 * t, -40.0])
                .expect("input derivatives");
            self.inst.do_step(t, H, false).expect("do_step");
            self.inst.get_real(&self.outputs, &mut y).expect("outputs");
            bits.extend(y.iter().map(|v| v.to_bits()));
        }
        bits
    }
}

#[test]
fn restoring_a_state_reproduces_the_following_steps_bit_for_bit() {
    let _serial = serial();
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    for exact in [false, true] {
        let mut r = rig(&fmu, "a", exact);
        r.run(0, 250);
        let saved = r.inst.get_fmu_state().expect("get state");
        assert_eq!(saved.time(), Some(0.25));
        let first = r.run(250, 100);
        r.inst.set_fmu_state(&saved).expect("set state");
        assert_eq!(r.inst.time(), 0.25);
        let second = r.run(250, 100);
        assert!(first == second, "exact={exact}: replay differs");
        // The same through a state updated in place.
        let mut reused = saved;
        r.inst.set_fmu_state(&reused).expect("set state");
        r.inst.update_fmu_state(&mut reused).expect("update state");
        let third = r.run(250, 100);
        r.inst.set_fmu_state(&reused).expect("set state");
        assert!(
            third == r.run(250, 100) && third == first,
            "exact={exact}: update differs"
        );
    }
}

#[test]
fn a_serialized_state_continues_bit_for_bit_in_a_second_instance() {
    let _serial = serial();
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let mut a = rig(&fmu, "a", false);
    a.run(0, 250);
    let state = a.inst.get_fmu_state().expect("get state");
    let bytes = a.inst.serialize_fmu_state(&state).expect("serialize");
    assert!(!bytes.is_empty());
    let mut again = Vec::new();
    a.inst
        .serialize_fmu_state_into(&state, &mut again)
        .expect("serialize into");
    assert_eq!(bytes, again);

    // A differently-parameterised second instance: the state carries everything.
    let mut b = rig(&fmu, "b", true);
    b.run(0, 10);
    let restored = b.inst.deserialize_fmu_state(&bytes).expect("deserialize");
    assert_eq!(restored.instance_name(), "b");
    b.inst
        .set_fmu_state(&restored)
        .expect("set deserialized state");
    assert!(
        a.run(250, 100) == b.run(250, 100),
        "second instance differs"
    );
}

#[test]
fn a_state_of_another_instance_is_refused_with_a_typed_error() {
    let _serial = serial();
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let mut a = rig(&fmu, "a", false);
    let mut b = rig(&fmu, "b", false);
    let mut of_a = a.inst.get_fmu_state().expect("state");
    for err in [
        b.inst.set_fmu_state(&of_a).unwrap_err(),
        b.inst.update_fmu_state(&mut of_a).unwrap_err(),
        b.inst.serialize_fmu_state(&of_a).unwrap_err(),
    ] {
        match &err {
            Error::ForeignState {
                instance, owner, ..
            } => assert_eq!((instance.as_str(), owner.as_str()), ("b", "a")),
            other => panic!("{other:?}"),
        }
        assert_one_line_naming(&err, &["'a'", "'b'"]);
    }
    // Another FMU's instance is refused the same way.
    let other = Fmu::open(oscillator_fmu()).expect("open again");
    let mut c = rig(&other, "c", false);
    assert!(matches!(
        c.inst.set_fmu_state(&of_a),
        Err(Error::ForeignState { .. })
    ));
    a.inst
        .set_fmu_state(&of_a)
        .expect("its own instance accepts it");
}

/// Repeats `cycle` and returns the RSS growth in bytes over `n` cycles, after a warm-up
/// that lets the allocator reach its steady state.
fn rss_growth(n: usize, mut cycle: impl FnMut()) -> u64 {
    for _ in 0..n / 10 {
        cycle();
    }
    let before = rss_bytes();
    for _ in 0..n {
        cycle();
    }
    rss_bytes().saturating_sub(before)
}

#[test]
fn state_get_free_and_update_cycles_do_not_grow_memory() {
    let _serial = serial();
    const CYCLES: usize = 100_000;
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let mut r = rig(&fmu, "a", false);
    r.run(0, 10);
    let probe = r.inst.get_fmu_state().expect("state");
    let state_bytes = r.inst.serialize_fmu_state(&probe).expect("size").len() as u64;
    // Leaking every state would cost at least this much; allow a tenth of it (and at
    // least the serialized size must make that bound meaningful: > 4 MiB).
    let leak_floor = state_bytes * CYCLES as u64;
    assert!(
        leak_floor > 4 << 20,
        "state too small for a meaningful bound: {state_bytes} B"
    );
    let bound = leak_floor / 10;

    let inst = &mut r.inst;
    let grew = rss_growth(CYCLES, || drop(inst.get_fmu_state().expect("get")));
    assert!(
        grew < bound,
        "get/free grew RSS by {grew} B (bound {bound} B)"
    );

    let mut reused = inst.get_fmu_state().expect("get");
    let grew = rss_growth(CYCLES, || {
        inst.update_fmu_state(&mut reused).expect("update")
    });
    assert!(
        grew < bound,
        "update grew RSS by {grew} B (bound {bound} B)"
    );

    let grew = rss_growth(CYCLES / 10, || {
        let bytes = inst.serialize_fmu_state(&reused).expect("serialize");
        drop(inst.deserialize_fmu_state(&bytes).expect("deserialize"));
    });
    assert!(
        grew < bound / 10,
        "serialize/deserialize grew RSS by {grew} B"
    );
}
