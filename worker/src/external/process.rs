//! One running external program: a child process with JSON lines on its
//! stdin and stdout, in a process group of its own. A reader thread turns
//! stdout into lines on a bounded channel, so every wait has a deadline; a
//! watchdog thread kills the group when a request's deadline passes, so a
//! write to a program that stopped reading cannot block either; another
//! thread keeps the last lines of stderr for the failure reason. Dropping
//! the process kills the group (the program and anything it started); a
//! worker killed outright takes the program with it ([`super::spawner`]).

use super::halt::{kill_group, Halt};
use super::protocol::{Reply, Request, MAX_LINE};
use super::spawner;
use std::collections::{BTreeMap, VecDeque};
use std::fmt;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::process::CommandExt;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, TryRecvError};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use tslg_method::external::{ExternalMode, OLDEST_PROTOCOL_VERSION, PROTOCOL_VERSION};

/// Lines of stderr kept for a failure's reason.
const STDERR_LINES: usize = 8;
/// How long an exited program's status is waited for.
const REAP: Duration = Duration::from_millis(500);

/// Why a program gave no valid answer.
#[derive(Debug, Clone, PartialEq)]
pub enum Fault {
    /// It could not be started.
    Spawn(String),
    /// It exited (a crash, or an early exit) or closed its stdout.
    Exited {
        /// The exit status as the system describes it.
        status: String,
        /// The end of what it wrote to stderr.
        stderr: String,
    },
    /// No answer before the per-test deadline; it was killed.
    Timeout {
        /// The per-test deadline (s).
        seconds: f64,
    },
    /// A line that is not the message the protocol expects here.
    Garbage {
        /// What was wrong with the line.
        detail: String,
    },
    /// It answered `{"type": "error"}`: it cannot run this test, but the
    /// conversation is intact.
    Refused(String),
}

impl Fault {
    /// Whether the process must be replaced: its state is unknown.
    pub fn is_broken(&self) -> bool {
        !matches!(self, Fault::Refused(_))
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Fault::Spawn(e) => write!(f, "could not be started: {e}"),
            Fault::Exited { status, stderr } if stderr.is_empty() => write!(f, "exited ({status})"),
            Fault::Exited { status, stderr } => write!(f, "exited ({status}); stderr: {stderr}"),
            Fault::Timeout { seconds } => write!(
                f,
                "gave no answer within the per-test timeout of {seconds} s and was killed"
            ),
            Fault::Garbage { detail } => write!(f, "broke the protocol: {detail}"),
            Fault::Refused(message) => write!(f, "reported an error: {message}"),
        }
    }
}

/// What a program said in its handshake.
#[derive(Debug, Clone, PartialEq)]
pub struct Capabilities {
    /// The name it gave itself, if any.
    pub name: Option<String>,
    /// The cases it drives and in which modes (step, episode).
    pub cases: BTreeMap<String, Vec<ExternalMode>>,
    /// Whether two runs of one test give the same outcome (its `hello`
    /// says `"deterministic": false` if not).
    pub deterministic: bool,
}

enum Line {
    Text(String),
    TooLong,
    Closed,
}

/// Lines a program may print ahead of the worker reading them.
const PENDING_LINES: usize = 16;

/// Kills a process group when an armed deadline passes.
#[derive(Default)]
struct Watchdog {
    state: Mutex<WatchState>,
    wake: Condvar,
}

#[derive(Default)]
struct WatchState {
    /// The armed deadline.
    deadline: Option<Instant>,
    /// Whether the watchdog killed the program since it was last armed, so
    /// a closed pipe is reported as the timeout it is, not as an exit.
    fired: bool,
    /// Whether the process is gone and the watchdog can stop.
    finished: bool,
}

impl Watchdog {
    fn arm(&self, deadline: Option<Instant>) {
        let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        state.deadline = deadline;
        state.fired = false;
        self.wake.notify_one();
    }

    fn finish(&self) {
        self.state
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .finished = true;
        self.wake.notify_one();
    }

