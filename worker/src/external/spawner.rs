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
//! worker kills on a timeout and when it lets the program go, but the
//! kernel signals only the program itself when the worker is killed; the
//! program's stdin closes then, which a program that starts others can
//! take as the sign to end them (docs/vut-protocol.md, "End").

use std::io;
use std::process::{Child, Command};
use std::sync::mpsc::{self, Sender, SyncSender};
use std::sync::OnceLock;

/// A command to start, and where its child goes.
type Job = (Command, SyncSender<io::Result<Child>>);

/// Starts `command` from the worker's spawner thread, tied to the worker's
/// life on Linux (module doc).
pub fn spawn(mut command: Command) -> io::Result<Child> {
    tie_to_worker(&mut command);
    static SPAWNER: OnceLock<Sender<Job>> = OnceLock::new();
    let spawner = SPAWNER.get_or_init(|| {
        let (jobs, waiting) = mpsc::channel::<Job>();
        std::thread::Builder::new()
            .name("tslg-program-spawner".into())
            .spawn(move || {
                // Never ends: the sender lives in a static.
                for (mut command, child) in waiting {
                    let _ = child.send(command.spawn());
                }
            })
            .expect("the spawner thread starts");
        jobs
    });
    let gone = || io::Error::other("the worker's spawner thread has ended");
    let (child, started) = mpsc::sync_channel(1);
    spawner.send((command, child)).map_err(|_| gone())?;
    started.recv().map_err(|_| gone())?
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
    use std::time::{Duration, Instant};

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
            spawn(sleep).unwrap()
        })
        .join()
        .unwrap();
        assert!(alive_after(&mut child, 0.5), "{:?}", child.try_wait());
        child.kill().unwrap();
        child.wait().unwrap();
    }

    /// A command that cannot start is an error, and the spawner serves the
    /// next one.
    #[test]
    fn a_command_that_cannot_start_is_an_error_and_the_next_starts() {
        let missing = spawn(Command::new("/nonexistent/tslg-program")).unwrap_err();
        assert_eq!(missing.kind(), io::ErrorKind::NotFound);
        let status = spawn(Command::new("true")).unwrap().wait().unwrap();
        assert!(status.success());
    }
}
