//! `tether compare A.csv B.csv`: the largest deviation per column between two
//! result files, e.g. a `tether run` and the fmpy reference of the same system
//! (docs/validation.md).
//!
//! Columns are matched by name. When the files have different times (fmpy's
//! default output interval differs from the step, a run used
//! `--output-interval`), both are compared on the coarser grid (the file with
//! fewer rows over the span both cover) over that common span, the finer one
//! interpolated linearly onto it, and the output says so; the order of the two
//! files does not matter. A file that stopped early (`# incomplete:`) is not
//! compared beyond its end: if the other reaches further, that is an error.
//! For each column c the measure is
//!
//! ```text
//! dev_c   = max over rows |a − b|
//! scale_c = max over rows max(|a|, |b|)           (the column's magnitude)
//! rel_c   = dev_c / max(scale_c, f64::MIN_POSITIVE)
//! ```
//!
//! and the column passes when `dev_c ≤ atol + rtol · scale_c` (by default
//! rtol = 1e-6, atol = 1e-12: [`RTOL`], [`ATOL`]). Scaling by the column's
//! magnitude over the whole run, not by each value, keeps zero crossings (a
//! multiplier changing sign) from inflating the measure. Residual columns
//! (`<constraint>.g`) are differences of nearly equal outputs and have a tiny
//! scale of their own; `--atol` bounds them in absolute terms.
//!
//! String columns (quoted text, as `tether run` writes String outputs) are
//! compared for equality: a column passes when every row has the same text
//! in both files (off the common grid, the text of the last row at or
//! before the time). A column of text in one file and numbers in the other
//! is an error naming it.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

/// The default relative tolerance: a millionth of each column's magnitude,
/// far above the rounding by which two correct runs of one method differ
/// (1e-16 to 1e-12 of the scale) and below the error of a usable macro step.
pub const RTOL: f64 = 1e-6;

/// The default absolute tolerance: keeps columns that are zero in one file and
/// rounding-small in the other (a multiplier at rest) from failing.
pub const ATOL: f64 = 1e-12;

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
pub struct Args {
    /// First result file (CSV with a `time` column, as `tether run` writes it).
    a: PathBuf,
    /// Second result file.
    b: PathBuf,
    /// Relative tolerance: a column passes when max |a − b| ≤ atol + rtol · scale.
    #[arg(long, default_value_t = RTOL, allow_hyphen_values = true)]
    rtol: f64,
    /// Absolute tolerance (see --rtol).
    #[arg(long, default_value_t = ATOL, allow_hyphen_values = true)]
    atol: f64,
    /// Compare only these columns (default: all; then both files must have the
    /// same columns): names separated by commas or spaces (commas inside
    /// brackets belong to the name: body.R[1,2]).
    #[arg(long, num_args = 1.., value_name = "NAME")]
    columns: Vec<String>,
    /// Compare column NEW of the first file with column OLD of the second
    /// (repeatable). One `*` on each side stands for the same text:
    /// `--map 'truck.*=*'` compares every column `truck.<name>` of the first
    /// file with `<name>` of the second.
    #[arg(long = "map", value_name = "NEW=OLD")]
    maps: Vec<String>,
}

/// `--map NEW=OLD`: renames the second file's columns to the first's; returns
/// (NEW, OLD) for every column renamed, for the report.
fn apply_maps(a: &Table, b: &mut Table, maps: &[String]) -> Result<Vec<(String, String)>> {
    let mut renamed: Vec<(String, String)> = Vec::new();
    for map in maps {
        let Some((new, old)) = map.split_once('=') else {
            bail!(
                "--map {map:?}: expected NEW=OLD, a column of {} and one of {}",
                a.path.display(),
                b.path.display()
            );
        };
        let (new, old) = (new.trim(), old.trim());
        let stars = (new.matches('*').count(), old.matches('*').count());
        let pairs: Vec<(String, String)> = match stars {
            (0, 0) => vec![(new.to_string(), old.to_string())],
            (1, 1) => {
                let (prefix, suffix) = new.split_once('*').unwrap_or_default();
                a.names
                    .iter()
                    .filter_map(|n| {
                        let rest = n.strip_prefix(prefix)?.strip_suffix(suffix)?;
                        Some((n.clone(), old.replacen('*', rest, 1)))
                    })
                    .filter(|(_, o)| b.names.contains(o))
                    .collect()
            }
            _ => bail!("--map {map:?}: one '*' on each side, or none"),
        };
        if pairs.is_empty() {
            bail!(
                "--map {map:?}: no column '{new}' of {} has a column '{old}' in {}",
                a.path.display(),
                b.path.display()
            );
        }
        for (new, old) in pairs {
            if !a.names.contains(&new) {
                bail!(
                    "--map {map:?}: column '{new}' is not in {}",
                    a.path.display()
                );
            }
            let Some(j) = b.names.iter().position(|n| *n == old) else {
                bail!(
                    "--map {map:?}: column '{old}' is not in {}",
                    b.path.display()
                );
            };
            if let Some((_, first)) = renamed.iter().find(|(n, _)| *n == new) {
                bail!("--map {map:?}: column '{new}' is already compared with '{first}'");
            }
            if new != old && b.names.contains(&new) {
                bail!(
                    "--map {map:?}: {} has a column '{new}' of its own",
                    b.path.display()
                );
            }
            b.names[j] = new.clone();
            renamed.push((new, old));
        }
    }
    Ok(renamed)
}

