//! External vehicles under test: programs the worker starts
//! (`--vut-exec NAME=COMMAND`) and drives over the JSON-lines protocol of
//! `docs/vut-protocol.md`.
//!
//! Each program keeps a pool of running processes, one per simulation
//! thread at most. A test takes a process, sends `reset`, runs (step or
//! episode mode) within the per-test deadline and gives the process back. A
//! process that crashes, hangs, prints garbage or exits is killed and
//! replaced, and the test is tried once more; a test that fails twice is
//! `invalid` with the reason. After `max_failures` failed tests in a row
//! the program is *unhealthy*: the worker stops offering it (and says so in
//! its lease requests) instead of burning the campaign, rests it for
//! `cooldown`, and offers it again once a fresh process answers the
//! handshake.

mod halt;
mod process;
mod protocol;
mod spawner;

pub use process::{Capabilities, Fault, ProgramProcess};

use protocol::{Reply, Request};
use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::str::FromStr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tslg_api::UnhealthyProgram;
use tslg_method::external::{
    check_program_name, requirement, Control, DriverError, EpisodeOutcome, ExternalVehicle,
    Observation, TestStart,
};
use tslg_method::registry::{CampaignTests, TestOutcome};

/// Times a test is tried with a fresh or intact process before it is
/// reported `invalid`.
pub const TRIES: usize = 2;

/// Longest reason of an invalid test (the coordinator takes 2000 bytes).
const MAX_REASON: usize = 1800;

/// `NAME=COMMAND`: COMMAND is split into words as a POSIX shell would
/// (quotes and backslashes, no expansion) and run directly.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProgramSpec {
    /// The name campaigns use for the program (`{"external": NAME}`).
    pub name: String,
    /// The command and its arguments, run without a shell.
    pub command: Vec<String>,
    /// The folder it runs in (a case file's; `None`: the worker's own).
    pub dir: Option<std::path::PathBuf>,
}

impl FromStr for ProgramSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (name, command) = s
            .split_once('=')
            .ok_or_else(|| format!("--vut-exec `{s}` must be NAME=COMMAND"))?;
        check_program_name(name)?;
        let command = shlex::split(command)
            .ok_or_else(|| format!("--vut-exec {name}: unbalanced quotes in `{command}`"))?;
        if command.is_empty() {
            return Err(format!("--vut-exec {name}: the command is empty"));
        }
        Ok(Self {
            name: name.to_owned(),
            command,
            dir: None,
        })
    }
}

/// How programs are run and judged.
#[derive(Debug, Clone)]
pub struct ProgramSettings {
    /// The worker's name, sent in the handshake.
    pub worker: String,
    /// Per-test time limit (also for the handshake).
    pub timeout: Duration,
    /// Failed tests in a row that make a program unhealthy.
    pub max_failures: u32,
    /// Rest of an unhealthy program before it is tried again.
    pub cooldown: Duration,
}

/// One test driven through a program: its outcome and criticality.
type TestRun<'a> =
    dyn Fn(&mut dyn ExternalVehicle) -> Result<(TestOutcome, Option<f64>), DriverError> + 'a;

/// What running one test with a program gave.
#[derive(Debug, Clone, PartialEq)]
pub enum ProgramRun {
    /// The program ran the test; its outcome, and its criticality when
    /// known (adaptive campaigns, [`Program::run_cell`]).
    Done(TestOutcome, Option<f64>),
    /// No valid outcome; the reason.
    Invalid(String),
    /// Not run: the program is unhealthy.
    Skipped,
}

#[derive(Debug, Default)]
struct Health {
    /// Failed tests in a row.
    failures: u32,
    unhealthy: Option<(Instant, String)>,
}

