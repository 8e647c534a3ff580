//! A chunk's outcomes cut into reports the coordinator accepts: each
//! covers at most [`MAX_REPORT_TESTS`] tests and carries at most
//! [`MAX_REPORT_EVENTS`] events and [`MAX_REPORT_INVALID`] invalid tests,
//! with its events packed ([`tslg_api::packed`]), so a report stays a few
//! megabytes however many tests have the event (FVDM tested with the IDM
//! library: about 91 %). Parts are contiguous and in order: each starts
//! where the previous ended, as the coordinator requires.

use tslg_api::{
    EventResult, InvalidResult, LeaseKey, NearMiss, ResultReport, MAX_INVALID_REASON,
    MAX_REPORT_EVENTS, MAX_REPORT_INVALID, MAX_REPORT_TESTS,
};

/// Who reports, on which attempt.
pub struct Reporter<'a> {
    pub worker: &'a str,
    pub attempt: i64,
    pub key: &'a LeaseKey,
    pub threads: u32,
}

/// Limits of one part (the API's, or smaller in tests).
#[derive(Debug, Clone, Copy)]
pub struct PartLimits {
    pub tests: u64,
    pub events: usize,
    pub invalid: usize,
}

impl Default for PartLimits {
    fn default() -> Self {
        Self {
            tests: MAX_REPORT_TESTS,
            events: MAX_REPORT_EVENTS,
            invalid: MAX_REPORT_INVALID,
        }
    }
}

/// The reports of tests `from..to` that took `seconds`, with `events` and
/// `invalid` in index order inside the range. Each part is charged the
/// seconds in proportion to its tests.
pub fn report_parts(
    who: &Reporter<'_>,
    from: u64,
    to: u64,
    seconds: f64,
    events: &[EventResult],
    invalid: &[InvalidResult],
    limits: PartLimits,
) -> Vec<ResultReport> {
    let mut parts = Vec::new();
    let (mut e, mut v) = (0, 0);
    let mut start = from;
    while start < to {
        // The end of this part: the range's end, a test limit, or the
        // first outcome past an outcome limit.
        let mut end = to.min(start.saturating_add(limits.tests));
        if let Some(next) = events.get(e + limits.events) {
            end = end.min(next.index);
        }
        if let Some(next) = invalid.get(v + limits.invalid) {
            end = end.min(next.index);
        }
        let e_end = e + events[e..].partition_point(|x| x.index < end);
        let v_end = v + invalid[v..].partition_point(|x| x.index < end);
        let mut report = ResultReport {
            worker: who.worker.to_owned(),
            attempt: who.attempt,
            key: who.key.clone(),
            from: start,
            to: end,
            events: Vec::new(),
            packed_events: None,
            invalid: invalid[v..v_end]
                .iter()
                .map(|i| InvalidResult {
                    index: i.index,
                    reason: truncated(&i.reason, MAX_INVALID_REASON),
                })
                .collect(),
            compute_seconds: seconds * (end - start) as f64 / (to - from) as f64,
            threads: who.threads,
            near_misses: Vec::new(),
            next_lease: None,
        };
        let list: Vec<(u64, f64)> = events[e..e_end]
            .iter()
            .map(|x| (x.index, x.weight))
            .collect();
        report.pack_events(&list);
        parts.push(report);
        (start, e, v) = (end, e_end, v_end);
    }
    parts
}

/// Puts each near miss (in index order) into the part whose range holds it.
pub fn attach_near_misses(parts: &mut [ResultReport], near_misses: &[NearMiss]) {
    for part in parts {
        part.near_misses = near_misses
            .iter()
            .copied()
            .filter(|m| (part.from..part.to).contains(&m.index))
            .collect();
    }
}

/// `text` cut to at most `max` bytes at a character boundary.
pub fn truncated(text: &str, max: usize) -> String {
    if text.len() <= max {
        return text.to_owned();
    }
    let mut end = max;
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    text[..end].to_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn who(key: &LeaseKey) -> Reporter<'_> {
        Reporter {
            worker: "w",
            attempt: 1,
            key,
            threads: 2,
        }
    }

    #[test]
    fn parts_are_contiguous_within_every_limit_and_lose_nothing() {
        let key = LeaseKey("k".into());
        // 91 % events over 10,000 tests, an invalid test every 97.
        let events: Vec<EventResult> = (0..10_000u64)
            .filter(|i| i % 11 != 0 && i % 97 != 0)
            .map(|index| EventResult {
                index: 5_000 + index,
                weight: 0.5,
            })
            .collect();
        let invalid: Vec<InvalidResult> = (0..10_000u64)
            .filter(|i| i % 97 == 0)
            .map(|i| InvalidResult {
                index: 5_000 + i,
                reason: "é".repeat(1500),
            })
            .collect();
        let limits = PartLimits {
            tests: 4_000,
            events: 1_000,
            invalid: 7,
        };
        let parts = report_parts(&who(&key), 5_000, 15_000, 2.0, &events, &invalid, limits);
        let mut at = 5_000;
        let (mut seen_events, mut seen_invalid, mut seconds) = (Vec::new(), 0, 0.0);
        for p in &parts {
            assert_eq!(p.from, at);
            assert!(p.to > p.from && p.to - p.from <= limits.tests);
            let list = p.event_list().unwrap();
            assert!(list.len() <= limits.events && p.invalid.len() <= limits.invalid);
            assert!(list.iter().all(|&(i, _)| (p.from..p.to).contains(&i)));
            assert!(p
                .invalid
                .iter()
                .all(|i| i.reason.len() <= MAX_INVALID_REASON));
            seen_events.extend(list.iter().map(|&(i, _)| i));
            seen_invalid += p.invalid.len();
            seconds += p.compute_seconds;
            at = p.to;
        }
        assert_eq!(at, 15_000);
        assert_eq!(
            seen_events,
            events.iter().map(|e| e.index).collect::<Vec<_>>()
        );
        assert_eq!(seen_invalid, invalid.len());
        assert!((seconds - 2.0).abs() < 1e-9);
        // With the API's limits, one part.
        let one = report_parts(
            &who(&key),
            5_000,
            15_000,
            1.0,
            &events,
            &[],
            PartLimits::default(),
        );
        assert_eq!(one.len(), 1);
    }

    #[test]
    fn truncation_keeps_whole_characters() {
        assert_eq!(truncated("abc", 5), "abc");
        assert_eq!(truncated("ééé", 5), "éé");
    }
}
