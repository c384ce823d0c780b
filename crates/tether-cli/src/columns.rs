//! Column names on the command line, the same for every command: after
//! `--columns`, one or more names, each argument also split at commas —
//! except commas inside brackets, so `body.R[1,2]` is one name:
//! `--columns a.x,body.R[1,2] link.g` is three.

/// The names in `args`, in order, split at commas outside `[…]`; empty
/// pieces (a trailing comma) are dropped.
pub fn split(args: &[String]) -> Vec<String> {
    let mut names = Vec::new();
    for arg in args {
        let mut depth = 0usize;
        let mut current = String::new();
        for c in arg.chars() {
            match c {
                '[' => depth += 1,
                ']' => depth = depth.saturating_sub(1),
                ',' if depth == 0 => {
                    names.push(std::mem::take(&mut current));
                    continue;
                }
                _ => {}
            }
            current.push(c);
        }
        names.push(current);
    }
    names.retain(|n| !n.trim().is_empty());
    names.iter().map(|n| n.trim().to_string()).collect()
}

/// `; did you mean 'a', 'b'?` with the columns that contain `name`'s last
/// part, or `; columns are: …` (the first twelve).
pub fn hint(name: &str, columns: &[String]) -> String {
    let tail = name.rsplit('.').next().unwrap_or(name);
    let close: Vec<&str> = columns
        .iter()
        .filter(|c| !tail.is_empty() && c.contains(tail))
        .take(6)
        .map(String::as_str)
        .collect();
    if !close.is_empty() {
        return format!("; did you mean '{}'?", close.join("', '"));
    }
    let shown: Vec<&str> = columns.iter().take(12).map(String::as_str).collect();
    let more = if columns.len() > shown.len() {
        format!(" … ({} in all)", columns.len())
    } else {
        String::new()
    };
    format!("; columns are: {}{more}", shown.join(", "))
}

#[cfg(test)]
mod tests {
    use super::split;

    #[test]
    fn commas_inside_brackets_stay_in_the_name() {
        let args = ["a.x,body.R[1,2]".to_string(), "link.g,".to_string()];
        assert_eq!(split(&args), ["a.x", "body.R[1,2]", "link.g"]);
        assert_eq!(split(&["j.lambda[3]".into()]), ["j.lambda[3]"]);
    }
}