/// One `--vut-exec` program.
pub struct Program {
    spec: ProgramSpec,
    settings: ProgramSettings,
    capabilities: Capabilities,
    idle: Mutex<Vec<ProgramProcess>>,
    health: Mutex<Health>,
    halt: halt::Halt,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Program {
    /// Starts the program once: its handshake tells what it offers. A
    /// program that cannot start is a configuration error.
    pub fn start(spec: ProgramSpec, settings: ProgramSettings) -> Result<Self, String> {
        let deadline = Instant::now() + settings.timeout;
        let (process, capabilities) = ProgramProcess::start(
            &spec.command,
            spec.dir.as_deref(),
            &settings.worker,
            settings.timeout,
            deadline,
            None,
        )
        .map_err(|f| format!("--vut-exec {}: the program {f}", spec.name))?;
        // A case the program names that this worker does not know may be a
        // user-defined case, which the coordinator's plans bring.
        for case in capabilities.cases.keys() {
            if tslg_method::cases::descriptor(case).is_err() {
                tracing::info!(program = %spec.name, case, "the program offers a case not built in");
            }
        }
        tracing::info!(program = %spec.name, cases = ?capabilities.cases, "external program ready");
        Ok(Self {
            spec,
            settings,
            capabilities,
            idle: Mutex::new(vec![process]),
            health: Mutex::new(Health::default()),
            halt: halt::Halt::default(),
        })
    }

    /// The program's name.
    pub fn name(&self) -> &str {
        &self.spec.name
    }

    /// What the program said it can drive, in its handshake.
    pub fn capabilities(&self) -> &Capabilities {
        &self.capabilities
    }

    /// `NAME:case:mode` for every known case and mode of the handshake;
    /// nothing while unhealthy.
    pub fn offers(&self) -> Vec<String> {
        if lock(&self.health).unhealthy.is_some() {
            return Vec::new();
        }
        self.capabilities
            .cases
            .iter()
            .flat_map(|(case, modes)| modes.iter().map(|m| requirement(self.name(), case, *m)))
            .collect()
    }

    /// [`Program::offers`] if its runs of one test may differ, else nothing.
    pub fn noisy_offers(&self) -> Vec<String> {
        if self.capabilities.deterministic {
            return Vec::new();
        }
        self.offers()
    }

    /// Why the program is resting, while it is.
    pub fn unhealthy(&self) -> Option<UnhealthyProgram> {
        let health = lock(&self.health);
        health
            .unhealthy
            .as_ref()
            .map(|(_, reason)| UnhealthyProgram {
                name: self.spec.name.clone(),
                reason: reason.clone(),
                failures: health.failures,
            })
    }

    /// Whether the program is unhealthy and has rested long enough to be
    /// tried again.
    pub fn rested(&self) -> bool {
        lock(&self.health)
            .unhealthy
            .as_ref()
            .is_some_and(|(since, _)| since.elapsed() >= self.settings.cooldown)
    }

    /// Tries a rested program: healthy again when a fresh process answers
    /// the handshake, else it rests once more. Blocking.
    pub fn probe(&self) {
        if !self.rested() {
            return;
        }
        match self.spawn(Instant::now() + self.settings.timeout) {
            Ok(process) => {
                *lock(&self.health) = Health::default();
                lock(&self.idle).push(process);
                tracing::info!(program = %self.spec.name, "external program healthy again");
            }
            Err(fault) => {
                let reason = clip_reason(format!("the program {fault}"));
                tracing::warn!(program = %self.spec.name, %reason, "external program still unhealthy");
                let mut health = lock(&self.health);
                health.unhealthy = Some((Instant::now(), reason));
            }
        }
    }

    /// A new process, its handshake done by `deadline`.
    fn spawn(&self, deadline: Instant) -> Result<ProgramProcess, Fault> {
        ProgramProcess::start(
            &self.spec.command,
            self.spec.dir.as_deref(),
            &self.settings.worker,
            self.settings.timeout,
            deadline,
            Some(&self.halt),
        )
        .map(|(process, _)| process)
    }

    /// An idle process that printed nothing since its last test (one that
    /// did is dropped: its answers would shift), or a new one.
    fn checkout(&self, deadline: Instant) -> Result<ProgramProcess, Fault> {
        loop {
            let Some(mut process) = lock(&self.idle).pop() else {
                return self.spawn(deadline);
            };
            if process.is_quiet() {
                return Ok(process);
            }
            tracing::warn!(program = %self.spec.name, "dropped a process that printed between tests");
        }
    }

    /// Stops running tests: what is asked for now is skipped (shutdown);
    /// the tests running finish.
    pub fn stop(&self) {
        self.halt.stop();
    }

    /// Cuts off the tests running (the shutdown's grace is over): their
    /// processes are killed and the tests end [`ProgramRun::Skipped`].
    pub fn abort(&self) {
        self.halt.abort();
    }

    /// Whether the worker is shutting down (no test starts any more).
    pub fn is_stopped(&self) -> bool {
        self.halt.stopped()
    }

    /// Ends the processes waiting for a test (the worker exits): each is
    /// killed with its process group, helpers it started included.
    pub fn shutdown(&self) {
        self.halt.stop();
        lock(&self.idle).clear();
    }

    /// Runs test `index` of `tests` (campaign `campaign`) with this
    /// program: a process from the pool, or a new one.
    pub fn run_test(&self, tests: &dyn CampaignTests, campaign: i64, index: u64) -> ProgramRun {
        self.run(campaign, &|vut| {
            tests
                .run_with(index, Some(vut))
                .map(|outcome| (outcome, None))
        })
    }

    /// Runs test `index` of `tests` on the scenario `cell` its lease names,
    /// with `weight` from the lease (adaptive campaigns).
    pub fn run_cell(
        &self,
        tests: &dyn CampaignTests,
        campaign: i64,
        index: u64,
        cell: usize,
        weight: f64,
    ) -> ProgramRun {
        self.run(campaign, &|vut| {
            tests
                .run_cell(index, cell, Some(vut))
                .map(|(event, criticality)| (TestOutcome { event, weight }, criticality))
        })
    }

    /// Runs one test with `test` on a process from the pool (or a new
    /// one), retrying once; failures count toward the program's health.
    fn run(&self, campaign: i64, test: &TestRun<'_>) -> ProgramRun {
        if self.halt.stopped() || lock(&self.health).unhealthy.is_some() {
            return ProgramRun::Skipped;
        }
        let mut last = String::new();
        for _ in 0..TRIES {
            if self.halt.stopped() && !last.is_empty() {
                // The first try failed while the worker stops: a batch
                // system's SIGTERM reaches every process of the job, the
                // program's too. Not a fault of its own, and no test starts
                // now: given back.
                return ProgramRun::Skipped;
            }
            // The whole try, a new process's handshake included.
            let deadline = Instant::now() + self.settings.timeout;
            let mut process = match self.checkout(deadline) {
                Ok(process) => process,
                Err(_) if self.halt.stopped() => return ProgramRun::Skipped,
                Err(fault) => {
                    last = format!("the program {fault}");
                    continue;
                }
            };
            let Some(running) = self.halt.running(process.group()) else {
                return ProgramRun::Skipped;
            };
            let mut session = Session {
                process: &mut process,
                campaign,
                deadline,
                fault: None,
            };
            let result = catch_unwind(AssertUnwindSafe(|| test(&mut session)));
            let fault = session.fault.take();
            drop(running);
            if result.as_ref().is_ok_and(|r| r.is_err()) && self.halt.stopped() {
                // Failed while the worker stops (killed past the grace, or
                // by a batch system's SIGTERM to every process of the job):
                // not a fault of its own, so the test is given back and the
                // program's health is untouched.
                return ProgramRun::Skipped;
            }
            match result {
                Ok(Ok((outcome, criticality))) => {
                    lock(&self.idle).push(process);
                    let mut health = lock(&self.health);
                    if health.unhealthy.is_none() {
                        health.failures = 0;
                    }
                    return ProgramRun::Done(outcome, criticality);
                }
                Ok(Err(DriverError(reason))) => {
                    last = reason;
                    // A refusal leaves the conversation intact; anything
                    // else leaves the process in an unknown state: drop
                    // (kill) it.
                    if fault.is_some_and(|f| !f.is_broken()) {
                        lock(&self.idle).push(process);
                    }
                }
                Err(panic) => last = crate::panics::panic_message(panic.as_ref()),
            }
        }
        let reason = clip_reason(format!(
            "external program `{}`: {last} (tried {TRIES} times)",
            self.spec.name
        ));
        self.record_failure(&reason);
        ProgramRun::Invalid(reason)
    }

    fn record_failure(&self, reason: &str) {
        let mut health = lock(&self.health);
        health.failures += 1;
        if health.failures >= self.settings.max_failures && health.unhealthy.is_none() {
            tracing::error!(
                program = %self.spec.name,
                failures = health.failures,
                reason,
                "external program unhealthy: no longer offered until it has rested"
            );
            health.unhealthy = Some((Instant::now(), reason.to_owned()));
            drop(health);
            lock(&self.idle).clear();
        }
    }
}

/// `reason` cut to [`MAX_REASON`] bytes.
fn clip_reason(mut reason: String) -> String {
    if reason.len() > MAX_REASON {
        let cut = (0..=MAX_REASON)
            .rev()
            .find(|&i| reason.is_char_boundary(i))
            .unwrap_or(0);
        reason.truncate(cut);
        reason.push('…');
    }
    reason
}

/// One test's conversation with a process, within the test's deadline.
struct Session<'a> {
    process: &'a mut ProgramProcess,
    campaign: i64,
    deadline: Instant,
    /// The first fault, to decide whether the process can be reused.
    fault: Option<Fault>,
}

