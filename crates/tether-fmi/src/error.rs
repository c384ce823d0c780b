//! The crate's error type: one enum, every variant carrying the context needed to act on it.

use std::fmt;
use std::path::PathBuf;

/// What an archive holds: named in errors, and it names the extraction folder
/// (`$TMPDIR/tether-fmu-*` or `$TMPDIR/tether-ssp-*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArchiveKind {
    /// An FMU (`.fmu`).
    Fmu,
    /// An SSP system (`.ssp`).
    Ssp,
}

impl std::fmt::Display for ArchiveKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ArchiveKind::Fmu => "FMU",
            ArchiveKind::Ssp => "SSP",
        })
    }
}

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong when importing or driving an FMI 2.0 FMU.
///
/// `Display` is always a single line naming the culprit (file, entry, instance, function,
/// time or variable).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file or directory could not be read or written.
    #[error("cannot access '{}': {source}", path.display())]
    Io {
        /// The path being accessed.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },

    /// A file or folder that cannot be reached, said with where it was looked
    /// for: the resolved path, the folder a relative path was resolved
    /// against, and a name that differs only in case.
    #[error("cannot access {}: {source}{}", .place.located(), .place.hint())]
    Missing {
        /// Where it was looked for.
        place: Box<crate::paths::Missing>,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },

    /// The path is neither a readable zip archive nor an unpacked FMU directory.
    #[error("'{}' is not an {kind} archive (not a valid zip file: {reason})", path.display())]
    NotAnArchive {
        /// What the archive should hold.
        kind: ArchiveKind,
        /// The offending path.
        path: PathBuf,
        /// Why the zip reader rejected it.
        reason: String,
    },

    /// An archive entry would be extracted outside the target directory (`..`).
    #[error("{kind} archive '{}' has entry '{entry}' that escapes the extraction directory", archive.display())]
    EntryEscapes {
        /// What the archive holds.
        kind: ArchiveKind,
        /// The archive.
        archive: PathBuf,
        /// The entry name as stored in the archive.
        entry: String,
    },

    /// An archive entry has an absolute path.
    #[error("{kind} archive '{}' has entry '{entry}' with an absolute path", archive.display())]
    AbsoluteEntry {
        /// What the archive holds.
        kind: ArchiveKind,
        /// The archive.
        archive: PathBuf,
        /// The entry name as stored in the archive.
        entry: String,
    },

    /// An archive entry is a symbolic link (refused: it could point anywhere).
    #[error("{kind} archive '{}' has entry '{entry}' that is a symbolic link", archive.display())]
    SymlinkEntry {
        /// What the archive holds.
        kind: ArchiveKind,
        /// The archive.
        archive: PathBuf,
        /// The entry name as stored in the archive.
        entry: String,
    },

    /// An archive entry cannot be extracted safely for another reason (encryption,
    /// compression method other than stored/deflate, duplicate name, control character
    /// in the name, data the zip reader cannot read).
    #[error("{kind} archive '{}' has entry '{entry}' that cannot be extracted: {reason}", archive.display())]
    UnsupportedEntry {
        /// What the archive holds.
        kind: ArchiveKind,
        /// The archive.
        archive: PathBuf,
        /// The entry name as stored in the archive.
        entry: String,
        /// What is wrong with it.
        reason: String,
    },

    /// Extraction would exceed a limit of [`ExtractLimits`](crate::ExtractLimits): total
    /// size, entry count, entry size or compression ratio (decompression bomb guard).
    #[error("{kind} archive '{}' exceeds the extraction limit at entry '{entry}': {reason}", archive.display())]
    ArchiveTooLarge {
        /// What the archive holds.
        kind: ArchiveKind,
        /// The archive.
        archive: PathBuf,
        /// The entry at which the limit was hit.
        entry: String,
        /// Which limit, with numbers.
        reason: String,
    },

    /// The path is neither a regular file nor a folder (a FIFO, a device, a
    /// socket): refused before it is opened, since opening a FIFO waits for a
    /// writer that may never come.
    #[error("'{}' is a {kind}, not an FMU archive (a regular file) nor an unpacked FMU folder", path.display())]
    NotAFile {
        /// The offending path.
        path: PathBuf,
        /// What it is: `FIFO`, `character device`, `block device`, `socket`.
        kind: &'static str,
    },

    /// The FMU has no `modelDescription.xml` at its root.
    #[error("'{}' has no modelDescription.xml at its root", path.display())]
    MissingModelDescription {
        /// The FMU (archive or directory).
        path: PathBuf,
    },

    /// `modelDescription.xml` is not well-formed XML.
    #[error("malformed XML in '{}' at line {line}, column {column}: {message}", file.display())]
    MalformedXml {
        /// The XML file.
        file: PathBuf,
        /// 1-based line of the problem.
        line: usize,
        /// 1-based column (in characters) of the problem.
        column: usize,
        /// What the parser found.
        message: String,
    },

    /// `modelDescription.xml` is over a limit of the XML reader: its size or its
    /// nesting depth ([`crate::xml::MAX_BYTES`], [`crate::xml::MAX_DEPTH`]).
    #[error("XML file '{}' is over a limit at line {line}, column {column}: {message}", file.display())]
    XmlLimit {
        /// The XML file.
        file: PathBuf,
        /// 1-based line of the problem.
        line: usize,
        /// 1-based column (in characters) of the problem.
        column: usize,
        /// Which limit, with numbers.
        message: String,
    },

    /// `modelDescription.xml` is well-formed but violates the FMI 2.0 schema or rules.
    #[error("invalid model description '{}' at line {line}: {message}", file.display())]
    InvalidModelDescription {
        /// The XML file.
        file: PathBuf,
        /// 1-based line of the offending element.
        line: usize,
        /// What is wrong.
        message: String,
    },

    /// The FMU is not an FMI 2.0 FMU.
    #[error("'{}' is an FMI {version} FMU; Tether supports FMI 2.0 and 3.0 (co-simulation and model exchange)", path.display())]
    UnsupportedFmiVersion {
        /// The FMU.
        path: PathBuf,
        /// The `fmiVersion` found (or a description when the attribute is absent).
        version: String,
    },

    /// An FMI 3.0 FMU offers no co-simulation (scheduled execution only, whose
    /// clocks need a scheduler Tether does not provide).
    #[error("'{}' (model '{model}') offers {offers} only, no co-simulation; Tether imports FMI 2.0 and 3.0 co-simulation and model exchange", path.display())]
    NotCoSimulationFmi3 {
        /// The FMU.
        path: PathBuf,
        /// The model name.
        model: String,
        /// What it offers instead.
        offers: &'static str,
    },

    /// The FMU needs something Tether does not offer (FMI 3.0 clocks, …).
    #[error("model '{model}' cannot run in Tether: {reason}")]
    Unsupported {
        /// The model name.
        model: String,
        /// What it needs, and why that is missing.
        reason: String,
    },

    /// The FMU implements model exchange only and was asked for co-simulation.
    #[error("'{}' (model '{model}') is a model-exchange-only FMU: it has no co-simulation interface; run it as model exchange (tether simulate --fmi-type model-exchange)", path.display())]
    NotCoSimulation {
        /// The FMU.
        path: PathBuf,
        /// The model name.
        model: String,
    },

    /// The FMU ships no binary for this platform.
    #[error("FMU '{model}' has no {} binary: expected '{}'", platform_of(expected), expected.display())]
    MissingBinary {
        /// The model name.
        model: String,
        /// Where the shared library was expected.
        expected: PathBuf,
    },

    /// The shared library could not be loaded.
    #[error("cannot load FMU library '{}': {}", path.display(), one_line(message))]
    LibraryLoad {
        /// The shared library.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },

    /// The shared library lacks a function of the FMI 2.0 co-simulation API.
    #[error("FMU library '{}' lacks the FMI {} function '{symbol}'", library.display(), standard_of(symbol))]
    MissingSymbol {
        /// The shared library.
        library: PathBuf,
        /// The first missing symbol.
        symbol: &'static str,
    },

    /// The shared library reports a different FMI version or types platform.
    #[error("FMU library '{}': {function} returned '{found}', expected '{expected}'", library.display())]
    IncompatibleLibrary {
        /// The shared library.
        library: PathBuf,
        /// `fmi2GetVersion` or `fmi2GetTypesPlatform`.
        function: &'static str,
        /// What the library returned.
        found: String,
        /// What Tether needs.
        expected: &'static str,
    },

    /// No variable of that name exists; close matches are suggested.
    #[error("no variable '{name}' in model '{model}'{}", Suggestions(suggestions))]
    UnknownVariable {
        /// The model name.
        model: String,
        /// The name asked for.
        name: String,
        /// Close matches (edit distance or prefix), best first.
        suggestions: Vec<String>,
    },

    /// The FMU does not declare a capability the requested operation needs.
    #[error("model '{model}' does not declare {capability}=\"true\", which {operation} needs")]
    MissingCapability {
        /// The model name.
        model: String,
        /// The capability flag, spelled as in modelDescription.xml.
        capability: &'static str,
        /// The operation that needs it.
        operation: &'static str,
    },

    /// A second instance of a model that declares `canBeInstantiatedOnlyOncePerProcess`.
    #[error("model '{model}' declares canBeInstantiatedOnlyOncePerProcess=\"true\": cannot create instance '{instance}' while instance '{existing}' exists in this process")]
    OnlyOncePerProcess {
        /// The model name.
        model: String,
        /// The instance that was refused.
        instance: String,
        /// The live instance of the same model (same GUID).
        existing: String,
    },

    /// `fmi2Instantiate` returned NULL.
    #[error("fmi2Instantiate failed for instance '{instance}' of model '{model}'{messages}")]
    InstantiationFailed {
        /// The model name.
        model: String,
        /// The requested instance name.
        instance: String,
        /// What the FMU logged during the call.
        messages: FmuMessages,
    },

    /// A function returned `fmi2Discard`.
    #[error(
        "{function} returned {}Discard on instance '{instance}' at t={time}{messages}",
        api(function)
    , time = crate::Time(*time))]
    Discard {
        /// The FMI function.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// The instance's communication time when the call was made.
        time: f64,
        /// The FMU's last log messages.
        messages: FmuMessages,
    },

    /// The FMU asked to end the simulation: its step returned Discard and it
    /// reports that it terminated (FMI 2.0: `fmi2GetBooleanStatus(fmi2Terminated)`).
    #[error("instance '{instance}' requested the end of the simulation at t = {time} ({})", how.as_deref().unwrap_or("fmi2DoStep returned fmi2Discard with fmi2Terminated = true"), time = crate::Time(*time))]
    TerminationRequested {
        /// The instance name.
        instance: String,
        /// The last time the instance reached (its `fmi2LastSuccessfulTime`,
        /// or the step's end if it does not say).
        time: f64,
        /// How the FMU asked, when not as FMI 2.0 does (`None`: fmi2DoStep returned
        /// fmi2Discard with fmi2Terminated = true).
        how: Option<String>,
    },

    /// A model-exchange instance could not go on: NaN or infinite derivatives,
    /// an integrator that cannot reach its tolerance, a chattering event.
    #[error("model-exchange instance '{instance}' stopped at t = {time}: {cause}", time = crate::Time(*time))]
    ModelExchange {
        /// The instance name.
        instance: String,
        /// The time the instance reached.
        time: f64,
        /// What went wrong, in one line.
        cause: String,
    },

    /// A function returned `fmi2Error`.
    #[error(
        "{function} returned {}Error on instance '{instance}' at t={time}{messages}",
        api(function)
    , time = crate::Time(*time))]
    Failed {
        /// The FMI function.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// The instance's communication time when the call was made.
        time: f64,
        /// The FMU's last log messages.
        messages: FmuMessages,
    },

    /// A function returned `fmi2Fatal`; the FMU is unusable from now on.
    #[error(
        "{function} returned {}Fatal on instance '{instance}' at t={time}{messages}",
        api(function)
    , time = crate::Time(*time))]
    Fatal {
        /// The FMI function.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// The instance's communication time when the call was made.
        time: f64,
        /// The FMU's last log messages.
        messages: FmuMessages,
    },

    /// A function returned `fmi2Pending` (asynchronous stepping is not supported).
    #[error("{function} returned fmi2Pending on instance '{instance}' at t={time}", time = crate::Time(*time))]
    Pending {
        /// The FMI function.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// The instance's communication time when the call was made.
        time: f64,
    },

    /// A function returned a status code outside the FMI 2.0 range.
    #[error(
        "{function} returned the unknown status code {code} on instance '{instance}' at t={time}"
    , time = crate::Time(*time))]
    UnknownStatus {
        /// The FMI function.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// The instance's communication time when the call was made.
        time: f64,
        /// The raw status code.
        code: i32,
    },

    /// A call was refused because an earlier call of this FMU returned `fmi2Fatal`.
    #[error("{function} refused on instance '{instance}' at t={time}: the FMU returned {}Fatal earlier{messages}", api(function), time = crate::Time(*time))]
    FmuDead {
        /// The FMI function that was not called.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// The instance's communication time.
        time: f64,
        /// The instance's last log messages.
        messages: FmuMessages,
    },

    /// An FMU state was used with an instance it does not belong to.
    #[error("{function} on instance '{instance}': the FMU state belongs to instance '{owner}'")]
    ForeignState {
        /// The FMI function.
        function: &'static str,
        /// The instance the call was made on.
        instance: String,
        /// The instance that created the state.
        owner: String,
    },

    /// Slices passed to a get/set function differ in length.
    #[error("{function} on instance '{instance}': {what} has {got} entries, expected {expected}")]
    LengthMismatch {
        /// The FMI function.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// Which argument.
        what: &'static str,
        /// The length required.
        expected: usize,
        /// The length passed.
        got: usize,
    },

    /// An error of an isolated instance's host process that crossed as a message.
    #[error("{message}")]
    Host {
        /// The instance name.
        instance: String,
        /// The error, as the host reported it.
        message: String,
    },

    /// The host process of an isolated instance could not be started.
    #[error("cannot start the host process of instance '{instance}': {reason}")]
    HostStart {
        /// The instance name.
        instance: String,
        /// Why.
        reason: String,
    },

    /// The host process of an isolated instance ended (crashed, exited, was
    /// killed) during a call.
    #[error("instance '{instance}': its host process {how} during {function} at t={time}", time = crate::Time(*time))]
    HostEnded {
        /// The instance name.
        instance: String,
        /// The FMI function in progress.
        function: &'static str,
        /// The instance's communication time when the call was made.
        time: f64,
        /// What happened: `was killed by signal 11 (SIGSEGV)`, `exited with code 3`.
        how: String,
    },

    /// A call of an isolated instance exceeded the call time-out; its host
    /// process was killed.
    #[error("instance '{instance}': {function} at t={time} did not return within the call time-out of {seconds} s; its host process was killed", time = crate::Time(*time))]
    CallTimeout {
        /// The instance name.
        instance: String,
        /// The FMI function in progress.
        function: &'static str,
        /// The instance's communication time when the call was made.
        time: f64,
        /// The time-out.
        seconds: f64,
    },

    /// An argument cannot be passed to (or a result cannot be taken from) the C API,
    /// e.g. a string with an interior NUL byte or a non-UTF-8 string from the FMU.
    #[error("{function} on instance '{instance}': {message}")]
    InvalidArgument {
        /// The FMI function.
        function: &'static str,
        /// The instance name.
        instance: String,
        /// What is wrong.
        message: String,
    },
}