/// One result file.
struct Table {
    path: PathBuf,
    names: Vec<String>,
    times: Vec<f64>,
    /// `rows[i][j]`: column `names[j]` (after `time`) at `times[i]`.
    rows: Vec<Vec<f64>>,
    /// `texts[j]`: the texts of column `names[j]` by row, if it is a
    /// String column.
    texts: Vec<Option<Vec<String>>>,
    /// The reason of a `# incomplete: …` line, if the run stopped early.
    incomplete: Option<String>,
}

fn read_table(path: &Path) -> Result<Table> {
    if let Some(e) = crate::missing(path) {
        return Err(e);
    }
    let results = tether_master::Results::read(path)
        .map_err(|reason| anyhow::anyhow!("{}: {reason}", path.display()))?;
    let mut texts = vec![None; results.columns.len()];
    for (j, column) in results.texts {
        texts[j] = Some(column);
    }
    Ok(Table {
        path: path.to_path_buf(),
        names: results.columns,
        times: results.times,
        rows: results.rows,
        texts,
        incomplete: results.incomplete,
    })
}

/// The deviation of one column.
struct Deviation {
    name: String,
    max_abs: f64,
    at_time: f64,
    scale: f64,
    relative: f64,
    /// max_abs / (atol + rtol·scale): above 1 fails.
    excess: f64,
    /// A String column: the rows whose texts differ, and the first of them.
    text: Option<(usize, Option<FirstDifference>)>,
}

/// Where a String column first differs: the time and the two texts.
type FirstDifference = (f64, String, String);

/// |a − b|, with equal non-finite values (both NaN, the same infinity) as 0.
fn difference(a: f64, b: f64) -> f64 {
    if a == b || (a.is_nan() && b.is_nan()) {
        0.0
    } else {
        (a - b).abs()
    }
}

/// The columns compared: `wanted`, else every column, which both files must
/// have; with `--map` (`mapped`), every column of the first file, which the
/// second must have (its other columns are left, and counted in `left`).
fn columns_to_compare(
    a: &Table,
    b: &Table,
    wanted: &[String],
    mapped: bool,
    left: &mut usize,
) -> Result<Vec<String>> {
    if !wanted.is_empty() {
        for name in wanted {
            for t in [a, b] {
                if !t.names.contains(name) {
                    bail!("column '{name}' is not in {}", t.path.display());
                }
            }
        }
        return Ok(wanted.to_vec());
    }
    let only = |x: &Table, y: &Table| -> Vec<String> {
        x.names
            .iter()
            .filter(|n| !y.names.contains(n))
            .cloned()
            .collect()
    };
    let (only_a, only_b) = (only(a, b), only(b, a));
    if mapped && only_a.is_empty() {
        *left = only_b.len();
        return Ok(a.names.clone());
    }
    if !only_a.is_empty() || !only_b.is_empty() {
        let list = |v: &[String]| {
            if v.is_empty() {
                "none".to_string()
            } else {
                v.join(", ")
            }
        };
        bail!(
            "the files have different columns: only in {}: {}; only in {}: {} (use --columns to compare the common ones, --map NEW=OLD to pair renamed ones)",
            a.path.display(),
            list(&only_a),
            b.path.display(),
            list(&only_b)
        );
    }
    Ok(a.names.clone())
}

/// Whether `b` has `a`'s times (within 1e-9 of `a`'s smallest time increment).
fn same_grid(a: &Table, b: &Table) -> bool {
    if a.times.len() != b.times.len() {
        return false;
    }
    let spacing = a
        .times
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let tolerance = if spacing.is_finite() {
        1e-9 * spacing
    } else {
        1e-9 * a.times[0].abs().max(1.0)
    };
    a.times
        .iter()
        .zip(&b.times)
        .all(|(ta, tb)| (ta - tb).abs() <= tolerance)
}