    /// Whether the program was killed at the deadline (or the deadline has
    /// passed, so it is about to be).
    fn timed_out(&self) -> bool {
        let state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        state.fired || state.deadline.is_some_and(|d| Instant::now() >= d)
    }

    fn watch(&self, group: i32) {
        let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            if state.finished {
                return;
            }
            state = match state.deadline {
                None => self.wake.wait(state).unwrap_or_else(|p| p.into_inner()),
                Some(deadline) if Instant::now() >= deadline => {
                    kill_group(group);
                    state.deadline = None;
                    state.fired = true;
                    state
                }
                Some(deadline) => {
                    let wait = deadline.saturating_duration_since(Instant::now());
                    self.wake
                        .wait_timeout(state, wait)
                        .unwrap_or_else(|p| p.into_inner())
                        .0
                }
            };
        }
    }
}

/// One running process of a program, with its pipes.
pub struct ProgramProcess {
    /// The per-test time limit, for the reason of a timeout.
    timeout: Duration,
    child: Child,
    group: i32,
    stdin: ChildStdin,
    lines: Receiver<Line>,
    /// A line taken from `lines` before its turn, read first: where a test
    /// waits for a line to have arrived (`wait_for_line`) without
    /// consuming it.
    early: Option<Line>,
    stderr: Arc<Mutex<VecDeque<String>>>,
    watchdog: Arc<Watchdog>,
}

