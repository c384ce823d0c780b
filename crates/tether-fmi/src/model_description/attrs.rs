//! Typed attribute access with errors that name the file, line, element and attribute.

use std::path::Path;
use std::str::FromStr;

use crate::error::Error;
use crate::xml::Element;

/// Reads typed attributes of elements of one file.
#[derive(Clone, Copy)]
pub(crate) struct Attrs<'a> {
    pub file: &'a Path,
    /// What the file does that FMI does not allow and Tether works around.
    pub quirks: &'a std::cell::RefCell<Vec<super::Quirk>>,
}

impl<'a> Attrs<'a> {
    /// Record a quirk of `kind` at `line` (reported by `Fmu::open`).
    pub fn quirk(&self, kind: &'static str, line: usize, message: String) {
        self.quirks.borrow_mut().push(super::Quirk {
            kind,
            line,
            message,
        });
    }

    /// An `InvalidModelDescription` error at `element`'s line.
    pub fn invalid(&self, element: &Element, message: impl Into<String>) -> Error {
        self.invalid_at(element.line, message)
    }

    /// An `InvalidModelDescription` error at `line`.
    pub fn invalid_at(&self, line: usize, message: impl Into<String>) -> Error {
        Error::InvalidModelDescription {
            file: self.file.to_owned(),
            line,
            message: crate::error::one_line(&message.into()),
        }
    }

    /// An optional string attribute.
    pub fn string(&self, e: &Element, key: &str) -> Option<String> {
        e.attr(key).map(str::to_owned)
    }

    /// A required string attribute.
    pub fn required(&self, e: &Element, key: &str) -> Result<String, Error> {
        e.attr(key).map(str::to_owned).ok_or_else(|| {
            self.invalid(
                e,
                format!("<{}> lacks the required attribute '{key}'", e.name),
            )
        })
    }

    /// An optional attribute parsed with `FromStr`.
    pub fn parsed<T: FromStr>(&self, e: &Element, key: &str) -> Result<Option<T>, Error> {
        match e.attr(key) {
            None => Ok(None),
            Some(raw) => raw.trim().parse().map(Some).map_err(|_| {
                self.invalid(
                    e,
                    format!(
                        "<{}> attribute {key}=\"{raw}\" is not a valid {}",
                        e.name,
                        short_type_name::<T>()
                    ),
                )
            }),
        }
    }

    /// An optional `xs:boolean` attribute.
    pub fn boolean(&self, e: &Element, key: &str) -> Result<Option<bool>, Error> {
        match e.attr(key).map(str::trim) {
            None => Ok(None),
            Some("true" | "1") => Ok(Some(true)),
            Some("false" | "0") => Ok(Some(false)),
            Some(raw) => Err(self.invalid(
                e,
                format!("<{}> attribute {key}=\"{raw}\" is not a boolean", e.name),
            )),
        }
    }

    /// A `xs:boolean` attribute with a default.
    pub fn flag(&self, e: &Element, key: &str, default: bool) -> Result<bool, Error> {
        Ok(self.boolean(e, key)?.unwrap_or(default))
    }

    /// An enumerated attribute: `table` maps the spelling to the value.
    pub fn choice<T: Copy>(
        &self,
        e: &Element,
        key: &str,
        table: &[(&str, T)],
    ) -> Result<Option<T>, Error> {
        let Some(raw) = e.attr(key) else {
            return Ok(None);
        };
        table
            .iter()
            .find(|(name, _)| *name == raw.trim())
            .map(|(_, v)| Some(*v))
            .ok_or_else(|| {
                let allowed: Vec<&str> = table.iter().map(|(n, _)| *n).collect();
                self.invalid(
                    e,
                    format!(
                        "<{}> attribute {key}=\"{raw}\" is not one of {}",
                        e.name,
                        allowed.join(", ")
                    ),
                )
            })
    }

    /// A whitespace-separated list attribute.
    pub fn list<T: FromStr>(&self, e: &Element, key: &str) -> Result<Option<Vec<T>>, Error> {
        let Some(raw) = e.attr(key) else {
            return Ok(None);
        };
        raw.split_whitespace()
            .map(|item| {
                item.parse().map_err(|_| {
                    self.invalid(
                        e,
                        format!(
                            "<{}> attribute {key} has the invalid entry \"{item}\"",
                            e.name
                        ),
                    )
                })
            })
            .collect::<Result<Vec<T>, Error>>()
            .map(Some)
    }
}

fn short_type_name<T>() -> &'static str {
    let full = std::any::type_name::<T>();
    match full {
        "f64" => "real number",
        "i32" => "32-bit integer",
        "u32" | "usize" => "non-negative integer",
        _ => full.rsplit("::").next().unwrap_or(full),
    }
}