/// The last messages an FMU instance logged (at most five, each cut to 300
/// characters), reported with a failed call: `; the FMU's last messages:
/// [category] text | …`, or nothing when it logged none. Errors are always
/// kept; other messages when they are shown (`--fmu-log`, `-v`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FmuMessages(pub Vec<String>);

impl fmt::Display for FmuMessages {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            return Ok(());
        }
        write!(f, "; the FMU's last messages: {}", self.0.join(" | "))
    }
}

impl Error {
    /// The FMI function named by a status or call error, if this is one.
    pub fn function(&self) -> Option<&'static str> {
        match self {
            Error::Discard { function, .. }
            | Error::Failed { function, .. }
            | Error::Fatal { function, .. }
            | Error::Pending { function, .. }
            | Error::UnknownStatus { function, .. }
            | Error::FmuDead { function, .. }
            | Error::ForeignState { function, .. }
            | Error::LengthMismatch { function, .. }
            | Error::InvalidArgument { function, .. }
            | Error::HostEnded { function, .. }
            | Error::CallTimeout { function, .. } => Some(function),
            _ => None,
        }
    }
}

/// Collapses whitespace runs (including newlines) so messages from other libraries stay
/// on one line.
pub(crate) fn one_line(message: &str) -> String {
    message.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Renders "; did you mean 'a', 'b'?" or nothing.
struct Suggestions<'a>(&'a [String]);

