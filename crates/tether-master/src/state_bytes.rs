//! The saved state as bytes (`fmi2SerializeFMUstate` of an exported system):
//! one [`Pass`] over the state's numbers in a fixed order, which writes them
//! or reads them back, so the two directions cannot drift apart. Numbers are
//! little-endian as in the host protocol ([`Out`], [`In`]); sizes and options
//! fixed by the system are written too and must match when read.

use tether_fmi::remote::protocol::{In, Out};

/// What went wrong reading bytes, as one sentence.
pub(crate) type Passed = Result<(), String>;

/// One pass over a state's numbers: write them, or overwrite them with the
/// bytes' (the state read into is one of the same simulation).
pub(crate) enum Pass<'a, 'b> {
    Write(&'a mut Out),
    Read(&'a mut In<'b>),
}

fn short(_: std::io::Error) -> String {
    "the bytes end early".into()
}

impl Pass<'_, '_> {
    pub(crate) fn f64(&mut self, x: &mut f64) -> Passed {
        match self {
            Pass::Write(out) => {
                out.f64(*x);
            }
            Pass::Read(input) => *x = input.f64().map_err(short)?,
        }
        Ok(())
    }

    pub(crate) fn u64(&mut self, x: &mut u64) -> Passed {
        match self {
            Pass::Write(out) => {
                out.u64(*x);
            }
            Pass::Read(input) => *x = input.u64().map_err(short)?,
        }
        Ok(())
    }

    pub(crate) fn bool(&mut self, x: &mut bool) -> Passed {
        let mut bit = u64::from(*x);
        self.u64(&mut bit)?;
        *x = match bit {
            0 => false,
            1 => true,
            _ => return Err(format!("a flag is {bit}, not 0 or 1")),
        };
        Ok(())
    }

    /// A size or choice of the system (`what`) that the bytes must have too.
    pub(crate) fn same(&mut self, n: usize, what: &str) -> Passed {
        let mut read = n as u64;
        self.u64(&mut read)?;
        if read != n as u64 {
            return Err(format!("{what} is {read} in the bytes, {n} in this system"));
        }
        Ok(())
    }

    /// Numbers whose count the system fixes.
    pub(crate) fn f64s(&mut self, xs: &mut [f64], what: &str) -> Passed {
        self.same(xs.len(), what)?;
        xs.iter_mut().try_for_each(|x| self.f64(x))
    }

    /// An option the system fixes (present in both or in neither).
    pub(crate) fn option<T>(
        &mut self,
        x: &mut Option<T>,
        what: &str,
        pass: impl FnOnce(&mut Self, &mut T) -> Passed,
    ) -> Passed {
        self.same(usize::from(x.is_some()), what)?;
        match x {
            Some(x) => pass(self, x),
            None => Ok(()),
        }
    }

    /// A text of any length (UTF-8).
    pub(crate) fn text(&mut self, x: &mut String) -> Passed {
        let mut bytes = std::mem::take(x).into_bytes();
        self.bytes(&mut bytes)?;
        *x = String::from_utf8(bytes).map_err(|_| "a text is not UTF-8".to_string())?;
        Ok(())
    }

    /// Texts, as many as the bytes hold (read one by one: bytes that claim
    /// more than they hold end early, before much is allocated).
    pub(crate) fn texts(&mut self, xs: &mut Vec<String>) -> Passed {
        let mut n = xs.len() as u64;
        self.u64(&mut n)?;
        match self {
            Pass::Write(_) => xs.iter_mut().try_for_each(|x| self.text(x)),
            Pass::Read(_) => {
                xs.clear();
                for _ in 0..n {
                    let mut x = String::new();
                    self.text(&mut x)?;
                    xs.push(x);
                }
                Ok(())
            }
        }
    }

    /// A byte string of any length (an instance's serialized FMU state).
    pub(crate) fn bytes(&mut self, x: &mut Vec<u8>) -> Passed {
        match self {
            Pass::Write(out) => {
                out.bytes(x);
            }
            Pass::Read(input) => {
                x.clear();
                x.extend_from_slice(input.bytes().map_err(short)?);
            }
        }
        Ok(())
    }
}
