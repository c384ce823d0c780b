//! `tether new A.fmu B.fmu [--out system.toml]`: a starter system file that
//! runs as written — the instances, their parameters as comments with start
//! values and units, their outputs and inputs, connections to start from
//! (commented) and the experiment from the FMUs' default experiments.

use std::fmt::Write as _;
use std::path::{Component, Path, PathBuf};

use anyhow::{bail, Result};
use tether_fmi::{
    Causality, Fmu, ModelDescription, ScalarVariable, Values, Variability, VariableKind,
};

#[derive(clap::Args)]
pub struct Args {
    /// The FMUs (`.fmu` files or unpacked FMU folders), one instance each.
    #[arg(required = true, num_args = 1..)]
    fmus: Vec<PathBuf>,
    /// The system file to write (not overwritten; default: standard output,
    /// FMU paths relative to the current folder).
    #[arg(long, short)]
    out: Option<PathBuf>,
}

pub fn main(args: Args) -> Result<()> {
    if let Some(out) = &args.out {
        if out.symlink_metadata().is_ok() {
            bail!(
                "{} exists: tether new does not overwrite it (choose another --out, or remove it)",
                out.display()
            );
        }
    }
    let opened: Vec<Fmu> = args.fmus.iter().map(Fmu::open).collect::<Result<_, _>>()?;
    // FMU paths as the system file resolves them: against its folder.
    let folder = match &args.out {
        Some(out) => absolute(out.parent().unwrap_or(Path::new(""))),
        None => absolute(Path::new("")),
    };
    // An FMU named by an absolute path keeps it; a relative one is made
    // relative to the system file's folder.
    let paths: Vec<String> = args
        .fmus
        .iter()
        .map(|p| {
            if p.is_absolute() {
                p.display().to_string()
            } else {
                relative(&absolute(p), &folder).display().to_string()
            }
        })
        .collect();
    let mds: Vec<&ModelDescription> = opened.iter().map(Fmu::model_description).collect();
    let text = starter(&mds, &paths);
    match &args.out {
        Some(out) => {
            std::fs::write(out, &text)
                .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", out.display()))?;
            crate::say!(
                "wrote {}: {} instances; run it with `tether run {}`",
                out.display(),
                mds.len(),
                out.display()
            );
        }
        None => crate::stdout(format_args!("{text}"))?,
    }
    Ok(())
}

/// The system file's text.
fn starter(mds: &[&ModelDescription], paths: &[String]) -> String {
    let names = instance_names(mds);
    let mut out = String::new();
    let title: Vec<&str> = mds.iter().map(|m| m.model_name.as_str()).collect();
    let _ = writeln!(
        out,
        "# A system of {} (written by tether new).",
        title.join(", ")
    );
    let _ = writeln!(
        out,
        "# Couple the instances with [[connection]] (signals) or [[constraint]] (rigid joints),"
    );
    let _ = writeln!(
        out,
        "# docs/system-file.md; uncomment a parameter to change its start value."
    );
    let _ = writeln!(out, "name = {}", quoted(&title.join(" + ")));
    let _ = writeln!(out);
    out.push_str(&experiment(mds));
    for ((md, name), path) in mds.iter().zip(&names).zip(paths) {
        let _ = writeln!(out);
        out.push_str(&instance(md, name, path));
    }
    let suggestions = connections(mds, &names);
    if !suggestions.is_empty() {
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "# Connections between outputs and inputs of one unit (uncomment to use):"
        );
        for (from, to) in suggestions.iter().take(MAX_SUGGESTIONS) {
            let _ = writeln!(out, "# [[connection]]");
            let _ = writeln!(out, "# from = {}", quoted(from));
            let _ = writeln!(out, "# to = {}", quoted(to));
        }
    }
    out
}

/// Connections suggested at most.
const MAX_SUGGESTIONS: usize = 8;

/// The instance names: the model names as identifiers (lower case), numbered
/// where a model appears more than once.
fn instance_names(mds: &[&ModelDescription]) -> Vec<String> {
    let base: Vec<String> = mds.iter().map(|m| identifier(&m.model_name)).collect();
    base.iter()
        .enumerate()
        .map(|(i, b)| {
            if base.iter().filter(|o| *o == b).count() > 1 {
                let n = base[..=i].iter().filter(|o| *o == b).count();
                format!("{b}{n}")
            } else {
                b.clone()
            }
        })
        .collect()
}

