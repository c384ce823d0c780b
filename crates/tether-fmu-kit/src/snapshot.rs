//! The complete internal state of an instance (what `fmi2GetFMUstate` copies) and its
//! byte format (`fmi2SerializeFMUstate`).
//!
//! Format, little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | 4 | magic `TFKS` |
//! | 4 | format version (u32, currently 1) |
//! | 8 | model fingerprint (u64, FNV-1a of the GUID): a state of another model is refused |
//! | 8 | payload length in bytes (u64) |
//! | … | payload: machine state (u8), time, start time, stop time (f64, NaN = none), step base (f64), step size (f64), step count (u64), then each vector as a u32 count followed by its items: Real parameters (f64), Integer parameters (i32), Boolean parameters (u8 0/1), inputs (3 × f64: value, d1, d2), states (f64) |
//!
//! Every count must equal the model's declaration; anything else is rejected.

use crate::input::InputJet;
use crate::machine::MachineState;

pub const MAGIC: [u8; 4] = *b"TFKS";
pub const VERSION: u32 = 1;
const HEADER_LEN: usize = 24;

/// Everything that changes during a simulation.
#[derive(Debug, PartialEq)]
pub struct Snapshot {
    pub machine: MachineState,
    /// The FMU's current time (the next expected communication point).
    pub time: f64,
    pub start_time: f64,
    pub stop_time: Option<f64>,
    /// `time = step_base + step_count · step_size` while the step size is constant.
    pub step_base: f64,
    pub step_size: f64,
    pub step_count: u64,
    /// Real parameter values; the last one is the tolerance.
    pub reals: Vec<f64>,
    pub integers: Vec<i32>,
    pub booleans: Vec<bool>,
    pub inputs: Vec<InputJet>,
    pub states: Vec<f64>,
}

impl Clone for Snapshot {
    fn clone(&self) -> Self {
        Snapshot {
            machine: self.machine,
            time: self.time,
            start_time: self.start_time,
            stop_time: self.stop_time,
            step_base: self.step_base,
            step_size: self.step_size,
            step_count: self.step_count,
            reals: self.reals.clone(),
            integers: self.integers.clone(),
            booleans: self.booleans.clone(),
            inputs: self.inputs.clone(),
            states: self.states.clone(),
        }
    }

    /// Field by field, so that `fmi2GetFMUstate` into an existing state and
    /// `fmi2SetFMUstate` reuse the vectors' memory instead of allocating (the derived
    /// `clone_from` would build a whole new snapshot).
    fn clone_from(&mut self, source: &Self) {
        // Exhaustive, so that a new field cannot be forgotten here.
        let Snapshot {
            machine,
            time,
            start_time,
            stop_time,
            step_base,
            step_size,
            step_count,
            reals,
            integers,
            booleans,
            inputs,
            states,
        } = source;
        self.machine = *machine;
        self.time = *time;
        self.start_time = *start_time;
        self.stop_time = *stop_time;
        self.step_base = *step_base;
        self.step_size = *step_size;
        self.step_count = *step_count;
        self.reals.clone_from(reals);
        self.integers.clone_from(integers);
        self.booleans.clone_from(booleans);
        self.inputs.clone_from(inputs);
        self.states.clone_from(states);
    }
}

/// The number of items of each kind a snapshot of one model has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shape {
    pub reals: usize,
    pub integers: usize,
    pub booleans: usize,
    pub inputs: usize,
    pub states: usize,
}

impl Snapshot {
    pub fn shape(&self) -> Shape {
        Shape {
            reals: self.reals.len(),
            integers: self.integers.len(),
            booleans: self.booleans.len(),
            inputs: self.inputs.len(),
            states: self.states.len(),
        }
    }

    pub fn serialized_size(&self) -> usize {
        HEADER_LEN
            + 1
            + 6 * 8
            + 5 * 4
            + self.reals.len() * 8
            + self.integers.len() * 4
            + self.booleans.len()
            + self.inputs.len() * 24
            + self.states.len() * 8
    }

