//! Shared pieces of the benchmarks in `benches/overhead.rs`: the oscillator
//! system of `examples/oscillator.toml` in the variants measured, the C floor
//! (`c/floor.c`, built by `build.rs`), the fmpy loop and the fmpy reference.
//!
//! Run with `cargo bench -p tether-bench`; see docs/performance.md.

pub mod scale;

use std::ffi::{c_char, c_int, c_long, CString};
use std::path::{Path, PathBuf};
use std::process::Command;

use tether_fmi::Fmu;
use tether_master::{Method, StartValue, SystemSpec};

/// The median of `v` (the mean of the middle two for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("workspace root")
}

/// One measured configuration of the paper's oscillator pair.
#[derive(Debug, Clone, Copy)]
pub struct Case {
    /// Integrate exactly (matrix exponential) instead of with Dop853.
    pub exact: bool,
    /// Degree k of the coupling polynomials.
    pub order: usize,
    /// The coupling method.
    pub method: Method,
    /// Macro step H.
    pub step: f64,
    /// Number of macro steps.
    pub steps: u64,
}

impl Case {
    /// Method 1, index 1 (β = 2e-3, γ = 1e-6) as in examples/oscillator.toml.
    pub fn example(exact: bool, order: usize) -> Case {
        Case {
            exact,
            order,
            method: Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            step: 1e-3,
            steps: 1000,
        }
    }

    /// The system: examples/oscillator.toml with this case's settings.
    pub fn spec(&self) -> SystemSpec {
        tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
        let path = workspace_root().join("examples/oscillator.toml");
        let mut spec = SystemSpec::from_file(&path).expect("examples/oscillator.toml");
        for instance in &mut spec.instances {
            instance
                .parameters
                .insert("exact".into(), StartValue::Boolean(self.exact));
        }
        spec.method = self.method;
        spec.coupling.order = self.order;
        spec.experiment.step = self.step;
        spec.experiment.stop = spec.experiment.start + self.steps as f64 * self.step;
        spec
    }
}

/// Mirrors `FloorConfig` in c/floor.c.
#[repr(C)]
struct FloorConfig {
    library: *const c_char,
    guid: *const c_char,
    resources: *const c_char,
    m: [f64; 2],
    c: f64,
    d: f64,
    x0: f64,
    v0: f64,
    exact: c_int,
    order: c_int,
    beta: f64,
    gamma: f64,
    epsilon: f64,
    h: f64,
    start: f64,
    lambda0: f64,
    steps: c_long,
    vrs: [u32; 10],
}

/// Mirrors `FloorResult` in c/floor.c.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy)]
pub struct FloorResult {
    /// Wall time of the macro-step loop.
    pub seconds: f64,
    /// λ at the last macro point.
    pub lambda: f64,
    /// x of mass 1 at the last macro point.
    pub x1: f64,
    /// Per instance: doStep, getFMUstate, setFMUstate, setReal, getReal,
    /// setRealInputDerivatives.
    pub calls: [[c_long; 6]; 2],
}

extern "C" {
    fn tether_transport_roundtrip(kind: c_int, n: c_long, size: c_long) -> f64;
    fn tether_one_core(on: c_int) -> c_int;
    fn tether_probe_independent(n: c_long) -> f64;
    fn tether_probe_dependent(n: c_long) -> f64;
    fn tether_floor_run(
        cfg: *const FloorConfig,
        res: *mut FloorResult,
        err: *mut c_char,
        errlen: usize,
    ) -> c_int;
}

/// The host-state probe of c/probe.c, about 0.1 ms: nanoseconds per iteration
/// of eight interleaved integer chains (work that can run in parallel) and of
/// one dependent chain. When the host is busy the first rises (to about twice
/// its quiet value on the machine of docs/performance.md) while the second
/// stays.
pub fn host_probe() -> HostProbe {
    const N: c_long = 20_000;
    // SAFETY: both functions take a count and touch only their locals and a
    // static of c/probe.c.
    let (independent, dependent) =
        unsafe { (tether_probe_independent(N), tether_probe_dependent(N)) };
    HostProbe {
        independent,
        dependent,
    }
}

