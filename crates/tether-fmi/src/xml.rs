//! Tether's one XML reader: an element tree with line numbers, built with quick-xml's
//! event reader. It reads `modelDescription.xml` here and the SSD and SSV files of
//! tether-ssp.
//!
//! The files are attribute-driven and small enough to hold in memory; building a tree
//! first keeps the mapping code free of reader state and lets every semantic error
//! point at the line of the element it concerns.
//!
//! Every document is bounded, whoever wrote it: at most [`MAX_BYTES`] bytes and
//! [`MAX_DEPTH`] levels of nested elements. A document over either limit is refused
//! with one [`XmlError`] naming the file and the position, and the reader's time and
//! memory are linear in the size of the document (no step depends on the depth or on
//! the length of a line).

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use quick_xml::events::{BytesRef, BytesStart, Event};
use quick_xml::Reader;

/// The deepest nesting of elements read: the root element is at depth 1. The
/// deepest FMI 2.0 or SSP 1.0 document needs a few tens of levels.
pub const MAX_DEPTH: usize = 256;

/// The largest XML document read, in bytes (128 MiB).
pub const MAX_BYTES: usize = 128 << 20;

/// One XML element: its name, attributes (entity-expanded), child elements and text.
#[derive(Debug, Clone)]
pub struct Element {
    /// The name: as written, or namespace-resolved with [`Names::Namespaces`].
    pub name: String,
    /// The attributes in document order, `(name, value)`, values entity-expanded.
    pub attrs: Vec<(String, String)>,
    /// The child elements in document order.
    pub children: Vec<Element>,
    /// The element's own text and CDATA content (not its children's), concatenated,
    /// with entity and character references expanded.
    pub text: String,
    /// 1-based line of the start tag.
    pub line: usize,
}

impl Element {
    fn new(name: String, attrs: Vec<(String, String)>, line: usize) -> Element {
        Element {
            name,
            attrs,
            children: Vec::new(),
            text: String::new(),
            line,
        }
    }

    /// The value of attribute `key`, if present.
    pub fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The first child element called `name`.
    pub fn child(&self, name: &str) -> Option<&Element> {
        self.children.iter().find(|c| c.name == name)
    }

    /// All child elements called `name`.
    pub fn children_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Element> {
        self.children.iter().filter(move |c| c.name == name)
    }
}

/// How element names are given in the tree.
#[derive(Debug, Clone, Copy)]
pub enum Names<'a> {
    /// As written in the file (`fmiModelDescription`, `xs:any`); attributes too,
    /// `xmlns` declarations included.
    AsWritten,
    /// Namespace-resolved: an element of one of the namespaces `(short, uri)` is
    /// named `short:local` whatever prefix the file uses, an element of another
    /// namespace `{uri}local`, one of no namespace `local`. Attributes keep their
    /// local names only, and `xmlns` declarations are not attributes.
    Namespaces(&'a [(&'a str, &'a str)]),
}

/// What is wrong with a document.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum XmlErrorKind {
    /// Not well-formed XML (or not UTF-8).
    Malformed,
    /// Over [`MAX_BYTES`] or [`MAX_DEPTH`].
    Limit,
}

/// A document that cannot be read: one line naming the file and the position.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}:{line}:{column}: {message}", file.display())]
pub struct XmlError {
    /// The file, as the user knows it.
    pub file: PathBuf,
    /// 1-based line.
    pub line: usize,
    /// 1-based column, in characters.
    pub column: usize,
    /// What is wrong, on one line.
    pub message: String,
    /// Malformed, or over a limit.
    pub kind: XmlErrorKind,
}

impl From<XmlError> for crate::error::Error {
    fn from(e: XmlError) -> crate::error::Error {
        let XmlError {
            file,
            line,
            column,
            message,
            kind,
        } = e;
        match kind {
            XmlErrorKind::Malformed => crate::error::Error::MalformedXml {
                file,
                line,
                column,
                message,
            },
            XmlErrorKind::Limit => crate::error::Error::XmlLimit {
                file,
                line,
                column,
                message,
            },
        }
    }
}

