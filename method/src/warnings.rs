//! What a campaign's interval cannot show on its own, in words, and only on
//! evidence (issue 21).
//!
//! A library campaign's interval assumes that the library covers where the
//! vehicle under test fails; its ε share of exploring tests is the only
//! check of that assumption. Two findings are worth a reader's attention:
//!
//! - **a surrogate mismatch**: an exploring test with the event (and a
//!   positive weight) in a scenario where the library's surrogate has none.
//!   That is direct evidence that the library misses part of this vehicle's
//!   failures;
//! - **an outside bound wider than accepted**: with the guard on, the
//!   campaign stopped (at `max_tests`) while the upper bound `U` on the
//!   failure mass outside the library still exceeds `β μ̂` beyond what the
//!   outside tests already carry; without the guard, the same shortfall
//!   when exploring tests did find events there (in scenarios where the
//!   surrogate fails too; a mismatch says it already).
//!
//! - **a noisy vehicle without the guard**: a scenario that passed in one
//!   run may fail in another, so no number of runs shows that the library
//!   or the support holds every scenario where it fails; the plain interval
//!   assumes it (it covered 0.30 to 0.44 of the time on a noisy Gipps
//!   program), and the campaign answers with the guarded interval
//!   ([`crate::campaign::answer`]), which is wide unless the guard ran.
//!
//! A plain campaign whose exploring tests found nothing gets no warning: its
//! outside bound is wide by construction (few tests sample there), and a
//! warning on every campaign would tell a user nothing. What each answer
//! assumes is stated with the answer instead (`docs/statistics.md`).
//!
//! The advice names the switches of whoever reads it: the API's fields or
//! the command line's flags ([`Dialect`]).

use crate::campaign::CampaignResult;
use crate::estimator::Decision;
use crate::number::Count;

/// Whose names the advice uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dialect {
    /// JSON fields of `POST /api/v1/campaigns`.
    Api,
    /// Flags of `tslg evaluate` and `tslg campaign start`, bare (a
    /// terminal shows Markdown's backticks as they are).
    Cli,
}

impl Dialect {
    /// How to turn the outside guard on, in this dialect.
    pub fn guard_advice(self) -> &'static str {
        match self {
            Dialect::Api => "`\"guard_outside\": true, \"outside\": \"ndd\"`",
            Dialect::Cli => "--guard-outside --outside ndd",
        }
    }

    /// How to spread the exploring tests by exposure, in this dialect.
    pub fn ndd_advice(self) -> &'static str {
        match self {
            Dialect::Api => "`\"outside\": \"ndd\"`",
            Dialect::Cli => "--outside ndd",
        }
    }

    /// The name of the test budget, in this dialect.
    pub fn max_tests(self) -> &'static str {
        match self {
            Dialect::Api => "`max_tests`",
            Dialect::Cli => "--max-tests",
        }
    }

    /// `text` (written in the API's dialect, as the coordinator's views
    /// are) with the advice in this dialect.
    pub fn translate(self, text: &str) -> String {
        text.replace(Dialect::Api.guard_advice(), self.guard_advice())
            .replace(Dialect::Api.max_tests(), self.max_tests())
            .replace(Dialect::Api.ndd_advice(), self.ndd_advice())
    }
}

/// The campaign settings the warnings depend on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarningContext {
    /// The campaign's target relative half-width β.
    pub beta: f64,
    /// Whether the campaign stops only under the outside guard.
    pub guard_outside: bool,
    /// Whose names the advice uses.
    pub dialect: Dialect,
    /// A library campaign with ε = 0: no test explores outside the
    /// library.
    pub unexplored: bool,
    /// Its exploring tests are spread uniformly over the outside cells
    /// (`outside: uniform`), not by exposure.
    pub uniform_spread: bool,
    /// An adaptive campaign: its exploring tests sample off its support K,
    /// which its warnings name instead of the library.
    pub adaptive: bool,
    /// The vehicle is noisy (a built-in one with noise, or a program's
    /// campaign with `vehicle_noise`): its scenarios fail only sometimes.
    pub noisy: bool,
}

