//! Which FMI call this thread is inside, for a program's exit hook or signal
//! handler: when an FMU calls `exit()` or `abort()`, the process ends inside
//! the FMU and the error value never comes back, so the hook asks
//! [`current_call`] whom to blame.
//!
//! Every call records its function, instance and time in a thread-local cell
//! before entering the FMU and clears it after (two stores, no allocation).

use std::cell::Cell;

/// The function, the instance name and the instance's time of the call in
/// progress on this thread.
type Entry = (&'static str, *const str, f64);

thread_local! {
    static CURRENT: Cell<Option<Entry>> = const { Cell::new(None) };
}

/// An FMI call in progress on the calling thread.
#[derive(Debug, Clone, PartialEq)]
pub struct CurrentCall {
    /// The C function, e.g. `fmi2DoStep`.
    pub function: &'static str,
    /// The instance's name.
    pub instance: String,
    /// The instance's communication time when the call began.
    pub time: f64,
}

/// The FMI call this thread is inside, if any: from an exit hook, a signal
/// handler or a logger callback running on the thread that called the FMU.
pub fn current_call() -> Option<CurrentCall> {
    let (function, instance, time) = CURRENT.try_with(Cell::get).ok().flatten()?;
    // SAFETY: the pointer is set by `Entered::new` from the name of the component
    // being called and cleared when that call returns; while it is set, code on this
    // thread runs only inside the call (the FMU itself, its callbacks, or a hook or
    // handler they trigger), during which the component and its name are alive.
    let instance = unsafe { &*instance }.to_owned();
    Some(CurrentCall {
        function,
        instance,
        time,
    })
}

/// Marks the calling thread as inside `function` of `instance` until dropped.
pub(crate) struct Entered {
    previous: Option<Entry>,
}

impl Entered {
    #[inline]
    pub(crate) fn new(function: &'static str, instance: &str, time: f64) -> Entered {
        let entry = (function, instance as *const str, time);
        let previous = CURRENT.try_with(|c| c.replace(Some(entry))).ok().flatten();
        Entered { previous }
    }
}

impl Drop for Entered {
    #[inline]
    fn drop(&mut self) {
        let _ = CURRENT.try_with(|c| c.set(self.previous));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_call_in_progress_is_known_on_its_thread_only() {
        assert_eq!(current_call(), None);
        let name = String::from("mass2");
        {
            let _outer = Entered::new("fmi2DoStep", &name, 0.5);
            let seen = current_call().unwrap();
            assert_eq!(
                (seen.function, seen.instance.as_str(), seen.time),
                ("fmi2DoStep", "mass2", 0.5)
            );
            std::thread::spawn(|| assert_eq!(current_call(), None))
                .join()
                .unwrap();
        }
        assert_eq!(current_call(), None);
    }
}
