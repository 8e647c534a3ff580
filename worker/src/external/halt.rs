//! Stopping a program's tests on shutdown, in two steps. *Stop* (the
//! worker was asked to leave): no test starts any more, and the tests
//! running may finish within the worker's `--grace-seconds`. *Abort* (the
//! grace is over): the processes running tests are killed, and those tests
//! end as not run, so their lease gives them back to the coordinator rather
//! than reporting them `invalid` or counting them against the program's
//! health.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// A program's shutdown state, and the process groups running its tests.
#[derive(Default)]
pub struct Halt {
    stopped: AtomicBool,
    aborted: AtomicBool,
    busy: Mutex<BTreeSet<i32>>,
}

impl Halt {
    /// No test starts any more.
    pub fn stop(&self) {
        self.stopped.store(true, Ordering::SeqCst);
    }

    /// Stops, and kills every process group running a test now.
    pub fn abort(&self) {
        self.stop();
        self.aborted.store(true, Ordering::SeqCst);
        let busy = self.busy.lock().unwrap_or_else(|p| p.into_inner());
        for &group in busy.iter() {
            kill_group(group);
        }
    }

    /// Whether tests may no longer start.
    pub fn stopped(&self) -> bool {
        self.stopped.load(Ordering::SeqCst)
    }

    /// Whether the tests running were cut off: a test that failed now
    /// failed because its process was killed.
    pub fn aborted(&self) -> bool {
        self.aborted.load(Ordering::SeqCst)
    }

    /// Marks `group` as running a test (or starting: its handshake) until
    /// the guard drops; `None` when the program was aborted meanwhile (the
    /// test is not run). The group is
    /// registered before the flag is read, and [`Halt::abort`] sets the flag
    /// before it reads the groups, so a test is either seen and killed or
    /// never started.
    pub fn running(&self, group: i32) -> Option<Running<'_>> {
        self.busy
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(group);
        let guard = Running { halt: self, group };
        (!self.aborted()).then_some(guard)
    }
}

/// SIGKILL to every process of the group.
#[allow(unsafe_code)]
pub fn kill_group(group: i32) {
    // SAFETY: kill(2) with a negative pid signals a process group; it takes
    // no pointers and cannot violate memory safety.
    unsafe {
        libc::kill(-group, libc::SIGKILL);
    }
}

/// A process group marked as running a test.
pub struct Running<'a> {
    halt: &'a Halt,
    group: i32,
}

impl Drop for Running<'_> {
    fn drop(&mut self) {
        self.halt
            .busy
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&self.group);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_group_registered_after_an_abort_does_not_run_and_is_forgotten() {
        let halt = Halt::default();
        {
            let running = halt.running(12345);
            assert!(running.is_some());
            assert_eq!(halt.busy.lock().unwrap().len(), 1);
        }
        assert!(halt.busy.lock().unwrap().is_empty(), "the guard unmarks");
        assert!(!halt.stopped() && !halt.aborted());
        halt.stop();
        assert!(halt.stopped() && !halt.aborted(), "a stop kills nothing");
        // Abort with nothing running (a kill of a real group is the
        // worker's shutdown test).
        halt.abort();
        assert!(halt.aborted());
        assert!(halt.running(12345).is_none());
        assert!(halt.busy.lock().unwrap().is_empty());
    }
}
