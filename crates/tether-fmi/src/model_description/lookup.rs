//! Close-match suggestions for unknown variable names.

/// Up to three names close to `wanted`: small edit distance or a shared prefix, best first.
pub(crate) fn suggestions<'a>(wanted: &str, names: impl Iterator<Item = &'a str>) -> Vec<String> {
    let limit = (wanted.chars().count() / 3).max(1);
    let lower = wanted.to_lowercase();
    let mut scored: Vec<(usize, &str)> = names
        .filter_map(|name| {
            let distance = edit_distance(&lower, &name.to_lowercase());
            let prefix =
                !wanted.is_empty() && (name.starts_with(wanted) || wanted.starts_with(name));
            (distance <= limit || prefix).then_some((distance, name))
        })
        .collect();
    scored.sort_by(|a, b| a.0.cmp(&b.0).then_with(|| a.1.cmp(b.1)));
    scored
        .into_iter()
        .take(3)
        .map(|(_, n)| n.to_owned())
        .collect()
}

/// Levenshtein distance over characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let substitution = diagonal + usize::from(ca != cb);
            diagonal = row[j + 1];
            row[j + 1] = substitution.min(row[j] + 1).min(row[j + 1] + 1);
        }
    }
    row[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edit_distance_counts_single_edits() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "ab"), 2);
        assert_eq!(edit_distance("x", "x"), 0);
    }

    #[test]
    fn close_names_are_suggested_best_first() {
        let names = ["x", "v", "a", "x0", "mass", "damping"];
        assert_eq!(suggestions("xx", names.into_iter()), ["x", "x0"]);
        assert_eq!(suggestions("dampnig", names.into_iter()), ["damping"]);
        assert!(suggestions("completely_unrelated", names.into_iter()).is_empty());
    }
}