    pub fn serialize(&self, fingerprint: u64) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.serialized_size());
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&fingerprint.to_le_bytes());
        out.extend_from_slice(&((self.serialized_size() - HEADER_LEN) as u64).to_le_bytes());
        out.push(self.machine as u8);
        for x in [
            self.time,
            self.start_time,
            self.stop_time.unwrap_or(f64::NAN),
            self.step_base,
            self.step_size,
        ] {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out.extend_from_slice(&self.step_count.to_le_bytes());
        let count = |out: &mut Vec<u8>, n: usize| out.extend_from_slice(&(n as u32).to_le_bytes());
        count(&mut out, self.reals.len());
        self.reals
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
        count(&mut out, self.integers.len());
        self.integers
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
        count(&mut out, self.booleans.len());
        self.booleans.iter().for_each(|&b| out.push(u8::from(b)));
        count(&mut out, self.inputs.len());
        for jet in &self.inputs {
            for x in [jet.value, jet.d1, jet.d2] {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        count(&mut out, self.states.len());
        self.states
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
        out
    }

    /// Parses bytes made by [`Snapshot::serialize`] for the model with `fingerprint`
    /// and `shape`; every inconsistency is an error message.
    pub fn deserialize(bytes: &[u8], fingerprint: u64, shape: Shape) -> Result<Snapshot, String> {
        let mut r = Reader { bytes, pos: 0 };
        if r.take(4)? != MAGIC {
            return Err("not a serialized FMU state of tether-fmu-kit (bad magic)".into());
        }
        let version = r.u32()?;
        if version != VERSION {
            return Err(format!(
                "serialized FMU state has format version {version}, expected {VERSION}"
            ));
        }
        if r.u64()? != fingerprint {
            return Err("serialized FMU state belongs to a different model (GUID mismatch)".into());
        }
        let payload = r.u64()?;
        if usize::try_from(payload)
            .ok()
            .and_then(|p| p.checked_add(HEADER_LEN))
            != Some(bytes.len())
        {
            return Err(format!(
                "serialized FMU state has {} bytes, its header says {}",
                bytes.len(),
                payload
            ));
        }
        let machine = r.u8()?;
        let machine =
            MachineState::from_u8(machine).ok_or(format!("invalid machine state {machine}"))?;
        let (time, start_time, stop_time, step_base, step_size) =
            (r.f64()?, r.f64()?, r.f64()?, r.f64()?, r.f64()?);
        let step_count = r.u64()?;
        let reals = r.vec(shape.reals, "Real parameters", Reader::f64)?;
        let integers = r.vec(shape.integers, "Integer parameters", |r| {
            r.u32().map(|x| x as i32)
        })?;
        let booleans = r.vec(shape.booleans, "Boolean parameters", |r| match r.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(format!("invalid Boolean byte {b}")),
        })?;
        let inputs = r.vec(shape.inputs, "inputs", |r| {
            Ok(InputJet {
                value: r.f64()?,
                d1: r.f64()?,
                d2: r.f64()?,
            })
        })?;
        let states = r.vec(shape.states, "states", Reader::f64)?;
        Ok(Snapshot {
            machine,
            time,
            start_time,
            stop_time: (!stop_time.is_nan()).then_some(stop_time),
            step_base,
            step_size,
            step_count,
            reals,
            integers,
            booleans,
            inputs,
            states,
        })
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or("serialized FMU state is truncated")?;
        let slice = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(slice)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<u32, String> {
        self.array().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> Result<u64, String> {
        self.array().map(u64::from_le_bytes)
    }
    fn f64(&mut self) -> Result<f64, String> {
        self.array().map(f64::from_le_bytes)
    }
    fn vec<T>(
        &mut self,
        expected: usize,
        what: &str,
        mut item: impl FnMut(&mut Self) -> Result<T, String>,
    ) -> Result<Vec<T>, String> {
        let n = self.u32()? as usize;
        if n != expected {
            return Err(format!(
                "serialized FMU state has {n} {what}, the model has {expected}"
            ));
        }
        (0..n).map(|_| item(self)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Snapshot {
        Snapshot {
            machine: MachineState::StepComplete,
            time: 0.30000000000000004,
            start_time: 0.0,
            stop_time: None,
            step_base: 0.0,
            step_size: 0.1,
            step_count: 3,
            reals: vec![1.0, 1000.0, 10.0, 0.0, 100.0, 1e-10],
            integers: vec![-7],
            booleans: vec![true],
            inputs: vec![InputJet {
                value: 1.5,
                d1: -2.0,
                d2: 0.25,
            }],
            states: vec![0.123, -4.5],
        }
    }

    #[test]
    fn serialization_round_trips_bit_exactly() {
        let s = sample();
        let bytes = s.serialize(42);
        assert_eq!(bytes.len(), s.serialized_size());
        assert_eq!(Snapshot::deserialize(&bytes, 42, s.shape()), Ok(s.clone()));
        let with_stop = Snapshot {
            stop_time: Some(2.0),
            ..s
        };
        let bytes = with_stop.serialize(42);
        assert_eq!(
            Snapshot::deserialize(&bytes, 42, with_stop.shape()),
            Ok(with_stop)
        );
    }

    #[test]
    fn bad_bytes_are_rejected_with_a_reason() {
        let s = sample();
        let bytes = s.serialize(42);
        let shape = s.shape();
        assert!(Snapshot::deserialize(&bytes, 43, shape)
            .unwrap_err()
            .contains("different model"));
        assert!(Snapshot::deserialize(&bytes[..bytes.len() - 1], 42, shape)
            .unwrap_err()
            .contains("bytes"));
        assert!(Snapshot::deserialize(&bytes[..10], 42, shape).is_err());
        assert!(Snapshot::deserialize(&[], 42, shape).is_err());
        let mut bad = bytes.clone();
        bad[0] = b'X';
        assert!(Snapshot::deserialize(&bad, 42, shape)
            .unwrap_err()
            .contains("magic"));
        let mut bad = bytes.clone();
        bad[4] = 9;
        assert!(Snapshot::deserialize(&bad, 42, shape)
            .unwrap_err()
            .contains("version"));
        let mut bad = bytes.clone();
        bad[HEADER_LEN] = 200;
        assert!(Snapshot::deserialize(&bad, 42, shape)
            .unwrap_err()
            .contains("machine state"));
        let other = Shape { states: 3, ..shape };
        assert!(Snapshot::deserialize(&bytes, 42, other)
            .unwrap_err()
            .contains("states"));
    }
}
