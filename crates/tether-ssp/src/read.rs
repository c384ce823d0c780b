//! Reading SSP: `.ssp` archive, unpacked folder or `SystemStructure.ssd`.

use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

use tether_fmi::archive::{extract_archive, ArchiveKind, ExtractLimits, FmuDir};
use tether_fmi::xml::{self, Element as Node, Names};
use tether_master::{
    ConnectionSpec, Experiment, ExportLink, ExportSource, ExportSpec, InstanceSpec,
    InterfaceChoice, StartValue, SystemSpec,
};

use crate::{Annotation, SspError, ANNOTATION_TYPE, NAMESPACES};

/// A system read from SSP.
pub struct Loaded {
    /// The system, FMU paths absolute.
    pub spec: SystemSpec,
    /// Other tools' annotations, skipped: `type (file:line)`.
    pub skipped: Vec<String>,
    /// Lines for the user (the CLI prints them as `note: …`): OSP's
    /// annotations Tether does not use, a `StepSizeHint` that is not n·H.
    pub notes: Vec<String>,
    /// The `SystemStructure.ssd` read.
    pub ssd: PathBuf,
    /// The extracted archive, removed when the system is dropped.
    _extracted: Option<FmuDir>,
}

/// Read an SSP system. `step` and `stop` (from the command line) win over
/// the Tether annotation's step and DefaultExperiment's stopTime; without a
/// step from either, reading fails. Skipped annotations of other tools are
/// logged (info) and listed in [`Loaded::skipped`].
///
/// The `source` of a component or a parameter binding in an `.ssp` archive must be
/// a relative path to a file in the archive; in an SSD file or a folder on disk it
/// may name any file (docs/ssp.md, "Files and limits").
pub fn read(path: &Path, step: Option<f64>, stop: Option<f64>) -> Result<Loaded, SspError> {
    let (ssd, extracted) = locate(path)?;
    let base = ssd.parent().unwrap_or(Path::new(".")).to_path_buf();
    let name = ssd.file_name().map_or_else(
        || "SystemStructure.ssd".into(),
        |n| n.to_string_lossy().into_owned(),
    );
    let root = parse_file(&ssd, &name)?;
    let mut reader = Reader {
        file: name,
        base,
        archive: extracted
            .as_ref()
            .map(|dir| (path.to_path_buf(), dir.root().to_path_buf())),
        ..Reader::default()
    };
    let spec = reader.description(&root, step, stop)?;
    for skipped in &reader.skipped {
        log::info!("skipped another tool's annotation {skipped}");
    }
    Ok(Loaded {
        spec,
        notes: reader.notes,
        skipped: reader.skipped,
        ssd,
        _extracted: extracted,
    })
}

/// Reads and parses an SSD or SSV file, bounded as every XML file is
/// ([`tether_fmi::xml`]); `shown` names it in errors.
fn parse_file(path: &Path, shown: &str) -> Result<Node, SspError> {
    let bytes = xml::read(path).map_err(|e| SspError::file(path, e))?;
    let shown = Path::new(shown);
    let text = xml::decode(&bytes, shown)?;
    Ok(xml::parse(text, shown, Names::Namespaces(&NAMESPACES))?)
}

/// The SSD of `path`, extracting an archive into a temporary folder under the
/// budget of FMU archives.
fn locate(path: &Path) -> Result<(PathBuf, Option<FmuDir>), SspError> {
    // A FIFO or a device is refused before it is opened: the open of a FIFO
    // waits for a writer that may never come.
    let metadata = std::fs::metadata(path).map_err(|e| SspError::file(path, e))?;
    if let Some(kind) = tether_fmi::special_file_kind(&metadata) {
        return Err(SspError::file(
            path,
            format!("is a {kind}, not an SSP archive, an SSD file or a folder"),
        ));
    }
    if metadata.is_dir() {
        let ssd = path.join("SystemStructure.ssd");
        if !ssd.is_file() {
            return Err(SspError::file(
                path,
                "no SystemStructure.ssd in this folder",
            ));
        }
        return Ok((ssd, None));
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "ssd" => Ok((path.to_path_buf(), None)),
        "ssp" => {
            let dir = extract_archive(path, ArchiveKind::Ssp, &ExtractLimits::default())?;
            let ssd = dir.root().join("SystemStructure.ssd");
            if !ssd.is_file() {
                return Err(SspError::file(
                    path,
                    "the archive has no SystemStructure.ssd at its root",
                ));
            }
            Ok((ssd, Some(dir)))
        }
        _ => Err(SspError::file(
            path,
            "expected an .ssp archive, an .ssd file or a folder with SystemStructure.ssd",
        )),
    }
}

/// Where a connection ends: a component's connector or a system's.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
enum End {
    /// Flat instance name, connector.
    Component(String, String),
    /// System path (empty for the root), connector.
    System(Vec<String>, String),
}

impl End {
    fn describe(&self) -> String {
        match self {
            End::Component(c, v) => format!("{c}.{v}"),
            End::System(p, v) if p.is_empty() => format!("connector '{v}' of the root system"),
            End::System(p, v) => format!("connector '{v}' of system '{}'", p.join(".")),
        }
    }
}

/// One `ssd:Connection`.
#[derive(Debug, Clone)]
struct Edge {
    from: End,
    to: End,
    gain: f64,
    offset: f64,
    /// A LinearTransformation was given (the user's own conversion).
    transformed: bool,
    suppress_units: bool,
    line: usize,
}