fn identifier(model: &str) -> String {
    let mut s: String = model
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if !s.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) {
        s.insert(0, 'm');
    }
    s
}

/// `[experiment]` from the default experiments: the earliest start, the
/// latest stop and the smallest step any FMU gives (else 0, 1 and a
/// thousandth of the span).
fn experiment(mds: &[&ModelDescription]) -> String {
    let des: Vec<_> = mds
        .iter()
        .filter_map(|m| m.default_experiment.as_ref())
        .collect();
    let least = |v: Vec<f64>| v.into_iter().filter(|x| x.is_finite()).reduce(f64::min);
    let most = |v: Vec<f64>| v.into_iter().filter(|x| x.is_finite()).reduce(f64::max);
    let start = least(des.iter().filter_map(|d| d.start_time).collect());
    let stop = most(des.iter().filter_map(|d| d.stop_time).collect());
    let step = least(
        des.iter()
            .filter_map(|d| d.step_size)
            .filter(|h| *h > 0.0)
            .collect(),
    );
    let start_value = start.unwrap_or(0.0);
    let stop_value = stop
        .filter(|s| *s > start_value)
        .unwrap_or(start_value + 1.0);
    let step_value = step
        .filter(|h| *h <= stop_value - start_value)
        .unwrap_or((stop_value - start_value) / 1000.0);
    let from = |found: bool| {
        if found {
            "from the FMUs' default experiments"
        } else {
            "no FMU gives one"
        }
    };
    let mut out = String::from("[experiment]\n");
    let step_note = if step.is_some() {
        "the macro step H: the smallest stepSize of the FMUs"
    } else {
        "the macro step H: a thousandth of the span (no FMU gives a stepSize)"
    };
    for (key, value, note) in [
        ("start", start_value, from(start.is_some())),
        ("stop", stop_value, from(stop.is_some())),
        ("step", step_value, step_note),
    ] {
        let _ = writeln!(out, "{:<20} # {note}", format!("{key} = {}", float(value)));
    }
    out
}

/// One `[[instance]]` with its parameters (commented) and its interface.
fn instance(md: &ModelDescription, name: &str, path: &str) -> String {
    let fmi3 = md.standard == tether_fmi::FmiStandard::Fmi3;
    let mut out = String::new();
    let _ = writeln!(out, "[[instance]]");
    let _ = writeln!(out, "name = {}", quoted(name));
    let _ = writeln!(
        out,
        "fmu = {}   # {} {}",
        quoted(path),
        md.model_name,
        md.fmi_version
    );
    let parameters: Vec<&ScalarVariable> = md
        .model_variables
        .iter()
        .filter(|v| {
            (v.causality == Causality::Parameter || v.structural_parameter)
                && v.variability != Variability::Constant
        })
        .collect();
    let _ = writeln!(out, "[instance.parameters]");
    if parameters.is_empty() {
        let _ = writeln!(out, "# (no parameters)");
    }
    for v in parameters {
        let value = start(v).unwrap_or_else(|| "…".into());
        let mut line = format!("# {} = {value}", key(&v.name));
        let note = describe(v, fmi3);
        if !note.is_empty() {
            line = format!("{line:<32} # {note}");
        }
        let _ = writeln!(out, "{line}");
    }
    for (label, causality) in [("outputs", Causality::Output), ("inputs", Causality::Input)] {
        let vars: Vec<&ScalarVariable> = md
            .model_variables
            .iter()
            .filter(|v| v.causality == causality)
            .collect();
        if vars.is_empty() {
            continue;
        }
        let _ = writeln!(out, "# {label}:");
        for v in vars {
            let shown = format!("{name}.{}", v.name);
            let note = describe(v, fmi3);
            if note.is_empty() {
                let _ = writeln!(out, "#   {shown}");
            } else {
                let _ = writeln!(out, "#   {shown:<28} {note}");
            }
        }
    }
    out
}

