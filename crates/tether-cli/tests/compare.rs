//! `tether compare`: per-column deviations between two result files, the exit
//! status and the one-line errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const HEADER: &str = "time,mass1.x,\"m.R[1,2]\",link.lambda,link.g";

/// A small result file: x = sin t, a name with a comma, λ crossing zero, g tiny.
fn rows() -> Vec<[f64; 5]> {
    (0..=10)
        .map(|n| {
            let t = n as f64 * 0.1;
            [t, t.sin(), 0.5, 300.0 * (3.0 * t).cos(), 1e-9 * t]
        })
        .collect()
}

fn write(dir: &Path, name: &str, header: &str, rows: &[[f64; 5]], tail: &str) -> PathBuf {
    let mut text = format!("{header}\n");
    for r in rows {
        let fields: Vec<String> = r.iter().map(|v| v.to_string()).collect();
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    text.push_str(tail);
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn compare(a: &Path, b: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .arg("compare")
        .arg(a)
        .arg(b)
        .args(extra)
        .output()
        .unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The single error line, which must be the whole of stderr.
fn one_error_line(out: &Output) -> String {
    assert!(!out.status.success(), "expected failure: {}", stdout(out));
    let err = stderr(out);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.starts_with("error: "), "{err}");
    err
}

#[test]
fn identical_files_pass_with_zero_deviation() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(dir.path(), "a.csv", HEADER, &rows(), "");
    let b = write(dir.path(), "b.csv", HEADER, &rows(), "");
    let out = compare(&a, &b, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    let table = stdout(&out);
    assert!(
        table.contains("m.R[1,2]"),
        "quoted names stay whole: {table}"
    );
    assert!(
        table.contains("largest relative deviation 0 (rtol = 1e-6, atol = 1e-12)"),
        "{table}"
    );
    assert_eq!(table.matches(" yes").count(), 4, "{table}");
}

#[test]
fn a_perturbed_value_fails_naming_the_column_and_its_relative_deviation() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(dir.path(), "a.csv", HEADER, &rows(), "");
    let mut perturbed = rows();
    // λ's scale is 300 (its value at t = 0); add 3e-3, i.e. 1e-5 of the scale,
    // at t = 0.5, where λ itself is only 300·cos(1.5) ≈ 21.
    perturbed[5][3] += 3e-3;
    let b = write(dir.path(), "b.csv", HEADER, &perturbed, "");
    let out = compare(&a, &b, &[]);
    let err = one_error_line(&out);
    assert!(err.contains("column 'link.lambda'"), "{err}");
    assert!(err.contains("at t = 0.5"), "{err}");
    let relative: f64 = err
        .split("deviates by ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no relative deviation in: {err}"));
    assert!((relative / 1e-5 - 1.0).abs() < 1e-3, "{relative} in {err}");
    assert!(stdout(&out).contains("NO"), "{}", stdout(&out));
    // The same files pass once the tolerance admits the deviation.
    let out = compare(&a, &b, &["--rtol", "2e-5"]);
    assert!(out.status.success(), "{}", stderr(&out));
    // The worst column is the one furthest above its bound.
    let mut both = perturbed.clone();
    both[2][1] += 1e-3; // x: scale ≈ 0.84, so ~1.2e-3 relative: the worst
    let c = write(dir.path(), "c.csv", HEADER, &both, "");
    let err = one_error_line(&compare(&a, &c, &[]));
    assert!(err.contains("column 'mass1.x'"), "{err}");
}

