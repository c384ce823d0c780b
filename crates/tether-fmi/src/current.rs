//! Which FMI call this thread is inside, for a program's exit hook or signal
//! handler: when an FMU calls `exit()` or `abort()`, the process ends inside
//! the FMU and the error value never comes back, so the hook asks
//! [`current_call`] whom to blame.
//!
//! Every call records its function, instance and time in a thread-local cell
//! before entering the FMU and clears it after (two stores, no allocation).
//!
//! It also publishes them for other threads ([`calls_in_progress`]), so that a
//! watchdog or a Ctrl-C handler can say which call is stuck: a few relaxed
//! atomic stores into this thread's slot and a sequence number that is odd
//! while the call runs. Instance names are found by an id in a registry that
//! holds them while the instance lives.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

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
    pub(crate) fn new(function: &'static str, instance: &Name, time: f64) -> Entered {
        let entry = (function, &*instance.name as *const str, time);
        let previous = CURRENT.try_with(|c| c.replace(Some(entry))).ok().flatten();
        let _ = SLOT.try_with(|s| s.0.enter(function, instance.id, time));
        Entered { previous }
    }
}

impl Drop for Entered {
    #[inline]
    fn drop(&mut self) {
        let _ = CURRENT.try_with(|c| c.set(self.previous));
        let _ = SLOT.try_with(|s| s.0.leave());
    }
}

/// An instance name registered for [`calls_in_progress`] while this value lives.
#[derive(Debug)]
pub(crate) struct Name {
    id: u64,
    name: Arc<str>,
}

static NEXT_NAME: AtomicU64 = AtomicU64::new(1);
static NAMES: Mutex<BTreeMap<u64, Arc<str>>> = Mutex::new(BTreeMap::new());

fn names() -> MutexGuard<'static, BTreeMap<u64, Arc<str>>> {
    NAMES.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Name {
    pub(crate) fn new(name: &str) -> Name {
        let id = NEXT_NAME.fetch_add(1, Ordering::Relaxed);
        let name: Arc<str> = Arc::from(name);
        names().insert(id, Arc::clone(&name));
        Name { id, name }
    }

    /// The name.
    pub(crate) fn as_str(&self) -> &str {
        &self.name
    }

    /// The shared name.
    pub(crate) fn shared(&self) -> &Arc<str> {
        &self.name
    }
}

impl std::fmt::Display for Name {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)
    }
}

impl Drop for Name {
    fn drop(&mut self) {
        names().remove(&self.id);
    }
}

/// One thread's published call; written by that thread only.
#[derive(Debug, Default)]
struct Published {
    /// Odd while a call runs; changes with every call.
    sequence: AtomicU64,
    function: AtomicUsize,
    function_len: AtomicUsize,
    instance: AtomicU64,
    time: AtomicU64,
}

impl Published {
    #[inline]
    fn enter(&self, function: &'static str, instance: u64, time: f64) {
        self.function
            .store(function.as_ptr() as usize, Ordering::Relaxed);
        self.function_len.store(function.len(), Ordering::Relaxed);
        self.instance.store(instance, Ordering::Relaxed);
        self.time.store(time.to_bits(), Ordering::Relaxed);
        let s = self.sequence.load(Ordering::Relaxed);
        self.sequence.store(s | 1, Ordering::Release);
    }

    #[inline]
    fn leave(&self) {
        let s = self.sequence.load(Ordering::Relaxed);
        if s & 1 == 1 {
            self.sequence.store(s + 1, Ordering::Release);
        }
    }
}

/// The slots of the live threads that made FMI calls.
static THREADS: Mutex<Vec<Arc<Published>>> = Mutex::new(Vec::new());

fn threads() -> MutexGuard<'static, Vec<Arc<Published>>> {
    THREADS.lock().unwrap_or_else(PoisonError::into_inner)
}

/// This thread's slot, registered on first use and removed when it ends.
struct Slot(Arc<Published>);

impl Slot {
    fn new() -> Slot {
        let slot = Arc::new(Published::default());
        threads().push(Arc::clone(&slot));
        Slot(slot)
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        threads().retain(|s| !Arc::ptr_eq(s, &self.0));
    }
}

thread_local! {
    static SLOT: Slot = Slot::new();
}

/// An FMI call in progress on some thread, as [`calls_in_progress`] sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct CallInProgress {
    /// The function, the instance and its time.
    pub call: CurrentCall,
    /// Which call this is: the same value for as long as the call runs, another
    /// for any other call (a watchdog times a call by seeing it again).
    pub key: (usize, u64),
}

/// The FMI calls running on every thread now (of instances in this process and
/// of isolated ones, whose calls wait for their host).
pub fn calls_in_progress() -> Vec<CallInProgress> {
    let slots: Vec<Arc<Published>> = threads().clone();
    let mut calls = Vec::new();
    for slot in slots {
        let sequence = slot.sequence.load(Ordering::Acquire);
        if sequence & 1 == 0 {
            continue;
        }
        let function = slot.function.load(Ordering::Relaxed);
        let len = slot.function_len.load(Ordering::Relaxed);
        let instance = slot.instance.load(Ordering::Relaxed);
        let time = f64::from_bits(slot.time.load(Ordering::Relaxed));
        if slot.sequence.load(Ordering::Acquire) != sequence {
            continue; // the call ended meanwhile
        }
        // SAFETY: `function` and `len` were stored together from a `&'static str`
        // by `Published::enter` of the same call (the sequence number did not
        // change while they were read), so they describe a valid static string.
        let function: &'static str = unsafe {
            std::str::from_utf8_unchecked(std::slice::from_raw_parts(function as *const u8, len))
        };
        let instance = names()
            .get(&instance)
            .map_or_else(|| "?".to_string(), |n| n.to_string());
        calls.push(CallInProgress {
            call: CurrentCall {
                function,
                instance,
                time,
            },
            key: (Arc::as_ptr(&slot) as usize, sequence),
        });
    }
    calls
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_call_in_progress_is_known_on_its_thread_only() {
        assert_eq!(current_call(), None);
        let name = Name::new("mass2");
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
            // Other threads see it through calls_in_progress.
            let seen = std::thread::spawn(calls_in_progress).join().unwrap();
            let ours: Vec<_> = seen.iter().filter(|c| c.call.instance == "mass2").collect();
            assert_eq!(ours.len(), 1, "{seen:?}");
            assert_eq!(
                (ours[0].call.function, ours[0].call.time),
                ("fmi2DoStep", 0.5)
            );
            assert_eq!(ours[0].key.1 & 1, 1);
        }
        assert_eq!(current_call(), None);
        assert!(calls_in_progress()
            .iter()
            .all(|c| c.call.instance != "mass2"));
    }
}