impl ProgramProcess {
    /// Starts `command` (program and arguments) and does the handshake
    /// by `deadline`; `timeout` is the per-test limit the reason of a
    /// timeout names. With `halt`, the process counts as running from its
    /// start, so a shutdown past its grace kills it in its handshake too.
    pub fn start(
        command: &[String],
        dir: Option<&std::path::Path>,
        worker: &str,
        timeout: Duration,
        deadline: Instant,
        halt: Option<&Halt>,
    ) -> Result<(Self, Capabilities), Fault> {
        let (program, args) = command
            .split_first()
            .ok_or_else(|| Fault::Spawn("empty command".into()))?;
        let mut command = Command::new(program);
        if let Some(dir) = dir {
            command.current_dir(dir);
        }
        command
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0);
        let mut child = spawner::spawn(command, deadline)
            .map_err(|e| Fault::Spawn(format!("{program}: {e}")))?;
        let group = child.id() as i32;
        let _starting = match halt.map(|h| h.running(group)) {
            Some(None) => {
                kill_group(group);
                let _ = child.kill();
                let _ = child.wait();
                return Err(Fault::Spawn(format!(
                    "{program}: not started, the worker is shutting down"
                )));
            }
            starting => starting.flatten(),
        };
        let watchdog = Arc::new(Watchdog::default());
        let watching = Arc::clone(&watchdog);
        std::thread::spawn(move || watching.watch(group));
        let stdin = child.stdin.take().expect("piped stdin");
        let stdout = child.stdout.take().expect("piped stdout");
        let stderr_pipe = child.stderr.take().expect("piped stderr");
        let (tx, lines) = mpsc::sync_channel(PENDING_LINES);
        std::thread::spawn(move || read_lines(stdout, tx));
        let stderr = Arc::new(Mutex::new(VecDeque::new()));
        let tail = Arc::clone(&stderr);
        std::thread::spawn(move || keep_tail(stderr_pipe, tail));
        let mut process = Self {
            timeout,
            child,
            group,
            stdin,
            lines,
            early: None,
            stderr,
            watchdog,
        };
        let hello = Request::Hello {
            protocol: PROTOCOL_VERSION,
            worker,
        };
        match process.call(&hello, "hello", deadline)? {
            Reply::Hello {
                protocol,
                name,
                cases,
                deterministic,
            } if (OLDEST_PROTOCOL_VERSION..=PROTOCOL_VERSION).contains(&protocol) => Ok((
                process,
                Capabilities {
                    name,
                    cases,
                    deterministic,
                },
            )),
            Reply::Hello { protocol, .. } => Err(Fault::Garbage {
                detail: format!(
                    "it speaks protocol version {protocol}; this worker speaks versions \
                     {OLDEST_PROTOCOL_VERSION} to {PROTOCOL_VERSION}"
                ),
            }),
            other => Err(unexpected("hello", &other)),
        }
    }

    /// Writes one message line.
    pub fn send(&mut self, request: &Request) -> Result<(), Fault> {
        let mut line = serde_json::to_vec(request).expect("requests serialise");
        line.push(b'\n');
        if self
            .stdin
            .write_all(&line)
            .and_then(|()| self.stdin.flush())
            .is_err()
        {
            return Err(self.gone());
        }
        Ok(())
    }

    /// Reads the next message, waiting until `deadline`. An `error` reply
    /// is [`Fault::Refused`].
    pub fn receive(&mut self, deadline: Instant) -> Result<Reply, Fault> {
        let wait = deadline.saturating_duration_since(Instant::now());
        let line = match self
            .early
            .take()
            .map_or_else(|| self.lines.recv_timeout(wait), Ok)
        {
            Ok(line) => line,
            Err(RecvTimeoutError::Timeout) => {
                self.kill();
                return Err(Fault::Timeout {
                    seconds: self.timeout.as_secs_f64(),
                });
            }
            Err(RecvTimeoutError::Disconnected) => Line::Closed,
        };
        match line {
            Line::Text(text) => match serde_json::from_str::<Reply>(&text) {
                Ok(Reply::Error { message }) => Err(Fault::Refused(clip(&message))),
                Ok(reply) => Ok(reply),
                Err(e) => Err(Fault::Garbage {
                    detail: format!("`{}` is not a protocol message ({e})", clip(&text)),
                }),
            },
            Line::TooLong => Err(Fault::Garbage {
                detail: format!("a line longer than {MAX_LINE} bytes"),
            }),
            Line::Closed => Err(self.gone()),
        }
    }

    /// The fault of a program whose pipes closed: killed by the watchdog at
    /// the deadline, or exited by itself.
    fn gone(&mut self) -> Fault {
        if !self.watchdog.timed_out() {
            return self.exited();
        }
        self.kill();
        Fault::Timeout {
            seconds: self.timeout.as_secs_f64(),
        }
    }

    /// Sends `request` and waits for a reply of kind `expected`, all by
    /// `deadline` (the watchdog kills the program then, even in a write).
    /// A line printed before the request is a breach: answers would shift.
    pub fn call(
        &mut self,
        request: &Request,
        expected: &'static str,
        deadline: Instant,
    ) -> Result<Reply, Fault> {
        self.watchdog.arm(Some(deadline));
        let reply = self.unprompted().and_then(|()| {
            self.send(request)?;
            self.receive(deadline)
        });
        self.watchdog.arm(None);
        match reply? {
            reply if reply.kind() == expected => Ok(reply),
            other => Err(unexpected(expected, &other)),
        }
    }

    /// The process group of the program and what it started.
    pub fn group(&self) -> i32 {
        self.group
    }

    /// Whether the program has printed nothing since its last reply; a
    /// process that has is not given another test.
    pub fn is_quiet(&mut self) -> bool {
        self.unprompted().is_ok()
    }

    /// Waits up to `limit` for a line to arrive, and keeps it for the next
    /// read: whether one did.
    #[cfg(test)]
    fn wait_for_line(&mut self, limit: Duration) -> bool {
        if self.early.is_none() {
            self.early = self.lines.recv_timeout(limit).ok();
        }
        self.early.is_some()
    }

    /// An error if a line is waiting that no request asked for.
    fn unprompted(&mut self) -> Result<(), Fault> {
        match self.early.take().map_or_else(|| self.lines.try_recv(), Ok) {
            Err(TryRecvError::Empty) => Ok(()),
            Ok(Line::Text(text)) => Err(Fault::Garbage {
                detail: format!("it printed `{}` without being asked", clip(&text)),
            }),
            Ok(Line::TooLong) => Err(Fault::Garbage {
                detail: format!("a line longer than {MAX_LINE} bytes"),
            }),
            Ok(Line::Closed) | Err(TryRecvError::Disconnected) => Err(self.exited()),
        }
    }

    fn kill(&mut self) {
        kill_group(self.group);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// The fault of a program whose stdout closed: its exit status (it is
    /// killed if it is still running) and the tail of its stderr.
    fn exited(&mut self) -> Fault {
        let until = Instant::now() + REAP;
        let status = loop {
            match self.child.try_wait() {
                Ok(Some(status)) => break status.to_string(),
                Ok(None) if Instant::now() < until => std::thread::sleep(Duration::from_millis(5)),
                _ => {
                    self.kill();
                    break "closed its output and was killed".to_owned();
                }
            }
        };
        // Let the stderr reader take the last lines.
        std::thread::sleep(Duration::from_millis(20));
        let stderr = self
            .stderr
            .lock()
            .map(|t| tail_text(&t))
            .unwrap_or_default();
        Fault::Exited { status, stderr }
    }
}

