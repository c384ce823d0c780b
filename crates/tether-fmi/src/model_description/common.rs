//! What the FMI 2.0 and FMI 3.0 model descriptions share, read once for both:
//! the root element, the units, log categories and default experiment, the
//! variables' index by name and the dependency kinds of `ModelStructure`.

use std::collections::HashMap;

use super::attrs::Attrs;
use super::types::*;
use crate::error::Result;
use crate::xml::Element;

/// The root must be `<fmiModelDescription>`.
pub(super) fn check_root(at: Attrs<'_>, root: &Element) -> Result<()> {
    if root.name != "fmiModelDescription" {
        return Err(at.invalid(
            root,
            format!(
                "root element is <{}>, expected <fmiModelDescription>",
                root.name
            ),
        ));
    }
    Ok(())
}

/// The parts of the header both standards write alike.
pub(super) struct Header {
    pub fmi_version: String,
    pub model_name: String,
    pub description: Option<String>,
    pub author: Option<String>,
    pub version: Option<String>,
    pub copyright: Option<String>,
    pub license: Option<String>,
    pub generation_tool: Option<String>,
    pub generation_date_and_time: Option<String>,
    pub variable_naming_convention: VariableNamingConvention,
    pub unit_definitions: Vec<Unit>,
    pub log_categories: Vec<LogCategory>,
    pub default_experiment: Option<DefaultExperiment>,
}

/// Reads the [`Header`] under `root`.
pub(super) fn header(at: Attrs<'_>, root: &Element) -> Result<Header> {
    let unit_definitions = match root.child("UnitDefinitions") {
        Some(units) => units
            .children_named("Unit")
            .map(|u| unit(at, u))
            .collect::<Result<_>>()?,
        None => Vec::new(),
    };
    let log_categories = match root.child("LogCategories") {
        Some(cats) => cats
            .children_named("Category")
            .map(|c| {
                Ok(LogCategory {
                    name: at.required(c, "name")?,
                    description: at.string(c, "description"),
                })
            })
            .collect::<Result<_>>()?,
        None => Vec::new(),
    };
    let default_experiment = match root.child("DefaultExperiment") {
        Some(d) => Some(DefaultExperiment {
            start_time: at.parsed(d, "startTime")?,
            stop_time: at.parsed(d, "stopTime")?,
            tolerance: at.parsed(d, "tolerance")?,
            step_size: at.parsed(d, "stepSize")?,
        }),
        None => None,
    };
    let naming = at.choice(
        root,
        "variableNamingConvention",
        &[
            ("flat", VariableNamingConvention::Flat),
            ("structured", VariableNamingConvention::Structured),
        ],
    )?;
    Ok(Header {
        fmi_version: at.required(root, "fmiVersion")?,
        model_name: at.required(root, "modelName")?,
        description: at.string(root, "description"),
        author: at.string(root, "author"),
        version: at.string(root, "version"),
        copyright: at.string(root, "copyright"),
        license: at.string(root, "license"),
        generation_tool: at.string(root, "generationTool"),
        generation_date_and_time: at.string(root, "generationDateAndTime"),
        variable_naming_convention: naming.unwrap_or_default(),
        unit_definitions,
        log_categories,
        default_experiment,
    })
}

/// The index of each variable by name; a name used twice is an error at the
/// second variable's line.
pub(super) fn by_name(
    at: Attrs<'_>,
    model_variables: &[ScalarVariable],
) -> Result<HashMap<String, usize>> {
    let mut by_name = HashMap::with_capacity(model_variables.len());
    for (i, v) in model_variables.iter().enumerate() {
        if by_name.insert(v.name.clone(), i).is_some() {
            return Err(at.invalid_at(v.line, format!("duplicate variable name '{}'", v.name)));
        }
    }
    Ok(by_name)
}

fn unit(at: Attrs<'_>, u: &Element) -> Result<Unit> {
    let base_unit = match u.child("BaseUnit") {
        Some(b) => {
            let exp = |key| -> Result<i32> { Ok(at.parsed(b, key)?.unwrap_or(0)) };
            Some(BaseUnit {
                kg: exp("kg")?,
                m: exp("m")?,
                s: exp("s")?,
                A: exp("A")?,
                K: exp("K")?,
                mol: exp("mol")?,
                cd: exp("cd")?,
                rad: exp("rad")?,
                factor: at.parsed(b, "factor")?.unwrap_or(1.0),
                offset: at.parsed(b, "offset")?.unwrap_or(0.0),
            })
        }
        None => None,
    };
    let display_units = u
        .children_named("DisplayUnit")
        .map(|d| {
            Ok(DisplayUnit {
                name: at.required(d, "name")?,
                factor: at.parsed(d, "factor")?.unwrap_or(1.0),
                offset: at.parsed(d, "offset")?.unwrap_or(0.0),
                inverse: at.flag(d, "inverse", false)?,
            })
        })
        .collect::<Result<_>>()?;
    Ok(Unit {
        name: at.required(u, "name")?,
        base_unit,
        display_units,
    })
}

pub(super) fn dependency_kind(at: Attrs<'_>, u: &Element, k: &str) -> Result<DependencyKind> {
    Ok(match k {
        "dependent" => DependencyKind::Dependent,
        "constant" => DependencyKind::Constant,
        "fixed" => DependencyKind::Fixed,
        "tunable" => DependencyKind::Tunable,
        "discrete" => DependencyKind::Discrete,
        other => return Err(at.invalid(u, format!("unknown dependenciesKind \"{other}\""))),
    })
}
