//! What every library file says about itself, whatever the case's format:
//! the case, preset, surrogate and exposure it was built for. Grid cases
//! write JSON ([`super::file`]); car-following writes a binary policy file
//! whose header is the same kind of JSON after a magic number and a length
//! (`crate::cases::carfollow::file`). Reading the head tells a command which
//! case to open before the file itself is read.

use super::{ExposureRef, LibraryFileError};
use serde::Deserialize;

/// The first eight bytes of a policy library file.
pub const POLICY_MAGIC: &[u8; 8] = b"TSLGPOL\0";

/// A library file's own account of what it was built for.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct LibraryHead {
    /// The case.
    pub case: String,
    /// The case's preset.
    pub preset: String,
    /// The surrogate, as its full specification.
    pub surrogate: serde_json::Value,
    /// The exposure.
    pub exposure: ExposureRef,
}

/// The head of library file `bytes`.
pub fn read_head(bytes: &[u8]) -> Result<LibraryHead, LibraryFileError> {
    let json = match bytes.strip_prefix(POLICY_MAGIC.as_slice()) {
        Some(rest) => {
            let length = rest
                .get(..4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
                .ok_or_else(|| LibraryFileError::Json("the file ends inside its header".into()))?;
            rest.get(4..4 + length)
                .ok_or_else(|| LibraryFileError::Json("the file ends inside its header".into()))?
        }
        None => bytes,
    };
    serde_json::from_slice(json).map_err(|e| LibraryFileError::Json(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heads_of_both_formats_and_damage() {
        let json = br#"{"format": "tslg-library", "case": "cut-in", "preset": "paper-code",
            "surrogate": {"model": "idm"}, "exposure": {"name": "builtin", "fingerprint": "ab"},
            "cells": []}"#;
        let head = read_head(json).unwrap();
        assert_eq!(
            (head.case.as_str(), head.preset.as_str()),
            ("cut-in", "paper-code")
        );
        let header = br#"{"case": "car-following", "preset": "risky", "surrogate": {},
            "exposure": {"name": "builtin", "fingerprint": "cd"}}"#;
        let mut policy = POLICY_MAGIC.to_vec();
        policy.extend((header.len() as u32).to_le_bytes());
        policy.extend(header);
        policy.extend([0u8; 16]);
        assert_eq!(read_head(&policy).unwrap().case, "car-following");
        assert!(read_head(&policy[..12]).is_err());
        assert!(read_head(b"not json").is_err());
    }
}
