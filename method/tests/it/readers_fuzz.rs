//! Property-based fuzzing of the readers that take user files: the NDD
//! exposure table (CSV text uploaded with a library) and the library files
//! (cut-in JSON cells, the car-following binary Q-table) that workers and
//! the coordinator read. Random text and bytes, and valid inputs damaged by
//! random edits, must give a result or a clean error: never a panic, and an
//! accepted input must satisfy what the readers promise (a probability
//! mass that sums to 1; Q-rows that are sub-probabilities).

use proptest::prelude::*;
use std::sync::LazyLock;
use tslg_method::cases::carfollow::file::PolicyLibraryFile;
use tslg_method::cases::open_case;
use tslg_method::library::SearchMethod;
use tslg_method::ndd_table::parse_table;
use tslg_method::registry::{BuildRequest, ExposureSource, LibrarySearch};

/// A small valid table: ranges 1, 3, 5 m by range rates −1, 0, 1 m/s.
const SMALL_TABLE: &str = ",-1,0,1\n1,0.1,0.1,0\n3,0.2,0.1,0.1\n5,0.2,0.1,0.1\n";

/// The authors' cut-in table, when `tslg_testkit::shared_data` holds it.
static AUTHORS_TABLE: LazyLock<Option<String>> = LazyLock::new(|| {
    std::fs::read_to_string(tslg_testkit::shared_data().join("cutin_ndd_spmd.csv")).ok()
});

/// The authors' table, or `None` after the running test recorded its skip
/// (once, not at each of a property's cases).
fn authors_table() -> Option<&'static str> {
    thread_local!(static SAID: std::cell::Cell<bool> = const { std::cell::Cell::new(false) });
    let text = AUTHORS_TABLE.as_deref();
    if text.is_none() && !SAID.replace(true) {
        tslg_testkit::authors_table(); // says SKIPPED, with the reason
    }
    text
}

/// Failing cases found are kept here and tried first on every run (commit
/// the file when a case is added).
const REGRESSIONS: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/it/readers_fuzz.proptest-regressions"
);

/// The cut-in library of the IDM by exhaustive search, as its JSON file.
static CUT_IN_FILE: LazyLock<Vec<u8>> = LazyLock::new(|| {
    let case = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    let request = BuildRequest {
        threshold: None,
        search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
    };
    case.build_library(&serde_json::json!({"model": "idm"}), &request)
        .unwrap()
        .file
});

/// The car-following library of the IDM on the risky preset (binary).
static FOLLOW_FILE: LazyLock<Vec<u8>> = LazyLock::new(|| {
    let case = open_case("car-following", Some("risky"), &ExposureSource::Builtin).unwrap();
    let request = BuildRequest {
        threshold: None,
        search: None,
    };
    case.build_library(&serde_json::json!({"model": "idm"}), &request)
        .unwrap()
        .file
});

/// One random edit of a byte string.
#[derive(Debug, Clone)]
enum Edit {
    Flip { at: usize, bit: u8 },
    Set { at: usize, byte: u8 },
    Insert { at: usize, bytes: Vec<u8> },
    Delete { at: usize, len: usize },
    Truncate { at: usize },
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 0u8..8).prop_map(|(at, bit)| Edit::Flip { at, bit }),
        (any::<usize>(), any::<u8>()).prop_map(|(at, byte)| Edit::Set { at, byte }),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(at, bytes)| Edit::Insert { at, bytes }),
        (any::<usize>(), 1usize..64).prop_map(|(at, len)| Edit::Delete { at, len }),
        any::<usize>().prop_map(|at| Edit::Truncate { at }),
    ]
}

fn damaged(original: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut bytes = original.to_vec();
    for e in edits {
        let n = bytes.len().max(1);
        match e {
            Edit::Flip { at, bit } => {
                if !bytes.is_empty() {
                    bytes[at % n] ^= 1 << bit;
                }
            }
            Edit::Set { at, byte } => {
                if !bytes.is_empty() {
                    bytes[at % n] = *byte;
                }
            }
            Edit::Insert { at, bytes: b } => {
                let at = at % (bytes.len() + 1);
                bytes.splice(at..at, b.iter().copied());
            }
            Edit::Delete { at, len } => {
                let at = at % n;
                let end = (at + len).min(bytes.len());
                bytes.drain(at.min(end)..end);
            }
            Edit::Truncate { at } => bytes.truncate(at % (bytes.len() + 1)),
        }
    }
    bytes
}