impl Session<'_> {
    fn call(&mut self, request: &Request, expected: &'static str) -> Result<Reply, DriverError> {
        self.process
            .call(request, expected, self.deadline)
            .map_err(|fault| {
                let error = DriverError(format!("the program {fault}"));
                self.fault.get_or_insert(fault);
                error
            })
    }
}

impl ExternalVehicle for Session<'_> {
    fn reset(&mut self, start: &TestStart) -> Result<(), DriverError> {
        let request = Request::Reset {
            campaign: self.campaign,
            start,
        };
        self.call(&request, "ready").map(|_| ())
    }

    fn step(&mut self, observation: &Observation) -> Result<Control, DriverError> {
        match self.call(&Request::Step(observation), "control")? {
            Reply::Control(control) => Ok(control),
            other => Err(DriverError(format!("unexpected `{}`", other.kind()))),
        }
    }

    fn episode(&mut self, scenario: &serde_json::Value) -> Result<EpisodeOutcome, DriverError> {
        match self.call(&Request::Episode { scenario }, "outcome")? {
            Reply::Outcome(outcome) => Ok(outcome),
            other => Err(DriverError(format!("unexpected `{}`", other.kind()))),
        }
    }
}

/// Every `--vut-exec` program of a worker, by name.
#[derive(Default)]
pub struct Programs {
    by_name: BTreeMap<String, Arc<Program>>,
}