/// A unit's SI exponents and its factor and offset (`ssc:BaseUnit`).
#[derive(Debug, Clone, PartialEq)]
struct BaseUnit {
    exponents: [i32; 8],
    factor: f64,
    offset: f64,
}

#[derive(Default)]
struct Reader {
    file: String,
    base: PathBuf,
    /// For an `.ssp`: the archive and the folder it is extracted to, which every
    /// `source` must stay in.
    archive: Option<(PathBuf, PathBuf)>,
    skipped: Vec<String>,
    instances: Vec<InstanceSpec>,
    /// Full path of each component → its flat instance name.
    components: BTreeMap<Vec<String>, String>,
    /// Paths of the (nested) systems.
    systems: Vec<Vec<String>>,
    /// Declared unit of each connector (component or system).
    units: BTreeMap<End, String>,
    /// The kind of each connector (`input`, `output`, `parameter`, …).
    kinds: BTreeMap<End, String>,
    unit_definitions: BTreeMap<String, BaseUnit>,
    edges: Vec<Edge>,
    /// System-level bindings: system path, parameter path, value, line.
    bindings: Vec<(Vec<String>, String, StartValue, usize)>,
    annotation: Option<Annotation>,
    /// OSP's `FixedStepAlgorithm baseStepSize` (libcosim's macro step).
    osp_step: Option<f64>,
    /// OSP's `StepSizeHint` of each component: instance, hint, line.
    osp_hints: Vec<(String, f64, usize)>,
    /// OSP's annotation elements Tether does not use: `<osp:X> (line N)`.
    osp_ignored: Vec<String>,
    notes: Vec<String>,
}

/// Where an `ssd:Annotations` is: OSP's annotation means something on the
/// default experiment (the algorithm) and on a component (its step hint).
#[derive(Clone, Copy)]
enum Place<'a> {
    /// The root `ssd:System`, where Tether's own annotation goes.
    RootSystem,
    /// `ssd:DefaultExperiment`.
    Experiment,
    /// An `ssd:Component`, by instance name.
    Component(&'a str),
    /// Anywhere else.
    Other,
}

/// OSP's annotation type, as libcosim reads it.
pub(crate) const OSP_TYPE: &str = "com.opensimulationplatform";

/// The namespace of OSP's annotation elements (`osp:`), as OSP's SSP files
/// declare it (libcosim matches the prefix only).
pub(crate) const OSP_NAMESPACE: &str = "http://opensimulationplatform.com/SSP/OSPAnnotations";

/// An element's local name (OSP's elements are matched by it, as libcosim
/// matches `osp:` names whatever namespace the prefix is bound to).
fn local(name: &str) -> &str {
    let name = name.rsplit('}').next().unwrap_or(name);
    name.rsplit(':').next().unwrap_or(name)
}

/// Seconds as libcosim's integer nanoseconds (truncated, as its
/// `to_duration` does).
fn nanoseconds(seconds: f64) -> i64 {
    (seconds * 1e9) as i64
}

/// libcosim's decimation factor of a `StepSizeHint`: n = max(1, ⌈hint/H⌉),
/// both in integer nanoseconds.
pub(crate) fn decimation(hint: f64, h: f64) -> u64 {
    let (hint, h) = (nanoseconds(hint), nanoseconds(h).max(1));
    u64::try_from(hint.div_euclid(h) + i64::from(hint.rem_euclid(h) != 0))
        .unwrap_or(0)
        .max(1)
}

impl Reader {
    fn at(&self, node: &Node, message: impl Into<String>) -> SspError {
        SspError::xml(&self.file, node.line, message)
    }

    fn unsupported(&self, node: &Node, context: &str) -> SspError {
        self.at(
            node,
            format!(
                "<{}> {context} is not supported by Tether (docs/ssp.md lists what is)",
                node.name
            ),
        )
    }