/// `b` linearly interpolated onto `a`'s times (between the two rows of `b`
/// around each time; at a repeated time of `b`, an event, its later row).
/// `a`'s times must lie within `b`'s, and `b`'s must not decrease.
fn interpolated(a: &Table, b: &Table) -> Result<Table> {
    let note = |t: &Table| match &t.incomplete {
        Some(r) => format!(" ({} is incomplete: {r})", t.path.display()),
        None => String::new(),
    };
    if let Some(i) = b.times.windows(2).position(|w| w[1] < w[0]) {
        bail!(
            "{}: the times decrease at row {} (t = {} after {}): cannot interpolate",
            b.path.display(),
            i + 2,
            b.times[i + 1],
            b.times[i]
        );
    }
    let (first, last) = (b.times[0], b.times[b.times.len() - 1]);
    let slack = 1e-9 * (last - first).abs().max(f64::MIN_POSITIVE);
    let (a_first, a_last) = (a.times[0], a.times[a.times.len() - 1]);
    if a_first < first - slack || a_last > last + slack {
        bail!(
            "the time grids differ and {} (t = {a_first} … {a_last}) is not within the times of \
             {} (t = {first} … {last}): cannot interpolate{}{}",
            a.path.display(),
            b.path.display(),
            note(a),
            note(b)
        );
    }
    let mut rows = Vec::with_capacity(a.times.len());
    let mut picked = Vec::with_capacity(a.times.len());
    let mut k = 0;
    for &t in &a.times {
        // The last row of b at or before t (its later row at a repeated time).
        while k + 1 < b.times.len() && b.times[k + 1] <= t {
            k += 1;
        }
        picked.push(k);
        let row = if k + 1 == b.times.len() || b.times[k] >= t {
            b.rows[k].clone()
        } else {
            let (t0, t1) = (b.times[k], b.times[k + 1]);
            let w = (t - t0) / (t1 - t0);
            b.rows[k]
                .iter()
                .zip(&b.rows[k + 1])
                .map(|(v0, v1)| if w == 0.0 { *v0 } else { v0 + w * (v1 - v0) })
                .collect()
        };
        rows.push(row);
    }
    Ok(Table {
        path: b.path.clone(),
        names: b.names.clone(),
        times: a.times.clone(),
        rows,
        texts: pick_texts(b, &picked),
        incomplete: b.incomplete.clone(),
    })
}

/// The String columns of `t` at its rows `rows`.
fn pick_texts(t: &Table, rows: &[usize]) -> Vec<Option<Vec<String>>> {
    t.texts
        .iter()
        .map(|c| {
            c.as_ref()
                .map(|texts| rows.iter().map(|&i| texts[i].clone()).collect())
        })
        .collect()
}

/// Both files on the coarser grid over the span both cover: the file with
/// fewer rows in that span keeps its rows there, the other is interpolated
/// linearly onto them. Returns them in the order given, with the note that
/// says what was done. A file that stopped early (`# incomplete:`) while the
/// other goes on is refused: the rest of the run cannot be compared.
fn on_the_coarser_grid(a: Table, b: Table) -> Result<(Table, Table, String)> {
    let span = |t: &Table| (t.times[0], t.times[t.times.len() - 1]);
    let ((a_first, a_last), (b_first, b_last)) = (span(&a), span(&b));
    let slack = 1e-9
        * (a_last - a_first)
            .abs()
            .max((b_last - b_first).abs())
            .max(f64::MIN_POSITIVE);
    for (short, long) in [(&a, &b), (&b, &a)] {
        if let Some(reason) = &short.incomplete {
            let (end, other_end) = (span(short).1, span(long).1);
            if end < other_end - slack {
                bail!(
                    "{} is incomplete ({reason}) and ends at t = {end}, {} goes on to t = {other_end}: \
                     the rest of the run cannot be compared",
                    short.path.display(),
                    long.path.display()
                );
            }
        }
    }
    let (first, last) = (a_first.max(b_first), a_last.min(b_last));
    if first > last + slack {
        bail!(
            "the files share no time span ({} has t = {a_first} … {a_last}, {} has t = {b_first} … {b_last})",
            a.path.display(),
            b.path.display()
        );
    }
    let within = |t: &Table| -> Vec<usize> {
        (0..t.times.len())
            .filter(|&i| t.times[i] >= first - slack && t.times[i] <= last + slack)
            .collect()
    };
    let (rows_a, rows_b) = (within(&a), within(&b));
    let a_is_coarser = rows_a.len() <= rows_b.len();
    let (coarse, fine, rows) = if a_is_coarser {
        (&a, &b, &rows_a)
    } else {
        (&b, &a, &rows_b)
    };
    let coarse = Table {
        path: coarse.path.clone(),
        names: coarse.names.clone(),
        times: rows.iter().map(|&i| coarse.times[i]).collect(),
        rows: rows.iter().map(|&i| coarse.rows[i].clone()).collect(),
        texts: pick_texts(coarse, rows),
        incomplete: coarse.incomplete.clone(),
    };
    let fine = interpolated(&coarse, fine)?;
    let whole = |t: &Table| {
        let (f, l) = span(t);
        (f - first).abs() <= slack && (l - last).abs() <= slack
    };
    let over = if whole(&a) && whole(&b) {
        String::new()
    } else {
        format!(
            " over the span both cover, t = {first} … {last} ({} has t = {a_first} … {a_last}, {} has t = {b_first} … {b_last})",
            a.path.display(),
            b.path.display()
        )
    };
    let note = format!(
        "note: the time grids differ ({} has {} rows, {} has {}): compared on the times of {}, \
         the coarser{over}; {} is interpolated linearly onto them",
        a.path.display(),
        a.times.len(),
        b.path.display(),
        b.times.len(),
        coarse.path.display(),
        fine.path.display()
    );
    Ok(if a_is_coarser {
        (coarse, fine, note)
    } else {
        (fine, coarse, note)
    })
}

