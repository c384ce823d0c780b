//! The get/set functions and the input/output derivative functions.

use std::ffi::CStr;

use super::{boolean, RawComponent};
use crate::error::Result;
use crate::raw::*;

impl RawComponent {
    /// `fmi2GetReal`.
    #[inline]
    pub(crate) fn fmi2GetReal(
        &mut self,
        vrs: &[fmi2ValueReference],
        out: &mut [f64],
    ) -> Result<()> {
        self.same_len("fmi2GetReal", "the value slice", vrs.len(), out.len())?;
        // SAFETY: both arrays hold `vrs.len()` elements (checked above).
        self.call("fmi2GetReal", |f, c| unsafe {
            (f.fmi2GetReal)(c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr())
        })
    }

    /// `fmi2GetInteger`.
    pub(crate) fn fmi2GetInteger(
        &mut self,
        vrs: &[fmi2ValueReference],
        out: &mut [i32],
    ) -> Result<()> {
        self.same_len("fmi2GetInteger", "the value slice", vrs.len(), out.len())?;
        // SAFETY: both arrays hold `vrs.len()` elements (checked above).
        self.call("fmi2GetInteger", |f, c| unsafe {
            (f.fmi2GetInteger)(c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr())
        })
    }

    /// `fmi2GetBoolean` (converted from `fmi2Boolean` through a reused scratch buffer).
    pub(crate) fn fmi2GetBoolean(
        &mut self,
        vrs: &[fmi2ValueReference],
        out: &mut [bool],
    ) -> Result<()> {
        self.same_len("fmi2GetBoolean", "the value slice", vrs.len(), out.len())?;
        let mut scratch = std::mem::take(&mut self.bool_scratch);
        scratch.clear();
        scratch.resize(vrs.len(), fmi2False);
        // SAFETY: both arrays hold `vrs.len()` elements.
        let result = self.call("fmi2GetBoolean", |f, c| unsafe {
            (f.fmi2GetBoolean)(c, vrs.as_ptr(), vrs.len(), scratch.as_mut_ptr())
        });
        if result.is_ok() {
            for (o, &b) in out.iter_mut().zip(&scratch) {
                *o = b != fmi2False;
            }
        }
        self.bool_scratch = scratch;
        result
    }

    /// `fmi2GetString` (copied into the caller's strings, reusing their buffers).
    pub(crate) fn fmi2GetString(
        &mut self,
        vrs: &[fmi2ValueReference],
        out: &mut [String],
    ) -> Result<()> {
        const F: &str = "fmi2GetString";
        self.same_len(F, "the value slice", vrs.len(), out.len())?;
        let mut ptrs: Vec<fmi2String> = vec![std::ptr::null(); vrs.len()];
        // SAFETY: both arrays hold `vrs.len()` elements.
        self.call(F, |f, c| unsafe {
            (f.fmi2GetString)(c, vrs.as_ptr(), vrs.len(), ptrs.as_mut_ptr())
        })?;
        for (o, &p) in out.iter_mut().zip(&ptrs) {
            o.clear();
            if p.is_null() {
                continue;
            }
            // SAFETY: the FMU returned NUL-terminated strings that stay valid until the
            // next call on this instance; they are copied before that.
            let s = unsafe { CStr::from_ptr(p) };
            o.push_str(&s.to_string_lossy());
        }
        Ok(())
    }

    /// `fmi2SetReal`.
    #[inline]
    pub(crate) fn fmi2SetReal(&mut self, vrs: &[fmi2ValueReference], values: &[f64]) -> Result<()> {
        self.same_len("fmi2SetReal", "the value slice", vrs.len(), values.len())?;
        // SAFETY: both arrays hold `vrs.len()` elements.
        self.call("fmi2SetReal", |f, c| unsafe {
            (f.fmi2SetReal)(c, vrs.as_ptr(), vrs.len(), values.as_ptr())
        })
    }

    /// `fmi2SetInteger`.
    pub(crate) fn fmi2SetInteger(
        &mut self,
        vrs: &[fmi2ValueReference],
        values: &[i32],
    ) -> Result<()> {
        self.same_len("fmi2SetInteger", "the value slice", vrs.len(), values.len())?;
        // SAFETY: both arrays hold `vrs.len()` elements.
        self.call("fmi2SetInteger", |f, c| unsafe {
            (f.fmi2SetInteger)(c, vrs.as_ptr(), vrs.len(), values.as_ptr())
        })
    }