/// Reads an XML file, refusing one of more than [`MAX_BYTES`] bytes without reading
/// past the limit (the error is an I/O error of kind `FileTooLarge` saying so).
pub fn read(path: &Path) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let too_large = || {
        std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!("more than {MAX_BYTES} bytes, the limit for XML files"),
        )
    };
    let declared = file.metadata()?.len();
    if declared > MAX_BYTES as u64 {
        return Err(too_large());
    }
    let mut bytes = Vec::with_capacity(declared as usize);
    file.take(MAX_BYTES as u64 + 1).read_to_end(&mut bytes)?;
    if bytes.len() > MAX_BYTES {
        return Err(too_large());
    }
    Ok(bytes)
}

/// Maps byte offsets to (line, column), moving forward incrementally: linear in the
/// text however the offsets are spread over its lines.
struct Lines<'a> {
    text: &'a str,
    offset: usize,
    line: usize,
    /// Characters between the start of the line and `offset`.
    column: usize,
}

impl<'a> Lines<'a> {
    fn new(text: &'a str) -> Self {
        Lines {
            text,
            offset: 0,
            line: 1,
            column: 0,
        }
    }

    fn position(&mut self, offset: usize) -> (usize, usize) {
        let mut offset = offset.min(self.text.len());
        while !self.text.is_char_boundary(offset) {
            offset -= 1;
        }
        if offset < self.offset {
            *self = Lines::new(self.text);
        }
        for &b in &self.text.as_bytes()[self.offset..offset] {
            if b == b'\n' {
                self.line += 1;
                self.column = 0;
            } else if b & 0xC0 != 0x80 {
                // Not a UTF-8 continuation byte: a new character.
                self.column += 1;
            }
        }
        self.offset = offset;
        (self.line, self.column + 1)
    }
}

fn error(
    file: &Path,
    (line, column): (usize, usize),
    message: &str,
    kind: XmlErrorKind,
) -> XmlError {
    XmlError {
        file: file.to_owned(),
        line,
        column,
        message: crate::error::one_line(message),
        kind,
    }
}

fn malformed(file: &Path, pos: (usize, usize), message: &str) -> XmlError {
    error(file, pos, message, XmlErrorKind::Malformed)
}

fn too_large(file: &Path) -> XmlError {
    error(
        file,
        (1, 1),
        &format!("the document is more than {MAX_BYTES} bytes (the limit)"),
        XmlErrorKind::Limit,
    )
}

/// Decodes a document's bytes as UTF-8 (stripping a BOM), refusing more than
/// [`MAX_BYTES`] bytes and reporting the position of the first invalid byte.
pub fn decode<'a>(bytes: &'a [u8], file: &Path) -> Result<&'a str, XmlError> {
    if bytes.len() > MAX_BYTES {
        return Err(too_large(file));
    }
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    std::str::from_utf8(bytes).map_err(|e| {
        let valid = &bytes[..e.valid_up_to()];
        // The prefix is valid UTF-8 by construction.
        let prefix = std::str::from_utf8(valid).unwrap_or_default();
        let pos = Lines::new(prefix).position(prefix.len());
        malformed(file, pos, "invalid UTF-8 (the file must be UTF-8)")
    })
}

/// Namespace declarations in scope: each prefix's URIs, innermost last (`""` is
/// the default namespace). A look-up costs the same at any depth.
#[derive(Default)]
struct Scopes {
    bound: HashMap<String, Vec<String>>,
    /// The prefixes each open element declared, to unbind at its end.
    declared: Vec<Vec<String>>,
}

impl Scopes {
    fn open(&mut self, declarations: Vec<(String, String)>) {
        let mut prefixes = Vec::with_capacity(declarations.len());
        for (prefix, uri) in declarations {
            self.bound.entry(prefix.clone()).or_default().push(uri);
            prefixes.push(prefix);
        }
        self.declared.push(prefixes);
    }

    fn close(&mut self) {
        for prefix in self.declared.pop().unwrap_or_default() {
            if let Some(uris) = self.bound.get_mut(&prefix) {
                uris.pop();
            }
        }
    }