impl Programs {
    /// Parses and starts every program (blocking: the handshakes).
    pub fn start(specs: &[String], settings: &ProgramSettings) -> Result<Self, String> {
        let specs = specs
            .iter()
            .map(|text| text.parse())
            .collect::<Result<Vec<ProgramSpec>, String>>()?;
        let mut names: Vec<&str> = specs.iter().map(|s| s.name.as_str()).collect();
        names.sort_unstable();
        if let Some(pair) = names.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("--vut-exec {}: the name is given twice", pair[0]));
        }
        Self::start_specs(specs, settings)
    }

    /// Starts the programs of `specs` (blocking: the handshakes).
    pub fn start_specs(
        specs: Vec<ProgramSpec>,
        settings: &ProgramSettings,
    ) -> Result<Self, String> {
        let mut by_name = BTreeMap::new();
        for spec in specs {
            if by_name.contains_key(&spec.name) {
                return Err(format!("program {}: the name is given twice", spec.name));
            }
            let name = spec.name.clone();
            by_name.insert(name, Arc::new(Program::start(spec, settings.clone())?));
        }
        Ok(Self { by_name })
    }

    /// The program named `name`.
    pub fn get(&self, name: &str) -> Option<&Arc<Program>> {
        self.by_name.get(name)
    }

    /// What the healthy programs offer, as the requirement strings of lease requests.
    pub fn offers(&self) -> Vec<String> {
        self.by_name.values().flat_map(|p| p.offers()).collect()
    }

    /// What the healthy programs that said their runs may differ offer.
    pub fn noisy_offers(&self) -> Vec<String> {
        self.by_name
            .values()
            .flat_map(|p| p.noisy_offers())
            .collect()
    }

    /// The programs resting, with why.
    pub fn unhealthy(&self) -> Vec<UnhealthyProgram> {
        self.by_name
            .values()
            .filter_map(|p| p.unhealthy())
            .collect()
    }

    /// Whether any program has rested long enough to be tried again.
    pub fn any_rested(&self) -> bool {
        self.by_name.values().any(|p| p.rested())
    }

    /// Stops every program's tests (shutdown): the running chunk ends with
    /// the tests begun.
    pub fn stop(&self) {
        for program in self.by_name.values() {
            program.stop();
        }
    }

    /// Ends every program's idle processes and their helpers (the worker
    /// exits; its process's exit would not drop them).
    pub fn shutdown(&self) {
        for program in self.by_name.values() {
            program.shutdown();
        }
    }

    /// Cuts off every program's running tests (the shutdown's grace is
    /// over): the running chunk ends at the first of them, and the lease
    /// gives the rest back.
    pub fn abort(&self) {
        for program in self.by_name.values() {
            program.abort();
        }
    }

    /// Tries every rested program again (blocking).
    pub fn probe_rested(&self) {
        for program in self.by_name.values() {
            program.probe();
        }
    }
}