/// A transport between two processes (c/transport.c).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// Two pipes, one each way (what isolated instances use).
    Pipes,
    /// A Unix stream socket pair.
    SocketPair,
    /// Shared memory with a futex wait/wake handshake.
    SharedMemoryFutex,
    /// Shared memory, both sides spinning (two busy cores: a reference only).
    SharedMemorySpin,
    /// A TCP connection on 127.0.0.1 with TCP_NODELAY (what remote hosts use).
    TcpLoopback,
    /// Two pipes with both processes on one core: no other core to wake.
    PipesOnOneCore,
}

/// Microseconds per round trip of `size` bytes each way between this process
/// and a forked child over `transport`, averaged over `n` round trips.
pub fn transport_round_trip(transport: Transport, n: u32, size: usize) -> Result<f64, String> {
    let kind = transport as c_int;
    // SAFETY: the C function takes plain numbers; it forks a child that makes
    // only system calls and `_exit`s, and waits for it.
    let us = unsafe { tether_transport_roundtrip(kind, c_long::from(n), size as c_long) };
    if us < 0.0 {
        Err(format!("{transport:?}: the round trip failed"))
    } else {
        Ok(us)
    }
}

/// Runs `f` with this thread, and the processes it starts, on the core it
/// runs on now; the former set of cores is given back afterwards.
pub fn on_one_core<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    // SAFETY: the C function only calls sched_getcpu/sched_{get,set}affinity
    // on the calling thread.
    if unsafe { tether_one_core(1) } != 0 {
        return Err("cannot pin this thread to one core".into());
    }
    let value = f();
    // SAFETY: as above; gives back the set saved by the call before.
    unsafe { tether_one_core(0) };
    Ok(value)
}

/// What [`host_probe`] measured, ns per iteration.
#[derive(Debug, Clone, Copy)]
pub struct HostProbe {
    /// Eight interleaved add/xor chains (16 integer operations an iteration).
    pub independent: f64,
    /// One dependent multiply-add.
    pub dependent: f64,
}

/// The C floor for `case`: the same FMU binary (its own unpacked copy), the same
/// FMI calls and scalar arithmetic per macro step, starting from `lambda0`.
pub fn floor(case: &Case, fmu: &Fmu, lambda0: f64) -> Result<FloorResult, String> {
    let spec = case.spec();
    let Method::Baumgarte { beta, gamma } = case.method else {
        return Err("the C floor implements Method 1 (baumgarte) only".into());
    };
    let md = fmu.model_description();
    let vr = |name: &str| md.value_reference(name).map_err(|e| e.to_string());
    let real = |i: usize, name: &str| match spec.instances[i].parameters.get(name) {
        Some(StartValue::Real(v)) => Ok(*v),
        other => Err(format!("parameter {name} of instance {i}: {other:?}")),
    };
    let cstr = |s: &str| CString::new(s).map_err(|e| e.to_string());
    let library = cstr(&fmu.library_path().to_string_lossy())?;
    let guid = cstr(&md.guid)?;
    let resources = cstr(&fmu.resource_location())?;
    let cfg = FloorConfig {
        library: library.as_ptr(),
        guid: guid.as_ptr(),
        resources: resources.as_ptr(),
        m: [real(0, "m")?, real(1, "m")?],
        c: real(0, "c")?,
        d: real(0, "d")?,
        x0: real(0, "x0")?,
        v0: real(0, "v0")?,
        exact: c_int::from(case.exact),
        order: case.order as c_int,
        beta,
        gamma,
        epsilon: spec.coupling.epsilon,
        h: spec.experiment.step,
        start: spec.experiment.start,
        lambda0,
        steps: case.steps as c_long,
        vrs: [
            vr("m")?,
            vr("c")?,
            vr("d")?,
            vr("x0")?,
            vr("v0")?,
            vr("exact")?,
            vr("F")?,
            vr("x")?,
            vr("v")?,
            vr("a")?,
        ],
    };
    let mut result = FloorResult::default();
    let mut err = [0 as c_char; 256];
    // SAFETY: `cfg` and its strings outlive the call, `result` and `err` are
    // valid for writes of their sizes; the C side reads and writes nothing else
    // of ours.
    let status = unsafe { tether_floor_run(&cfg, &mut result, err.as_mut_ptr(), err.len()) };
    if status != 0 {
        let bytes: Vec<u8> = err
            .iter()
            .take_while(|&&c| c != 0)
            .map(|&c| c as u8)
            .collect();
        return Err(format!("C floor: {}", String::from_utf8_lossy(&bytes)));
    }
    Ok(result)
}