impl fmt::Display for Suggestions<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some((first, rest)) = self.0.split_first() else {
            return Ok(());
        };
        write!(f, "; did you mean '{first}'")?;
        for s in rest {
            write!(f, ", '{s}'")?;
        }
        f.write_str("?")
    }
}

/// The C prefix of `function`'s standard: "fmi3" for an FMI 3.0 function, else "fmi2".
fn api(function: &str) -> &'static str {
    if function.starts_with("fmi3") {
        "fmi3"
    } else {
        "fmi2"
    }
}

/// "3.0" for an FMI 3.0 symbol, else "2.0".
fn standard_of(symbol: &str) -> &'static str {
    if symbol.starts_with("fmi3") {
        "3.0"
    } else {
        "2.0"
    }
}

/// The platform directory of an expected binary path (`linux64`, `x86_64-linux`).
fn platform_of(path: &std::path::Path) -> String {
    path.parent()
        .and_then(|p| p.file_name())
        .map(|p| p.to_string_lossy().into_owned())
        .unwrap_or_else(|| "this platform's".to_owned())
}

/// What an FMI 2.0 instance says after a step returned fmi2Discard: whether
/// it terminated (`fmi2GetBooleanStatus(fmi2Terminated)`) and the time it
/// reached (`fmi2GetRealStatus(fmi2LastSuccessfulTime)`). In process and in a
/// host process alike.
pub(crate) trait StepStatus {
    fn name(&self) -> &str;
    fn terminated(&mut self) -> Result<bool>;
    fn last_successful_time(&mut self) -> Result<f64>;
}

