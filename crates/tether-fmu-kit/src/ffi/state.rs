//! fmi2GetFMUstate and friends: boxed [`Snapshot`]s tagged with the model's fingerprint.

use std::ffi::c_char;
use std::ptr;

use super::{null, slice, slice_mut, with_instance, Fmi2Component, Fmi2FmuState, Fmi2Status};
use crate::instance::{Failure, Instance, Outcome};
use crate::machine::Call;
use crate::model::Model;
use crate::snapshot::Snapshot;

/// What an fmi2FMUstate points at: a boxed snapshot tagged with its model.
struct FmuState {
    fingerprint: u64,
    snapshot: Snapshot,
}

/// Checks that an fmi2FMUstate belongs to this model and borrows it.
///
/// # Safety
/// `state` must be null or a pointer made by [`get_fmu_state`]/[`deserialize_fmu_state`]
/// of this library, not yet freed.
unsafe fn fmu_state<'a>(state: Fmi2FmuState, fingerprint: u64) -> Outcome<&'a mut FmuState> {
    if state.is_null() {
        return Err(null("FMUstate"));
    }
    // SAFETY: per the contract, state is a live Box<FmuState> of this library.
    let state = unsafe { &mut *state.cast::<FmuState>() };
    if state.fingerprint != fingerprint {
        return Err(Failure::usage("FMUstate belongs to a different model"));
    }
    Ok(state)
}

/// Refuses the FMU-state functions of a model that declares
/// `canGetAndSetFMUstate="false"`.
fn declared<M: Model>() -> Outcome {
    if M::DECLARATION.capabilities.can_get_and_set_fmu_state {
        Ok(())
    } else {
        Err(Failure::usage(
            "FMU states are not supported (canGetAndSetFMUstate=\"false\")",
        ))
    }
}

/// fmi2GetFMUstate: updates `*state` in place if it is non-null, else allocates.
///
/// # Safety
/// See [`with_instance`] and [`fmu_state`]; `state` must be null or writable.
pub unsafe fn get_fmu_state<M: Model>(c: Fmi2Component, state: *mut Fmi2FmuState) -> Fmi2Status {
    let f = |inst: &mut Instance<M>| -> Outcome {
        declared::<M>()?;
        if state.is_null() {
            return Err(null("FMUstate"));
        }
        // SAFETY: non-null and writable per the contract.
        let current = unsafe { *state };
        if current.is_null() {
            let boxed = Box::new(FmuState {
                fingerprint: inst.fingerprint(),
                snapshot: inst.data.clone(),
            });
            // SAFETY: as above.
            unsafe { *state = Box::into_raw(boxed).cast() };
        } else {
            // SAFETY: a non-null *state must be an FMUstate of this library.
            let existing = unsafe { fmu_state(current, inst.fingerprint())? };
            existing.snapshot.clone_from(&inst.data);
        }
        Ok(())
    };
    // SAFETY: see with_instance; c is this library's instance.
    unsafe { with_instance::<M>(c, Call::GetFMUstate, f) }
}

/// # Safety
/// See [`with_instance`] and [`fmu_state`].
pub unsafe fn set_fmu_state<M: Model>(c: Fmi2Component, state: Fmi2FmuState) -> Fmi2Status {
    let f = |inst: &mut Instance<M>| -> Outcome {
        declared::<M>()?;
        // SAFETY: forwarded contract.
        let state = unsafe { fmu_state(state, inst.fingerprint())? };
        inst.restore(&state.snapshot)
    };
    // SAFETY: see with_instance; c is this library's instance.
    unsafe { with_instance::<M>(c, Call::SetFMUstate, f) }
}

/// # Safety
/// See [`with_instance`] and [`fmu_state`]; `state` must be null or writable.
pub unsafe fn free_fmu_state<M: Model>(c: Fmi2Component, state: *mut Fmi2FmuState) -> Fmi2Status {
    let f = |inst: &mut Instance<M>| -> Outcome {
        if state.is_null() {
            return Err(null("FMUstate"));
        }
        // SAFETY: non-null and readable per the contract.
        let current = unsafe { *state };
        if current.is_null() {
            return Ok(());
        }
        // SAFETY: forwarded contract: a live FMUstate of this library.
        unsafe { fmu_state(current, inst.fingerprint())? };
        // SAFETY: it was made by Box::into_raw and is freed exactly once, here.
        drop(unsafe { Box::from_raw(current.cast::<FmuState>()) });
        // SAFETY: writable per the contract.
        unsafe { *state = ptr::null_mut() };
        Ok(())
    };
    // SAFETY: see with_instance; c is this library's instance.
    unsafe { with_instance::<M>(c, Call::FreeFMUstate, f) }
}

