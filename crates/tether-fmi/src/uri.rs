//! `file://` URIs for `fmuResourceLocation` (RFC 8089 / RFC 3986 percent-encoding).

use std::os::unix::ffi::OsStrExt;
use std::path::Path;

/// Converts an absolute path into a `file:///…` URI, percent-encoding every byte that is
/// not an RFC 3986 unreserved character or a path separator.
pub(crate) fn file_uri(path: &Path) -> String {
    let mut uri = String::from("file://");
    let bytes = path.as_os_str().as_bytes();
    if !bytes.starts_with(b"/") {
        uri.push('/');
    }
    for &b in bytes {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~' | b'/') {
            uri.push(char::from(b));
        } else {
            uri.push_str(&format!("%{b:02X}"));
        }
    }
    uri
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reserved_and_non_ascii_bytes_are_percent_encoded() {
        assert_eq!(
            file_uri(Path::new("/tmp/a b/ü%#/resources")),
            "file:///tmp/a%20b/%C3%BC%25%23/resources"
        );
    }
}
