//! Which FMI call is in progress, on this thread for a program's exit hook or
//! signal handler (when an FMU calls `exit()` or `abort()`, the process ends
//! inside the FMU and the error value never comes back, so the hook asks
//! [`current_call`] whom to blame), and on every thread for a watchdog or a
//! Ctrl-C handler ([`calls_in_progress`]: which call is stuck).
//!
//! Every call publishes its function, instance and time in its thread's slot
//! before entering the FMU, and a sequence number that is odd while the call
//! runs: a few relaxed atomic stores through a constant thread-local pointer,
//! no allocation, no lock. Instance names are found by an id in a registry
//! that holds them while the instance lives. Slots are never freed: a thread
//! that ends gives its slot back for the next one.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

/// An FMI call in progress.
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
    let slot = SLOT.try_with(Cell::get).ok()?;
    if slot.is_null() {
        return None;
    }
    // SAFETY: slots are leaked, never freed (`register`).
    let slot = unsafe { &*slot };
    slot.read().map(|(call, _)| call)
}

/// Marks the calling thread as inside `function` of `instance` until dropped.
pub(crate) struct Entered {
    slot: &'static Published,
}

impl Entered {
    #[inline]
    pub(crate) fn new(function: &'static str, instance: &Name, time: f64) -> Entered {
        let slot = match SLOT.try_with(Cell::get) {
            Ok(p) if !p.is_null() => {
                // SAFETY: slots are leaked, never freed (`register`).
                unsafe { &*p }
            }
            _ => register(),
        };
        slot.enter(function, instance.id, time);
        Entered { slot }
    }
}

impl Drop for Entered {
    #[inline]
    fn drop(&mut self) {
        self.slot.leave();
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
    /// Whether a live thread owns the slot.
    owned: AtomicBool,
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

    /// The call in progress and its key, if any.
    fn read(&'static self) -> Option<(CurrentCall, (usize, u64))> {
        let sequence = self.sequence.load(Ordering::Acquire);
        if sequence & 1 == 0 {
            return None;
        }
        let function = self.function.load(Ordering::Relaxed);
        let len = self.function_len.load(Ordering::Relaxed);
        let instance = self.instance.load(Ordering::Relaxed);
        let time = f64::from_bits(self.time.load(Ordering::Relaxed));
        if self.sequence.load(Ordering::Acquire) != sequence {
            return None; // the call ended meanwhile
        }
        // SAFETY: `function` and `len` were stored together from a `&'static str`
        // by `enter` of the same call (the sequence number did not change while
        // they were read), so they describe a valid static string.
        let function: &'static str = unsafe {
            std::str::from_utf8_unchecked(std::slice::from_raw_parts(function as *const u8, len))
        };
        let instance = names()
            .get(&instance)
            .map_or_else(|| "?".to_string(), |n| n.to_string());
        let call = CurrentCall {
            function,
            instance,
            time,
        };
        Some((call, (self as *const Published as usize, sequence)))
    }
}

/// Every slot ever made (owned or free for the next thread).
static SLOTS: Mutex<Vec<&'static Published>> = Mutex::new(Vec::new());

fn slots() -> MutexGuard<'static, Vec<&'static Published>> {
    SLOTS.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Gives the slot back when the thread ends.
struct Owner(&'static Published);

impl Drop for Owner {
    fn drop(&mut self) {
        // `exit()` inside an FMU call runs the thread's destructors before the
        // exit hooks: the slot then stays as it is, for `current_call`.
        if self.0.sequence.load(Ordering::Relaxed) & 1 == 1 {
            return;
        }
        let _ = SLOT.try_with(|s| s.set(std::ptr::null()));
        self.0.owned.store(false, Ordering::Release);
    }
}

thread_local! {
    static SLOT: Cell<*const Published> = const { Cell::new(std::ptr::null()) };
    static OWNER: Cell<Option<Owner>> = const { Cell::new(None) };
}

/// This thread's slot, taken on its first call: a free one or a new one
/// (leaked: slots live as long as the process).
#[cold]
#[inline(never)]
fn register() -> &'static Published {
    let mut all = slots();
    let free = all.iter().copied().find(|s| {
        s.owned
            .compare_exchange(false, true, Ordering::AcqRel, Ordering::Relaxed)
            .is_ok()
    });
    let slot = free.unwrap_or_else(|| {
        let slot: &'static Published = Box::leak(Box::default());
        slot.owned.store(true, Ordering::Relaxed);
        all.push(slot);
        slot
    });
    drop(all);
    let _ = SLOT.try_with(|s| s.set(slot));
    let _ = OWNER.try_with(|o| o.set(Some(Owner(slot))));
    slot
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
    let all: Vec<&'static Published> = slots().clone();
    all.into_iter()
        .filter(|s| s.owned.load(Ordering::Acquire))
        .filter_map(Published::read)
        .map(|(call, key)| CallInProgress { call, key })
        .collect()
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
