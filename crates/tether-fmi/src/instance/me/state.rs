//! The instance's part of a serialized model-exchange state: a tag, the
//! time, the continuous states, their nominals, the event indicators, the
//! next time event and the event counts, little-endian; the FMU's serialized
//! state follows with its length.

use super::Saved;

/// What starts every serialized state of a model-exchange instance.
const TAG: &[u8; 8] = b"TETHERME";

/// Appends the instance's part of `saved` to `out`.
pub(super) fn write(saved: &Saved, out: &mut Vec<u8>) {
    out.extend_from_slice(TAG);
    let f = |out: &mut Vec<u8>, v: f64| out.extend_from_slice(&v.to_le_bytes());
    f(out, saved.time);
    for list in [&saved.x, &saved.nominals, &saved.z] {
        out.extend_from_slice(&(list.len() as u64).to_le_bytes());
        for &v in list.iter() {
            f(out, v);
        }
    }
    for option in [saved.next_event, saved.last_event] {
        out.push(u8::from(option.is_some()));
        f(out, option.unwrap_or(0.0));
    }
    f(out, saved.event_time);
    out.extend_from_slice(&saved.event_iterations.to_le_bytes());
    out.extend_from_slice(&saved.events.to_le_bytes());
}

/// The instance's part of `bytes` for `nx` states and `nz` indicators, and the
/// FMU's serialized state after it; `None` for bytes of another shape.
pub(super) fn read(bytes: &[u8], nx: usize, nz: usize) -> Option<(Saved, &[u8])> {
    let mut r = Reader(bytes);
    if r.take(TAG.len())? != TAG {
        return None;
    }
    let mut saved = Saved {
        time: r.f64()?,
        ..Saved::default()
    };
    for (list, n) in [
        (&mut saved.x, nx),
        (&mut saved.nominals, nx),
        (&mut saved.z, nz),
    ] {
        if r.u64()? != n as u64 {
            return None;
        }
        for _ in 0..n {
            list.push(r.f64()?);
        }
    }
    let mut option = || -> Option<Option<f64>> {
        let some = r.take(1)?[0];
        let v = r.f64()?;
        match some {
            0 => Some(None),
            1 => Some(Some(v)),
            _ => None,
        }
    };
    saved.next_event = option()?;
    saved.last_event = option()?;
    saved.event_time = r.f64()?;
    saved.event_iterations = u32::from_le_bytes(r.take(4)?.try_into().ok()?);
    saved.events = r.u64()?;
    let len = usize::try_from(r.u64()?).ok()?;
    let fmu = r.take(len)?;
    r.0.is_empty().then_some((saved, fmu))
}

struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Some(head)
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_state_reads_back_and_other_bytes_do_not() {
        let saved = Saved {
            time: 0.25,
            x: vec![1.0, -2.0],
            nominals: vec![1.0, 10.0],
            z: vec![0.5],
            next_event: Some(1.0),
            event_time: 0.1,
            event_iterations: 2,
            events: 7,
            last_event: None,
            ..Saved::default()
        };
        let mut bytes = Vec::new();
        write(&saved, &mut bytes);
        bytes.extend_from_slice(&3u64.to_le_bytes());
        bytes.extend_from_slice(b"fmu");
        let (back, fmu) = read(&bytes, 2, 1).unwrap();
        assert_eq!(fmu, b"fmu");
        assert_eq!(
            (
                back.time,
                &back.x,
                &back.nominals,
                &back.z,
                back.next_event,
                back.last_event
            ),
            (0.25, &saved.x, &saved.nominals, &saved.z, Some(1.0), None)
        );
        assert_eq!((back.event_iterations, back.events), (2, 7));
        // Another shape, a cut or a longer tail, another tag.
        assert!(read(&bytes, 3, 1).is_none());
        assert!(read(&bytes[..bytes.len() - 1], 2, 1).is_none());
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(read(&longer, 2, 1).is_none());
        assert!(read(b"TETHERMX", 2, 1).is_none());
        assert!(read(&[], 0, 0).is_none());
    }
}
