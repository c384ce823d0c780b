//! Running fmpy (the reference FMI importer) from tests.
//!
//! Python comes from `TETHER_PYTHON` if set, else from a virtualenv at
//! `<root>/target/fmpy-venv` with `fmpy==0.3.32` and `pythonfmu3==0.3.4`, created once under a file lock so
//! parallel test binaries share it.

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The fmpy version the tests are written against.
pub const FMPY_VERSION: &str = "0.3.32";

/// The pythonfmu3 version the FMI 3.0 tests build their Python FMU with.
pub const PYTHONFMU3_VERSION: &str = "0.3.4";

/// The workspace root (the root test package's manifest directory).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `tests/fmpy/<name>`.
pub fn script(name: &str) -> PathBuf {
    workspace_root().join("tests").join("fmpy").join(name)
}

/// A Python interpreter that can `import fmpy`, else why not.
pub fn python() -> Result<PathBuf, String> {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            let python = match std::env::var_os("TETHER_PYTHON") {
                Some(python) => PathBuf::from(python),
                None => venv_python(&workspace_root().join("target"))?,
            };
            imports(&python, "fmpy")?;
            Ok(python)
        })
        .clone()
}

/// `Ok` if `python` can `import module`, else why not.
pub fn imports(python: &Path, module: &str) -> Result<(), String> {
    let out = Command::new(python)
        .args(["-c", &format!("import {module}")])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "{} cannot import {module}: {}",
            python.display(),
            String::from_utf8_lossy(&out.stderr)
                .trim()
                .lines()
                .last()
                .unwrap_or_default()
        ))
    }
}

/// The pinned libcosimpy (as `.ci/run` installs it).
const LIBCOSIMPY: &str = "libcosimpy==0.0.6";

/// The test Python if it can import libcosimpy, else why not. The tests'
/// own virtualenv (without `TETHER_PYTHON`) gets libcosimpy installed.
pub fn libcosim_python() -> Result<PathBuf, String> {
    let python = python()?;
    let module = "libcosimpy.CosimExecution";
    if imports(&python, module).is_err() && std::env::var_os("TETHER_PYTHON").is_none() {
        let pip = Command::new(&python)
            .args(["-m", "pip", "install", "--quiet", LIBCOSIMPY])
            .output()
            .map_err(|e| e.to_string())?;
        if !pip.status.success() {
            return Err(format!(
                "pip install {LIBCOSIMPY}: {}",
                String::from_utf8_lossy(&pip.stderr)
                    .trim()
                    .replace('\n', " ")
            ));
        }
    }
    imports(&python, module)?;
    Ok(python)
}

fn run(command: &mut Command) -> Result<(), String> {
    let shown = format!("{command:?}");
    let output = command
        .output()
        .map_err(|e| format!("cannot run {shown}: {e}"))?;
    if output.status.success() {
        Ok(())
    } else {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let tail: Vec<&str> = stderr.lines().rev().take(10).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        Err(format!(
            "{shown} failed ({}): {}",
            output.status,
            tail.join(" | ")
        ))
    }
}

fn venv_python(target: &Path) -> Result<PathBuf, String> {
    let venv = target.join("fmpy-venv");
    let python = venv.join("bin").join("python");
    let ready = venv.join(format!(
        ".fmpy-{FMPY_VERSION}-pythonfmu3-{PYTHONFMU3_VERSION}-installed"
    ));
    fs::create_dir_all(target).map_err(|e| format!("cannot create {}: {e}", target.display()))?;
    let lock_path = target.join("fmpy-venv.lock");
    let lock = File::create(&lock_path)
        .map_err(|e| format!("cannot create {}: {e}", lock_path.display()))?;
    lock.lock()
        .map_err(|e| format!("cannot lock {}: {e}", lock_path.display()))?;
    if !ready.exists() {
        if !python.exists() {
            run(Command::new("python3").arg("-m").arg("venv").arg(&venv))?;
        }
        run(Command::new(&python).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            &format!("fmpy=={FMPY_VERSION}"),
            &format!("pythonfmu3=={PYTHONFMU3_VERSION}"),
        ]))?;
        fs::write(&ready, "").map_err(|e| format!("cannot write {}: {e}", ready.display()))?;
    }
    Ok(python)
}