    /// `fmi2SetBoolean` (converted to `fmi2Boolean` through a reused scratch buffer).
    pub(crate) fn fmi2SetBoolean(
        &mut self,
        vrs: &[fmi2ValueReference],
        values: &[bool],
    ) -> Result<()> {
        self.same_len("fmi2SetBoolean", "the value slice", vrs.len(), values.len())?;
        let mut scratch = std::mem::take(&mut self.bool_scratch);
        scratch.clear();
        scratch.extend(values.iter().map(|&b| boolean(b)));
        // SAFETY: both arrays hold `vrs.len()` elements.
        let result = self.call("fmi2SetBoolean", |f, c| unsafe {
            (f.fmi2SetBoolean)(c, vrs.as_ptr(), vrs.len(), scratch.as_ptr())
        });
        self.bool_scratch = scratch;
        result
    }

    /// `fmi2SetString`.
    pub(crate) fn fmi2SetString(
        &mut self,
        vrs: &[fmi2ValueReference],
        values: &[&str],
    ) -> Result<()> {
        const F: &str = "fmi2SetString";
        self.same_len(F, "the value slice", vrs.len(), values.len())?;
        let owned = super::super::c_strings(values, "string value", F, &self.name.to_string())?;
        let ptrs: Vec<fmi2String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: both arrays hold `vrs.len()` elements; the strings outlive the call.
        self.call(F, |f, c| unsafe {
            (f.fmi2SetString)(c, vrs.as_ptr(), vrs.len(), ptrs.as_ptr())
        })
    }

    /// `fmi2SetRealInputDerivatives`.
    #[inline]
    pub(crate) fn fmi2SetRealInputDerivatives(
        &mut self,
        vrs: &[fmi2ValueReference],
        orders: &[i32],
        values: &[f64],
    ) -> Result<()> {
        const F: &str = "fmi2SetRealInputDerivatives";
        self.same_len(F, "the order slice", vrs.len(), orders.len())?;
        self.same_len(F, "the value slice", vrs.len(), values.len())?;
        // SAFETY: all three arrays hold `vrs.len()` elements.
        self.call(F, |f, c| unsafe {
            (f.fmi2SetRealInputDerivatives)(
                c,
                vrs.as_ptr(),
                vrs.len(),
                orders.as_ptr(),
                values.as_ptr(),
            )
        })
    }

    /// `fmi2GetRealOutputDerivatives`.
    pub(crate) fn fmi2GetRealOutputDerivatives(
        &mut self,
        vrs: &[fmi2ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        const F: &str = "fmi2GetRealOutputDerivatives";
        self.same_len(F, "the order slice", vrs.len(), orders.len())?;
        self.same_len(F, "the value slice", vrs.len(), out.len())?;
        // SAFETY: all three arrays hold `vrs.len()` elements.
        self.call(F, |f, c| unsafe {
            (f.fmi2GetRealOutputDerivatives)(
                c,
                vrs.as_ptr(),
                vrs.len(),
                orders.as_ptr(),
                out.as_mut_ptr(),
            )
        })
    }

    /// `fmi2GetDirectionalDerivative`.
    pub(crate) fn fmi2GetDirectionalDerivative(
        &mut self,
        unknowns: &[fmi2ValueReference],
        knowns: &[fmi2ValueReference],
        dv_known: &[f64],
        dv_unknown: &mut [f64],
    ) -> Result<()> {
        const F: &str = "fmi2GetDirectionalDerivative";
        self.same_len(F, "the seed slice", knowns.len(), dv_known.len())?;
        self.same_len(F, "the result slice", unknowns.len(), dv_unknown.len())?;
        // SAFETY: each array has the length passed with it (checked above).
        self.call(F, |f, c| unsafe {
            (f.fmi2GetDirectionalDerivative)(
                c,
                unknowns.as_ptr(),
                unknowns.len(),
                knowns.as_ptr(),
                knowns.len(),
                dv_known.as_ptr(),
                dv_unknown.as_mut_ptr(),
            )
        })
    }
}