    fn resolve(&self, qname: &str, known: &[(&str, &str)]) -> String {
        let (prefix, local) = qname.split_once(':').unwrap_or(("", qname));
        let uri = self
            .bound
            .get(prefix)
            .and_then(|uris| uris.last())
            .filter(|uri| !uri.is_empty());
        match uri {
            Some(uri) => match known.iter().find(|(_, u)| u == uri) {
                Some((short, _)) => format!("{short}:{local}"),
                None => format!("{{{uri}}}{local}"),
            },
            None if prefix.is_empty() => local.to_owned(),
            None => qname.to_owned(),
        }
    }
}

/// The element of a start tag (without children); with namespaces, its declarations
/// are opened in `scopes`.
fn start_element(
    e: &BytesStart<'_>,
    file: &Path,
    pos: (usize, usize),
    names: Names<'_>,
    scopes: &mut Scopes,
) -> Result<Element, XmlError> {
    let mut attrs = Vec::new();
    let mut declarations = Vec::new();
    for attr in e.attributes() {
        let attr = attr.map_err(|err| malformed(file, pos, &err.to_string()))?;
        let key = attr.key.as_ref().to_owned();
        let value = attr
            .normalized_value(quick_xml::XmlVersion::Implicit1_0)
            .map_err(|err| malformed(file, pos, &format!("attribute '{key}': {err}")))?
            .into_owned();
        match names {
            Names::AsWritten => attrs.push((key, value)),
            Names::Namespaces(_) => {
                if key == "xmlns" {
                    declarations.push((String::new(), value));
                } else if let Some(prefix) = key.strip_prefix("xmlns:") {
                    declarations.push((prefix.to_owned(), value));
                } else {
                    let local = key.rsplit(':').next().unwrap_or(&key).to_owned();
                    attrs.push((local, value));
                }
            }
        }
    }
    let qname = e.name().as_ref().to_owned();
    let name = match names {
        Names::AsWritten => qname,
        Names::Namespaces(known) => {
            scopes.open(declarations);
            scopes.resolve(&qname, known)
        }
    };
    Ok(Element::new(name, attrs, pos.0))
}

/// Reads only up to the root element's start tag and returns it (without children),
/// names as written.
pub fn parse_root(text: &str, file: &Path) -> Result<Element, XmlError> {
    if text.len() > MAX_BYTES {
        return Err(too_large(file));
    }
    let mut reader = Reader::from_str(text);
    let mut lines = Lines::new(text);
    loop {
        let before = reader.buffer_position() as usize;
        match reader.read_event() {
            Ok(Event::Start(e)) | Ok(Event::Empty(e)) => {
                let pos = lines.position(before);
                return start_element(&e, file, pos, Names::AsWritten, &mut Scopes::default());
            }
            Ok(Event::Eof) => {
                return Err(malformed(
                    file,
                    lines.position(text.len()),
                    "no root element",
                ))
            }
            Ok(_) => {}
            Err(e) => {
                let pos = lines.position(reader.error_position() as usize);
                return Err(malformed(file, pos, &e.to_string()));
            }
        }
    }
}

/// The text a reference stands for: a character reference or one of XML's five
/// predefined entities (a document without a DTD can use no other).
fn reference(r: &BytesRef<'_>) -> Result<String, String> {
    let name: &str = r;
    match r.resolve_char_ref() {
        Ok(Some(c)) => return Ok(c.to_string()),
        Ok(None) => {}
        Err(e) => return Err(format!("&{name};: {e}")),
    }
    quick_xml::escape::resolve_predefined_entity(name)
        .map(str::to_owned)
        .ok_or_else(|| format!("unknown entity &{name};"))
}