/// The deviation of String column `name` (`ja` in `a`, `jb` in `b`): the
/// rows whose texts differ.
fn text_deviation(
    (a, ja): (&Table, usize),
    (b, jb): (&Table, usize),
    name: &str,
) -> Result<Deviation> {
    let (Some(ta), Some(tb)) = (&a.texts[ja], &b.texts[jb]) else {
        let (text, numbers) = if a.texts[ja].is_some() {
            (a, b)
        } else {
            (b, a)
        };
        bail!(
            "column '{name}' is text (a String output) in {} and numbers in {}: cannot compare",
            text.path.display(),
            numbers.path.display()
        );
    };
    let mut differing = 0;
    let mut first = None;
    for (i, (x, y)) in ta.iter().zip(tb).enumerate() {
        if x != y {
            differing += 1;
            first.get_or_insert_with(|| (a.times[i], x.clone(), y.clone()));
        }
    }
    Ok(Deviation {
        name: name.to_string(),
        max_abs: 0.0,
        at_time: first.as_ref().map_or(a.times[0], |f| f.0),
        scale: 0.0,
        relative: 0.0,
        excess: 0.0,
        text: Some((differing, first)),
    })
}

fn deviations(
    a: &Table,
    b: &Table,
    names: &[String],
    rtol: f64,
    atol: f64,
) -> Result<Vec<Deviation>> {
    names
        .iter()
        .map(|name| {
            let ja = a.names.iter().position(|n| n == name).expect("checked");
            let jb = b.names.iter().position(|n| n == name).expect("checked");
            if a.texts[ja].is_some() || b.texts[jb].is_some() {
                return text_deviation((a, ja), (b, jb), name);
            }
            let (mut max_abs, mut at_time, mut scale) = (0.0f64, a.times[0], 0.0f64);
            for (i, (ra, rb)) in a.rows.iter().zip(&b.rows).enumerate() {
                let (x, y) = (ra[ja], rb[jb]);
                let d = difference(x, y);
                if d > max_abs || (d.is_nan() && !max_abs.is_nan()) {
                    max_abs = d;
                    at_time = a.times[i];
                }
                for v in [x, y] {
                    if v.is_finite() {
                        scale = scale.max(v.abs());
                    }
                }
            }
            let relative = if max_abs == 0.0 {
                0.0
            } else {
                max_abs / scale.max(f64::MIN_POSITIVE)
            };
            let bound = atol + rtol * scale;
            let excess = if max_abs == 0.0 {
                0.0
            } else if bound > 0.0 {
                max_abs / bound
            } else {
                f64::INFINITY
            };
            Ok(Deviation {
                name: name.clone(),
                max_abs,
                at_time,
                scale,
                relative,
                excess: if excess.is_nan() {
                    f64::INFINITY
                } else {
                    excess
                },
                text: None,
            })
        })
        .collect()
}

