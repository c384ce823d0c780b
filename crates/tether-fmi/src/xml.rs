//! A minimal element tree with line numbers, built with quick-xml's event reader.
//!
//! modelDescription.xml is attribute-driven and small enough to hold in memory; building
//! a tree first keeps the FMI mapping code free of reader state and lets every semantic
//! error point at the line of the element it concerns.

use std::path::Path;

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;

use crate::error::{one_line, Error, Result};

/// One XML element: its name, attributes (entity-expanded) and child elements.
#[derive(Debug, Clone)]
pub(crate) struct Element {
    pub name: String,
    pub attrs: Vec<(String, String)>,
    pub children: Vec<Element>,
    /// 1-based line of the start tag.
    pub line: usize,
}

impl Element {
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

/// Maps byte offsets to (line, column), moving forward incrementally.
struct Lines<'a> {
    text: &'a str,
    offset: usize,
    line: usize,
    line_start: usize,
}

impl<'a> Lines<'a> {
    fn new(text: &'a str) -> Self {
        Lines {
            text,
            offset: 0,
            line: 1,
            line_start: 0,
        }
    }

    fn position(&mut self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        if offset < self.offset {
            *self = Lines::new(self.text);
        }
        let bytes = self.text.as_bytes();
        for (i, &b) in bytes[self.offset..offset].iter().enumerate() {
            if b == b'\n' {
                self.line += 1;
                self.line_start = self.offset + i + 1;
            }
        }
        self.offset = offset;
        let column = self
            .text
            .get(self.line_start..offset)
            .map_or(offset - self.line_start, |s| s.chars().count())
            + 1;
        (self.line, column)
    }
}

fn malformed(file: &Path, (line, column): (usize, usize), message: &str) -> Error {
    Error::MalformedXml {
        file: file.to_owned(),
        line,
        column,
        message: one_line(message),
    }
}

/// Decodes the file's bytes as UTF-8 (stripping a BOM), reporting the position of the
/// first invalid byte.
pub(crate) fn decode<'a>(bytes: &'a [u8], file: &Path) -> Result<&'a str> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    std::str::from_utf8(bytes).map_err(|e| {
        let valid = &bytes[..e.valid_up_to()];
        // The prefix is valid UTF-8 by construction.
        let prefix = std::str::from_utf8(valid).unwrap_or_default();
        let pos = Lines::new(prefix).position(prefix.len());
        malformed(file, pos, "invalid UTF-8 (FMI requires UTF-8 encoding)")
    })
}

fn start_element(
    e: &BytesStart<'_>,
    file: &Path,
    pos: (usize, usize),
) -> Result<(String, Vec<(String, String)>)> {
    let name = e.name().as_ref().to_owned();
    let mut attrs = Vec::new();
    for attr in e.attributes() {
        let attr = attr.map_err(|err| malformed(file, pos, &err.to_string()))?;
        let key = attr.key.as_ref().to_owned();
        let value = attr
            .normalized_value(quick_xml::XmlVersion::Implicit1_0)
            .map_err(|err| malformed(file, pos, &format!("attribute '{key}': {err}")))?
            .into_owned();
        attrs.push((key, value));
    }
    Ok((name, attrs))
}

/// Reads only up to the root element's start tag and returns it (without children).
pub(crate) fn parse_root(text: &str, file: &Path) -> Result<Element> {
    let mut reader = Reader::from_str(text);
    let mut lines = Lines::new(text);
    loop {
        let before = reader.buffer_position() as usize;
        match reader.read_event() {
            Ok(Event::Start(e)) | Ok(Event::Empty(e)) => {
                let pos = lines.position(before);
                let (name, attrs) = start_element(&e, file, pos)?;
                return Ok(Element {
                    name,
                    attrs,
                    children: Vec::new(),
                    line: pos.0,
                });
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

/// Parses a whole document into an element tree.
pub(crate) fn parse_document(text: &str, file: &Path) -> Result<Element> {
    let mut reader = Reader::from_str(text);
    reader.config_mut().check_end_names = true;
    let mut lines = Lines::new(text);
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
            Event::Start(e) | Event::Empty(e) if root.is_some() => {
                let _ = e;
                return Err(malformed(
                    file,
                    lines.position(before),
                    "content after the root element",
                ));
            }
            Event::Start(e) => {
                let pos = lines.position(before);
                let (name, attrs) = start_element(&e, file, pos)?;
                stack.push(Element {
                    name,
                    attrs,
                    children: Vec::new(),
                    line: pos.0,
                });
            }
            Event::Empty(e) => {
                let pos = lines.position(before);
                let (name, attrs) = start_element(&e, file, pos)?;
                let element = Element {
                    name,
                    attrs,
                    children: Vec::new(),
                    line: pos.0,
                };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(element),
                    None => root = Some(element),
                }
            }
            Event::End(_) => {
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
            Event::Text(t) if stack.is_empty() && !t.as_ref().chars().all(char::is_whitespace) => {
                return Err(malformed(
                    file,
                    lines.position(before),
                    "text outside the root element",
                ));
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

    #[test]
    fn tree_keeps_lines_and_unescapes_attributes() {
        let doc =
            "<?xml version=\"1.0\"?>\n<a x=\"1 &amp; 2\">\n  <b/>\n  <c><d y='&#65;'/></c>\n</a>\n";
        let root = parse_document(doc, Path::new("m.xml")).unwrap();
        assert_eq!(root.name, "a");
        assert_eq!(root.attr("x"), Some("1 & 2"));
        assert_eq!(root.line, 2);
        assert_eq!(root.children[0].line, 3);
        let d = &root.child("c").unwrap().children[0];
        assert_eq!((d.line, d.attr("y")), (4, Some("A")));
    }

    #[test]
    fn errors_carry_line_numbers() {
        let doc = "<a>\n<b>\n</c>\n</a>";
        match parse_document(doc, Path::new("m.xml")) {
            Err(Error::MalformedXml { line, .. }) => assert_eq!(line, 3),
            other => panic!("{other:?}"),
        }
        let doc = "<a>\n<b>\n";
        assert!(matches!(
            parse_document(doc, Path::new("m.xml")),
            Err(Error::MalformedXml { .. })
        ));
    }
}