/// The warnings `result` deserves under `context`: empty unless the tests
/// gave evidence (see the module documentation).
pub fn warnings(result: &CampaignResult, context: WarningContext) -> Vec<String> {
    let mut found = Vec::new();
    let advice = context.dialect.guard_advice();
    let region = if context.adaptive {
        "its support K"
    } else {
        "the library"
    };
    if context.unexplored {
        // Not evidence of a miss, but the absence of any check: the only
        // campaign whose interval can be exact and wrong (a vehicle that
        // fails on every library scenario gives every test the same
        // weight, a zero-width interval at P(library)).
        found.push(format!(
            "no test explores outside the library (ε = 0): nothing checks that the library \
             holds every failure of this vehicle, and the interval is right only if it does; \
             the estimate counts only failures inside the library. Use ε > 0 (0.1 by default) \
             with {advice} to bound what the library leaves out"
        ));
    }
    if result.mismatched_events > 0 {
        let remedy = if context.guard_outside {
            "The guard keeps the campaign testing until the outside bound is within β; a \
             library built with a surrogate closer to this vehicle would need fewer tests"
                .to_owned()
        } else {
            format!(
                "Rerun with {advice} to test until the outside bound is within β, or build the \
                 library with a surrogate closer to this vehicle"
            )
        };
        found.push(format!(
            "surrogate mismatch: the vehicle failed in {} whose scenario the \
             library's surrogate passes ({} outside the library in all, {:.0}% of the \
             estimate): the library does not cover where this vehicle fails, and the interval \
             rests on its exploring tests ({} of {}){bound}. {remedy}",
            Count(result.mismatched_events, "exploring test"),
            Count(result.outside_events, "event"),
            100.0 * result.outside_share.unwrap_or(0.0),
            result.outside_tests,
            result.tests,
            bound = match result.guarded_ci_high {
                Some(high) => format!(" (the guarded upper end is {high:.3e})"),
                None => String::new(),
            }
        ));
    }
    if context.noisy && !context.guard_outside {
        found.push(format!(
            "the vehicle is noisy: a scenario that passed in one run may fail in another, so \
             no number of runs shows that {region} holds every scenario where it fails, and \
             the interval [{low:.3e}, {plain:.3e}] assumes it does{evidence}. The answer is \
             the guarded interval{guarded}; rerun with {advice} for one within β",
            low = result.ci_low,
            plain = result.ci_high,
            evidence = if result.outside_events > 0 {
                format!(
                    "; its exploring tests found {} outside it",
                    Count(result.outside_events, "event")
                )
            } else {
                String::new()
            },
            guarded = match result.guarded_ci_high {
                Some(high) => format!(" [{:.3e}, {high:.3e}]", result.ci_low),
                None => String::new(),
            },
        ));
    }
    if let (Some(upper), Some(high)) = (result.outside_upper, result.guarded_ci_high) {
        let unseen = high - result.ci_high;
        let short = unseen > context.beta * result.estimate;
        if context.guard_outside && short && result.status == Decision::Exhausted {
            let remedy = if context.uniform_spread && result.outside_events > 0 {
                // U = F(p_U) with F the exposure of the most exposed share
                // p of the outside cells: p_U tends to the share of
                // failing cells, not to 0, so U does not fall below F(p̂).
                format!(
                    "Under the uniform outside spread the bound lets every failure found lie in \
                     the most exposed outside cells: with {:.2}% of the exploring tests failing \
                     it stays near {upper:.3e} however many tests run. Use {}, the guard's \
                     default, whose bound falls as 1/(exploring tests)",
                    100.0 * result.outside_events as f64 / result.outside_tests.max(1) as f64,
                    context.dialect.ndd_advice()
                )
            } else {
                format!(
                    "Raise {}{}",
                    context.dialect.max_tests(),
                    if context.adaptive {
                        ""
                    } else {
                        ", or use a library that covers this vehicle's failures"
                    }
                )
            };
            found.push(format!(
                "the outside bound never came within β × the estimate: up to {upper:.3e} of \
                 failure mass may lie outside {region} ({} exploring tests, {}); the \
                 guarded upper end is {high:.3e}. {remedy}",
                result.outside_tests,
                Count(result.outside_events, "event"),
            ));
        }
        let converged = result.relative_half_width <= context.beta;
        // A mismatch already says this, with its advice, and so does a
        // noisy vehicle's warning.
        let unexplained =
            result.outside_events > 0 && result.mismatched_events == 0 && !context.noisy;
        if !context.guard_outside && short && converged && unexplained {
            found.push(format!(
                "the interval does not bound what {region} leaves out: its exploring tests \
                 found {} outside it, and up to {upper:.3e} of failure mass may lie there \
                 ({} exploring tests), more than β × the estimate; the guarded upper end is \
                 {high:.3e}. Rerun with {advice} to test until it is bounded",
                Count(result.outside_events, "event"),
                result.outside_tests
            ));
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A converged library campaign: μ̂ = 1e-3 ± 1.5e-4 from 2,000 tests,
    /// 200 of them exploring without an event, and a wide outside bound
    /// (U = 0.01): the state of every plain campaign of a matched pair.
    fn matched() -> CampaignResult {
        CampaignResult {
            status: Decision::Converged,
            tests: 2000,
            events: 1800,
            invalid: 0,
            indices: 2000,
            estimate: 1e-3,
            half_width: 1.5e-4,
            relative_half_width: 0.15,
            ci_low: 8.5e-4,
            ci_high: 1.15e-3,
            effective_events: 1700.0,
            largest_weight_share: Some(0.01),
            outside_tests: 200,
            outside_events: 0,
            mismatched_events: 0,
            outside_share: Some(0.0),
            outside_upper: Some(0.01),
            guarded_ci_high: Some(1.115e-2),
            interval: Default::default(),
        }
    }

    fn context(guard_outside: bool, dialect: Dialect) -> WarningContext {
        WarningContext {
            beta: 0.2,
            guard_outside,
            dialect,
            unexplored: false,
            uniform_spread: false,
            adaptive: false,
            noisy: false,
        }
    }

    /// A library campaign that never explores is warned whatever it found:
    /// nothing tested its assumption. Here every test had the same weight
    /// (a zero-width interval at the library's probability).
    #[test]
    fn a_campaign_that_never_explores_is_warned() {
        let blind = CampaignResult {
            half_width: 0.0,
            relative_half_width: 0.0,
            ci_low: 1e-3,
            ci_high: 1e-3,
            outside_tests: 0,
            outside_share: None,
            outside_upper: None,
            guarded_ci_high: None,
            ..matched()
        };
        let unexplored = WarningContext {
            unexplored: true,
            ..context(false, Dialect::Cli)
        };
        let found = warnings(&blind, unexplored);
        assert_eq!(found.len(), 1, "{found:?}");
        assert!(
            found[0].starts_with("no test explores outside the library (ε = 0)")
                && found[0].contains("--guard-outside --outside ndd"),
            "{}",
            found[0]
        );
        assert!(warnings(&blind, context(false, Dialect::Cli)).is_empty());
    }

    #[test]
    fn no_evidence_no_warning() {
        // The outside bound is ten times the estimate, but no exploring
        // test found anything: nothing to say.
        assert!(warnings(&matched(), context(false, Dialect::Api)).is_empty());
        assert!(warnings(&matched(), context(false, Dialect::Cli)).is_empty());
    }

    #[test]
    fn a_mismatch_warns_once_and_advises_in_the_readers_names() {
        let result = CampaignResult {
            outside_events: 3,
            mismatched_events: 2,
            outside_share: Some(0.6),
            ..matched()
        };
        let cli = warnings(&result, context(false, Dialect::Cli));
        assert_eq!(cli.len(), 1, "{cli:?}");
        assert!(
            cli[0].starts_with("surrogate mismatch: the vehicle failed in 2 exploring tests whose")
        );
        assert!(
            cli[0].contains("--guard-outside --outside ndd"),
            "{}",
            cli[0]
        );
        assert!(!cli[0].contains("guard_outside"), "{}", cli[0]);
        let api = warnings(&result, context(false, Dialect::Api));
        assert!(api[0].contains(r#""guard_outside": true"#), "{}", api[0]);
        // The coordinator's text, shown by the command line, names flags.
        assert_eq!(Dialect::Cli.translate(&api[0]), cli[0]);
        // A guarded campaign is not told to turn the guard on.
        let guarded = warnings(&result, context(true, Dialect::Cli));
        assert_eq!(guarded.len(), 1);
        assert!(!guarded[0].contains("--guard-outside"), "{}", guarded[0]);
    }

    #[test]
    fn the_outside_bound_warns_when_the_guard_ran_out_of_tests() {
        let converged = warnings(&matched(), context(true, Dialect::Cli));
        assert!(converged.is_empty(), "{converged:?}");
        let exhausted = CampaignResult {
            status: Decision::Exhausted,
            ..matched()
        };
        let found = warnings(&exhausted, context(true, Dialect::Cli));
        assert_eq!(found.len(), 1);
        assert!(found[0].contains("never came within β"), "{}", found[0]);
        assert!(
            found[0].contains("raise --max-tests") || found[0].contains("Raise --max-tests"),
            "{}",
            found[0]
        );
        assert!(
            !found[0].contains('`'),
            "the command line's words, bare: {}",
            found[0]
        );
        // Within the bound: nothing, exhausted or not.
        let bounded = CampaignResult {
            guarded_ci_high: Some(1.3e-3),
            ..exhausted
        };
        assert!(warnings(&bounded, context(true, Dialect::Cli)).is_empty());
        // Under the uniform spread, with failures found outside, more tests
        // do not help: the remedy is the spread, in the reader's names.
        let uniform = CampaignResult {
            outside_events: 18,
            ..exhausted
        };
        for (dialect, advice) in [
            (Dialect::Cli, "Use --outside ndd, the guard's default"),
            (Dialect::Api, "`\"outside\": \"ndd\"`"),
        ] {
            let spread = WarningContext {
                uniform_spread: true,
                ..context(true, dialect)
            };
            let found = warnings(&uniform, spread);
            assert_eq!(found.len(), 1, "{found:?}");
            assert!(
                found[0].contains("with 9.00% of the exploring tests failing")
                    && found[0].contains(advice)
                    && !found[0].contains("max-tests")
                    && !found[0].contains("max_tests"),
                "{}",
                found[0]
            );
            if dialect == Dialect::Api {
                let cli = warnings(
                    &uniform,
                    WarningContext {
                        dialect: Dialect::Cli,
                        ..spread
                    },
                );
                assert_eq!(Dialect::Cli.translate(&found[0]), cli[0]);
            }
        }
    }

    #[test]
    fn events_outside_where_the_surrogate_fails_too_warn_a_plain_campaign() {
        let result = CampaignResult {
            outside_events: 2,
            outside_share: Some(0.1),
            ..matched()
        };
        let found = warnings(&result, context(false, Dialect::Api));
        assert_eq!(found.len(), 1);
        assert!(
            found[0].starts_with("the interval does not bound"),
            "{}",
            found[0]
        );
        assert!(warnings(&result, context(true, Dialect::Api)).is_empty());
        // An adaptive campaign's exploring tests sample off its support K:
        // the warning names it, not the library.
        let adaptive = WarningContext {
            adaptive: true,
            ..context(false, Dialect::Api)
        };
        let found = warnings(&result, adaptive);
        assert!(
            found[0].starts_with("the interval does not bound what its support K leaves out"),
            "{}",
            found[0]
        );
    }

    #[test]
    fn a_noisy_vehicle_without_the_guard_is_warned_with_the_guarded_answer() {
        let result = CampaignResult {
            outside_events: 2,
            outside_share: Some(0.1),
            ..matched()
        };
        let noisy = |guard_outside, dialect| WarningContext {
            noisy: true,
            adaptive: true,
            ..context(guard_outside, dialect)
        };
        let cli = warnings(&result, noisy(false, Dialect::Cli));
        assert_eq!(cli.len(), 1, "{cli:?}");
        assert!(
            cli[0].starts_with("the vehicle is noisy")
                && cli[0].contains("its support K holds every scenario")
                && cli[0].contains("[8.500e-4, 1.150e-3] assumes it does")
                && cli[0].contains("found 2 events outside it")
                && cli[0].contains("guarded interval [8.500e-4, 1.115e-2]")
                && cli[0].contains("--guard-outside --outside ndd"),
            "{}",
            cli[0]
        );
        let api = warnings(&result, noisy(false, Dialect::Api));
        assert_eq!(Dialect::Cli.translate(&api[0]), cli[0]);
        // Without events outside: the warning stands (a cell may still
        // fail), without the evidence clause.
        let quiet = warnings(&matched(), noisy(false, Dialect::Cli));
        assert_eq!(quiet.len(), 1);
        assert!(!quiet[0].contains("exploring tests found"), "{}", quiet[0]);
        // Under the guard, the default for a noisy vehicle: nothing to say.
        assert!(warnings(&result, noisy(true, Dialect::Cli)).is_empty());
    }
}
