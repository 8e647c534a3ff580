//! The states of the store's rows (a lease's, an audit's; campaigns' and
//! libraries' are the API's enums), and every state its SQL statements
//! name, in one place: each is the enum's `as_str()` quoted as an SQL
//! literal (a test checks them against the enums), spliced into the
//! statements at compile time
//! (`const_format::formatcp!`). Literals rather than bound values where a
//! partial index must be seen to apply (`leases_active`, `leases_open`:
//! `WHERE state = 'active'`), and everywhere else alike, so a statement
//! reads as what it does.

use const_format::formatcp;

/// Where a lease stands: being worked on (or expired, waiting for another
/// worker), fully reported, or cancelled with its campaign.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LeaseState {
    Active,
    Done,
    Cancelled,
}

impl LeaseState {
    /// The state as the `leases` table stores it.
    pub fn as_str(self) -> &'static str {
        match self {
            LeaseState::Active => "active",
            LeaseState::Done => "done",
            LeaseState::Cancelled => "cancelled",
        }
    }
}

/// Where an audit stands (see `report/audit.rs` and the `audits` table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AuditState {
    /// Waits for a second run.
    Replica,
    /// Two runs disagree; a third decides.
    Tiebreak,
    Agreed,
    /// The third run decided and the minority was flagged.
    Settled,
    /// The first run was taken back with its worker.
    Void,
    /// Three runs, three outcomes.
    Undecided,
    /// Still open when its campaign stopped before its test.
    Past,
}

impl AuditState {
    /// The state as the `audits` table stores it.
    pub fn as_str(self) -> &'static str {
        match self {
            AuditState::Replica => "replica",
            AuditState::Tiebreak => "tiebreak",
            AuditState::Agreed => "agreed",
            AuditState::Settled => "settled",
            AuditState::Void => "void",
            AuditState::Undecided => "undecided",
            AuditState::Past => "past",
        }
    }
}

/// `CampaignStatus::Pending`.
pub const CAMPAIGN_PENDING: &str = "'pending'";
/// `CampaignStatus::Running`.
pub const CAMPAIGN_RUNNING: &str = "'running'";
/// `CampaignStatus::Cancelled`.
pub const CAMPAIGN_CANCELLED: &str = "'cancelled'";
/// `CampaignStatus::Failed`.
pub const CAMPAIGN_FAILED: &str = "'failed'";

/// `LeaseState::Active`.
pub const LEASE_ACTIVE: &str = "'active'";
/// `LeaseState::Done`.
pub const LEASE_DONE: &str = "'done'";
/// `LeaseState::Cancelled`.
pub const LEASE_CANCELLED: &str = "'cancelled'";

/// `AuditState::Replica`.
pub const AUDIT_REPLICA: &str = "'replica'";
/// `AuditState::Tiebreak`.
pub const AUDIT_TIEBREAK: &str = "'tiebreak'";
/// `AuditState::Agreed`.
pub const AUDIT_AGREED: &str = "'agreed'";
/// `AuditState::Void`.
pub const AUDIT_VOID: &str = "'void'";
/// `AuditState::Undecided`.
pub const AUDIT_UNDECIDED: &str = "'undecided'";
/// `AuditState::Past`.
pub const AUDIT_PAST: &str = "'past'";
/// The states in which an audit waits for a run and holds the campaign's
/// prefix at its test.
pub const AUDIT_OPEN: &str = formatcp!("({AUDIT_REPLICA}, {AUDIT_TIEBREAK})");

/// `LibraryStatus::Building`.
pub const LIBRARY_BUILDING: &str = "'building'";
/// `LibraryStatus::Ready`.
pub const LIBRARY_READY: &str = "'ready'";
/// `LibraryStatus::Failed`.
pub const LIBRARY_FAILED: &str = "'failed'";

/// `PairStop::Cancelled`.
pub const PAIR_CANCELLED: &str = "'cancelled'";

#[cfg(test)]
mod tests {
    use super::*;
    use tslg_api::{CampaignStatus, LibraryStatus, PairStop};

    fn quoted(name: &str) -> String {
        format!("'{name}'")
    }

    /// Each literal is its enum's name, as the rows store it.
    #[test]
    fn every_literal_is_its_enum_s_name() {
        let pairs: [(&str, String); 18] = [
            (CAMPAIGN_PENDING, quoted(CampaignStatus::Pending.as_str())),
            (CAMPAIGN_RUNNING, quoted(CampaignStatus::Running.as_str())),
            (
                CAMPAIGN_CANCELLED,
                quoted(CampaignStatus::Cancelled.as_str()),
            ),
            (CAMPAIGN_FAILED, quoted(CampaignStatus::Failed.as_str())),
            (LEASE_ACTIVE, quoted(LeaseState::Active.as_str())),
            (LEASE_DONE, quoted(LeaseState::Done.as_str())),
            (LEASE_CANCELLED, quoted(LeaseState::Cancelled.as_str())),
            (AUDIT_REPLICA, quoted(AuditState::Replica.as_str())),
            (AUDIT_TIEBREAK, quoted(AuditState::Tiebreak.as_str())),
            (AUDIT_AGREED, quoted(AuditState::Agreed.as_str())),
            (AUDIT_VOID, quoted(AuditState::Void.as_str())),
            (AUDIT_UNDECIDED, quoted(AuditState::Undecided.as_str())),
            (AUDIT_PAST, quoted(AuditState::Past.as_str())),
            (LIBRARY_BUILDING, quoted(LibraryStatus::Building.as_str())),
            (LIBRARY_READY, quoted(LibraryStatus::Ready.as_str())),
            (LIBRARY_FAILED, quoted(LibraryStatus::Failed.as_str())),
            (
                PAIR_CANCELLED,
                quoted(
                    serde_json::to_value(PairStop::Cancelled)
                        .unwrap()
                        .as_str()
                        .unwrap(),
                ),
            ),
            (
                AUDIT_OPEN,
                format!(
                    "({}, {})",
                    quoted(AuditState::Replica.as_str()),
                    quoted(AuditState::Tiebreak.as_str())
                ),
            ),
        ];
        for (literal, name) in pairs {
            assert_eq!(literal, name);
        }
    }
}