/// What the fmpy loop printed: its per-step time and final values.
#[derive(Debug, Clone, Copy)]
pub struct FmpyResult {
    /// Wall time of the loop per macro step, seconds.
    pub per_step: f64,
    /// λ at the last macro point.
    pub lambda: f64,
    /// x of mass 1 at the last macro point.
    pub x1: f64,
}

/// Run the fmpy loop `script` (a Python file) on `case` starting from `lambda0`.
///
/// The script is called as
/// `python SCRIPT --fmu F --steps N --step H --order K --exact 0|1 --beta B
/// --gamma G --epsilon E --lambda0 L` and prints one line
/// `per_step_s=<seconds> lambda=<value> x1=<value>` (other lines are ignored).
pub fn fmpy_loop(
    python: &Path,
    script: &Path,
    case: &Case,
    lambda0: f64,
) -> Result<FmpyResult, String> {
    let spec = case.spec();
    let Method::Baumgarte { beta, gamma } = case.method else {
        return Err("the fmpy loop implements Method 1 (baumgarte) only".into());
    };
    let output = Command::new(python)
        .arg(script)
        .arg("--fmu")
        .arg(&spec.instances[0].fmu)
        .args(["--steps", &case.steps.to_string()])
        .args(["--step", &format!("{:e}", spec.experiment.step)])
        .args(["--order", &case.order.to_string()])
        .args(["--exact", if case.exact { "1" } else { "0" }])
        .args(["--beta", &format!("{beta:e}")])
        .args(["--gamma", &format!("{gamma:e}")])
        .args(["--epsilon", &format!("{:e}", spec.coupling.epsilon)])
        .args(["--lambda0", &format!("{lambda0:e}")])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    succeeded(python, script, &output)?;
    let line = stdout
        .lines()
        .find(|l| l.starts_with("per_step_s="))
        .ok_or_else(|| format!("{} printed no per_step_s= line", script.display()))?;
    let field = |key: &str| -> Result<f64, String> {
        line.split_whitespace()
            .find_map(|kv| kv.strip_prefix(key))
            .and_then(|v| v.parse().ok())
            .ok_or_else(|| format!("no {key} in {line:?}"))
    };
    Ok(FmpyResult {
        per_step: field("per_step_s=")?,
        lambda: field("lambda=")?,
        x1: field("x1=")?,
    })
}

/// `Err` with the last line of the script's stderr unless it exited with 0.
fn succeeded(python: &Path, script: &Path, output: &std::process::Output) -> Result<(), String> {
    if output.status.success() {
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&output.stderr);
    Err(format!(
        "{} {} failed ({}): {}",
        python.display(),
        script.display(),
        output.status,
        stderr.lines().last().unwrap_or("")
    ))
}

/// What one run of the fmpy reference (`tools/fmpy_reference`) gave.
#[derive(Debug, Clone, Copy)]
pub struct ReferenceRun {
    /// Wall time of the whole process (Python start, imports, unpacking the
    /// FMU, setup, the run, writing the CSV), seconds.
    pub seconds: f64,
    /// `link.lambda` in the CSV's last row.
    pub lambda: f64,
}