    fn required<'a>(&self, node: &'a Node, key: &str) -> Result<&'a str, SspError> {
        node.attr(key)
            .ok_or_else(|| self.at(node, format!("<{}> needs the attribute '{key}'", node.name)))
    }

    fn number(&self, node: &Node, key: &str) -> Result<Option<f64>, SspError> {
        node.attr(key)
            .map(|v| {
                v.trim().parse::<f64>().map_err(|_| {
                    self.at(
                        node,
                        format!("<{}> {key}=\"{v}\" is not a number", node.name),
                    )
                })
            })
            .transpose()
    }

    fn description(
        &mut self,
        root: &Node,
        step: Option<f64>,
        stop: Option<f64>,
    ) -> Result<SystemSpec, SspError> {
        if root.name != "ssd:SystemStructureDescription" {
            return Err(self.at(
                root,
                format!(
                    "the root element is <{}>, not <ssd:SystemStructureDescription> (namespace {})",
                    root.name, NAMESPACES[0].1
                ),
            ));
        }
        let version = self.required(root, "version")?;
        if !version.starts_with("1.") {
            return Err(self.at(root, format!("SSP version {version}: Tether reads SSP 1.x")));
        }
        let mut system = None;
        let mut experiment = None;
        for child in &root.children {
            match child.name.as_str() {
                "ssd:System" => system = Some(child),
                "ssd:DefaultExperiment" => experiment = Some(child),
                "ssd:Units" => self.unit_definitions(child)?,
                "ssd:Annotations" => self.annotations(child, Place::Other)?,
                "ssd:MetaData" | "ssd:Signature" => {}
                "ssd:Enumerations" => return Err(self.unsupported(child, "(enumeration types)")),
                _ => return Err(self.unsupported(child, "in <ssd:SystemStructureDescription>")),
            }
        }
        let system = system.ok_or_else(|| self.at(root, "no <ssd:System>"))?;
        self.system(system, &[], true)?;
        let (connections, export) = self.connections()?;
        self.apply_bindings()?;
        let annotation = self.annotation.take().unwrap_or_default();
        let (mut start, mut stop_time) = (0.0, None);
        if let Some(e) = experiment {
            start = self.number(e, "startTime")?.unwrap_or(0.0);
            stop_time = self.number(e, "stopTime")?;
            for child in &e.children {
                match child.name.as_str() {
                    "ssd:Annotations" => self.annotations(child, Place::Experiment)?,
                    _ => return Err(self.unsupported(child, "in <ssd:DefaultExperiment>")),
                }
            }
        }
        let stop = stop.or(stop_time).ok_or_else(|| {
            SspError::Other(format!(
                "{}: no stop time: <ssd:DefaultExperiment stopTime=…> is missing; give --stop",
                self.file
            ))
        })?;
        let step = step.or(annotation.step).or(self.osp_step).ok_or_else(|| {
            SspError::Other(format!(
                "{}: no macro-step size: SSP's DefaultExperiment has none; give --step, or \
                 step in the Tether annotation, or OSP's FixedStepAlgorithm baseStepSize (docs/ssp.md)",
                self.file
            ))
        })?;
        self.step_hints(step)?;
        if !self.osp_ignored.is_empty() {
            self.notes.push(format!(
                "{}: OSP annotations Tether does not use, ignored: {}",
                self.file,
                self.osp_ignored.join(", ")
            ));
        }
        let spec = SystemSpec {
            name: Some(system.attr("name").unwrap_or("ssp").to_string()),
            experiment: Experiment {
                start,
                stop,
                step,
                tolerance: annotation.tolerance,
            },
            method: annotation.method.unwrap_or_default(),
            coupling: annotation.coupling.unwrap_or_default(),
            instances: std::mem::take(&mut self.instances),
            constraints: annotation.constraints,
            joints: annotation.joints,
            coupling_variables: annotation.coupling_variables,
            connections,
            signals: annotation.signals.unwrap_or_default(),
            step_control: annotation.step_control,
            output: Default::default(),
            export: export.map(|mut export| {
                export.model_name = flat_name(&[system.attr("name").unwrap_or("ssp").to_string()]);
                export
            }),
            source: None,
        };
        spec.validate()?;
        Ok(spec)
    }

    fn unit_definitions(&mut self, units: &Node) -> Result<(), SspError> {
        for unit in &units.children {
            if unit.name != "ssc:Unit" {
                return Err(self.unsupported(unit, "in <ssd:Units>"));
            }
            let name = self.required(unit, "name")?.to_string();
            let mut base = BaseUnit {
                exponents: [0; 8],
                factor: 1.0,
                offset: 0.0,
            };
            if let Some(b) = unit.child("ssc:BaseUnit") {
                for (i, key) in ["kg", "m", "s", "A", "K", "mol", "cd", "rad"]
                    .iter()
                    .enumerate()
                {
                    if let Some(v) = b.attr(key) {
                        base.exponents[i] = v.trim().parse().map_err(|_| {
                            self.at(b, format!("<ssc:BaseUnit> {key}=\"{v}\" is not an integer"))
                        })?;
                    }
                }
                base.factor = self.number(b, "factor")?.unwrap_or(1.0);
                base.offset = self.number(b, "offset")?.unwrap_or(0.0);
            }
            self.unit_definitions.insert(name, base);
        }
        Ok(())
    }

    /// `ssd:Annotations`: Tether's on the root system, others skipped.
    fn annotations(&mut self, node: &Node, place: Place<'_>) -> Result<(), SspError> {
        let root_system = matches!(place, Place::RootSystem);
        for a in &node.children {
            if a.name != "ssc:Annotation" {
                return Err(self.unsupported(a, "in <ssd:Annotations>"));
            }
            let kind = self.required(a, "type")?;
            if kind == OSP_TYPE {
                self.osp(a, place)?;
                continue;
            }
            if kind != ANNOTATION_TYPE {
                self.skipped
                    .push(format!("{kind} ({}:{})", self.file, a.line));
                continue;
            }
            if !root_system {
                return Err(self.at(
                    a,
                    format!("the {ANNOTATION_TYPE} annotation belongs on the root <ssd:System>"),
                ));
            }
            let text: String = a
                .children
                .iter()
                .map(|c| c.text.as_str())
                .chain(std::iter::once(a.text.as_str()))
                .collect();
            let parsed: Annotation = toml::from_str(&text).map_err(|e| {
                self.at(
                    a,
                    format!(
                        "the {ANNOTATION_TYPE} annotation: {}",
                        tether_master::spec::toml_error(&text, &e)
                    ),
                )
            })?;
            self.annotation = Some(parsed);
        }
        Ok(())
    }

    /// OSP's annotation (`com.opensimulationplatform`), as libcosim reads
    /// it: `osp:Algorithm/osp:FixedStepAlgorithm baseStepSize` on the default
    /// experiment, `osp:StepSizeHint value` on a component; every other
    /// element is noted as ignored.
    fn osp(&mut self, a: &Node, place: Place<'_>) -> Result<(), SspError> {
        let positive = |this: &Self, node: &Node, key: &str| -> Result<f64, SspError> {
            let name = format!("osp:{}", local(&node.name));
            let value = node
                .attr(key)
                .ok_or_else(|| this.at(node, format!("<{name}> needs the attribute '{key}'")))?;
            match value.trim().parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
                _ => Err(this.at(
                    node,
                    format!("<{name}> {key}=\"{value}\": expected a time > 0"),
                )),
            }
        };
        for child in &a.children {
            match (local(&child.name), place) {
                ("Algorithm", Place::Experiment) => {
                    for algorithm in &child.children {
                        if local(&algorithm.name) == "FixedStepAlgorithm" {
                            self.osp_step = Some(positive(self, algorithm, "baseStepSize")?);
                        } else {
                            self.osp_ignored.push(format!(
                                "<osp:{}> (line {})",
                                local(&algorithm.name),
                                algorithm.line
                            ));
                        }
                    }
                }
                ("StepSizeHint", Place::Component(name)) => {
                    let hint = positive(self, child, "value")?;
                    self.osp_hints.push((name.to_string(), hint, child.line));
                }
                _ => self.osp_ignored.push(format!(
                    "<osp:{}> (line {})",
                    local(&child.name),
                    child.line
                )),
            }
        }
        Ok(())
    }

    /// Each component's OSP `StepSizeHint` against the macro step H: n =
    /// max(1, ⌈hint/H⌉) as libcosim computes it, the instance's `step` n·H
    /// (docs/system-file.md "Per-instance steps"); a note when n·H is not
    /// the hint.
    fn step_hints(&mut self, h: f64) -> Result<(), SspError> {
        for (instance, hint, line) in std::mem::take(&mut self.osp_hints) {
            let n = decimation(hint, h);
            if n > 1 {
                if let Some(i) = self.instances.iter_mut().find(|i| i.name == instance) {
                    i.step = Some(n as f64 * h);
                }
            }
            if nanoseconds(hint) != nanoseconds(h) * n as i64 {
                self.notes.push(format!(
                    "{}:{line}: component '{instance}': OSP's StepSizeHint {hint} is not a multiple \
                     of H = {h}: it steps at {n}·H = {}, as libcosim does",
                    self.file,
                    n as f64 * h
                ));
            }
        }
        Ok(())
    }

    fn system(&mut self, node: &Node, path: &[String], root: bool) -> Result<(), SspError> {
        self.systems.push(path.to_vec());
        for child in &node.children {
            match child.name.as_str() {
                "ssd:Connectors" => {
                    self.connectors(child, |name| End::System(path.to_vec(), name))?
                }
                "ssd:ParameterBindings" => {
                    for (name, value, line) in self.bindings(child)? {
                        self.bindings.push((path.to_vec(), name, value, line));
                    }
                }
                "ssd:Elements" => {
                    for element in &child.children {
                        let name = self.required(element, "name")?.to_string();
                        let mut inner = path.to_vec();
                        inner.push(name);
                        match element.name.as_str() {
                            "ssd:Component" => self.component(element, inner)?,
                            "ssd:System" => self.system(element, &inner, false)?,
                            _ => return Err(self.unsupported(element, "in <ssd:Elements>")),
                        }
                    }
                }
                "ssd:Connections" => {
                    for c in &child.children {
                        if c.name != "ssd:Connection" {
                            return Err(self.unsupported(c, "in <ssd:Connections>"));
                        }
                        self.connection(c, path)?;
                    }
                }
                "ssd:Annotations" => {
                    let place = if root {
                        Place::RootSystem
                    } else {
                        Place::Other
                    };
                    self.annotations(child, place)?
                }
                // Graphical information only.
                "ssd:SystemGeometry" | "ssd:GraphicalElements" | "ssd:ElementGeometry" => {}
                _ => return Err(self.unsupported(child, "in <ssd:System>")),
            }
        }
        Ok(())
    }

    fn component(&mut self, node: &Node, path: Vec<String>) -> Result<(), SspError> {
        let kind = node
            .attr("type")
            .unwrap_or("application/x-fmu-sharedlibrary");
        if kind != "application/x-fmu-sharedlibrary" {
            return Err(self.at(
                node,
                format!("<ssd:Component> type=\"{kind}\" is not supported: Tether runs FMUs"),
            ));
        }
        // SSP's implementation: which FMI interface runs (`fmi_type`).
        let fmi_type = match node.attr("implementation") {
            None | Some("any") => InterfaceChoice::Auto,
            Some("CoSimulation") => InterfaceChoice::CoSimulation,
            Some("ModelExchange") => InterfaceChoice::ModelExchange,
            Some(other) => {
                return Err(self.at(
                    node,
                    format!(
                        "<ssd:Component> implementation=\"{other}\" is not supported: Tether runs \
                         \"any\", \"CoSimulation\" or \"ModelExchange\""
                    ),
                ))
            }
        };
        let source = self.required(node, "source")?;
        let fmu = self.source(node, source)?;
        let name = flat_name(&path);
        if let Some((other, _)) = self.components.iter().find(|(_, n)| **n == name) {
            return Err(self.at(
                node,
                format!(
                    "component '{}' and '{}' both become instance '{name}'",
                    path.join("."),
                    other.join(".")
                ),
            ));
        }
        let mut parameters = BTreeMap::new();
        for child in &node.children {
            match child.name.as_str() {
                "ssd:Connectors" => self.connectors(child, |c| End::Component(name.clone(), c))?,
                "ssd:ParameterBindings" => {
                    for (var, value, _) in self.bindings(child)? {
                        parameters.insert(var, value);
                    }
                }
                "ssd:Annotations" => self.annotations(child, Place::Component(&name))?,
                "ssd:ElementGeometry" => {}
                _ => return Err(self.unsupported(child, "in <ssd:Component>")),
            }
        }
        self.components.insert(path, name.clone());
        self.instances.push(InstanceSpec {
            name,
            fmu,
            parameters,
            isolation: Default::default(),
            call_timeout: None,
            host: None,
            token_file: None,
            fmu_on_host: None,
            resources: Default::default(),
            step: None,
            parallel: None,
            fmi_type,
            integrator: None,
        });
        Ok(())
    }

    /// A component's or parameter binding's `source`: relative to the SSD's
    /// folder, absolute, or a `file:` URI; in an `.ssp`, relative and inside the
    /// archive.
    fn source(&self, node: &Node, source: &str) -> Result<PathBuf, SspError> {
        let path = if let Some(rest) = source.strip_prefix("file://") {
            PathBuf::from(rest)
        } else if let Some(rest) = source.strip_prefix("file:") {
            PathBuf::from(rest)
        } else if source.contains("://") {
            return Err(self.at(
                node,
                format!("source=\"{source}\": only files (relative paths, absolute paths, file: URIs) are supported"),
            ));
        } else {
            PathBuf::from(source)
        };
        if let Some((archive, root)) = &self.archive {
            self.inside_archive(node, source, &path, archive, root)?;
        }
        let path = if path.is_relative() {
            self.base.join(path)
        } else {
            path
        };
        if !path.exists() {
            return Err(self.at(
                node,
                format!("source=\"{source}\": no such file ({})", path.display()),
            ));
        }
        Ok(path)
    }

    /// Refuses a `source` of an `.ssp` that is absolute or leaves the archive's
    /// folder: the archive's author names files in the archive, not on the disk of
    /// whoever runs it.
    fn inside_archive(
        &self,
        node: &Node,
        source: &str,
        path: &Path,
        archive: &Path,
        root: &Path,
    ) -> Result<(), SspError> {
        let refused = |why: &str| {
            self.at(
                node,
                format!(
                    "source=\"{source}\" {why}: a source in the .ssp archive '{}' must be a \
                     relative path to a file in it",
                    archive.display()
                ),
            )
        };
        // Where the SSD's folder is inside the archive, then the source from there.
        let mut inside: Vec<&std::ffi::OsStr> = match self.base.strip_prefix(root) {
            Ok(rel) => rel.iter().collect(),
            Err(_) => return Err(refused("is not in the archive")),
        };
        for component in path.components() {
            match component {
                Component::Normal(part) => inside.push(part),
                Component::CurDir => {}
                Component::ParentDir => {
                    if inside.pop().is_none() {
                        return Err(refused("leaves the archive"));
                    }
                }
                Component::RootDir | Component::Prefix(_) => {
                    return Err(refused("is an absolute path"))
                }
            }
        }
        Ok(())
    }

    fn connectors(&mut self, node: &Node, end: impl Fn(String) -> End) -> Result<(), SspError> {
        for c in &node.children {
            if c.name != "ssd:Connector" {
                return Err(self.unsupported(c, "in <ssd:Connectors>"));
            }
            let name = self.required(c, "name")?.to_string();
            let kind = self.required(c, "kind")?;
            self.kinds.insert(end(name.clone()), kind.to_string());
            if !matches!(
                kind,
                "input" | "output" | "parameter" | "calculatedParameter" | "inout"
            ) {
                return Err(self.at(
                    c,
                    format!("<ssd:Connector> kind=\"{kind}\" is not an SSP kind"),
                ));
            }
            for t in &c.children {
                match t.name.as_str() {
                    "ssc:Real" => {
                        if let Some(unit) = t.attr("unit") {
                            self.units.insert(end(name.clone()), unit.to_string());
                        }
                    }
                    "ssc:Integer" | "ssc:Boolean" | "ssc:String" => {}
                    "ssc:Enumeration" | "ssc:Binary" => {
                        return Err(self.unsupported(t, "(connector type)"))
                    }
                    "ssd:ConnectorGeometry" => {}
                    "ssd:Annotations" => self.annotations(t, Place::Other)?,
                    _ => return Err(self.unsupported(t, "in <ssd:Connector>")),
                }
            }
        }
        Ok(())
    }

    fn connection(&mut self, c: &Node, path: &[String]) -> Result<(), SspError> {
        let end = |element: Option<&str>, connector: &str| match element {
            None => End::System(path.to_vec(), connector.to_string()),
            Some(e) => {
                let mut full = path.to_vec();
                full.push(e.to_string());
                match self.components.get(&full) {
                    Some(flat) => End::Component(flat.clone(), connector.to_string()),
                    None => End::System(full, connector.to_string()),
                }
            }
        };
        let from = end(c.attr("startElement"), self.required(c, "startConnector")?);
        let to = end(c.attr("endElement"), self.required(c, "endConnector")?);
        for (e, attr) in [(&from, "startElement"), (&to, "endElement")] {
            if let End::System(p, _) = e {
                if !self.systems.contains(p) {
                    return Err(self.at(
                        c,
                        format!(
                            "<ssd:Connection> {attr}=\"{}\" names no component or system here",
                            p.last().map_or("", String::as_str)
                        ),
                    ));
                }
            }
        }
        let mut edge = Edge {
            from,
            to,
            gain: 1.0,
            offset: 0.0,
            transformed: false,
            suppress_units: c.attr("suppressUnitConversion") == Some("true"),
            line: c.line,
        };
        for t in &c.children {
            match t.name.as_str() {
                "ssc:LinearTransformation" => {
                    edge.gain = self.number(t, "factor")?.unwrap_or(1.0);
                    edge.offset = self.number(t, "offset")?.unwrap_or(0.0);
                    edge.transformed = true;
                }
                "ssd:ConnectionGeometry" => {}
                "ssd:Annotations" => self.annotations(t, Place::Other)?,
                _ => return Err(self.unsupported(t, "in <ssd:Connection>")),
            }
        }
        self.edges.push(edge);
        Ok(())
    }

    /// Parameter values of `ssd:ParameterBindings`: (name, value, line).
    fn bindings(&mut self, node: &Node) -> Result<Vec<(String, StartValue, usize)>, SspError> {
        let mut out = Vec::new();
        for b in &node.children {
            if b.name != "ssd:ParameterBinding" {
                return Err(self.unsupported(b, "in <ssd:ParameterBindings>"));
            }
            if let Some(prefix) = b.attr("prefix").filter(|p| !p.is_empty()) {
                return Err(self.at(
                    b,
                    format!("<ssd:ParameterBinding> prefix=\"{prefix}\" is not supported"),
                ));
            }
            if b.attr("sourceBase") == Some("component") {
                return Err(self.at(
                    b,
                    "<ssd:ParameterBinding> sourceBase=\"component\" is not supported",
                ));
            }
            let kind = b.attr("type").unwrap_or("application/x-ssp-parameter-set");
            if kind != "application/x-ssp-parameter-set" {
                return Err(self.at(b, format!("<ssd:ParameterBinding> type=\"{kind}\" is not supported (only SSV parameter sets)")));
            }
            if let Some(source) = b.attr("source") {
                let path = self.source(b, source)?;
                let file = source.to_string();
                let set = parse_file(&path, &file)?;
                let saved = std::mem::replace(&mut self.file, file);
                let result = self.parameter_set(&set);
                self.file = saved;
                out.extend(result?);
            }
            for child in &b.children {
                match child.name.as_str() {
                    "ssd:ParameterValues" => {
                        for set in &child.children {
                            out.extend(self.parameter_set(set)?);
                        }
                    }
                    "ssd:ParameterMapping" => {
                        return Err(self.unsupported(child, "(parameter mappings)"))
                    }
                    "ssd:Annotations" => self.annotations(child, Place::Other)?,
                    _ => return Err(self.unsupported(child, "in <ssd:ParameterBinding>")),
                }
            }
        }
        Ok(out)
    }

    /// An `ssv:ParameterSet`.
    fn parameter_set(&mut self, set: &Node) -> Result<Vec<(String, StartValue, usize)>, SspError> {
        if set.name != "ssv:ParameterSet" {
            return Err(self.at(set, format!("<{}> is not an <ssv:ParameterSet>", set.name)));
        }
        let mut out = Vec::new();
        for child in &set.children {
            match child.name.as_str() {
                "ssv:Parameters" => {
                    for p in &child.children {
                        if p.name != "ssv:Parameter" {
                            return Err(self.unsupported(p, "in <ssv:Parameters>"));
                        }
                        let name = self.required(p, "name")?.to_string();
                        let mut value = None;
                        for v in &p.children {
                            let text = || self.required(v, "value");
                            value = Some(match v.name.as_str() {
                                "ssv:Real" => {
                                    StartValue::Real(self.number(v, "value")?.ok_or_else(|| {
                                        self.at(v, "<ssv:Real> needs the attribute 'value'")
                                    })?)
                                }
                                "ssv:Integer" => {
                                    StartValue::Integer(text()?.trim().parse().map_err(|_| {
                                        self.at(v, "<ssv:Integer> value is not an integer")
                                    })?)
                                }
                                "ssv:Boolean" => StartValue::Boolean(match text()?.trim() {
                                    "true" | "1" => true,
                                    "false" | "0" => false,
                                    other => {
                                        return Err(self.at(
                                            v,
                                            format!(
                                                "<ssv:Boolean> value=\"{other}\" is not a boolean"
                                            ),
                                        ))
                                    }
                                }),
                                "ssv:String" => StartValue::String(text()?.to_string()),
                                "ssd:Annotations" | "ssv:Annotations" => continue,
                                _ => return Err(self.unsupported(v, "(parameter type)")),
                            });
                        }
                        let value = value.ok_or_else(|| {
                            self.at(p, format!("parameter '{name}' has no value"))
                        })?;
                        out.push((name, value, p.line));
                    }
                }
                "ssv:Units" | "ssv:Enumerations" | "ssv:Annotations" => {}
                _ => return Err(self.unsupported(child, "in <ssv:ParameterSet>")),
            }
        }
        Ok(out)
    }

    /// System-level bindings `element.variable` (nested: `sub.element.variable`).
    fn apply_bindings(&mut self) -> Result<(), SspError> {
        for (path, name, value, line) in std::mem::take(&mut self.bindings) {
            let segments: Vec<&str> = name.split('.').collect();
            let found = (1..segments.len()).find_map(|i| {
                let mut full = path.clone();
                full.extend(segments[..i].iter().map(|s| s.to_string()));
                self.components
                    .get(&full)
                    .map(|flat| (flat.clone(), segments[i..].join(".")))
            });
            let Some((instance, variable)) = found else {
                return Err(SspError::xml(
                    &self.file,
                    line,
                    format!("parameter '{name}' names no component's variable (expected <component>.<variable>)"),
                ));
            };
            let inst = self
                .instances
                .iter_mut()
                .find(|i| i.name == instance)
                .expect("every component is an instance");
            inst.parameters.insert(variable, value);
        }
        Ok(())
    }

    /// Connections between components, followed through system connectors,
    /// with their transformations and unit conversions composed; and the
    /// exported interface the root system's own connectors declare: an input
    /// or parameter connector that nothing inside drives sets the component
    /// connectors it is connected to, an output connector reads the component
    /// output connected to it (`[export]`, docs/fmu-export.md). `None` when
    /// the root system has no such connectors.
    fn connections(&self) -> Result<(Vec<ConnectionSpec>, Option<ExportSpec>), SspError> {
        let mut edges = self.edges.clone();
        for e in &mut edges {
            (e.gain, e.offset) = self.conversion(e)?;
        }
        let root_kind = |end: &End| match end {
            End::System(p, _) if p.is_empty() => self.kinds.get(end).map(String::as_str),
            _ => None,
        };
        let mut out = Vec::new();
        let mut export = ExportSpec {
            model_name: String::new(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            parameters: Vec::new(),
        };
        for edge in &edges {
            // Where the chain starts: a component output, or a root input or
            // parameter connector nothing inside drives (exported).
            let exported = match &edge.from {
                End::System(p, _) if p.is_empty() => {
                    if edges.iter().any(|e| e.to == edge.from) {
                        continue;
                    }
                    match root_kind(&edge.from) {
                        Some(kind @ ("input" | "parameter")) => Some(kind),
                        _ => {
                            return Err(SspError::xml(
                                &self.file,
                                edge.line,
                                format!(
                                    "<ssd:Connection> from {}: nothing drives it, and Tether runs closed systems \
                                     (a root connector of kind input or parameter is the exported FMU's)",
                                    edge.from.describe()
                                ),
                            ));
                        }
                    }
                }
                End::System(..) => continue,
                End::Component(..) => None,
            };
            let mut stack = vec![(edge.clone(), 0usize)];
            while let Some((e, depth)) = stack.pop() {
                let root_output = root_kind(&e.to) == Some("output");
                if matches!(e.to, End::Component(..)) || root_output {
                    if exported.is_some() || root_output {
                        self.exported(&e, exported, &mut export)?;
                    } else {
                        out.push(ConnectionSpec {
                            from: e.from.describe(),
                            to: e.to.describe(),
                            gain: (e.gain != 1.0).then_some(e.gain),
                            offset: (e.offset != 0.0).then_some(e.offset),
                        });
                    }
                    continue;
                }
                if depth > edges.len() {
                    return Err(SspError::xml(
                        &self.file,
                        e.line,
                        "connections through system connectors form a cycle",
                    ));
                }
                for next in edges.iter().filter(|n| n.from == e.to) {
                    let mut chained = next.clone();
                    chained.from = e.from.clone();
                    chained.gain = e.gain * next.gain;
                    chained.offset = next.gain * e.offset + next.offset;
                    stack.push((chained, depth + 1));
                }
            }
        }
        let any = !(export.inputs.is_empty()
            && export.outputs.is_empty()
            && export.parameters.is_empty());
        Ok((out, any.then_some(export)))
    }

    /// One connection of the exported interface (see [`connections`]):
    /// from a root input or parameter connector (`kind`) to a component, or
    /// from a component to a root output connector. Values pass unchanged.
    fn exported(
        &self,
        e: &Edge,
        kind: Option<&str>,
        export: &mut ExportSpec,
    ) -> Result<(), SspError> {
        let name = |end: &End| match end {
            End::System(_, n) | End::Component(_, n) => n.clone(),
        };
        if e.gain != 1.0 || e.offset != 0.0 {
            return Err(SspError::xml(
                &self.file,
                e.line,
                format!(
                    "<ssd:Connection> {} → {}: a connector of the exported interface passes values unchanged \
                     (no LinearTransformation or unit conversion)",
                    e.from.describe(),
                    e.to.describe()
                ),
            ));
        }
        match (kind, &e.to) {
            (Some(kind), End::Component(..)) => {
                let link = ExportLink {
                    name: name(&e.from),
                    to: e.to.describe(),
                };
                match kind {
                    "parameter" => export.parameters.push(link),
                    _ => export.inputs.push(link),
                }
            }
            (None, End::System(..)) if matches!(e.from, End::Component(..)) => {
                export.outputs.push(ExportSource {
                    name: name(&e.to),
                    from: e.from.describe(),
                })
            }
            _ => {
                return Err(SspError::xml(
                    &self.file,
                    e.line,
                    format!(
                        "<ssd:Connection> {} → {}: the root system's connectors are the exported FMU's \
                         inputs, parameters and outputs: connect each to a component",
                        e.from.describe(),
                        e.to.describe()
                    ),
                ))
            }
        }
        Ok(())
    }

    /// The (gain, offset) of one connection: its LinearTransformation, else
    /// the conversion between the declared units of its ends (SI value =
    /// factor·value + offset on both sides); units that differ without a
    /// conversion are an error naming both ends.
    fn conversion(&self, e: &Edge) -> Result<(f64, f64), SspError> {
        if e.transformed {
            return Ok((e.gain, e.offset));
        }
        let (Some(a), Some(b)) = (self.units.get(&e.from), self.units.get(&e.to)) else {
            return Ok((1.0, 0.0));
        };
        if a == b {
            return Ok((1.0, 0.0));
        }
        match (self.unit_definitions.get(a), self.unit_definitions.get(b)) {
            (Some(ua), Some(ub)) if ua.exponents == ub.exponents && !e.suppress_units => Ok((
                ua.factor / ub.factor,
                (ua.offset - ub.offset) / ub.factor,
            )),
            _ => Err(SspError::xml(
                &self.file,
                e.line,
                format!(
                    "<ssd:Connection> {} → {}: units '{a}' and '{b}' differ and there is no conversion between them",
                    e.from.describe(),
                    e.to.describe()
                ),
            )),
        }
    }
}

