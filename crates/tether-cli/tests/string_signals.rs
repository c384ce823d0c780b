//! String signals end to end with the `tether` binary: the Reference FMU
//! `Feedthrough` (FMI 2.0 and 3.0, whose `String_output` is its
//! `String_input`) sends text to another instance; the CSV has the String
//! columns in quotes (commas and quotes inside the text), the receiver's own
//! output shows what it received, `tether compare` compares them for
//! equality, a String connection in a loop is held, an SSD connects String
//! connectors, and wrong uses are one error line naming the connection.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Text with a comma, quotes and a semicolon: what CSV must quote.
const TEXT: &str = r#"a, "quoted" text; ok"#;

fn feedthrough(version: &str) -> Option<PathBuf> {
    tether_fmu_build::fixture_fmu(&format!("reference-fmus/{version}/Feedthrough.fmu"))
}

/// `text` as a TOML basic string.
fn toml_string(text: &str) -> String {
    format!("\"{}\"", text.replace('\\', "\\\\").replace('"', "\\\""))
}

/// `src` (FMU `a`, its String input set to `text`) sends its String output to
/// `dst` (FMU `b`); `extra` is added to the connection.
fn chain(a: &Path, b: &Path, text: &str, extra: &str) -> String {
    format!(
        "[experiment]\nstop = 0.05\nstep = 0.01\n\n\
         [[instance]]\nname = \"src\"\nfmu = {a:?}\nparameters = {{ String_input = {} }}\n\n\
         [[instance]]\nname = \"dst\"\nfmu = {b:?}\n\n\
         [[connection]]\nfrom = \"src.String_output\"\nto = \"dst.String_input\"\n{extra}",
        toml_string(text)
    )
}