/// Parses a whole document into an element tree; `file` names it in errors.
pub fn parse(text: &str, file: &Path, names: Names<'_>) -> Result<Element, XmlError> {
    if text.len() > MAX_BYTES {
        return Err(too_large(file));
    }
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut reader = Reader::from_str(text);
    reader.config_mut().check_end_names = true;
    let mut lines = Lines::new(text);
    let mut scopes = Scopes::default();
    let mut stack: Vec<Element> = Vec::new();
    let mut root: Option<Element> = None;
    loop {
        let before = reader.buffer_position() as usize;
        let event = match reader.read_event() {
            Ok(event) => event,
            Err(e) => {
                let pos = lines.position(reader.error_position() as usize);
                return Err(malformed(file, pos, &e.to_string()));
            }
        };
        match event {
            Event::Start(_) | Event::Empty(_) if root.is_some() => {
                return Err(malformed(
                    file,
                    lines.position(before),
                    "content after the root element",
                ));
            }
            Event::Start(_) | Event::Empty(_) if stack.len() >= MAX_DEPTH => {
                return Err(error(
                    file,
                    lines.position(before),
                    &format!("elements nested more than {MAX_DEPTH} deep (the limit)"),
                    XmlErrorKind::Limit,
                ));
            }
            Event::Start(e) => {
                let pos = lines.position(before);
                stack.push(start_element(&e, file, pos, names, &mut scopes)?);
            }
            Event::Empty(e) => {
                let pos = lines.position(before);
                let element = start_element(&e, file, pos, names, &mut scopes)?;
                if let Names::Namespaces(_) = names {
                    scopes.close();
                }
                match stack.last_mut() {
                    Some(parent) => parent.children.push(element),
                    None => root = Some(element),
                }
            }
            Event::End(_) => {
                if let Names::Namespaces(_) = names {
                    scopes.close();
                }
                // check_end_names guarantees the end tag matches the open element.
                let Some(done) = stack.pop() else {
                    return Err(malformed(
                        file,
                        lines.position(before),
                        "unexpected end tag",
                    ));
                };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(done),
                    None => root = Some(done),
                }
            }
            Event::Text(t) => match stack.last_mut() {
                Some(open) => open.text.push_str(&t),
                None if !t.chars().all(char::is_whitespace) => {
                    return Err(malformed(
                        file,
                        lines.position(before),
                        "text outside the root element",
                    ));
                }
                None => {}
            },
            Event::CData(c) => match stack.last_mut() {
                Some(open) => open.text.push_str(&c),
                None => {
                    return Err(malformed(
                        file,
                        lines.position(before),
                        "text outside the root element",
                    ))
                }
            },
            Event::GeneralRef(r) => {
                let expanded =
                    reference(&r).map_err(|m| malformed(file, lines.position(before), &m))?;
                match stack.last_mut() {
                    Some(open) => open.text.push_str(&expanded),
                    None => {
                        return Err(malformed(
                            file,
                            lines.position(before),
                            "text outside the root element",
                        ))
                    }
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if let Some(open) = stack.last() {
        return Err(malformed(
            file,
            lines.position(text.len()),
            &format!(
                "unexpected end of file: element <{}> opened at line {} is not closed",
                open.name, open.line
            ),
        ));
    }
    root.ok_or_else(|| malformed(file, lines.position(text.len()), "no root element"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(text: &str) -> Result<Element, XmlError> {
        parse(text, Path::new("m.xml"), Names::AsWritten)
    }

    #[test]
    fn tree_keeps_lines_and_unescapes_attributes_and_text() {
        let doc = doc(
            "<?xml version=\"1.0\"?>\n<a x=\"1 &amp; 2\">\n  <b/>\n  <c><d y='&#65;'/>t &lt;&#66;<![CDATA[&c]]></c>\n</a>\n",
        )
        .unwrap();
        assert_eq!(doc.name, "a");
        assert_eq!(doc.attr("x"), Some("1 & 2"));
        assert_eq!(doc.line, 2);
        assert_eq!(doc.children[0].line, 3);
        let c = doc.child("c").unwrap();
        assert_eq!(c.text, "t <B&c");
        let d = &c.children[0];
        assert_eq!((d.line, d.attr("y")), (4, Some("A")));
    }

    #[test]
    fn errors_carry_line_and_column() {
        let err = doc("<a>\n<b>\n  </c>\n</a>").unwrap_err();
        assert_eq!((err.line, err.kind), (3, XmlErrorKind::Malformed), "{err}");
        let err = doc("<a>\n<b>\n").unwrap_err();
        assert!(err.message.contains("<b> opened at line 2"), "{err}");
        let err = doc("<a/>\n<b/>").unwrap_err();
        assert_eq!((err.line, err.column), (2, 1), "{err}");
        assert!(err.message.contains("after the root"), "{err}");
        let err = doc("<a>&nbsp;</a>").unwrap_err();
        assert!(err.message.contains("&nbsp;"), "{err}");
        // Columns count characters, not bytes.
        let err = doc("<a é='1'><b></c></a>").unwrap_err();
        assert_eq!((err.line, err.column), (1, 13), "{err}");
        assert_eq!(err.to_string(), format!("m.xml:1:13: {}", err.message));
    }

    #[test]
    fn namespaces_resolve_whatever_the_prefix() {
        let known = [("ssd", "urn:ssd"), ("ssc", "urn:ssc")];
        let text = r#"<x:A xmlns:x="urn:ssd" xmlns="urn:ssc" x:k="1" v="2">
  <B/><x:C xmlns:x="urn:other"><x:D/></x:C><x:E/><p:F/><G xmlns=""/>
</x:A>"#;
        let root = parse(text, Path::new("s.ssd"), Names::Namespaces(&known)).unwrap();
        assert_eq!(root.name, "ssd:A");
        assert_eq!(
            root.attrs,
            [("k".into(), "1".into()), ("v".into(), "2".into())]
        );
        let names: Vec<&str> = root.children.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["ssc:B", "{urn:other}C", "ssd:E", "p:F", "G"]);
        assert_eq!(root.children[1].children[0].name, "{urn:other}D");
    }

    /// `<a><a>…` `depth` levels deep, closed, on one line.
    fn nested(depth: usize) -> String {
        format!("{}{}", "<a>".repeat(depth), "</a>".repeat(depth))
    }

    #[test]
    fn nesting_up_to_the_limit_is_read_and_deeper_is_one_error() {
        assert!(doc(&nested(MAX_DEPTH)).is_ok());
        let err = doc(&nested(MAX_DEPTH + 1)).unwrap_err();
        assert_eq!(err.kind, XmlErrorKind::Limit);
        assert_eq!((err.line, err.column), (1, 3 * MAX_DEPTH + 1));
        assert_eq!(
            err.to_string(),
            "m.xml:1:769: elements nested more than 256 deep (the limit)"
        );
        // An empty element one level too deep too.
        let text = format!(
            "{}<b/>{}",
            "<a>".repeat(MAX_DEPTH),
            "</a>".repeat(MAX_DEPTH)
        );
        assert_eq!(doc(&text).unwrap_err().kind, XmlErrorKind::Limit);
    }

    #[test]
    fn two_hundred_thousand_levels_are_one_error() {
        // 1.4 MB on one line: refused at level 257 (the reader never looks further).
        let text = nested(200_000);
        for names in [Names::AsWritten, Names::Namespaces(&[("a", "urn:a")])] {
            let err = parse(&text, Path::new("deep.xml"), names).unwrap_err();
            assert_eq!(err.kind, XmlErrorKind::Limit, "{err}");
        }
    }

    #[test]
    fn a_document_over_the_size_limit_is_refused() {
        let big = vec![b' '; MAX_BYTES + 1];
        let err = decode(&big, Path::new("big.xml")).unwrap_err();
        assert_eq!(err.kind, XmlErrorKind::Limit);
        assert!(err.message.contains("134217728"), "{err}");
        let text = std::str::from_utf8(&big).unwrap();
        assert_eq!(
            parse(text, Path::new("big.xml"), Names::AsWritten)
                .unwrap_err()
                .kind,
            XmlErrorKind::Limit
        );

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("big.xml");
        let file = std::fs::File::create(&path).unwrap();
        // A sparse file: nothing is written.
        file.set_len(MAX_BYTES as u64 + 1).unwrap();
        let err = read(&path).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::FileTooLarge);
        assert!(err.to_string().contains("limit for XML files"), "{err}");
    }
}