/// # Safety
/// See [`with_instance`] and [`fmu_state`]; `size` must be null or writable.
pub unsafe fn serialized_fmu_state_size<M: Model>(
    c: Fmi2Component,
    state: Fmi2FmuState,
    size: *mut usize,
) -> Fmi2Status {
    let f = |inst: &mut Instance<M>| -> Outcome {
        declared::<M>()?;
        // SAFETY: forwarded contract.
        let state = unsafe { fmu_state(state, inst.fingerprint())? };
        if size.is_null() {
            return Err(null("size"));
        }
        // SAFETY: non-null and writable per the contract.
        unsafe { size.write(state.snapshot.serialized_size()) };
        Ok(())
    };
    // SAFETY: see with_instance; c is this library's instance.
    unsafe { with_instance::<M>(c, Call::SerializedFMUstateSize, f) }
}

/// # Safety
/// See [`with_instance`] and [`fmu_state`]; `bytes` must hold `size` writable bytes.
pub unsafe fn serialize_fmu_state<M: Model>(
    c: Fmi2Component,
    state: Fmi2FmuState,
    bytes: *mut c_char,
    size: usize,
) -> Fmi2Status {
    // SAFETY: the caller guarantees size writable bytes.
    let out = unsafe { slice_mut(bytes.cast::<u8>(), size) };
    let f = |inst: &mut Instance<M>| -> Outcome {
        declared::<M>()?;
        // SAFETY: forwarded contract.
        let state = unsafe { fmu_state(state, inst.fingerprint())? };
        let data = state.snapshot.serialize(inst.fingerprint());
        let out = out.ok_or_else(|| null("serializedState"))?;
        if out.len() != data.len() {
            return Err(Failure::usage(format!(
                "size is {}, the serialized state has {} bytes",
                out.len(),
                data.len()
            )));
        }
        out.copy_from_slice(&data);
        Ok(())
    };
    // SAFETY: see with_instance; c is this library's instance.
    unsafe { with_instance::<M>(c, Call::SerializeFMUstate, f) }
}

/// fmi2DeSerializeFMUstate: into `*state` in place if non-null, else a new state.
///
/// # Safety
/// See [`with_instance`] and [`fmu_state`]; `bytes` must hold `size` bytes and `state`
/// must be null or writable.
pub unsafe fn deserialize_fmu_state<M: Model>(
    c: Fmi2Component,
    bytes: *const c_char,
    size: usize,
    state: *mut Fmi2FmuState,
) -> Fmi2Status {
    // SAFETY: the caller guarantees size readable bytes.
    let data = unsafe { slice(bytes.cast::<u8>(), size) };
    let f = |inst: &mut Instance<M>| -> Outcome {
        declared::<M>()?;
        let data = data.ok_or_else(|| null("serializedState"))?;
        if state.is_null() {
            return Err(null("FMUstate"));
        }
        let snapshot = Snapshot::deserialize(data, inst.fingerprint(), Instance::<M>::shape())
            .map_err(Failure::usage)?;
        // SAFETY: non-null and readable per the contract.
        let current = unsafe { *state };
        if current.is_null() {
            let boxed = Box::new(FmuState {
                fingerprint: inst.fingerprint(),
                snapshot,
            });
            // SAFETY: writable per the contract.
            unsafe { *state = Box::into_raw(boxed).cast() };
        } else {
            // SAFETY: a non-null *state must be an FMUstate of this library.
            unsafe { fmu_state(current, inst.fingerprint())? }.snapshot = snapshot;
        }
        Ok(())
    };
    // SAFETY: see with_instance; c is this library's instance.
    unsafe { with_instance::<M>(c, Call::DeSerializeFMUstate, f) }
}