impl Case {
    /// This case as a system file at `path`, for tools that read system files
    /// (the fmpy reference): examples/oscillator.toml with the FMU's absolute
    /// path and the `exact` parameter set. The method, order, step and stop
    /// are passed on the command line (see [`fmpy_reference`]).
    pub fn write_system(&self, path: &Path) -> Result<(), String> {
        let spec = self.spec();
        let example = workspace_root().join("examples/oscillator.toml");
        let text = std::fs::read_to_string(&example)
            .map_err(|e| format!("cannot read {}: {e}", example.display()))?;
        let fmu = format!("fmu = {:?}", spec.instances[0].fmu.display().to_string());
        let exact = format!("v0 = 100.0, exact = {} }}", self.exact);
        let edits = [
            (r#"fmu = "../target/fmus/oscillator.fmu""#, fmu.as_str()),
            ("v0 = 100.0 }", exact.as_str()),
        ];
        let mut text = text;
        for (from, to) in edits {
            if text.matches(from).count() != 2 {
                return Err(format!(
                    "{} no longer has two instances with `{from}`: update Case::write_system",
                    example.display()
                ));
            }
            text = text.replace(from, to);
        }
        std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
    }
}

/// Run the fmpy reference of `tether run` (`tools/fmpy_reference`, the one
/// docs/validation.md compares against) on the system file `system` for
/// `steps` macro steps of `case`, writing its CSV to `out`.
pub fn fmpy_reference(
    python: &Path,
    system: &Path,
    case: &Case,
    steps: u64,
    out: &Path,
) -> Result<ReferenceRun, String> {
    let Method::Baumgarte { beta, gamma } = case.method else {
        return Err("the reference bench uses Method 1 (baumgarte) only".into());
    };
    let script = workspace_root().join("tools/fmpy_reference");
    let start = case.spec().experiment.start;
    let clock = std::time::Instant::now();
    let output = Command::new(python)
        .arg(&script)
        .arg(system)
        .args(["--method", "baumgarte"])
        .args(["--beta", &format!("{beta:e}")])
        .args(["--gamma", &format!("{gamma:e}")])
        .args(["--order", &case.order.to_string()])
        .args(["--step", &format!("{:e}", case.step)])
        .args(["--stop", &format!("{:e}", start + steps as f64 * case.step)])
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    let seconds = clock.elapsed().as_secs_f64();
    succeeded(python, &script, &output)?;
    Ok(ReferenceRun {
        seconds,
        lambda: last_value(out, "link.lambda")?,
    })
}

/// The value of column `name` in the last row of the CSV file `path`.
pub fn last_value(path: &Path, name: &str) -> Result<f64, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().unwrap_or("");
    let column = header
        .split(',')
        .position(|c| c == name)
        .ok_or_else(|| format!("{} has no column {name}", path.display()))?;
    let last = lines
        .last()
        .ok_or_else(|| format!("{} has no rows", path.display()))?;
    last.split(',')
        .nth(column)
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| format!("{}: no number in column {name} of {last:?}", path.display()))
}

/// Closed form of the coupled oscillator of examples/oscillator.toml (one
/// damped oscillator with m = m1 + m2, c = c1 + c2, d = d1 + d2, as in
/// tests/master_oscillator.rs): (x, v) at time t.
pub fn reference(t: f64) -> (f64, f64) {
    const M1: f64 = 1.0;
    const M2: f64 = 2.0;
    const C: f64 = 1000.0;
    const D: f64 = 10.0;
    const V0: f64 = 100.0;
    let (m, c, d) = (M1 + M2, 2.0 * C, 2.0 * D);
    let delta = d / (2.0 * m);
    let wd = (c / m - delta * delta).sqrt();
    let (s, co, e) = ((wd * t).sin(), (wd * t).cos(), (-delta * t).exp());
    (e * V0 / wd * s, e * V0 * (co - delta / wd * s))
}

/// Observer tracking the max state error max(|x1 − x|, |v1 − v|) against [`reference`].
#[derive(Debug, Default)]
pub struct StateError {
    columns: Option<(usize, usize)>,
    /// The largest error so far.
    pub max: f64,
}

impl tether_master::Observer for StateError {
    fn start(&mut self, columns: &[String]) -> std::io::Result<()> {
        let find = |name: &str| columns.iter().position(|c| c == name);
        self.columns = find("mass1.x").zip(find("mass1.v"));
        Ok(())
    }

    fn sample(&mut self, sample: tether_master::Sample<'_>) -> std::io::Result<()> {
        let (ix, iv) = self.columns.expect("columns mass1.x and mass1.v");
        let (x, v) = reference(sample.time);
        let e = (sample.values[ix] - x)
            .abs()
            .max((sample.values[iv] - v).abs());
        self.max = self.max.max(e);
        Ok(())
    }

    fn finish(&mut self, _failure: Option<&str>) -> std::io::Result<()> {
        Ok(())
    }
}

