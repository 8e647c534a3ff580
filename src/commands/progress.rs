//! Progress in the terminal: one bar per campaign toward β, and one per
//! library build. A campaign's bar runs over the tests predicted to reach β
//! (`n (rₙ/β)²`, from the coordinator), so it fills as the relative
//! half-width falls; until that prediction exists (too few events) it runs
//! over the campaign's budget (`max_tests`), not over the tests so far,
//! which drew a full bar far from β. When stderr is not a terminal (a log,
//! a pipe) the bars are hidden: a line of each running campaign's state,
//! or of a count's progress, is printed every [`line_every`] (10 s, or
//! `TSLG_PROGRESS_EVERY` seconds) instead, and each campaign's final state
//! as one line. Why a campaign waits (no worker) is printed once as it
//! appears.

use crate::commands::remote::progress_line;
use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tslg_api::{CampaignView, LibraryView};
use tslg_method::number::Count;
use tslg_method::progress::Progress;

fn style() -> ProgressStyle {
    ProgressStyle::with_template(
        "{prefix:<9} [{bar:30.cyan/blue}] {human_pos:>11}/{human_len:<11} tests  {msg}",
    )
    .expect("a valid template")
    .progress_chars("=> ")
}

/// Before the first state is known there is nothing to draw a bar of: a
/// bar of 0 of 0 is drawn full (indicatif's fraction of an empty length
/// is 1), which read as a campaign already done.
fn waiting_style() -> ProgressStyle {
    ProgressStyle::with_template("{prefix:<9} {msg}").expect("a valid template")
}

/// What follows the bar: r against β, events, rate and time left.
fn message(view: &CampaignView) -> String {
    let r = view
        .relative_half_width
        .map_or("∞".into(), |r| format!("{r:.3}"));
    // Which interval r is read on: a Wald interval holds at the stop, an
    // anytime one (a confidence sequence) at every number of tests.
    let kind = match view.interval {
        tslg_api::IntervalKind::Wald => "",
        tslg_api::IntervalKind::Anytime => " (anytime)",
    };
    let mut text = format!(
        "r {r}{kind} → β {}  {}",
        view.beta,
        Count(view.events, "event")
    );
    if let Some(rate) = view.tests_per_second {
        text.push_str(&format!("  {rate:.0} tests/s"));
    }
    if let Some(left) = view.seconds_left {
        text.push_str(&format!("  ~{} left", duration(left)));
    }
    if view.status.is_final() {
        text.push_str(&format!("  {}", view.status.as_str()));
    }
    text
}

fn duration(seconds: f64) -> String {
    match seconds {
        s if s < 60.0 => format!("{s:.0} s"),
        s if s < 3600.0 => format!("{:.0} min", s / 60.0),
        s => format!("{:.1} h", s / 3600.0),
    }
}

/// How often a line of progress is printed when stderr is not a
/// terminal: `TSLG_PROGRESS_EVERY` seconds (a positive number), else 10 s,
/// so that a log shows a long run is alive without filling up.
pub fn line_every() -> Duration {
    std::env::var("TSLG_PROGRESS_EVERY")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .map_or(Duration::from_secs(10), Duration::from_secs_f64)
}

/// Bars for a set of campaigns, drawn together.
pub struct CampaignBars {
    bars: Vec<(String, ProgressBar)>,
    shown: bool,
    /// When each campaign's last line was printed (bars hidden).
    lines: std::cell::RefCell<Vec<Option<Instant>>>,
    every: Duration,
    /// Whether the newline after the bars was printed.
    ended: std::cell::Cell<bool>,
    _group: MultiProgress,
}

impl CampaignBars {
    pub fn new(labels: &[&str]) -> Self {
        let shown = std::io::stderr().is_terminal();
        let group = MultiProgress::with_draw_target(if shown {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        });
        let bars = labels
            .iter()
            .map(|label| {
                let bar = group.add(ProgressBar::new(0).with_style(waiting_style()));
                bar.set_prefix(label.to_string());
                bar.set_message("waiting for its first state");
                (label.to_string(), bar)
            })
            .collect();
        Self {
            lines: std::cell::RefCell::new(vec![None; labels.len()]),
            every: line_every(),
            bars,
            shown,
            ended: Default::default(),
            _group: group,
        }
    }

    /// Prints `text` above the bars, or on its own line when they are
    /// hidden.
    pub fn note(&self, k: usize, text: &str) {
        if self.shown {
            self.bars[k].1.println(text);
        } else {
            eprintln!("{text}");
        }
    }

    /// Shows campaign `k`'s state; a stopped campaign's bar is finished.
    pub fn update(&self, k: usize, view: &CampaignView) {
        let (label, bar) = &self.bars[k];
        if bar.is_finished() {
            return;
        }
        let target = view
            .predicted_tests
            .unwrap_or(view.max_tests)
            .max(view.tests)
            .max(1);
        if bar.length() == Some(0) {
            bar.set_style(style());
        }
        bar.set_length(target);
        bar.set_position(view.tests);
        bar.set_message(message(view));
        if !self.shown && !view.status.is_final() {
            let last = &mut self.lines.borrow_mut()[k];
            if last.is_none_or(|at| at.elapsed() >= self.every) {
                let mut line = progress_line(label, view);
                if let Some(rate) = view.tests_per_second {
                    line.push_str(&format!("  {rate:.0} tests/s"));
                }
                if let Some(left) = view.seconds_left {
                    line.push_str(&format!("  ~{} left", duration(left)));
                }
                eprintln!("{line}");
                *last = Some(Instant::now());
            }
        }
        if view.status.is_final() {
            bar.set_length(view.tests.max(1));
            bar.finish();
            if !self.shown {
                eprintln!("{}", progress_line(label, view));
            } else if self.bars.iter().all(|(_, b)| b.is_finished()) {
                // The bars leave the cursor at the end of their last line:
                // what is printed next starts on a line of its own.
                eprintln!();
                self.ended.set(true);
            }
        }
    }
}