/// The programs as a host a case runs them through in this process (the
/// command line's user-defined cases: surrogates, vehicles, exact answers),
/// with the same pooling, retries and fault reasons as a worker's tests.
impl tslg_method::external::ProgramHost for Programs {
    fn has(&self, name: &str) -> bool {
        self.by_name.contains_key(name)
    }

    fn converse(
        &self,
        name: &str,
        conversation: &tslg_method::external::ProgramConversation<'_>,
    ) -> Result<(bool, Option<f64>), String> {
        let program = self
            .get(name)
            .ok_or_else(|| format!("no program `{name}` runs here"))?;
        match program.run(0, &|vut| {
            conversation(vut)
                .map(|(event, criticality)| (TestOutcome { event, weight: 1.0 }, criticality))
        }) {
            ProgramRun::Done(outcome, criticality) => Ok((outcome.event, criticality)),
            ProgramRun::Invalid(reason) => Err(reason),
            ProgramRun::Skipped if program.is_stopped() => Err(format!(
                "the program `{name}` was stopped: the worker is shutting down"
            )),
            ProgramRun::Skipped => Err(format!(
                "the program `{name}` is resting after repeated failures: {}",
                program.unhealthy().map_or_else(String::new, |u| u.reason)
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn program_specs_parse_like_a_shell_and_reject_bad_names() {
        let spec: ProgramSpec = r#"py-idm=python3 "my vut.py" --v0 36"#.parse().unwrap();
        assert_eq!(spec.name, "py-idm");
        assert_eq!(spec.command, ["python3", "my vut.py", "--v0", "36"]);
        let err = "py-idm".parse::<ProgramSpec>().unwrap_err();
        assert!(err.contains("NAME=COMMAND"), "{err}");
        let err = "a b=python3".parse::<ProgramSpec>().unwrap_err();
        assert!(err.contains("must be 1 to 64"), "{err}");
        let err = "x=python3 'open".parse::<ProgramSpec>().unwrap_err();
        assert!(err.contains("unbalanced quotes"), "{err}");
        let err = "x=  ".parse::<ProgramSpec>().unwrap_err();
        assert!(err.contains("empty"), "{err}");
    }
}