/// The rigid pair of `case` as the system file of an exported FMU
/// (`tether fmu export`, docs/fmu-export.md), written into `resources` with
/// its [export] table (input F on mass 1, outputs x, v, a and the multiplier)
/// and sequential perturbed runs, as the exported FMU runs them. Returns the
/// system and the FMU's GUID (the hash of the file's text).
pub fn exported_system(case: &Case, resources: &Path) -> Result<(SystemSpec, String), String> {
    let mut spec = case.spec();
    spec.coupling.parallel = tether_master::Parallel::Off;
    let mut text = toml::to_string(&spec).map_err(|e| e.to_string())?;
    text.push_str(
        "\n[export]\nmodel_name = \"rigid_pair\"\n\
         [[export.input]]\nname = \"F\"\nto = \"mass1.F_ext\"\n\
         [[export.output]]\nname = \"x\"\nfrom = \"mass1.x\"\n\
         [[export.output]]\nname = \"v\"\nfrom = \"mass1.v\"\n\
         [[export.output]]\nname = \"a\"\nfrom = \"mass1.a\"\n\
         [[export.output]]\nname = \"lambda\"\nfrom = \"link.lambda\"\n",
    );
    let file = resources.join(tether_fmu_export::SYSTEM_FILE);
    std::fs::write(&file, &text).map_err(|e| format!("{}: {e}", file.display()))?;
    Ok((spec, tether_fmu_export::description::guid(&text)))
}

/// The exported FMU's runtime library (the binary `tether fmu export`
/// packs), built with this bench.
pub fn export_runtime() -> Result<PathBuf, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let name = "libtether_fmu_export.so";
    exe.ancestors()
        .skip(1)
        .take(2)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
        .ok_or_else(|| format!("{name} is not beside {}", exe.display()))
}

/// A native FMI 2.0 importer of the exported FMU: the runtime library loaded
/// with libloading, one instance on the system in `resources`.
pub struct ExportedFmu {
    library: libloading::Library,
    component: tether_fmi::raw::fmi2Component,
    _callbacks: Box<tether_fmi::raw::fmi2CallbackFunctions>,
}

type Fmi2Status = tether_fmi::raw::fmi2Status;

impl ExportedFmu {
    /// Load `library`, instantiate on `resources` (with `guid`) and
    /// initialize from t = 0.
    pub fn new(library: &Path, resources: &Path, guid: &str) -> Result<ExportedFmu, String> {
        use tether_fmi::raw::{fmi2CallbackFunctions, fmi2Component, fmi2String};
        // SAFETY: loading the exported FMU's runtime, a Rust cdylib whose
        // initialisers only set up its own statics.
        let library = unsafe { libloading::Library::new(library) }.map_err(|e| e.to_string())?;
        let callbacks = Box::new(fmi2CallbackFunctions {
            logger: None,
            allocateMemory: None,
            freeMemory: None,
            stepFinished: None,
            componentEnvironment: std::ptr::null_mut(),
        });
        let uri = format!("file://{}/", resources.display());
        let texts = ["bench", guid, &uri].map(|t| CString::new(t).expect("no NUL"));
        type Instantiate = unsafe extern "C" fn(
            fmi2String,
            c_int,
            fmi2String,
            fmi2String,
            *const fmi2CallbackFunctions,
            c_int,
            c_int,
        ) -> fmi2Component;
        // SAFETY: the FMI 2.0 signature of fmi2Instantiate; the strings and
        // the callbacks outlive the call (the callbacks the instance).
        let component = unsafe {
            let instantiate = library
                .get::<Instantiate>(b"fmi2Instantiate")
                .map_err(|e| e.to_string())?;
            instantiate(
                texts[0].as_ptr(),
                1,
                texts[1].as_ptr(),
                texts[2].as_ptr(),
                &*callbacks,
                0,
                0,
            )
        };
        if component.is_null() {
            return Err("fmi2Instantiate returned NULL".into());
        }
        let fmu = ExportedFmu {
            library,
            component,
            _callbacks: callbacks,
        };
        type Setup =
            unsafe extern "C" fn(*mut std::ffi::c_void, c_int, f64, f64, c_int, f64) -> Fmi2Status;
        type Mode = unsafe extern "C" fn(*mut std::ffi::c_void) -> Fmi2Status;
        // SAFETY: FMI 2.0 signatures, called on the live instance in order.
        let status = unsafe {
            let setup = fmu.symbol::<Setup>(b"fmi2SetupExperiment")?;
            let enter = fmu.symbol::<Mode>(b"fmi2EnterInitializationMode")?;
            let exit = fmu.symbol::<Mode>(b"fmi2ExitInitializationMode")?;
            [
                setup(fmu.component, 0, 0.0, 0.0, 0, 0.0),
                enter(fmu.component),
                exit(fmu.component),
            ]
        };
        match status.iter().find(|&&s| s != 0) {
            Some(s) => Err(format!("initialization returned status {s}")),
            None => Ok(fmu),
        }
    }

