//! What happens to a worker's report, from the route that parsed it to the
//! folded estimate: its shape checked ([`check`]), its tests run again
//! ([`replay`], on the [`secret_sample`]) or audited by other workers
//! ([`audit`], which a worker cannot dodge: `leasing/dodging.rs`; by
//! statistics for noisy programs: [`noisy`]), recorded ([`record`]), weighed with every
//! other resolved test of the campaign ([`evidence`]), and the campaign's
//! resolved prefix folded ([`fold`], with the exploring tests the replay
//! found kept in [`explored`]; an anytime campaign's sequences in
//! [`anytime`]) or, for an adaptive campaign, its stages resolved
//! ([`stages`]), and a paired campaign's pair folded ([`pair_fold`]). A
//! worker caught is flagged ([`flag`]); an audit run's decision is a
//! [`verdict`], a contradicted outcome a [`mismatch`]; the replays' counts
//! for `/metrics` are [`replay_counts`]. Each running campaign's tests are
//! built once, from its plan, in [`tests_cache`]. [`receive`] runs them in
//! order.

pub mod anytime;
pub mod audit;
pub mod check;
pub mod evidence;
pub mod explored;
pub mod flag;
pub mod fold;
pub mod mismatch;
pub mod noisy;
pub mod pair_fold;
pub mod receive;
pub mod record;
pub mod replay;
pub mod replay_counts;
pub mod secret_sample;
pub mod stages;
pub mod tests_cache;
pub mod verdict;