/// `[unit] type, description`.
fn describe(v: &ScalarVariable, fmi3: bool) -> String {
    let mut parts = Vec::new();
    if let Some(unit) = v.real().and_then(|r| r.attributes.unit.as_deref()) {
        parts.push(format!("[{unit}]"));
    }
    // The type where it is not a Real (FMI 3.0: Float64).
    let ty = match &v.kind {
        VariableKind::Real(_) if v.value_type.name() == "Float64" => None,
        VariableKind::Real(_) => Some(v.value_type.name()),
        _ if fmi3 => Some(v.value_type.name()),
        VariableKind::Integer(_) => Some("Integer"),
        VariableKind::Enumeration(_) => Some("Enumeration"),
        VariableKind::Boolean(_) => Some("Boolean"),
        VariableKind::String(_) => Some("String"),
    };
    parts.extend(ty.map(str::to_string));
    if v.is_array() {
        parts.push("array".into());
    }
    if let Some(d) = &v.description {
        parts.push(d.clone());
    }
    parts.join(" ")
}

/// A variable name as a TOML key: bare where TOML allows, else quoted.
fn key(name: &str) -> String {
    if !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        name.to_string()
    } else {
        quoted(name)
    }
}

/// A TOML string.
fn quoted(text: &str) -> String {
    toml::Value::String(text.to_string()).to_string()
}

/// A TOML float that reads back to the same number.
fn float(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else {
        let text = format!("{x:?}");
        text
    }
}

/// The start value as TOML, if the FMU gives one.
fn start(v: &ScalarVariable) -> Option<String> {
    if let Some(values) = &v.start_values {
        let items: Vec<String> = match values {
            Values::Float(x) => x.iter().map(|x| float(*x)).collect(),
            Values::Int(x) => x.iter().map(i64::to_string).collect(),
            Values::UInt(x) => x.iter().map(u64::to_string).collect(),
            Values::Boolean(x) => x.iter().map(bool::to_string).collect(),
            Values::String(x) => x.iter().map(|s| quoted(s)).collect(),
            Values::Binary(_) => return None,
        };
        return Some(if v.is_array() {
            format!("[{}]", items.join(", "))
        } else {
            items.into_iter().next()?
        });
    }
    match &v.kind {
        VariableKind::Real(r) => r.start.map(float),
        VariableKind::Integer(i) | VariableKind::Enumeration(i) => i.start.map(|x| x.to_string()),
        VariableKind::Boolean(b) => b.start.map(|x| x.to_string()),
        VariableKind::String(s) => s.start.as_deref().map(quoted),
    }
}

/// Output → input pairs of two different instances with the same declared
/// unit (Real) or type (others), each input once.
fn connections(mds: &[&ModelDescription], names: &[String]) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for (j, md_to) in mds.iter().enumerate() {
        for input in md_to
            .model_variables
            .iter()
            .filter(|v| v.causality == Causality::Input && !v.is_array())
        {
            let unit = |v: &ScalarVariable| v.real().and_then(|r| r.attributes.unit.clone());
            let found = mds
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != j)
                .find_map(|(i, md)| {
                    md.model_variables
                        .iter()
                        .find(|o| {
                            o.causality == Causality::Output
                                && !o.is_array()
                                && o.base_type() == input.base_type()
                                && unit(o).is_some()
                                && unit(o) == unit(input)
                        })
                        .map(|o| format!("{}.{}", names[i], o.name))
                });
            if let Some(from) = found {
                out.push((from, format!("{}.{}", names[j], input.name)));
            }
        }
    }
    out
}

/// `path` against the current folder, `.` and `..` taken away.
fn absolute(path: &Path) -> PathBuf {
    let joined = if path.as_os_str().is_empty() {
        std::env::current_dir().unwrap_or_default()
    } else {
        std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
    };
    let mut out = PathBuf::new();
    for c in joined.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// `path` relative to `folder` (both absolute).
fn relative(path: &Path, folder: &Path) -> PathBuf {
    let a: Vec<Component> = path.components().collect();
    let b: Vec<Component> = folder.components().collect();
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &a[common..] {
        out.push(c.as_os_str());
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}
