//! One running external program: a child process with JSON lines on its
//! stdin and stdout. A reader thread turns stdout into lines on a channel,
//! so every wait has a deadline (a program that hangs is killed, not waited
//! for); another keeps the last lines of stderr for the failure reason.
//! Dropping the process kills it.

use super::protocol::{Reply, Request, MAX_LINE};
use std::collections::{BTreeMap, VecDeque};
use std::fmt;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tslg_method::external::{ExternalMode, PROTOCOL_VERSION};

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
    Exited { status: String, stderr: String },
    /// No answer before the per-test deadline; it was killed.
    Timeout { seconds: f64 },
    /// A line that is not the message the protocol expects here.
    Garbage { detail: String },
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
            Fault::Exited { status, stderr } if stderr.is_empty() => {
                write!(f, "exited ({status}) in the middle of a test")
            }
            Fault::Exited { status, stderr } => {
                write!(
                    f,
                    "exited ({status}) in the middle of a test; stderr: {stderr}"
                )
            }
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
    pub name: Option<String>,
    pub cases: BTreeMap<String, Vec<ExternalMode>>,
}

enum Line {
    Text(String),
    TooLong,
    Closed,
}

pub struct ProgramProcess {
    /// The per-test time limit, for the reason of a timeout.
    timeout: Duration,
    child: Child,
    stdin: ChildStdin,
    lines: Receiver<Line>,
    stderr: Arc<Mutex<VecDeque<String>>>,
}

impl ProgramProcess {
    /// Starts `command` (program and arguments) and does the handshake
    /// within `timeout`.
    pub fn start(
        command: &[String],
        worker: &str,
        timeout: Duration,
    ) -> Result<(Self, Capabilities), Fault> {
        let (program, args) = command
            .split_first()
            .ok_or_else(|| Fault::Spawn("empty command".into()))?;
        let mut child = Command::new(program)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| Fault::Spawn(format!("{program}: {e}")))?;
        let stdin = child.stdin.take().expect("piped stdin");
        let stdout = child.stdout.take().expect("piped stdout");
        let stderr_pipe = child.stderr.take().expect("piped stderr");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || read_lines(stdout, tx));
        let stderr = Arc::new(Mutex::new(VecDeque::new()));
        let tail = Arc::clone(&stderr);
        std::thread::spawn(move || keep_tail(stderr_pipe, tail));
        let mut process = Self {
            timeout,
            child,
            stdin,
            lines,
            stderr,
        };
        let deadline = Instant::now() + timeout;
        process.send(&Request::Hello {
            protocol: PROTOCOL_VERSION,
            worker,
        })?;
        match process.receive(deadline)? {
            Reply::Hello {
                protocol: PROTOCOL_VERSION,
                name,
                cases,
            } => Ok((process, Capabilities { name, cases })),
            Reply::Hello { protocol, .. } => Err(Fault::Garbage {
                detail: format!(
                    "it speaks protocol version {protocol}; this worker speaks {PROTOCOL_VERSION}"
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
            return Err(self.exited());
        }
        Ok(())
    }

    /// Reads the next message, waiting until `deadline`. An `error` reply
    /// is [`Fault::Refused`].
    pub fn receive(&mut self, deadline: Instant) -> Result<Reply, Fault> {
        let wait = deadline.saturating_duration_since(Instant::now());
        let line = match self.lines.recv_timeout(wait) {
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
            Line::Closed => Err(self.exited()),
        }
    }

    /// Sends `request` and waits for a reply of kind `expected`.
    pub fn call(
        &mut self,
        request: &Request,
        expected: &'static str,
        deadline: Instant,
    ) -> Result<Reply, Fault> {
        self.send(request)?;
        let reply = self.receive(deadline)?;
        if reply.kind() == expected {
            Ok(reply)
        } else {
            Err(unexpected(expected, &reply))
        }
    }

    fn kill(&mut self) {
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

fn read_lines(stdout: impl Read, tx: mpsc::Sender<Line>) {
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