impl Drop for ProgramProcess {
    fn drop(&mut self) {
        self.kill();
        self.watchdog.finish();
    }
}

fn unexpected(expected: &str, got: &Reply) -> Fault {
    Fault::Garbage {
        detail: format!("expected a `{expected}` message, got `{}`", got.kind()),
    }
}

/// The first 200 characters of what a program said.
fn clip(text: &str) -> String {
    let mut clipped: String = text.chars().take(200).collect();
    if clipped.len() < text.len() {
        clipped.push('…');
    }
    clipped
}

fn tail_text(tail: &VecDeque<String>) -> String {
    tail.iter().cloned().collect::<Vec<_>>().join(" | ")
}

fn read_lines(stdout: impl Read, tx: mpsc::SyncSender<Line>) {
    let mut reader = BufReader::new(stdout);
    loop {
        let mut buffer = Vec::new();
        let line = match reader
            .by_ref()
            .take(MAX_LINE as u64 + 1)
            .read_until(b'\n', &mut buffer)
        {
            Ok(0) | Err(_) => Line::Closed,
            Ok(_) if buffer.last() != Some(&b'\n') && buffer.len() > MAX_LINE => Line::TooLong,
            Ok(_) => Line::Text(String::from_utf8_lossy(&buffer).trim_end().to_owned()),
        };
        let done = !matches!(line, Line::Text(_));
        if tx.send(line).is_err() || done {
            return;
        }
    }
}

