//! The Real and Integer type attributes (`quantity`, `unit`, `min`, `max`, …) shared by
//! `<SimpleType>` definitions and the variables that declare or refine them.

use super::attrs::Attrs;
use super::types::{IntegerType, RealType};
use crate::error::Result;
use crate::xml::Element;

/// Reads the Real attributes of a type definition or variable element.
pub(crate) fn real_type(at: Attrs<'_>, e: &Element, base: Option<&RealType>) -> Result<RealType> {
    let base = base.cloned().unwrap_or_default();
    Ok(RealType {
        quantity: at.string(e, "quantity").or(base.quantity),
        unit: at.string(e, "unit").or(base.unit),
        display_unit: at.string(e, "displayUnit").or(base.display_unit),
        relative_quantity: at
            .boolean(e, "relativeQuantity")?
            .unwrap_or(base.relative_quantity),
        min: at.parsed(e, "min")?.or(base.min),
        max: at.parsed(e, "max")?.or(base.max),
        nominal: at.parsed(e, "nominal")?.or(base.nominal),
        unbounded: at.boolean(e, "unbounded")?.unwrap_or(base.unbounded),
    })
}

/// Reads the Integer/Enumeration attributes of a type definition or variable element.
pub(crate) fn integer_type(
    at: Attrs<'_>,
    e: &Element,
    base: Option<&IntegerType>,
) -> Result<IntegerType> {
    let base = base.cloned().unwrap_or_default();
    Ok(IntegerType {
        quantity: at.string(e, "quantity").or(base.quantity),
        min: at.parsed(e, "min")?.or(base.min),
        max: at.parsed(e, "max")?.or(base.max),
    })
}
