//! Programs that do not outlive their worker.
//!
//! A worker that stops normally kills its programs (dropping a
//! [`super::process::ProgramProcess`] kills its process group). A worker
//! killed outright (SIGKILL, the OOM killer) cannot: its programs would run
//! on, orphaned, a program stuck in a scenario for as long as it is stuck,
//! holding its CPU, memory or simulator licence. On Linux each program is
//! therefore started with `PR_SET_PDEATHSIG = SIGKILL`, so the kernel kills
//! it when the worker dies.
//!
//! The kernel ties that signal to the *thread* that started the child, not
//! to the process (prctl(2)): it fires when that thread ends. Programs are
//! started from threads that end early (the async runtime's blocking pool
//! lets an idle thread go after 10 s) and a started process is kept for
//! later tests on other threads, so every program is started from one
//! thread that lives as long as the worker ([`spawn`]).
//!
//! What the program starts in turn is in its process group, which the
//! worker kills on a timeout and when it lets the program go; but when the
//! worker is killed the kernel signals only the program, so its helpers
//! must see to themselves (docs/vut-protocol.md, "End"). A program that
//! runs a set-user-ID binary loses the signal (the kernel clears it).

use std::io;
use std::process::{Child, Command};
use std::sync::mpsc::{self, RecvTimeoutError, SendError, Sender, SyncSender};
use std::sync::OnceLock;
use std::time::Instant;

/// A command to start, and where its child goes.
type Job = (Command, SyncSender<io::Result<Child>>);

/// Starts `command` from the worker's spawner thread, tied to the worker's
/// life on Linux (module doc), by `deadline`: starts are made one at a
/// time, and one that hangs (an `exec` from a stuck file system) must not
/// hold the others' callers past their tests' deadlines.
pub fn spawn(mut command: Command, deadline: Instant) -> io::Result<Child> {
    tie_to_worker(&mut command);
    static SPAWNER: OnceLock<Sender<Job>> = OnceLock::new();
    let spawner = SPAWNER.get_or_init(|| {
        let (jobs, waiting) = mpsc::channel::<Job>();
        std::thread::Builder::new()
            .name("tslg-program-spawner".into())
            .spawn(move || {
                // Never ends (the sender lives in a static; `spawn` returns
                // its errors), which matters: the kernel kills every program
                // when this thread ends.
                for (mut command, caller) in waiting {
                    // A caller that gave up leaves its program to nobody.
                    if let Err(SendError(Ok(mut child))) = caller.send(command.spawn()) {
                        let _ = child.kill();
                        let _ = child.wait();
                    }
                }
            })
            .expect("the spawner thread starts");
        jobs
    });
    let gone = || io::Error::other("the worker's spawner thread has ended");
    let (caller, started) = mpsc::sync_channel(1);
    spawner.send((command, caller)).map_err(|_| gone())?;
    match started.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
        Ok(child) => child,
        Err(RecvTimeoutError::Timeout) => Err(io::Error::new(
            io::ErrorKind::TimedOut,
            "not started by its deadline (the worker starts programs one at a time)",
        )),
        Err(RecvTimeoutError::Disconnected) => Err(gone()),
    }
}

/// Asks the kernel to SIGKILL the child when the thread that starts it
/// (the spawner) ends, which is when the worker ends.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn tie_to_worker(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    let worker = std::process::id() as libc::pid_t;
    // SAFETY: the closure runs in the child between fork and exec, where
    // only async-signal-safe calls are allowed: prctl(2) and getppid(2)
    // are, and the errors are built without allocating.
    unsafe {
        command.pre_exec(move || {
            let signal = libc::SIGKILL as libc::c_ulong;
            if libc::prctl(libc::PR_SET_PDEATHSIG, signal, 0, 0, 0) == -1 {
                return Err(io::Error::last_os_error());
            }
            // A worker that died before the prctl sends no signal: its
            // child must not start at all.
            if libc::getppid() != worker {
                return Err(io::Error::from_raw_os_error(libc::ESRCH));
            }
            Ok(())
        });
    }
}

/// Elsewhere the program is only killed when the worker lets it go.
#[cfg(not(target_os = "linux"))]
fn tie_to_worker(_command: &mut Command) {}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn soon() -> Instant {
        Instant::now() + Duration::from_secs(60)
    }

    /// Whether `child` is still running after `seconds`.
    fn alive_after(child: &mut Child, seconds: f64) -> bool {
        let until = Instant::now() + Duration::from_secs_f64(seconds);
        while Instant::now() < until {
            if child.try_wait().unwrap().is_some() {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        true
    }

    /// A program started from a thread that then ends runs on: the signal
    /// is tied to the spawner thread, not to the caller's (which would kill
    /// a kept program when a blocking-pool thread retires).
    #[test]
    fn a_program_outlives_the_thread_that_asked_for_it() {
        let mut child = std::thread::spawn(|| {
            let mut sleep = Command::new("sleep");
            sleep.arg("30");
            spawn(sleep, soon()).unwrap()
        })
        .join()
        .unwrap();
        assert!(alive_after(&mut child, 0.5), "{:?}", child.try_wait());
        child.kill().unwrap();
        child.wait().unwrap();
    }

    /// A start that hangs holds the spawner, but not past the others'
    /// deadlines: they get an error in time, and the spawner serves again
    /// once it is done.
    #[test]
    #[allow(unsafe_code)]
    fn a_hanging_start_does_not_hold_other_callers_past_their_deadlines() {
        use std::io::Read;
        use std::os::fd::AsRawFd;
        // The forked child says it has begun its start on this socket.
        let (mut begun, child_end) = std::os::unix::net::UnixStream::pair().unwrap();
        let fd = child_end.as_raw_fd();
        let slow = std::thread::spawn(move || {
            let mut command = Command::new("true");
            // SAFETY: write(2) and sleep(3) are async-signal-safe; the
            // sleep stands for an exec stuck in the kernel.
            unsafe {
                std::os::unix::process::CommandExt::pre_exec(&mut command, move || {
                    libc::write(fd, b"x".as_ptr().cast(), 1);
                    libc::sleep(3);
                    Ok(())
                });
            }
            spawn(command, soon()).unwrap().wait().unwrap()
        });
        // The slow start is under way: its child has forked and says so.
        begun
            .set_read_timeout(Some(Duration::from_secs(30)))
            .unwrap();
        begun.read_exact(&mut [0]).expect("the slow start began");
        let late = spawn(
            Command::new("true"),
            Instant::now() + Duration::from_millis(100),
        );
        let late = late.unwrap_err();
        assert_eq!(late.kind(), io::ErrorKind::TimedOut, "{late}");
        assert!(
            !slow.is_finished(),
            "the error came only when the hang ended"
        );
        assert!(slow.join().unwrap().success());
        drop(child_end);
        assert!(spawn(Command::new("true"), soon())
            .unwrap()
            .wait()
            .unwrap()
            .success());
    }

    /// A command that cannot start is an error, and the spawner serves the
    /// next one.
    #[test]
    fn a_command_that_cannot_start_is_an_error_and_the_next_starts() {
        let missing = spawn(Command::new("/nonexistent/tslg-program"), soon()).unwrap_err();
        assert_eq!(missing.kind(), io::ErrorKind::NotFound);
        let status = spawn(Command::new("true"), soon()).unwrap().wait().unwrap();
        assert!(status.success());
    }
}