#[test]
fn tiny_residual_columns_are_bounded_by_atol() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(dir.path(), "a.csv", HEADER, &rows(), "");
    let mut shifted = rows();
    shifted[3][4] += 1e-11; // g's scale is 1e-9: 1e-2 relative, above the default atol
    let b = write(dir.path(), "b.csv", HEADER, &shifted, "");
    let err = one_error_line(&compare(&a, &b, &[]));
    assert!(err.contains("column 'link.g'"), "{err}");
    let out = compare(&a, &b, &["--atol", "1e-10"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn mismatched_columns_are_one_clear_error_unless_selected() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(dir.path(), "a.csv", HEADER, &rows(), "");
    let other = HEADER.replace("link.g", "link.h");
    let b = write(dir.path(), "b.csv", &other, &rows(), "");
    let err = one_error_line(&compare(&a, &b, &[]));
    assert!(
        err.contains("only in") && err.contains("link.g") && err.contains("link.h"),
        "{err}"
    );
    let out = compare(&a, &b, &["--columns", "mass1.x", "link.lambda"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stdout(&out).contains("link.g"), "{}", stdout(&out));
    let err = one_error_line(&compare(&a, &b, &["--columns", "link.g"]));
    assert!(
        err.contains("'link.g' is not in") && err.contains("b.csv"),
        "{err}"
    );
}

/// Files on different time grids: both are compared on the coarser grid over
/// the span both cover, whichever file comes first, and the output says so; a
/// run that stopped early is not compared beyond its end.
#[test]
fn different_time_grids_are_compared_on_the_coarser_one() {
    let dir = tempfile::tempdir().unwrap();
    // Linear in t: the interpolation is exact (to rounding).
    let linear = |step: f64, n: usize| -> Vec<[f64; 5]> {
        (0..=n)
            .map(|i| {
                let t = i as f64 * step;
                [t, 2.0 * t + 1.0, 0.5, -3.0 * t, 1e-9 * t]
            })
            .collect()
    };
    let a = write(dir.path(), "a.csv", HEADER, &linear(0.1, 10), "");
    let fine = write(dir.path(), "fine.csv", HEADER, &linear(0.03125, 32), "");
    let note = format!(
        "note: the time grids differ ({a} has 11 rows, {b} has 33): compared on the times of \
         {a}, the coarser; {b} is interpolated linearly onto them\n",
        a = a.display(),
        b = fine.display()
    );
    let out = compare(&a, &fine, &["--rtol", "1e-12"]);
    let text = stdout(&out);
    assert!(out.status.success(), "{text}{}", stderr(&out));
    assert!(text.starts_with(&note), "{text}");
    assert!(text.contains("11 rows, 4 columns"), "{text}");
    // Symmetric: the finer file first gives the same rows and deviations.
    let out = compare(&fine, &a, &["--rtol", "1e-12"]);
    let swapped = stdout(&out);
    assert!(out.status.success(), "{swapped}{}", stderr(&out));
    assert!(
        swapped.starts_with(&format!(
            "note: the time grids differ ({b} has 33 rows, {a} has 11): compared on the times of \
             {a}, the coarser; {b} is interpolated linearly onto them\n",
            a = a.display(),
            b = fine.display()
        )),
        "{swapped}"
    );
    assert_eq!(
        text.lines().skip(1).collect::<Vec<_>>(),
        swapped.lines().skip(1).collect::<Vec<_>>()
    );
    // A longer run (to t = 2) is compared over the span both cover.
    let long = write(dir.path(), "long.csv", HEADER, &linear(0.03125, 64), "");
    let out = compare(&long, &a, &["--rtol", "1e-12"]);
    let text = stdout(&out);
    assert!(out.status.success(), "{text}{}", stderr(&out));
    assert!(
        text.starts_with(&format!(
            "note: the time grids differ ({l} has 65 rows, {a} has 11): compared on the times of \
             {a}, the coarser over the span both cover, t = 0 … 1 ({l} has t = 0 … 2, {a} has t = \
             0 … 1); {l} is interpolated linearly onto them\n",
            a = a.display(),
            l = long.display()
        )),
        "{text}"
    );
    // Times a grid spacing's billionth apart are the same point: no note.
    let mut close = rows();
    close[7][0] += 1e-12;
    let a = write(dir.path(), "a.csv", HEADER, &rows(), "");
    let c = write(dir.path(), "c.csv", HEADER, &close, "");
    let out = compare(&a, &c, &[]);
    assert!(out.status.success() && !stdout(&out).contains("note:"));
    // Stopped early: not compared beyond its end, with the reason, in either order.
    let short = write(
        dir.path(),
        "short.csv",
        HEADER,
        &rows()[..6],
        "# incomplete: coupling diverged at t = 0.5\n",
    );
    let expected = format!(
        "error: {s} is incomplete (coupling diverged at t = 0.5) and ends at t = 0.5, {a} goes \
         on to t = 1: the rest of the run cannot be compared",
        a = a.display(),
        s = short.display()
    );
    assert_eq!(
        one_error_line(&compare(&a, &short, &[])).trim_end(),
        expected
    );
    assert_eq!(
        one_error_line(&compare(&short, &a, &[])).trim_end(),
        expected
    );
}

#[test]
fn unreadable_input_names_the_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(dir.path(), "a.csv", HEADER, &rows(), "");
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, format!("{HEADER}\n0,1,2,abc,4\n")).unwrap();
    let err = one_error_line(&compare(&a, &bad, &[]));
    assert!(
        err.contains("bad.csv: line 2, column 'link.lambda': 'abc' is not a number"),
        "{err}"
    );
    let ragged = dir.path().join("ragged.csv");
    std::fs::write(&ragged, format!("{HEADER}\n0,1,2\n")).unwrap();
    let err = one_error_line(&compare(&a, &ragged, &[]));
    assert!(err.contains("ragged.csv"), "{err}");
    let missing = dir.path().join("missing.csv");
    let err = one_error_line(&compare(&a, &missing, &[]));
    assert!(err.contains("missing.csv"), "{err}");
    let err = one_error_line(&compare(&a, &a, &["--rtol", "-1"]));
    assert!(err.contains("--rtol"), "{err}");
}

