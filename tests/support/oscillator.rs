//! The paper's two-mass oscillator (Sect. 2 and 4.1) and its closed form, for
//! the tests that run it (tests/master_oscillator.rs, tests/adaptive_steps.rs).
//!
//! The coupled system is one damped oscillator with m = m1 + m2, c = c1 + c2,
//! d = d1 + d2, so x(t), v(t) and λ(t) are known exactly (EXAMPLES.md §1). The
//! FMUs integrate exactly (`exact = true`), so every error measured with it is
//! the coupling error.

use tether_master::{MasterError, MemoryRecorder, Simulation, SystemSpec};

pub const M1: f64 = 1.0;
pub const M2: f64 = 2.0;
pub const C: f64 = 1000.0;
pub const D: f64 = 10.0;
pub const V0: f64 = 100.0;

/// Closed form of the coupled oscillator: (x, v, λ) at time t.
pub fn reference(t: f64) -> (f64, f64, f64) {
    let (m, c, d) = (M1 + M2, 2.0 * C, 2.0 * D);
    let delta = d / (2.0 * m);
    let wd = (c / m - delta * delta).sqrt();
    let (s, co, e) = ((wd * t).sin(), (wd * t).cos(), (-delta * t).exp());
    let x = e * V0 / wd * s;
    let v = e * V0 * (co - delta / wd * s);
    let lambda = M1 * M2 / (M1 + M2) * ((C / M1 - C / M2) * x + (D / M1 - D / M2) * v);
    (x, v, lambda)
}

pub fn system(method: &str, order: usize, h: f64, stop: f64) -> SystemSpec {
    system_with(method, order, h, stop, "")
}

/// [`system`] with `keys` (TOML lines) added to both instances, such as
/// `fmi_type = "model_exchange"`.
pub fn system_with(method: &str, order: usize, h: f64, stop: f64, keys: &str) -> SystemSpec {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    let text = format!(
        r#"
        [experiment]
        stop = {stop}
        step = {h}

        [method]
        {method}

        [coupling]
        order = {order}

        [[instance]]
        name = "mass1"
        fmu = "{fmu}"
        parameters = {{ m = {M1}, c = {C}, d = {D}, x0 = 0.0, v0 = {V0}, exact = true }}
        {keys}

        [[instance]]
        name = "mass2"
        fmu = "{fmu}"
        parameters = {{ m = {M2}, c = {C}, d = {D}, x0 = 0.0, v0 = {V0}, exact = true }}
        {keys}

        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        velocity = "mass2.v - mass1.v"
        acceleration = "mass2.a - mass1.a"
        drives = "mass1.F - mass2.F"
        "#,
        fmu = fmu.display()
    );
    SystemSpec::from_toml(&text).expect("valid system")
}

pub fn run(spec: &SystemSpec) -> Result<MemoryRecorder, MasterError> {
    let mut sim = Simulation::new(spec)?;
    let mut rec = MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {})?;
    Ok(rec)
}

/// Max-norm errors of x1, v1 and λ over the whole run.
#[derive(Debug, Clone, Copy)]
pub struct Errors {
    pub x: f64,
    pub v: f64,
    pub lambda: f64,
}

impl Errors {
    /// The global state error: the larger of the x1 and v1 errors.
    pub fn state(&self) -> f64 {
        self.x.max(self.v)
    }
}

pub fn errors(rec: &MemoryRecorder) -> Errors {
    let (x1, v1, lam) = (
        rec.series("mass1.x").unwrap(),
        rec.series("mass1.v").unwrap(),
        rec.series("link.lambda").unwrap(),
    );
    let mut e = Errors {
        x: 0.0,
        v: 0.0,
        lambda: 0.0,
    };
    for (i, &t) in rec.times.iter().enumerate() {
        let (x, v, l) = reference(t);
        e.x = e.x.max((x1[i] - x).abs());
        e.v = e.v.max((v1[i] - v).abs());
        e.lambda = e.lambda.max((lam[i] - l).abs());
    }
    e
}

pub const VARIANTS: [(&str, &str); 6] = [
    (
        "baumgarte index 1",
        "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6",
    ),
    ("baumgarte index 2", "kind = \"baumgarte\"\nbeta = 2e-3"),
    ("baumgarte index 3", "kind = \"baumgarte\""),
    ("weighted index 1", "kind = \"weighted\"\na = 1.0\nb = 1.0"),
    ("weighted index 2", "kind = \"weighted\"\na = 1.0"),
    ("weighted index 3", "kind = \"weighted\""),
];