/// Parses a table and checks what an accepted table promises.
fn check_table(text: &str) {
    if let Ok(table) = parse_table(text, "range", "range_rate") {
        let masses = table.mass.masses();
        assert!(
            masses.iter().all(|p| p.is_finite() && *p >= 0.0),
            "{text:?}"
        );
        let sum: f64 = masses.iter().sum();
        assert!((sum - 1.0).abs() < 1e-9, "sum {sum} for {text:?}");
    }
    // Through the case, as an upload reaches it: a clean error or a case.
    let _ = open_case(
        "cut-in",
        None,
        &ExposureSource::Table {
            name: "fuzz.csv".into(),
            text: text.to_owned(),
        },
    );
}

/// Reads a library file as a campaign does; any answer but a panic is
/// fine. Returns whether it was accepted.
fn check_library(case: &str, preset: Option<&str>, bytes: &[u8]) -> bool {
    let case = open_case(case, preset, &ExposureSource::Builtin).unwrap();
    case.campaign(
        Some(bytes),
        &serde_json::json!({"model": "idm"}),
        0.1,
        Default::default(),
        Default::default(),
        1,
    )
    .is_ok()
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        failure_persistence: Some(Box::new(
            proptest::test_runner::FileFailurePersistence::Direct(REGRESSIONS),
        )),
        ..ProptestConfig::default()
    })]

    #[test]
    fn any_text_is_a_table_or_a_clean_error(text in "\\PC{0,300}") {
        check_table(&text);
    }

    #[test]
    fn table_like_text_is_a_table_or_a_clean_error(
        text in "([-,.0-9eE+ ]{0,12}(,|\r?\n)){0,40}"
    ) {
        check_table(&text);
    }

    #[test]
    fn a_damaged_table_is_a_table_or_a_clean_error(
        edits in prop::collection::vec(edit(), 1..6)
    ) {
        let text = damaged(SMALL_TABLE.as_bytes(), &edits);
        check_table(&String::from_utf8_lossy(&text));
    }

    #[test]
    fn a_damaged_authors_table_is_a_table_or_a_clean_error(
        edits in prop::collection::vec(edit(), 1..6)
    ) {
        if let Some(text) = authors_table() {
            check_table(&String::from_utf8_lossy(&damaged(text.as_bytes(), &edits)));
        }
    }

    #[test]
    fn any_bytes_are_a_library_or_a_clean_error(
        bytes in prop::collection::vec(any::<u8>(), 0..400)
    ) {
        check_library("cut-in", None, &bytes);
        check_library("car-following", Some("risky"), &bytes);
        let _ = PolicyLibraryFile::from_bytes(&bytes);
    }

    #[test]
    fn a_damaged_cut_in_library_is_a_library_or_a_clean_error(
        edits in prop::collection::vec(edit(), 1..6)
    ) {
        check_library("cut-in", None, &damaged(&CUT_IN_FILE, &edits));
    }

    #[test]
    fn a_damaged_policy_library_is_a_library_or_a_clean_error(
        edits in prop::collection::vec(edit(), 1..4)
    ) {
        let bytes = damaged(&FOLLOW_FILE, &edits);
        if let Ok(file) = PolicyLibraryFile::from_bytes(&bytes) {
            let a = file.library.actions;
            for row in file.library.q.chunks(a) {
                assert!(row.iter().all(|q| (0.0..=1.0).contains(q)));
                assert!(row.iter().sum::<f64>() <= 1.0 + 1e-9);
            }
        }
        check_library("car-following", Some("risky"), &bytes);
    }
}

#[test]
fn the_undamaged_inputs_are_accepted() {
    // The seeds above must be valid, or their damage would test nothing.
    assert!(parse_table(SMALL_TABLE, "range", "range_rate").is_ok());
    assert!(check_library("cut-in", None, &CUT_IN_FILE));
    assert!(PolicyLibraryFile::from_bytes(&FOLLOW_FILE).is_ok());
    assert!(check_library("car-following", Some("risky"), &FOLLOW_FILE));
    if let Some(text) = authors_table() {
        assert!(parse_table(text, "range", "range_rate").is_ok());
    }
}