/// `--map NEW=OLD` compares renamed columns, one `*` per side maps a whole
/// prefix, and a map that pairs nothing is one line.
#[test]
fn renamed_columns_are_compared_with_map() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(
        dir.path(),
        "new.csv",
        "time,mass1_x,\"m.R[1,2]\",link.lambda,link.g",
        &rows(),
        "",
    );
    let b = write(dir.path(), "old.csv", HEADER, &rows(), "");
    let err = one_error_line(&compare(&a, &b, &[]));
    assert!(err.contains("--map NEW=OLD"), "{err}");
    let out = compare(&a, &b, &["--map", "mass1_x=mass1.x"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let table = stdout(&out);
    assert!(table.contains("mass1_x=mass1.x "), "{table}");
    assert_eq!(table.matches(" yes").count(), 4, "{table}");
    assert!(
        table.contains("largest relative deviation 0 (rtol = 1e-6, atol = 1e-12)"),
        "{table}"
    );

    // A prefix, in one option; the second file's other columns are left.
    let prefixed = HEADER
        .replace("mass1.x", "pair.mass1.x")
        .replace("link.", "pair.link.");
    let p = write(dir.path(), "nested.csv", &prefixed, &rows(), "");
    let out = compare(&p, &b, &["--map", "pair.*=*"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let table = stdout(&out);
    for line in [
        "pair.mass1.x=mass1.x ",
        "pair.link.lambda=link.lambda ",
        "pair.link.g=link.g ",
    ] {
        assert!(table.contains(line), "{line} in {table}");
    }
    assert!(!table.contains("note:"), "{table}");
    // The first file has fewer columns: its own are compared, the rest noted.
    let text = std::fs::read_to_string(&p).unwrap();
    let fewer: String = text
        .lines()
        .map(|l| {
            let (head, _) = l.rsplit_once(',').unwrap();
            format!("{head}\n")
        })
        .collect();
    std::fs::write(&p, fewer).unwrap();
    let out = compare(&p, &b, &["--map", "pair.*=*"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let table = stdout(&out);
    assert!(
        table.starts_with(&format!(
            "note: 1 column of {} is not in {} and not compared\n",
            b.display(),
            p.display()
        )),
        "{table}"
    );
    assert!(!table.contains("link.g"), "{table}");

    for (map, expected) in [
        (
            "mass1_x",
            "error: --map \"mass1_x\": expected NEW=OLD, a column of",
        ),
        (
            "mass1_x=mass2.x",
            "error: --map \"mass1_x=mass2.x\": column 'mass2.x' is not in",
        ),
        (
            "pair.*=other.*",
            "error: --map \"pair.*=other.*\": no column 'pair.*' of",
        ),
        (
            "a*b*=*",
            "error: --map \"a*b*=*\": one '*' on each side, or none",
        ),
    ] {
        let err = one_error_line(&compare(&a, &b, &["--map", map]));
        assert!(err.starts_with(expected), "{map}: {err}");
    }
}