impl Drop for CampaignBars {
    /// Bars left before every campaign stopped (a gate that decided early,
    /// an error) end their line too.
    fn drop(&mut self) {
        if self.shown && !self.ended.get() {
            for (_, bar) in &self.bars {
                bar.abandon();
            }
            eprintln!();
        }
    }
}

/// A spinner, then a bar, for a library build on the coordinator, with
/// the coordinator's word on what the build waits for (no worker to lease
/// its surrogate runs to) printed above it, once each time it starts to
/// wait (also when stderr is not a terminal: a silent wait looks hung).
pub struct BuildBar {
    bar: ProgressBar,
    said: std::cell::RefCell<Option<String>>,
}

impl BuildBar {
    pub fn new(id: i64) -> Self {
        let bar = counting_bar(&format!("library {id}"));
        bar.set_message("queued");
        bar.enable_steady_tick(Duration::from_millis(200));
        Self {
            bar,
            said: Default::default(),
        }
    }

    pub fn update(&self, view: &LibraryView) {
        // Only a wait is news; the counts the detail also gives are the bar's.
        let detail = view
            .status_detail
            .clone()
            .filter(|d| d.starts_with("waiting"));
        if detail.is_some() && *self.said.borrow() != detail {
            let text = format!(
                "library {}: {}",
                view.id,
                detail.as_deref().unwrap_or_default()
            );
            if self.bar.is_hidden() {
                eprintln!("{text}");
            } else {
                self.bar.println(text);
            }
        }
        *self.said.borrow_mut() = detail;
        match view.progress {
            Some(p) => {
                show_counts(
                    &self.bar,
                    "{prefix} [{bar:30.cyan/blue}] {human_pos}/{human_len} {msg} ({elapsed})",
                    p.done,
                    p.total,
                );
                self.bar.set_message(search_unit(&view.case));
            }
            None => self.bar.set_message("queued"),
        }
    }

    pub fn finish(&self, view: &LibraryView) {
        self.bar.finish_and_clear();
        if !std::io::stderr().is_terminal() {
            return;
        }
        eprintln!(
            "library {} {}: {} of {} scenarios",
            view.id,
            view.status.as_str(),
            view.size.unwrap_or(0),
            view.total_scenarios
        );
    }
}

/// What a build's progress counts (the case's descriptor says).
fn search_unit(case: &str) -> &'static str {
    tslg_method::cases::descriptor(case).map_or("searched", |d| d.build_unit)
}

/// Runs `work` with a bar on stderr that follows the [`Progress`] it
/// reports to; when stderr is not a terminal, a line `label: done of
/// total` every [`line_every`] instead.
pub fn with_progress<T>(label: &str, work: impl FnOnce(&Progress) -> T) -> T {
    let progress = Progress::default();
    let bar = counting_bar(label);
    /// Stops the drawing thread however `work` ends, a panic included
    /// (the scope would otherwise wait for that thread forever).
    struct Finish<'a>(&'a AtomicBool);
    impl Drop for Finish<'_> {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Relaxed);
        }
    }
    let finished = AtomicBool::new(false);
    let result = std::thread::scope(|scope| {
        scope.spawn(|| {
            let (every, mut said) = (line_every(), Instant::now());
            while !finished.load(Ordering::Relaxed) {
                let (done, total) = progress.get();
                if bar.is_hidden() && total > 0 && said.elapsed() >= every {
                    eprintln!("{label}: {done} of {total}");
                    said = Instant::now();
                }
                show_counts(
                    &bar,
                    "{prefix} [{bar:30.cyan/blue}] {human_pos}/{human_len} ({elapsed}, ~{eta} left)",
                    done,
                    total,
                );
                std::thread::sleep(Duration::from_millis(100));
            }
        });
        let _finish = Finish(&finished);
        work(&progress)
    });
    bar.finish_and_clear();
    result
}

/// A bar on stderr, hidden when it is not a terminal, that shows only its
/// prefix and message until [`show_counts`] gives it a length.
fn counting_bar(prefix: &str) -> ProgressBar {
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::new(0)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(waiting_style());
    bar.set_prefix(prefix.to_owned());
    bar
}

/// `done` of `total` on `bar`, drawn with `template` from the first
/// positive total on (see [`waiting_style`]).
fn show_counts(bar: &ProgressBar, template: &str, done: u64, total: u64) {
    if total == 0 {
        return;
    }
    if bar.length() == Some(0) {
        bar.set_style(
            ProgressStyle::with_template(template)
                .expect("a valid template")
                .progress_chars("=> "),
        );
    }
    bar.set_length(total);
    bar.set_position(done);
}
