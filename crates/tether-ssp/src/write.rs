//! Writing SSP (`tether ssp export`) and a system file from SSP
//! (`tether ssp import`).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use tether_fmi::{BaseType, Causality, ModelDescription};
use tether_master::{InterfaceChoice, StartValue, SystemSpec};

use crate::read::{Loaded, OSP_NAMESPACE, OSP_TYPE};
use crate::NAMESPACES;
use crate::{Annotation, SspError, ANNOTATION_NAMESPACE, ANNOTATION_TYPE};

/// XML-escape text for an attribute value.
fn esc(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The FMU's model description, read from the archive.
fn model_description(fmu: &Path) -> Result<ModelDescription, SspError> {
    if fmu.is_dir() {
        return Err(SspError::file(
            fmu,
            "an unpacked FMU folder: SSP export packs .fmu files",
        ));
    }
    let file = std::fs::File::open(fmu).map_err(|e| SspError::file(fmu, e))?;
    let mut archive = zip::ZipArchive::new(file).map_err(|e| SspError::file(fmu, e))?;
    let entry_err = |e: &dyn std::fmt::Display| {
        SspError::file(fmu, format!("entry 'modelDescription.xml': {e}"))
    };
    let entry = archive
        .by_name("modelDescription.xml")
        .map_err(|e| entry_err(&e))?;
    // One byte past the XML reader's limit, for it to refuse.
    let mut bytes = Vec::new();
    entry
        .take(tether_fmi::xml::MAX_BYTES as u64 + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| entry_err(&e))?;
    ModelDescription::from_bytes(&bytes).map_err(|e| SspError::file(fmu, e))
}

/// One `ssd:Connector` for variable `name` of `md`, or nothing if the FMU
/// has no such variable (the master reports it when the system is built).
fn connector(md: &ModelDescription, name: &str) -> Option<String> {
    let var = md.variable(name).ok()?;
    let kind = match var.causality {
        Causality::Input => "input",
        Causality::Output => "output",
        Causality::Parameter => "parameter",
        Causality::CalculatedParameter => "calculatedParameter",
        _ => return None,
    };
    let ty = match var.base_type() {
        BaseType::Real => match var.real().and_then(|r| r.attributes.unit.as_deref()) {
            Some(unit) => format!(r#"<ssc:Real unit="{}"/>"#, esc(unit)),
            None => "<ssc:Real/>".into(),
        },
        BaseType::Integer | BaseType::Enumeration => "<ssc:Integer/>".into(),
        BaseType::Boolean => "<ssc:Boolean/>".into(),
        BaseType::String => "<ssc:String/>".into(),
    };
    Some(format!(
        r#"          <ssd:Connector name="{}" kind="{kind}">{ty}</ssd:Connector>"#,
        esc(name)
    ))
}

/// One `ssv:Parameter` line; `None` for an array (SSP 1.0 has none).
fn parameter(name: &str, value: &StartValue) -> Option<String> {
    let v = match value {
        StartValue::Real(r) => format!(r#"<ssv:Real value="{r:?}"/>"#),
        StartValue::Integer(i) => format!(r#"<ssv:Integer value="{i}"/>"#),
        StartValue::Boolean(b) => format!(r#"<ssv:Boolean value="{b}"/>"#),
        StartValue::String(s) => format!(r#"<ssv:String value="{}"/>"#, esc(s)),
        StartValue::Array(_) => return None,
    };
    Some(format!(
        r#"                <ssv:Parameter name="{}">{v}</ssv:Parameter>"#,
        esc(name)
    ))
}

/// The SSD of `spec`, with each instance's FMU at `sources[i]`.
fn ssd(
    spec: &SystemSpec,
    sources: &[String],
    mds: &[ModelDescription],
) -> Result<String, SspError> {
    let name = spec.name.clone().unwrap_or_else(|| "system".into());
    let ns = |p: &str| {
        NAMESPACES
            .iter()
            .find(|(s, _)| *s == p)
            .map_or("", |(_, u)| u)
    };
    let mut x = String::new();
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<ssd:SystemStructureDescription xmlns:ssc="{}" xmlns:ssd="{}" xmlns:ssv="{}" version="1.0" name="{}" generationTool="Tether">"#,
        ns("ssc"),
        ns("ssd"),
        ns("ssv"),
        esc(&name)
    );
    let _ = writeln!(x, r#"  <ssd:System name="{}">"#, esc(&name));
    let _ = writeln!(x, "    <ssd:Elements>");
    for (i, inst) in spec.instances.iter().enumerate() {
        // `fmi_type` as SSP's implementation ("any" is the default).
        let implementation = match inst.fmi_type {
            InterfaceChoice::Auto => "",
            InterfaceChoice::CoSimulation => r#" implementation="CoSimulation""#,
            InterfaceChoice::ModelExchange => r#" implementation="ModelExchange""#,
        };
        let _ = writeln!(
            x,
            r#"      <ssd:Component name="{}" type="application/x-fmu-sharedlibrary" source="{}"{implementation}>"#,
            esc(&inst.name),
            esc(&sources[i])
        );
        let mut used: Vec<&str> = Vec::new();
        for c in &spec.connections {
            for end in [&c.from, &c.to] {
                if let Some((instance, var)) = end.split_once('.') {
                    if instance == inst.name && !used.contains(&var) {
                        used.push(var);
                    }
                }
            }
        }
        let connectors: Vec<String> = used.iter().filter_map(|v| connector(&mds[i], v)).collect();
        if !connectors.is_empty() {
            let _ = writeln!(x, "        <ssd:Connectors>");
            for c in connectors {
                let _ = writeln!(x, "{c}");
            }
            let _ = writeln!(x, "        </ssd:Connectors>");
        }
        if !inst.parameters.is_empty() {
            let _ = writeln!(x, "        <ssd:ParameterBindings>");
            let _ = writeln!(x, "          <ssd:ParameterBinding>");
            let _ = writeln!(x, "            <ssd:ParameterValues>");
            let _ = writeln!(
                x,
                r#"              <ssv:ParameterSet version="1.0" name="{}">"#,
                esc(&inst.name)
            );
            let _ = writeln!(x, "              <ssv:Parameters>");
            for (name, value) in &inst.parameters {
                let Some(line) = parameter(name, value) else {
                    return Err(SspError::Other(format!(
                        "instance '{}': parameter '{name}' is a whole array, which SSP 1.0 parameter sets cannot hold; set its elements ('{name}[1]', …)",
                        inst.name
                    )));
                };
                let _ = writeln!(x, "{line}");
            }
            let _ = writeln!(x, "              </ssv:Parameters>");
            let _ = writeln!(x, "              </ssv:ParameterSet>");
            let _ = writeln!(x, "            </ssd:ParameterValues>");
            let _ = writeln!(x, "          </ssd:ParameterBinding>");
            let _ = writeln!(x, "        </ssd:ParameterBindings>");
        }
        // The instance's own step as OSP's step hint, as libcosim reads it.
        if let Some(step) = inst.step {
            let _ = writeln!(x, "        <ssd:Annotations>");
            let _ = writeln!(
                x,
                r#"          <ssc:Annotation type="{OSP_TYPE}" xmlns:osp="{OSP_NAMESPACE}">"#
            );
            let _ = writeln!(x, r#"            <osp:StepSizeHint value="{step:?}"/>"#);
            let _ = writeln!(x, "          </ssc:Annotation>");
            let _ = writeln!(x, "        </ssd:Annotations>");
        }
        let _ = writeln!(x, "      </ssd:Component>");
    }
    let _ = writeln!(x, "    </ssd:Elements>");
    if !spec.connections.is_empty() {
        let _ = writeln!(x, "    <ssd:Connections>");
        for c in &spec.connections {
            let split = |end: &str| {
                end.split_once('.')
                    .map(|(a, b)| (a.to_string(), b.to_string()))
                    .ok_or_else(|| {
                        SspError::Other(format!(
                            "connection end '{end}' is not <instance>.<variable>"
                        ))
                    })
            };
            let ((se, sc), (ee, ec)) = (split(&c.from)?, split(&c.to)?);
            let open = format!(
                r#"      <ssd:Connection startElement="{}" startConnector="{}" endElement="{}" endConnector="{}""#,
                esc(&se),
                esc(&sc),
                esc(&ee),
                esc(&ec)
            );
            if c.gain.is_some() || c.offset.is_some() {
                let _ = writeln!(x, "{open}>");
                let _ = writeln!(
                    x,
                    r#"        <ssc:LinearTransformation factor="{:?}" offset="{:?}"/>"#,
                    c.gain.unwrap_or(1.0),
                    c.offset.unwrap_or(0.0)
                );
                let _ = writeln!(x, "      </ssd:Connection>");
            } else {
                let _ = writeln!(x, "{open}/>");
            }
        }
        let _ = writeln!(x, "    </ssd:Connections>");
    }
    let annotation = Annotation {
        step: Some(spec.experiment.step),
        tolerance: spec.experiment.tolerance,
        method: Some(spec.method),
        coupling: Some(spec.coupling),
        signals: Some(spec.signals),
        step_control: spec.step_control,
        constraints: spec.constraints.clone(),
        joints: spec.joints.clone(),
        coupling_variables: spec.coupling_variables.clone(),
    };
    let toml = toml::to_string(&annotation).map_err(|e| SspError::Other(e.to_string()))?;
    if toml.contains("]]>") {
        return Err(SspError::Other(
            "the system's text contains ']]>', which the annotation's CDATA cannot hold".into(),
        ));
    }
    let _ = writeln!(x, "    <ssd:Annotations>");
    let _ = writeln!(x, r#"      <ssc:Annotation type="{ANNOTATION_TYPE}">"#);
    let _ = writeln!(
        x,
        r#"        <tether:System xmlns:tether="{ANNOTATION_NAMESPACE}"><![CDATA["#
    );
    x.push_str(&toml);
    let _ = writeln!(x, "]]></tether:System>");
    let _ = writeln!(x, "      </ssc:Annotation>");
    let _ = writeln!(x, "    </ssd:Annotations>");
    let _ = writeln!(x, "  </ssd:System>");
    // The macro step also as OSP's annotation, which libcosim reads.
    let e = spec.experiment;
    let _ = writeln!(
        x,
        r#"  <ssd:DefaultExperiment startTime="{:?}" stopTime="{:?}">"#,
        e.start, e.stop
    );
    let _ = writeln!(x, "    <ssd:Annotations>");
    // libcosim takes every child of osp:Algorithm, attributes too, for an
    // algorithm: the namespace is declared on the annotation.
    let _ = writeln!(
        x,
        r#"      <ssc:Annotation type="{OSP_TYPE}" xmlns:osp="{OSP_NAMESPACE}">"#
    );
    let _ = writeln!(x, "        <osp:Algorithm>");
    let _ = writeln!(
        x,
        r#"          <osp:FixedStepAlgorithm baseStepSize="{:?}"/>"#,
        e.step
    );
    let _ = writeln!(x, "        </osp:Algorithm>");
    let _ = writeln!(x, "      </ssc:Annotation>");
    let _ = writeln!(x, "    </ssd:Annotations>");
    let _ = writeln!(x, "  </ssd:DefaultExperiment>");
    let _ = writeln!(x, "</ssd:SystemStructureDescription>");
    Ok(x)
}

/// Each distinct FMU file once, under `resources/` with a unique name:
/// (file, name in the archive) and each instance's name in the archive.
fn resources(spec: &SystemSpec) -> (Vec<(PathBuf, String)>, Vec<String>) {
    let mut files: Vec<(PathBuf, String)> = Vec::new();
    let mut sources = Vec::new();
    for inst in &spec.instances {
        let known = files
            .iter()
            .find(|(p, _)| *p == inst.fmu)
            .map(|(_, n)| n.clone());
        let name = known.unwrap_or_else(|| {
            let stem = inst
                .fmu
                .file_stem()
                .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
            let mut name = format!("resources/{stem}.fmu");
            let mut n = 2;
            while files.iter().any(|(_, f)| *f == name) {
                name = format!("resources/{stem}_{n}.fmu");
                n += 1;
            }
            files.push((inst.fmu.clone(), name.clone()));
            name
        });
        sources.push(name);
    }
    (files, sources)
}

/// Write `spec` (FMU paths resolved) as the SSP archive `out`: the SSD, the
/// FMUs under `resources/`, the parameters inline, the rest in Tether's
/// annotation.
pub fn write(spec: &SystemSpec, out: &Path) -> Result<(), SspError> {
    spec.validate()?;
    let (files, sources) = resources(spec);
    let mds = spec
        .instances
        .iter()
        .map(|i| model_description(&i.fmu))
        .collect::<Result<Vec<_>, _>>()?;
    let text = ssd(spec, &sources, &mds)?;
    let file = std::fs::File::create(out).map_err(|e| SspError::file(out, e))?;
    let mut zip = zip::ZipWriter::new(file);
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    let fail = |e: &dyn std::fmt::Display| SspError::file(out, e);
    zip.start_file("SystemStructure.ssd", options)
        .map_err(|e| fail(&e))?;
    zip.write_all(text.as_bytes()).map_err(|e| fail(&e))?;
    for (path, name) in &files {
        let bytes = std::fs::read(path).map_err(|e| SspError::file(path, e))?;
        // FMUs are archives already: stored, not compressed again.
        let stored = options.compression_method(zip::CompressionMethod::Stored);
        zip.start_file(name.as_str(), stored)
            .map_err(|e| fail(&e))?;
        zip.write_all(&bytes).map_err(|e| fail(&e))?;
    }
    zip.finish().map_err(|e| fail(&e))?;
    Ok(())
}

/// Write a system read from SSP as a system file `out`, with its FMUs
/// copied to `resources/` next to it (paths relative to it).
pub fn write_toml(loaded: &Loaded, out: &Path) -> Result<(), SspError> {
    let dir = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut spec = loaded.spec.clone();
    let (files, sources) = resources(&spec);
    std::fs::create_dir_all(dir.join("resources")).map_err(|e| SspError::file(dir, e))?;
    let mut copied = BTreeMap::new();
    for (path, name) in &files {
        let target = dir.join(name);
        // The SSP's own file (imported next to it): copying a file onto
        // itself would empty it.
        let same = |a: &Path, b: &Path| matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b);
        if same(path, &target) {
            copied.insert(path.clone(), name.clone());
            continue;
        }
        if target.exists() && std::fs::read(&target).ok() != std::fs::read(path).ok() {
            return Err(SspError::file(
                &target,
                "exists with other content; not overwritten",
            ));
        }
        std::fs::copy(path, &target).map_err(|e| SspError::file(&target, e))?;
        copied.insert(path.clone(), name.clone());
    }
    for (inst, source) in spec.instances.iter_mut().zip(sources) {
        inst.fmu = PathBuf::from(source);
    }
    let text = toml::to_string(&spec).map_err(|e| SspError::Other(e.to_string()))?;
    std::fs::write(out, text).map_err(|e| SspError::file(out, e))
}