pub fn main(args: Args) -> Result<()> {
    for (name, v) in [("--rtol", args.rtol), ("--atol", args.atol)] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{name} = {v}: expected a finite number >= 0");
        }
    }
    let a = read_table(&args.a)?;
    let mut b = read_table(&args.b)?;
    let renamed = apply_maps(&a, &mut b, &args.maps)?;
    let mut left = 0;
    let wanted = crate::columns::split(&args.columns);
    let names = columns_to_compare(&a, &b, &wanted, !args.maps.is_empty(), &mut left)?;
    if left > 0 {
        crate::stdout(format_args!(
            "note: {left} column{} of {} {} not in {} and not compared\n",
            if left == 1 { "" } else { "s" },
            b.path.display(),
            if left == 1 { "is" } else { "are" },
            a.path.display()
        ))?;
    }
    let (a, b) = if same_grid(&a, &b) {
        (a, b)
    } else {
        let (a, b, note) = on_the_coarser_grid(a, b)?;
        crate::stdout(format_args!("{note}\n"))?;
        (a, b)
    };
    let mut devs = deviations(&a, &b, &names, args.rtol, args.atol)?;
    for d in &mut devs {
        if let Some((new, old)) = renamed.iter().find(|(n, o)| *n == d.name && n != o) {
            d.name = format!("{new}={old}");
        }
    }

    let width = devs.iter().map(|d| d.name.len()).max().unwrap_or(6).max(6);
    crate::stdout(format_args!(
        "{:<width$}  {:>10}  {:>12}  {:>10}  {:>10}  ok\n",
        "column", "max |a-b|", "at t", "scale", "relative"
    ))?;
    for d in &devs {
        if let Some((differing, _)) = &d.text {
            let at = if *differing == 0 {
                "-".to_string()
            } else {
                d.at_time.to_string()
            };
            let rows = format!("{differing} rows");
            crate::stdout(format_args!(
                "{:<width$}  {:>10}  {:>12}  {:>10}  {:>10}  {}\n",
                d.name,
                if *differing == 0 { "same text" } else { &rows },
                at,
                "text",
                "-",
                if *differing == 0 { "yes" } else { "NO" }
            ))?;
            continue;
        }
        let at = if d.max_abs == 0.0 {
            "-".to_string()
        } else {
            d.at_time.to_string()
        };
        crate::stdout(format_args!(
            "{:<width$}  {:>10}  {:>12}  {:>10}  {:>10}  {}\n",
            d.name,
            sci(d.max_abs),
            at,
            sci(d.scale),
            sci(d.relative),
            if d.excess <= 1.0 { "yes" } else { "NO" }
        ))?;
    }
    for t in [&a, &b] {
        if let Some(reason) = &t.incomplete {
            crate::stdout(format_args!(
                "note: {} is incomplete: {reason}\n",
                t.path.display()
            ))?;
        }
    }
    let worst_relative = devs.iter().map(|d| d.relative).fold(0.0, f64::max);
    crate::stdout(format_args!(
        "{} rows, {} columns; largest relative deviation {} (rtol = {}, atol = {})\n",
        a.times.len(),
        devs.len(),
        sci(worst_relative),
        tol(args.rtol),
        tol(args.atol)
    ))?;
    let worst = devs
        .iter()
        .filter(|d| d.excess > 1.0)
        .max_by(|x, y| x.excess.total_cmp(&y.excess));
    if let Some(d) = worst {
        bail!(
            "column '{}' deviates by {} relative to its scale {} (max |a-b| = {} at t = {}), above rtol = {}, atol = {}",
            d.name,
            sci(d.relative),
            sci(d.scale),
            sci(d.max_abs),
            d.at_time,
            tol(args.rtol),
            tol(args.atol)
        );
    }
    let texts = devs.iter().filter_map(|d| match &d.text {
        Some((n, Some(first))) => Some((d, n, first)),
        _ => None,
    });
    if let Some((d, n, (t, x, y))) = texts.into_iter().next() {
        bail!(
            "column '{}' has other text in {n} of {} rows, first at t = {t}: {x:?} in {}, {y:?} in {}",
            d.name,
            a.times.len(),
            a.path.display(),
            b.path.display()
        );
    }
    Ok(())
}

/// `1.234e-05`, `0`, `inf`: four significant digits, a signed two-digit exponent.
fn sci(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    let text = format!("{x:.3e}");
    let (mantissa, exponent) = text.split_once('e').expect("{:e} has an exponent");
    let exponent: i32 = exponent.parse().expect("integer exponent");
    let sign = if exponent < 0 { '-' } else { '+' };
    format!("{mantissa}e{sign}{:02}", exponent.abs())
}

/// A tolerance as given: `1e-9`, `0`.
fn tol(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else {
        format!("{x:e}")
    }
}
