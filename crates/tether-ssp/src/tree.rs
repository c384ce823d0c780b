//! A namespace-aware element tree with line numbers, built with quick-xml's
//! event reader. Element names are canonical: `ssd:`, `ssc:`, `ssv:`, `ssm:`
//! or `ssb:` for the SSP 1.0 namespaces whatever prefix the file uses, and
//! `{uri}local` for other namespaces.

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;

use crate::SspError;

/// The SSP 1.0 namespaces and the prefixes the standard's examples use.
pub(crate) const NAMESPACES: [(&str, &str); 5] = [
    (
        "ssd",
        "http://ssp-standard.org/SSP1/SystemStructureDescription",
    ),
    ("ssc", "http://ssp-standard.org/SSP1/SystemStructureCommon"),
    (
        "ssv",
        "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    ),
    (
        "ssm",
        "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    ),
    (
        "ssb",
        "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
    ),
];

/// One element: canonical name, attributes (unprefixed names), children, text.
#[derive(Debug, Clone)]
pub(crate) struct Node {
    pub name: String,
    pub attrs: Vec<(String, String)>,
    pub children: Vec<Node>,
    /// Text and CDATA content, concatenated.
    pub text: String,
    /// 1-based line of the start tag.
    pub line: usize,
}

impl Node {
    pub fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    pub fn child(&self, name: &str) -> Option<&Node> {
        self.children.iter().find(|c| c.name == name)
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    1 + text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

/// Namespace scopes: (prefix, uri) pairs, innermost last.
type Scopes = Vec<Vec<(String, String)>>;

fn canonical(qname: &str, scopes: &Scopes) -> String {
    let (prefix, local) = match qname.split_once(':') {
        Some((p, l)) => (p, l),
        None => ("", qname),
    };
    let uri = scopes
        .iter()
        .rev()
        .flat_map(|s| s.iter().rev())
        .find(|(p, _)| p == prefix)
        .map(|(_, u)| u.as_str());
    match uri {
        Some(uri) => match NAMESPACES.iter().find(|(_, u)| *u == uri) {
            Some((short, _)) => format!("{short}:{local}"),
            None => format!("{{{uri}}}{local}"),
        },
        None if prefix.is_empty() => local.to_string(),
        None => qname.to_string(),
    }
}

fn start(
    e: &BytesStart<'_>,
    scopes: &mut Scopes,
    file: &str,
    line: usize,
) -> Result<Node, SspError> {
    let mut scope = Vec::new();
    let mut attrs = Vec::new();
    for attr in e.attributes() {
        let attr = attr.map_err(|err| SspError::xml(file, line, err.to_string()))?;
        let key = attr.key.as_ref().to_string();
        let value = attr
            .normalized_value(quick_xml::XmlVersion::Implicit1_0)
            .map_err(|err| SspError::xml(file, line, format!("attribute '{key}': {err}")))?
            .into_owned();
        if key == "xmlns" {
            scope.push((String::new(), value));
        } else if let Some(prefix) = key.strip_prefix("xmlns:") {
            scope.push((prefix.to_string(), value));
        } else {
            // Attributes of SSP elements are unqualified; drop any prefix
            // (xml:lang and other tools' attributes are not read).
            let local = key.rsplit(':').next().unwrap_or(&key).to_string();
            attrs.push((local, value));
        }
    }
    scopes.push(scope);
    let qname = e.name().as_ref().to_string();
    Ok(Node {
        name: canonical(&qname, scopes),
        attrs,
        children: Vec::new(),
        text: String::new(),
        line,
    })
}

/// Parse a whole document; `file` names it in errors.
pub(crate) fn parse(text: &str, file: &str) -> Result<Node, SspError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut reader = Reader::from_str(text);
    reader.config_mut().check_end_names = true;
    let mut scopes: Scopes = Vec::new();
    let mut stack: Vec<Node> = Vec::new();
    let mut root = None;
    loop {
        let before = reader.buffer_position() as usize;
        let event = reader.read_event().map_err(|e| {
            SspError::xml(
                file,
                line_of(text, reader.error_position() as usize),
                e.to_string(),
            )
        })?;
        match event {
            Event::Start(e) => {
                let node = start(&e, &mut scopes, file, line_of(text, before))?;
                stack.push(node);
            }
            Event::Empty(e) => {
                let node = start(&e, &mut scopes, file, line_of(text, before))?;
                scopes.pop();
                match stack.last_mut() {
                    Some(parent) => parent.children.push(node),
                    None => root = Some(node),
                }
            }
            Event::End(_) => {
                scopes.pop();
                let done = stack.pop().ok_or_else(|| {
                    SspError::xml(file, line_of(text, before), "unexpected end tag")
                })?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(done),
                    None => root = Some(done),
                }
            }
            Event::Text(t) => {
                if let Some(node) = stack.last_mut() {
                    node.text.push_str(t.as_ref());
                }
            }
            Event::GeneralRef(r) => {
                if let Some(node) = stack.last_mut() {
                    let name = r.as_ref().to_string();
                    let c = match name.as_str() {
                        "lt" => "<",
                        "gt" => ">",
                        "amp" => "&",
                        "quot" => "\"",
                        "apos" => "'",
                        _ => {
                            return Err(SspError::xml(
                                file,
                                line_of(text, before),
                                format!("unknown entity &{name};"),
                            ))
                        }
                    };
                    node.text.push_str(c);
                }
            }
            Event::CData(c) => {
                if let Some(node) = stack.last_mut() {
                    node.text.push_str(c.as_ref());
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    root.ok_or_else(|| SspError::xml(file, 1, "no root element"))
}