    /// # Safety
    /// `T` is the symbol's C signature.
    unsafe fn symbol<T: Copy>(&self, name: &[u8]) -> Result<T, String> {
        // SAFETY: per the contract, T is the symbol's type.
        unsafe { self.library.get::<T>(name) }
            .map(|s| *s)
            .map_err(|e| e.to_string())
    }

    /// `steps` calls of `fmi2DoStep(t, h)`, each followed by one
    /// `fmi2GetReal` of `outputs` into `values`; the wall time in seconds.
    pub fn run(
        &mut self,
        h: f64,
        steps: u64,
        outputs: &[u32],
        values: &mut [f64],
    ) -> Result<f64, String> {
        type DoStep = unsafe extern "C" fn(*mut std::ffi::c_void, f64, f64, c_int) -> Fmi2Status;
        type GetReal =
            unsafe extern "C" fn(*mut std::ffi::c_void, *const u32, usize, *mut f64) -> Fmi2Status;
        // SAFETY: FMI 2.0 signatures.
        let (do_step, get_real) = unsafe {
            (
                self.symbol::<DoStep>(b"fmi2DoStep")?,
                self.symbol::<GetReal>(b"fmi2GetReal")?,
            )
        };
        let n = outputs.len().min(values.len());
        let clock = std::time::Instant::now();
        for i in 0..steps {
            let t = i as f64 * h;
            // SAFETY: the live instance; `n` value references and values.
            let status = unsafe {
                do_step(self.component, t, h, 1)
                    | get_real(self.component, outputs.as_ptr(), n, values.as_mut_ptr())
            };
            if status != 0 {
                return Err(format!("step {i} at t = {t}: status {status}"));
            }
        }
        Ok(clock.elapsed().as_secs_f64())
    }
}

impl Drop for ExportedFmu {
    fn drop(&mut self) {
        type Free = unsafe extern "C" fn(*mut std::ffi::c_void);
        // SAFETY: the FMI 2.0 signature; the instance is freed once, here.
        if let Ok(free) = unsafe { self.symbol::<Free>(b"fmi2FreeInstance") } {
            // SAFETY: as above.
            unsafe { free(self.component) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_written_system_file_is_the_case() {
        let dir = tempfile::tempdir().expect("temporary directory");
        for exact in [true, false] {
            let case = Case::example(exact, 1);
            let path = dir.path().join("system.toml");
            case.write_system(&path).expect("write the system file");
            let written = SystemSpec::from_file(&path).expect("the written file reads back");
            let expected = case.spec();
            assert_eq!(written.instances.len(), expected.instances.len());
            for (w, e) in written.instances.iter().zip(&expected.instances) {
                assert_eq!(w.name, e.name);
                assert!(w.fmu.is_absolute() && w.fmu.exists(), "{}", w.fmu.display());
                assert_eq!(w.fmu.canonicalize().ok(), e.fmu.canonicalize().ok());
                assert_eq!(w.parameters, e.parameters, "instance {}", w.name);
            }
        }
    }

    #[test]
    fn last_value_reads_the_named_column_of_the_last_row() {
        let dir = tempfile::tempdir().expect("temporary directory");
        let path = dir.path().join("out.csv");
        std::fs::write(
            &path,
            "time,link.lambda,link.g\n0.0,1.5,0.0\n0.001,333.25,-2e-9\n",
        )
        .expect("write");
        assert_eq!(last_value(&path, "link.lambda"), Ok(333.25));
        assert_eq!(last_value(&path, "link.g"), Ok(-2e-9));
        let missing = last_value(&path, "link.x").unwrap_err();
        assert!(missing.contains("has no column link.x"), "{missing}");
        std::fs::write(&path, "time,link.lambda\n").expect("write");
        assert!(last_value(&path, "link.lambda")
            .unwrap_err()
            .contains("has no rows"));
    }
}