/// Runs `tests/fmpy/<script>` with `args` and returns its output (whatever the exit
/// status: callers assert on it).
pub fn run_script(script_name: &str, args: &[&std::ffi::OsStr]) -> Result<Output, String> {
    let python = python()?;
    let script = script(script_name);
    Command::new(&python)
        .arg(&script)
        .args(args)
        .output()
        .map_err(|e| format!("cannot run {} {}: {e}", python.display(), script.display()))
}

/// An FMI 3.0 FMU made by pythonfmu3 from `tests/fixtures/pythonfmu3/<name>.py`
/// (state handling and serialization on), and what a process that loads it
/// needs: the FMU embeds the interpreter, so that process preloads `libpython`
/// and finds the test Python's packages (numpy, for arrays) on `site_packages`.
#[derive(Debug, Clone)]
pub struct PythonFmu {
    /// The `.fmu`.
    pub fmu: PathBuf,
    /// The shared libpython of the Python that built it (`LD_PRELOAD`).
    pub libpython: PathBuf,
    /// That Python's site-packages (`PYTHONPATH`).
    pub site_packages: PathBuf,
}

impl PythonFmu {
    /// `command` with the environment the FMU needs.
    pub fn env<'a>(&self, command: &'a mut Command) -> &'a mut Command {
        command
            .env("LD_PRELOAD", &self.libpython)
            .env("PYTHONPATH", &self.site_packages)
    }
}

/// Builds the pythonfmu3 FMU of fixture `name` into `target/pythonfmu3/`.
pub fn pythonfmu3(name: &str) -> Result<PythonFmu, String> {
    let python = python()?;
    let root = workspace_root();
    let dir = root.join("target").join("pythonfmu3");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    run(Command::new(&python)
        .args(["-m", "pythonfmu3", "build", "-f"])
        .arg(root.join(format!("tests/fixtures/pythonfmu3/{name}.py")))
        .args([
            "--no-external-tool",
            "--handle-state",
            "--serialize-state",
            "-d",
        ])
        .arg(&dir))?;
    let ask = |code: &str| -> Result<String, String> {
        let out = Command::new(&python)
            .args(["-c", code])
            .output()
            .map_err(|e| e.to_string())?;
        let text = String::from_utf8_lossy(&out.stdout).trim().to_string();
        if out.status.success() && !text.is_empty() {
            Ok(text)
        } else {
            Err(format!("{} -c {code:?} failed", python.display()))
        }
    };
    let libpython = ask(
        "import sysconfig, os; d = sysconfig.get_config_var('LIBDIR'); \
         names = [sysconfig.get_config_var(k) for k in ('INSTSONAME', 'LDLIBRARY')]; \
         print(next(os.path.join(d, n) for n in names if n and os.path.exists(os.path.join(d, n))))",
    )
    .map_err(|e| format!("this Python has no shared libpython to preload ({e})"))?;
    let site_packages = ask("import sysconfig; print(sysconfig.get_paths()['purelib'])")?;
    Ok(PythonFmu {
        fmu: dir.join(format!("{name}.fmu")),
        libpython: PathBuf::from(libpython),
        site_packages: PathBuf::from(site_packages),
    })
}

/// [`pythonfmu3`] built once per process for a test: `None` (skip, with the reason
/// printed) without Python or pythonfmu3, unless `CI` is set: then it panics.
pub fn pythonfmu3_for_test(name: &str) -> Option<PythonFmu> {
    static BUILT: std::sync::Mutex<Vec<(String, Result<PythonFmu, String>)>> =
        std::sync::Mutex::new(Vec::new());
    let mut built = BUILT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let k = match built.iter().position(|(n, _)| n == name) {
        Some(k) => k,
        None => {
            built.push((name.to_string(), pythonfmu3(name)));
            built.len() - 1
        }
    };
    match &built[k].1 {
        Ok(fmu) => Some(fmu.clone()),
        Err(reason) if std::env::var_os("CI").is_some() => {
            panic!("the pythonfmu3 FMU {name} is needed on CI: {reason}")
        }
        Err(reason) => {
            eprintln!("skipped: no pythonfmu3 FMU {name} ({reason})");
            None
        }
    }
}