/// A component path as an instance name: letters, digits and `_`, the
/// systems' names joined with `_`.
fn flat_name(path: &[String]) -> String {
    let joined = path
        .iter()
        .map(|s| {
            s.chars()
                .map(|c| {
                    if c.is_alphanumeric() || c == '_' {
                        c
                    } else {
                        '_'
                    }
                })
                .collect::<String>()
        })
        .collect::<Vec<_>>()
        .join("_");
    match joined.chars().next() {
        Some(c) if c.is_alphabetic() || c == '_' => joined,
        _ => format!("_{joined}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tempfile::TempDir;

    /// An SSD in a folder with empty stand-ins for the FMUs (reading does not
    /// open them).
    fn folder(ssd: &str) -> TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a.fmu"), b"").unwrap();
        std::fs::write(dir.path().join("SystemStructure.ssd"), ssd).unwrap();
        dir
    }

    fn ssd(unit_from: &str, unit_to: &str, extra: &str) -> String {
        format!(
            r#"<?xml version="1.0"?>
<ssd:SystemStructureDescription version="1.0" name="t"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">
  <ssd:System name="s">
    <ssd:Elements>
      <ssd:Component name="a" source="a.fmu">
        <ssd:Connectors><ssd:Connector name="y" kind="output"><ssc:Real unit="{unit_from}"/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="b" source="a.fmu">
        <ssd:Connectors><ssd:Connector name="u" kind="input"><ssc:Real unit="{unit_to}"/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="a" startConnector="y" endElement="b" endConnector="u"/>
    </ssd:Connections>
    {extra}
  </ssd:System>
  <ssd:Units>
    <ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit>
    <ssc:Unit name="mm"><ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit>
    <ssc:Unit name="K"><ssc:BaseUnit K="1"/></ssc:Unit>
    <ssc:Unit name="degC"><ssc:BaseUnit K="1" offset="273.15"/></ssc:Unit>
  </ssd:Units>
  <ssd:DefaultExperiment stopTime="1"/>
</ssd:SystemStructureDescription>"#
        )
    }

    fn connection(from: &str, to: &str) -> Result<ConnectionSpec, SspError> {
        let dir = folder(&ssd(from, to, ""));
        read(dir.path(), Some(0.1), None).map(|l| l.spec.connections[0].clone())
    }

    #[test]
    fn units_with_the_same_dimension_are_converted() {
        let c = connection("m", "mm").unwrap();
        assert_eq!((c.gain, c.offset), (Some(1000.0), None));
        let c = connection("degC", "K").unwrap();
        assert_eq!((c.gain, c.offset), (None, Some(273.15)));
        let c = connection("m", "m").unwrap();
        assert_eq!((c.gain, c.offset), (None, None));
        let err = connection("m", "K").unwrap_err().to_string();
        assert_eq!(
            err,
            "SystemStructure.ssd:15: <ssd:Connection> a.y → b.u: units 'm' and 'K' differ and \
             there is no conversion between them"
        );
    }

    #[test]
    fn the_tether_annotation_gives_step_method_and_constraints() {
        let annotation = r#"<ssd:Annotations>
      <ssc:Annotation type="org.tether.system">
        <tether:System xmlns:tether="urn:tether:ssp:1"><![CDATA[
step = 0.25
[method]
kind = "weighted"
a = 0.5
[[constraint]]
name = "c"
position = "b.u - a.y"
drives = "b.u"
]]></tether:System>
      </ssc:Annotation>
      <ssc:Annotation type="com.example.other"><x/></ssc:Annotation>
    </ssd:Annotations>"#;
        let dir = folder(&ssd("m", "m", annotation));
        let loaded = read(dir.path(), None, None).unwrap();
        assert_eq!(loaded.spec.experiment.step, 0.25);
        assert_eq!(
            loaded.spec.method,
            tether_master::Method::Weighted { a: 0.5, b: 0.0 }
        );
        assert_eq!(loaded.spec.constraints[0].position, "b.u - a.y");
        assert_eq!(
            loaded.skipped,
            ["com.example.other (SystemStructure.ssd:30)"]
        );
        // --step wins over the annotation.
        let loaded = read(dir.path(), Some(0.5), None).unwrap();
        assert_eq!(loaded.spec.experiment.step, 0.5);
        // An unknown key in the annotation is an error with its line.
        let bad = annotation.replace("a = 0.5", "a = 0.5\nbogus = 1");
        let dir = folder(&ssd("m", "m", &bad));
        let err = read(dir.path(), None, None).err().unwrap().to_string();
        assert!(
            err.starts_with("SystemStructure.ssd:18: the org.tether.system annotation:"),
            "{err}"
        );
    }
}