fn tether(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

/// Runs `system` in `dir` into `csv`; the output.
fn run(dir: &Path, system: &str, csv: &str, args: &[&str]) -> Output {
    std::fs::write(dir.join("system.toml"), system).unwrap();
    let mut all = vec!["run", "system.toml", "--out", csv];
    all.extend_from_slice(args);
    tether(dir, &all)
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "tether failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The one `error: ` line of a failed command.
fn error_line(out: &Output) -> String {
    assert!(!out.status.success(), "the command succeeded");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("error: "))
        .collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    lines[0].to_string()
}

/// The CSV as read by the `csv` crate: the header and the rows' fields.
fn read(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .unwrap();
    let header = reader.headers().unwrap().iter().map(String::from).collect();
    let rows = reader
        .records()
        .map(|r| r.unwrap().iter().map(String::from).collect())
        .collect();
    (header, rows)
}

fn column(header: &[String], rows: &[Vec<String>], name: &str) -> Vec<String> {
    let j = header.iter().position(|h| h == name).unwrap();
    rows.iter().map(|r| r[j].clone()).collect()
}

/// FMI 2.0 to FMI 2.0 and FMI 2.0 to FMI 3.0: every row has the sender's
/// text, and the receiver's `String_output`, which is the input it got, has
/// it too; the text is written in quotes, its quotes doubled. Isolated
/// instances (host processes) give the same file.
#[test]
fn a_string_connection_hands_text_with_commas_and_quotes_to_the_receiver() {
    let (Some(fmi2), Some(fmi3)) = (feedthrough("fmi2"), feedthrough("fmi3")) else {
        return;
    };
    for receiver in [&fmi2, &fmi3] {
        let dir = tempfile::tempdir().unwrap();
        let out = run(dir.path(), &chain(&fmi2, receiver, TEXT, ""), "r.csv", &[]);
        ok(&out);
        let (header, rows) = read(&dir.path().join("r.csv"));
        assert_eq!(rows.len(), 6);
        for name in ["src.String_output", "dst.String_output"] {
            assert_eq!(column(&header, &rows, name), vec![TEXT; 6], "{name}");
        }
        // String columns come after an instance's numbers, and are quoted.
        let last = header.iter().rposition(|h| h.starts_with("src.")).unwrap();
        assert_eq!(header[last], "src.String_output");
        let text = std::fs::read_to_string(dir.path().join("r.csv")).unwrap();
        let line = text.lines().nth(1).unwrap();
        assert!(line.contains(r#","a, ""quoted"" text; ok","#), "{line}");
        // Through host processes: the texts cross the protocol whole.
        let isolated =
            chain(&fmi2, receiver, TEXT, "").replace("fmu = ", "isolation = \"process\"\nfmu = ");
        ok(&run(dir.path(), &isolated, "isolated.csv", &[]));
        let again = std::fs::read_to_string(dir.path().join("isolated.csv")).unwrap();
        assert_eq!(again, text);
    }
}

/// `tether compare` of two runs with the same texts passes and prints the
/// String columns as text; with another text it fails with one line naming
/// the first String column that differs, the time and both texts.
#[test]
fn compare_takes_string_columns_as_equal_or_not() {
    let Some(fmi2) = feedthrough("fmi2") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    ok(&run(
        dir.path(),
        &chain(&fmi2, &fmi2, TEXT, ""),
        "a.csv",
        &[],
    ));
    ok(&run(
        dir.path(),
        &chain(&fmi2, &fmi2, TEXT, ""),
        "b.csv",
        &[],
    ));
    ok(&run(
        dir.path(),
        &chain(&fmi2, &fmi2, "other", ""),
        "c.csv",
        &[],
    ));
    let same = tether(dir.path(), &["compare", "a.csv", "b.csv"]);
    ok(&same);
    let stdout = String::from_utf8_lossy(&same.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("dst.String_output"))
        .unwrap();
    assert!(
        line.contains("same text") && line.ends_with("yes"),
        "{line}"
    );
    let differ = tether(dir.path(), &["compare", "a.csv", "c.csv"]);
    assert_eq!(
        error_line(&differ),
        r#"error: column 'src.String_output' has other text in 6 of 6 rows, first at t = 0: "a, \"quoted\" text; ok" in a.csv, "other" in c.csv"#
    );
    let stdout = String::from_utf8_lossy(&differ.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("dst.String_output"))
        .unwrap();
    assert!(line.contains("6 rows") && line.ends_with("NO"), "{line}");
}

/// A String column compared with a column of numbers is one error line.
#[test]
fn compare_refuses_text_against_numbers() {
    let Some(fmi2) = feedthrough("fmi2") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    ok(&run(
        dir.path(),
        &chain(&fmi2, &fmi2, TEXT, ""),
        "a.csv",
        &[],
    ));
    let text = std::fs::read_to_string(dir.path().join("a.csv")).unwrap();
    let numbers = text.replace(r#""a, ""quoted"" text; ok""#, "1");
    std::fs::write(dir.path().join("n.csv"), numbers).unwrap();
    let out = tether(dir.path(), &["compare", "a.csv", "n.csv"]);
    assert_eq!(
        error_line(&out),
        "error: column 'src.String_output' is text (a String output) in a.csv and numbers in n.csv: cannot compare"
    );
}

/// `gain` or `offset` on a String connection, a String output to a Real
/// input and an FMI 3.0 Binary output: one line naming the connection.
#[test]
fn wrong_string_connections_are_one_line_naming_the_connection() {
    let (Some(fmi2), Some(fmi3)) = (feedthrough("fmi2"), feedthrough("fmi3")) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for extra in ["gain = 2.0\n", "offset = 1.0\n"] {
        let out = run(dir.path(), &chain(&fmi2, &fmi2, TEXT, extra), "r.csv", &[]);
        assert_eq!(
            error_line(&out),
            "error: connection src.String_output → dst.String_input: gain and offset apply \
             to Real connections only"
        );
    }
    let to_real = chain(&fmi2, &fmi2, TEXT, "").replace(
        "to = \"dst.String_input\"",
        "to = \"dst.Float64_continuous_input\"",
    );
    let out = run(dir.path(), &to_real, "r.csv", &[]);
    let line = error_line(&out);
    assert!(
        line.starts_with("error: connection src.String_output → dst.Float64_continuous_input: ")
            && line.ends_with("a connection joins variables of one type"),
        "{line}"
    );
    let binary = chain(&fmi3, &fmi3, "x", "")
        .replace("String_input = \"x\"", "Binary_input = \"0a0b\"")
        .replace("src.String_output", "src.Binary_output")
        .replace("dst.String_input", "dst.Binary_input");
    let out = run(dir.path(), &binary, "r.csv", &[]);
    let line = error_line(&out);
    assert!(
        line.contains("Binary_output")
            && line.contains("needs a Real, Integer, Boolean or String output"),
        "{line}"
    );
}

/// Two instances feeding each other's String input through (a
/// direct-feedthrough loop): the loop is closed at T_0, `-v` names its
/// connections, each passing the value at T_N (held, as Integer and Boolean
/// links are), and both carry the text set on `src` at every point.
#[test]
fn a_string_loop_is_held() {
    let Some(fmi2) = feedthrough("fmi2") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let system = chain(&fmi2, &fmi2, TEXT, "")
        + "\n[[connection]]\nfrom = \"dst.String_output\"\nto = \"src.String_input\"\n";
    let out = run(dir.path(), &system, "r.csv", &["-v"]);
    ok(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("direct-feedthrough loop 1: src.String_output → dst.String_input (value at T_N), dst.String_output → src.String_input (value at T_N)"),
        "{stderr}"
    );
    let (header, rows) = read(&dir.path().join("r.csv"));
    // At T_0 the loop settles on the text src started with.
    for name in ["src.String_output", "dst.String_output"] {
        assert_eq!(column(&header, &rows, name), vec![TEXT; 6], "{name}");
    }
}

/// An SSD whose components connect String connectors (`ssc:String`) runs
/// like the system file: the receiver gets the text of an `ssv:String`
/// parameter binding.
#[test]
fn ssp_string_connectors_connect() {
    let Some(fmi2) = feedthrough("fmi2") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("resources")).unwrap();
    std::fs::copy(&fmi2, dir.path().join("resources/Feedthrough.fmu")).unwrap();
    let component = |name: &str, kind: &str, connector: &str, binding: &str| {
        format!(
            r#"      <ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" source="resources/Feedthrough.fmu">
        <ssd:Connectors>
          <ssd:Connector name="{connector}" kind="{kind}"><ssc:String/></ssd:Connector>
        </ssd:Connectors>{binding}
      </ssd:Component>
"#
        )
    };
    let binding = r#"
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="text">
                <ssv:Parameters>
                  <ssv:Parameter name="String_input"><ssv:String value="from SSP, &quot;quoted&quot;"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>"#;
    let ssd = format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    version="1.0" name="texts">
  <ssd:System name="texts">
    <ssd:Elements>
{}{}    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="src" startConnector="String_output" endElement="dst" endConnector="String_input"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="0.05"/>
</ssd:SystemStructureDescription>
"#,
        component("src", "output", "String_output", binding),
        component("dst", "input", "String_input", ""),
    );
    std::fs::write(dir.path().join("SystemStructure.ssd"), ssd).unwrap();
    let out = tether(
        dir.path(),
        &[
            "run",
            "SystemStructure.ssd",
            "--step",
            "0.01",
            "--out",
            "r.csv",
        ],
    );
    ok(&out);
    let (header, rows) = read(&dir.path().join("r.csv"));
    assert_eq!(
        column(&header, &rows, "dst.String_output"),
        vec![r#"from SSP, "quoted""#; rows.len()]
    );
}

/// The pythonfmu3 FMU of tests/fixtures/pythonfmu3/Texts.py (a String output
/// `label` that changes every step; a String input `text` whose `length`
/// and `echo` are outputs), built once; `None` (skip) without Python or
/// pythonfmu3 outside CI.
fn texts() -> Option<tether_tests::fmpy::PythonFmu> {
    tether_tests::fmpy::pythonfmu3_for_test("Texts")
}

/// `a` sends its label to `b`; `extra` is added to the system.
fn texts_system(fmu: &Path, extra: &str) -> String {
    format!(
        "[experiment]\nstop = 0.5\nstep = 0.1\n\n\
         [[instance]]\nname = \"a\"\nfmu = {fmu:?}\n\n\
         [[instance]]\nname = \"b\"\nfmu = {fmu:?}\n\n\
         [[connection]]\nfrom = \"a.label\"\nto = \"b.text\"\n{extra}"
    )
}

/// Runs a system of the Python FMU; the CSV's header and fields.
fn run_texts(fmu: &tether_tests::fmpy::PythonFmu, system: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("system.toml"), system).unwrap();
    let out = fmu
        .env(Command::new(env!("CARGO_BIN_EXE_tether")).current_dir(dir.path()))
        .args(["run", "system.toml", "--out", "r.csv"])
        .output()
        .unwrap();
    ok(&out);
    read(&dir.path().join("r.csv"))
}

/// The label after step s, as Texts.py writes it.
fn label(s: usize) -> String {
    let t = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5][s];
    format!("step {s}, \"t\" = {t}")
}

/// A text that changes every step: with Jacobi the receiver takes the
/// sender's text at T_N, held over the step, so its echo at T_{N+1} is the
/// label of the row before (at T_0 the label of T_0, set at initialization);
/// with Gauss–Seidel the sender steps first and the echo is the label of the
/// same row. The receiver's `length` counts the characters it received.
#[test]
fn a_changing_text_is_held_over_each_step_as_the_scheme_says() {
    let Some(fmu) = texts() else {
        return;
    };
    let (header, rows) = run_texts(&fmu, &texts_system(&fmu.fmu, ""));
    let labels: Vec<String> = (0..6).map(label).collect();
    assert_eq!(column(&header, &rows, "a.label"), labels);
    let echo = column(&header, &rows, "b.echo");
    assert_eq!(echo[0], labels[0]);
    assert_eq!(echo[1..], labels[..5]);
    let lengths: Vec<String> = echo
        .iter()
        .map(|e| format!("{:?}", e.chars().count() as f64))
        .collect();
    assert_eq!(column(&header, &rows, "b.length"), lengths);

    let gauss_seidel = texts_system(&fmu.fmu, "\n[signals]\nscheme = \"gauss_seidel\"\n");
    let (header, rows) = run_texts(&fmu, &gauss_seidel);
    assert_eq!(column(&header, &rows, "b.echo"), labels);
}

/// A loop of String connections, a → b → a (Texts.py declares no
/// dependencies, so its outputs are taken to feed through): closed at macro
/// points, each connection passes the text at T_N, so a's echo lags a's own
/// label by two steps; iterated (`[signals] iterations`), every receiver
/// takes the text at T_{N+1}, compared for equality, and the loop converges
/// on the label of the same row.
#[test]
fn a_loop_of_changing_texts_is_held_or_iterated() {
    let Some(fmu) = texts() else {
        return;
    };
    let back = "\n[[connection]]\nfrom = \"b.echo\"\nto = \"a.text\"\n";
    let labels: Vec<String> = (0..6).map(label).collect();
    let (header, rows) = run_texts(&fmu, &texts_system(&fmu.fmu, back));
    let echo = column(&header, &rows, "a.echo");
    assert_eq!(echo[..2], [labels[0].clone(), labels[0].clone()]);
    assert_eq!(echo[2..], labels[..4]);

    let iterated = format!("{back}\n[signals]\niterations = 5\nstrict = true\n");
    let (header, rows) = run_texts(&fmu, &texts_system(&fmu.fmu, &iterated));
    assert_eq!(column(&header, &rows, "b.echo"), labels);
    assert_eq!(column(&header, &rows, "a.echo"), labels);
}

/// `[output]` picks String columns like others: `variables` keeps the
/// chosen String column, `interval` records every second point and the last
/// one, held back off the grid, with its text.
#[test]
fn output_selection_keeps_string_columns() {
    let Some(fmu) = texts() else {
        return;
    };
    let output = "\n[output]\nvariables = [\"b.echo\", \"a.label\"]\ninterval = 0.2\n";
    let (header, rows) = run_texts(&fmu, &texts_system(&fmu.fmu, output));
    assert_eq!(header, ["time", "a.label", "b.echo"]);
    let times: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(times, ["0.0", "0.2", "0.4", "0.5"]);
    assert_eq!(
        column(&header, &rows, "a.label"),
        [label(0), label(2), label(4), label(5)]
    );
    assert_eq!(
        column(&header, &rows, "b.echo"),
        [label(0), label(1), label(3), label(4)]
    );
}

/// The run summary counts String calls: per recorded point one
/// `fmi2GetString` of each instance's recorded String outputs, and for the
/// connection one get of the sender and one `fmi2SetString` of the
/// receiver per macro step and per sweep at T_0.
#[test]
fn the_summary_counts_string_calls() {
    let Some(fmi2) = feedthrough("fmi2") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("system.toml"),
        chain(&fmi2, &fmi2, TEXT, ""),
    )
    .unwrap();
    let out = tether(
        dir.path(),
        &[
            "run",
            "system.toml",
            "--out",
            "r.csv",
            "--summary-json",
            "s.json",
        ],
    );
    ok(&out);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("s.json")).unwrap()).unwrap();
    let calls = |i: &str, key: &str| json["instances"][i][key].as_u64().unwrap();
    // 6 recorded points; the link read and set 3 times at T_0 (the setup
    // sweeps until nothing changes, before and after the consistent
    // multipliers: 2 + 1) and once for each of the 5 steps, as Integer
    // and Boolean links are.
    assert_eq!(calls("src", "get_string"), 6 + 3 + 5);
    assert_eq!(calls("dst", "get_string"), 6);
    assert_eq!(calls("dst", "set_string"), 3 + 5);
    assert_eq!(calls("src", "set_string"), 0);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("  fmi2GetString"), "{stderr}");
}

/// `tether ssp export` writes the String connectors (`ssc:String`) and the
/// String start value; the archive runs to the same CSV byte for byte.
#[test]
fn a_string_system_round_trips_through_ssp() {
    let Some(fmi2) = feedthrough("fmi2") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&run(d, &chain(&fmi2, &fmi2, TEXT, ""), "toml.csv", &[]));
    ok(&tether(
        d,
        &["ssp", "export", "system.toml", "-o", "system.ssp"],
    ));
    ok(&tether(d, &["run", "system.ssp", "--out", "ssp.csv"]));
    let toml = std::fs::read_to_string(d.join("toml.csv")).unwrap();
    assert!(toml.contains(r#""a, ""quoted"" text; ok""#), "{toml}");
    assert_eq!(std::fs::read_to_string(d.join("ssp.csv")).unwrap(), toml);
}