/// The error of a failed FMI 2.0 step of `instance` to `end`: a request to end
/// the simulation (fmi2Discard with `fmi2Terminated`) becomes
/// [`Error::TerminationRequested`], any other error stays as it is.
#[cold]
#[inline(never)]
pub(crate) fn step_failure(e: Error, instance: &mut impl StepStatus, end: f64) -> Error {
    if matches!(e, Error::Discard { .. }) && matches!(instance.terminated(), Ok(true)) {
        let time = instance.last_successful_time().unwrap_or(end);
        return Error::TerminationRequested {
            instance: instance.name().to_string(),
            time,
            how: None,
        };
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_variable_message_lists_suggestions() {
        let e = Error::UnknownVariable {
            model: "oscillator".into(),
            name: "xx".into(),
            suggestions: vec!["x".into()],
        };
        assert_eq!(
            e.to_string(),
            "no variable 'xx' in model 'oscillator'; did you mean 'x'?"
        );
        let e = Error::UnknownVariable {
            model: "m".into(),
            name: "q".into(),
            suggestions: vec![],
        };
        assert_eq!(e.to_string(), "no variable 'q' in model 'm'");
    }

    #[test]
    fn loader_messages_are_collapsed_to_one_line() {
        let e = Error::LibraryLoad {
            path: "/a.so".into(),
            message: "first\n  second".into(),
        };
        assert_eq!(
            e.to_string(),
            "cannot load FMU library '/a.so': first second"
        );
    }
}
