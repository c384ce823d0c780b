//! The FMU state functions (`fmi2GetFMUstate` & co).

use std::sync::Arc;

use super::{RawComponent, RawState};
use crate::error::{Error, Result};
use crate::raw::*;

impl RawComponent {
    /// `fmi2GetFMUstate` with a NULL state: the FMU allocates a new one.
    pub(crate) fn fmi2GetFMUstate_new(&mut self) -> Result<RawState> {
        let mut ptr: fmi2FMUstate = std::ptr::null_mut();
        // SAFETY: `ptr` is a valid in/out pointer holding NULL, asking for a new state.
        self.call("fmi2GetFMUstate", |f, c| unsafe {
            (f.fmi2GetFMUstate)(c, &mut ptr)
        })?;
        self.adopt("fmi2GetFMUstate", ptr)
    }

    /// `fmi2GetFMUstate` with an existing state the FMU may overwrite in place.
    #[inline]
    pub(crate) fn fmi2GetFMUstate_update(&mut self, state: &mut RawState) -> Result<()> {
        const F: &str = "fmi2GetFMUstate";
        self.owned(F, state)?;
        let mut ptr = state.ptr;
        // SAFETY: `ptr` is a state previously returned by this component and not freed.
        let result = self.call(F, |f, c| unsafe { (f.fmi2GetFMUstate)(c, &mut ptr) });
        // The FMU may have replaced the pointer even on failure; keep what it left.
        if !ptr.is_null() {
            state.ptr = ptr;
        }
        result
    }

    /// `fmi2SetFMUstate`.
    #[inline]
    pub(crate) fn fmi2SetFMUstate(&mut self, state: &RawState) -> Result<()> {
        const F: &str = "fmi2SetFMUstate";
        self.owned(F, state)?;
        let ptr = state.ptr;
        // SAFETY: `ptr` is a live state created by this component.
        self.call(F, |f, c| unsafe { (f.fmi2SetFMUstate)(c, ptr) })
    }

    /// `fmi2FreeFMUstate`; the state is marked freed (NULL) whatever the outcome, so it
    /// can never be passed to the FMU again.
    pub(crate) fn fmi2FreeFMUstate(&mut self, state: &mut RawState) -> Result<()> {
        const F: &str = "fmi2FreeFMUstate";
        self.owned(F, state)?;
        let mut ptr = std::mem::replace(&mut state.ptr, std::ptr::null_mut());
        // SAFETY: `ptr` is a live state created by this component (`owned` checked that
        // it is not NULL); `state` no longer holds it.
        self.call(F, |f, c| unsafe { (f.fmi2FreeFMUstate)(c, &mut ptr) })
    }

    /// `fmi2SerializedFMUstateSize`.
    pub(crate) fn fmi2SerializedFMUstateSize(&mut self, state: &RawState) -> Result<usize> {
        const F: &str = "fmi2SerializedFMUstateSize";
        self.owned(F, state)?;
        let ptr = state.ptr;
        let mut size = 0usize;
        // SAFETY: `ptr` is a live state of this component; `size` is a valid out-pointer.
        self.call(F, |f, c| unsafe {
            (f.fmi2SerializedFMUstateSize)(c, ptr, &mut size)
        })?;
        Ok(size)
    }

    /// `fmi2SerializeFMUstate` into `out` (whose length is the size passed to the FMU).
    pub(crate) fn fmi2SerializeFMUstate(&mut self, state: &RawState, out: &mut [u8]) -> Result<()> {
        const F: &str = "fmi2SerializeFMUstate";
        self.owned(F, state)?;
        let ptr = state.ptr;
        // SAFETY: `out` is writable for `out.len()` bytes; `ptr` is a live state.
        self.call(F, |f, c| unsafe {
            (f.fmi2SerializeFMUstate)(c, ptr, out.as_mut_ptr().cast::<fmi2Byte>(), out.len())
        })
    }

    /// `fmi2DeSerializeFMUstate` into a new state.
    pub(crate) fn fmi2DeSerializeFMUstate(&mut self, bytes: &[u8]) -> Result<RawState> {
        const F: &str = "fmi2DeSerializeFMUstate";
        let mut ptr: fmi2FMUstate = std::ptr::null_mut();
        // SAFETY: `bytes` is readable for `bytes.len()` bytes; `ptr` holds NULL, asking
        // the FMU for a new state.
        self.call(F, |f, c| unsafe {
            (f.fmi2DeSerializeFMUstate)(c, bytes.as_ptr().cast::<fmi2Byte>(), bytes.len(), &mut ptr)
        })?;
        self.adopt(F, ptr)
    }

    fn adopt(&self, function: &'static str, ptr: fmi2FMUstate) -> Result<RawState> {
        if ptr.is_null() {
            return Err(Error::InvalidArgument {
                function,
                instance: self.name.to_string(),
                message: "the FMU returned fmi2OK but a NULL state".into(),
            });
        }
        Ok(RawState {
            ptr,
            owner: self.id,
            owner_name: Arc::clone(self.name.shared()),
        })
    }
}