/// Drains stderr to the end (a full pipe would block the program), keeping
/// the last lines; a line is cut at [`MAX_LINE`] bytes.
fn keep_tail(stderr: impl Read, tail: Arc<Mutex<VecDeque<String>>>) {
    let mut reader = BufReader::new(stderr);
    loop {
        let mut buffer = Vec::new();
        match reader
            .by_ref()
            .take(MAX_LINE as u64)
            .read_until(b'\n', &mut buffer)
        {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        let line = String::from_utf8_lossy(&buffer).trim_end().to_owned();
        tracing::debug!(target: "tslg_worker::external::stderr", "{line}");
        if let Ok(mut tail) = tail.lock() {
            if tail.len() == STDERR_LINES {
                tail.pop_front();
            }
            tail.push_back(clip(&line));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn python(code: &str) -> Vec<String> {
        vec!["python3".into(), "-c".into(), code.into()]
    }

    /// Answers the worker's `hello` request (read first, so that no later
    /// reply of the test program answers it).
    const HELLO: &str = r#"import json, os, sys, time
sys.stdin.readline()
print(json.dumps({"type": "hello", "protocol": 1, "name": str(os.getpid()), "cases": {}}), flush=True)
"#;

    fn start(command: &[String]) -> (ProgramProcess, Capabilities) {
        let timeout = Duration::from_secs(10);
        ProgramProcess::start(
            command,
            None,
            "test",
            timeout,
            Instant::now() + timeout,
            None,
        )
        .unwrap()
    }

    /// Whether process `pid` is gone (or a zombie nobody has reaped yet).
    fn dead(pid: &str) -> bool {
        std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .map_or(true, |stat| stat.split_whitespace().nth(2) == Some("Z"))
    }

    #[test]
    fn a_second_reply_is_a_breach_not_the_next_answer() {
        let code = format!(
            "{HELLO}for line in sys.stdin:\n    print(json.dumps({{\"type\": \"ready\"}}))\n    \
             print(json.dumps({{\"type\": \"ready\"}}), flush=True)\n"
        );
        let world = serde_json::json!({});
        let test = tslg_method::external::TestStart {
            case: "cut-in",
            mode: ExternalMode::Step,
            index: 0,
            noise_seed: 0,
            world: &world,
        };
        let reset = Request::Reset {
            campaign: 1,
            start: &test,
        };
        let deadline = Instant::now() + Duration::from_secs(10);
        // Between tests the extra line marks the process as not reusable.
        let (mut p, _) = start(&python(&code));
        assert!(p.call(&reset, "ready", deadline).is_ok());
        // The extra line has arrived (a wait on it, not a sleep that a
        // loaded host could outlast).
        assert!(p.wait_for_line(Duration::from_secs(10)), "the extra line");
        assert!(!p.is_quiet(), "the extra line is noticed between tests");
        // Without that check the next request fails rather than taking the
        // stale line as its answer.
        let (mut p, _) = start(&python(&code));
        assert!(p.call(&reset, "ready", deadline).is_ok());
        assert!(p.wait_for_line(Duration::from_secs(10)), "the extra line");
        let fault = p.call(&reset, "ready", deadline).unwrap_err();
        assert!(fault.to_string().contains("without being asked"), "{fault}");
    }

    #[test]
    fn a_closed_pipe_after_the_watchdog_fired_is_a_timeout() {
        // The watchdog disarms itself when it kills; the reader may see the
        // closed pipe only after that, and must still call it a timeout.
        let watchdog = Arc::new(Watchdog::default());
        let watching = Arc::clone(&watchdog);
        // A process group that cannot exist (beyond any pid_max).
        let thread = std::thread::spawn(move || watching.watch(i32::MAX));
        watchdog.arm(Some(Instant::now()));
        while watchdog.state.lock().unwrap().deadline.is_some() {
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(
            watchdog.timed_out(),
            "fired, then disarmed: still a timeout"
        );
        watchdog.arm(Some(Instant::now() + Duration::from_secs(3600)));
        assert!(!watchdog.timed_out(), "a new arming starts afresh");
        watchdog.finish();
        thread.join().unwrap();
    }

    #[test]
    fn a_timeout_kills_the_program_and_what_it_started() {
        // A shell that runs the program as its child: the timeout must kill
        // both, not only the shell.
        let code = format!("{HELLO}sys.stdin.readline()\ntime.sleep(3600)\n");
        let quoted = code.replace('\'', "'\\''");
        let shell = vec![
            "sh".to_owned(),
            "-c".to_owned(),
            format!("python3 -c '{quoted}'; true"),
        ];
        let (mut p, capabilities) = start(&shell);
        let pid = capabilities.name.unwrap();
        assert!(!dead(&pid));
        let deadline = Instant::now() + Duration::from_millis(300);
        let hello = Request::Hello {
            protocol: 1,
            worker: "test",
        };
        let fault = p.call(&hello, "hello", deadline).unwrap_err();
        assert!(matches!(fault, Fault::Timeout { .. }), "{fault}");
        // The kill is sent with the timeout; its delivery is waited for,
        // up to 10 s (the program would sleep an hour).
        let until = Instant::now() + Duration::from_secs(10);
        while !dead(&pid) && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(dead(&pid), "the program {pid} outlived the timeout");
    }
}
