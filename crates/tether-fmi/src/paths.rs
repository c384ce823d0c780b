//! Where a path that cannot be opened was looked for: the resolved path, the
//! folder a relative path was resolved against, and a name that differs only
//! in case (`wheel.fmu` for `Wheel.fmu`), for one error line.

use std::path::{Component, Path, PathBuf};

/// A path that could not be reached, as an error line shows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Missing {
    /// The path as the user wrote it.
    pub written: PathBuf,
    /// Absolute, with `.` and `..` taken away.
    pub resolved: PathBuf,
    /// The folder a relative `written` was resolved against, and what that
    /// folder is (`the current folder`, `the system file's folder`).
    pub folder: Option<(PathBuf, &'static str)>,
    /// `written` with one or more names corrected in case, when that exists.
    pub suggestion: Option<PathBuf>,
}

impl Missing {
    /// `written`, resolved against `folder` (the current folder when `None`
    /// and `written` is relative).
    pub fn new(written: &Path, folder: Option<(&Path, &'static str)>) -> Missing {
        let folder = if written.is_absolute() {
            None
        } else {
            let (dir, what) = folder.unwrap_or((Path::new(""), "the current folder"));
            Some((absolute(dir), what))
        };
        let base = folder
            .as_ref()
            .map_or_else(|| PathBuf::from("/"), |(dir, _)| dir.clone());
        let resolved = normalize(&base.join(written));
        let suggestion = case_fix(&base, written);
        Missing {
            written: written.to_path_buf(),
            resolved,
            folder,
            suggestion,
        }
    }

    /// `'/abs/x.fmu' ('x.fmu' in /abs, the current folder)`: the text after
    /// `cannot access `.
    pub fn located(&self) -> String {
        match &self.folder {
            Some((dir, what)) => format!(
                "'{}' ('{}' in {}, {what})",
                self.resolved.display(),
                self.written.display(),
                dir.display()
            ),
            None => format!("'{}'", self.resolved.display()),
        }
    }

    /// `; did you mean 'Wheel.fmu'?`, or nothing.
    pub fn hint(&self) -> String {
        self.suggestion
            .as_ref()
            .map(|s| format!("; did you mean '{}'?", s.display()))
            .unwrap_or_default()
    }
}

/// `path` against the current folder.
fn absolute(path: &Path) -> PathBuf {
    let joined = if path.as_os_str().is_empty() {
        std::env::current_dir().unwrap_or_default()
    } else {
        std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
    };
    normalize(&joined)
}

/// `.` and `..` taken away lexically (as the user reads the path).
fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// `written` (relative to `base`) with each name that does not exist replaced
/// by the one entry of its folder that differs from it only in case, if the
/// corrected path then exists.
fn case_fix(base: &Path, written: &Path) -> Option<PathBuf> {
    let mut actual = base.to_path_buf();
    let mut fixed = PathBuf::new();
    let mut changed = false;
    for c in written.components() {
        match c {
            Component::Normal(name) => {
                let candidate = actual.join(name);
                if candidate.symlink_metadata().is_ok() {
                    actual = candidate;
                    fixed.push(name);
                    continue;
                }
                let wanted = name.to_string_lossy().to_lowercase();
                let matches: Vec<std::ffi::OsString> = std::fs::read_dir(&actual)
                    .ok()?
                    .filter_map(|e| e.ok().map(|e| e.file_name()))
                    .filter(|n| n.to_string_lossy().to_lowercase() == wanted)
                    .collect();
                let [only] = matches.as_slice() else {
                    return None;
                };
                actual.push(only);
                fixed.push(only);
                changed = true;
            }
            Component::ParentDir => {
                actual = normalize(&actual.join(".."));
                fixed.push("..");
            }
            Component::CurDir => fixed.push("."),
            Component::RootDir | Component::Prefix(_) => {
                actual = PathBuf::from(c.as_os_str());
                fixed.push(c.as_os_str());
            }
        }
    }
    (changed && actual.exists()).then_some(fixed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_name_that_differs_in_case_is_suggested_with_the_written_folders() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("fmus")).unwrap();
        std::fs::write(dir.path().join("fmus/Wheel.fmu"), b"").unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        let m = Missing::new(
            Path::new("../fmus/wheel.fmu"),
            Some((&sub, "the system file's folder")),
        );
        assert_eq!(m.suggestion, Some(PathBuf::from("../fmus/Wheel.fmu")));
        assert_eq!(m.resolved, normalize(&dir.path().join("fmus/wheel.fmu")));
        assert!(
            m.located().ends_with("the system file's folder)"),
            "{}",
            m.located()
        );
        let none = Missing::new(Path::new("../fmus/tyre.fmu"), Some((&sub, "x")));
        assert_eq!(none.suggestion, None);
        assert_eq!(none.hint(), "");
    }
}
