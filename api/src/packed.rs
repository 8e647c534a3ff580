//! A compact encoding of a report's events, used on the wire
//! (`ResultReport::packed_events`, base64) and in the coordinator's storage.
//!
//! A campaign tested with a library that its vehicle fails often has an
//! event in most tests (FVDM with the IDM library: about 91 %), and a list
//! of `{"index": …, "weight": …}` objects costs about 45 bytes per event.
//! The packed form costs 2 to 10:
//!
//! ```text
//! tag (1 byte: 0 raw weights, 1 dictionary of weights)
//! n                          varint: the number of events
//! d₁ … dₙ                    varints: dᵢ = indexᵢ − indexᵢ₋₁ − 1, index₀ = from − 1
//! raw:        w₁ … wₙ        f64, little-endian
//! dictionary: k, v₁ … vₖ     varint, then the k distinct weights as f64 LE
//!             j₁ … jₙ        varints: wᵢ = v_{jᵢ}
//! ```
//!
//! Indices are strictly increasing and measured from the range's start, so
//! a dense run of events costs one byte per index. Weights are copied bit
//! for bit. A grid case draws a weight per cell, so its events share few
//! distinct weights and the dictionary form wins (the encoder picks
//! whichever is smaller); car-following's weights are products along the
//! test and stay raw. Varints are unsigned LEB128 (7 bits a byte, low
//! first), at most 10 bytes for a `u64`.

use std::fmt;

const RAW: u8 = 0;
const DICTIONARY: u8 = 1;
/// The most distinct weights a dictionary holds.
const MAX_DICTIONARY: usize = 4096;

/// Why a packed list could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PackedError(pub String);

impl fmt::Display for PackedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "packed events: {}", self.0)
    }
}

impl std::error::Error for PackedError {}

fn put_varint(out: &mut Vec<u8>, mut value: u64) {
    while value >= 0x80 {
        out.push((value as u8) | 0x80);
        value >>= 7;
    }
    out.push(value as u8);
}

/// Reads bytes front to back, with errors that say what was cut short.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn byte(&mut self, what: &str) -> Result<u8, PackedError> {
        let b = *self
            .bytes
            .get(self.at)
            .ok_or_else(|| PackedError(format!("ends inside {what}")))?;
        self.at += 1;
        Ok(b)
    }

    fn varint(&mut self, what: &str) -> Result<u64, PackedError> {
        let mut value = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.byte(what)?;
            let part = u64::from(b & 0x7f);
            if shift == 63 && part > 1 {
                return Err(PackedError(format!("{what} overflows 64 bits")));
            }
            value |= part << shift;
            if b & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err(PackedError(format!("{what} overflows 64 bits")))
    }

    fn f64(&mut self, what: &str) -> Result<f64, PackedError> {
        let end = self.at + 8;
        let slice = self
            .bytes
            .get(self.at..end)
            .ok_or_else(|| PackedError(format!("ends inside {what}")))?;
        self.at = end;
        Ok(f64::from_le_bytes(slice.try_into().expect("8 bytes")))
    }

    /// A count that cannot exceed what the remaining bytes can hold
    /// (`min_bytes` each), so a forged count cannot make us allocate.
    fn count(&mut self, what: &str, min_bytes: usize) -> Result<usize, PackedError> {
        let n = self.varint(what)?;
        let room = (self.bytes.len() - self.at) / min_bytes.max(1);
        if n > room as u64 {
            return Err(PackedError(format!(
                "{what} is {n}, but only {} bytes follow",
                self.bytes.len() - self.at
            )));
        }
        Ok(n as usize)
    }
}

/// Packs `events` (`(index, weight)`, indices strictly increasing and ≥
/// `from`) into the smaller of the raw and the dictionary form.
///
/// # Panics
/// When the indices are not strictly increasing from `from`: the caller
/// builds the list and must sort it.
pub fn pack(from: u64, events: &[(u64, f64)]) -> Vec<u8> {
    let mut head = Vec::with_capacity(events.len() * 2 + 10);
    put_varint(&mut head, events.len() as u64);
    // The first index the next event may have; `None` after `u64::MAX`.
    let mut next = Some(from);
    for &(index, _) in events {
        let first = next.filter(|&n| index >= n);
        let first =
            first.unwrap_or_else(|| panic!("event indices must increase strictly from {from}"));
        put_varint(&mut head, index - first);
        next = index.checked_add(1);
    }
    // The dictionary, in order of first appearance.
    let mut distinct: Vec<u64> = Vec::new();
    // Fx hashing, far cheaper than SipHash per event. Weights come from
    // workers, so a hostile one could send keys that collide; the
    // dictionary is given up past MAX_DICTIONARY distinct weights, which
    // bounds the cost of collisions (and a dictionary that large saves
    // little anyway).
    let mut position = rustc_hash::FxHashMap::default();
    let mut codes = Vec::with_capacity(events.len());
    for &(_, weight) in events {
        let bits = weight.to_bits();
        let code = *position.entry(bits).or_insert_with(|| {
            distinct.push(bits);
            distinct.len() - 1
        });
        if distinct.len() > MAX_DICTIONARY {
            break;
        }
        put_varint(&mut codes, code as u64);
    }
    let dictionary_size = if distinct.len() > MAX_DICTIONARY {
        usize::MAX
    } else {
        10 + distinct.len() * 8 + codes.len()
    };
    let raw_size = events.len() * 8;
    let mut out = Vec::with_capacity(1 + head.len() + raw_size.min(dictionary_size));
    if dictionary_size < raw_size {
        out.push(DICTIONARY);
        out.extend_from_slice(&head);
        put_varint(&mut out, distinct.len() as u64);
        for bits in distinct {
            out.extend_from_slice(&bits.to_le_bytes());
        }
        out.extend_from_slice(&codes);
    } else {
        out.push(RAW);
        out.extend_from_slice(&head);
        for &(_, weight) in events {
            out.extend_from_slice(&weight.to_le_bytes());
        }
    }
    out
}

/// Unpacks what [`pack`] wrote for a range starting at `from`: the events
/// with strictly increasing indices. Every byte must be used.
pub fn unpack(from: u64, bytes: &[u8]) -> Result<Vec<(u64, f64)>, PackedError> {
    let mut r = Reader { bytes, at: 0 };
    let tag = r.byte("the tag")?;
    if tag != RAW && tag != DICTIONARY {
        return Err(PackedError(format!(
            "unknown tag {tag} (0 raw, 1 dictionary)"
        )));
    }
    // Every event needs at least one byte of index and one of weight code.
    let n = r.count("the number of events", 2)?;
    let mut indices = Vec::with_capacity(n);
    // The first index the next event may have; `None` after `u64::MAX`.
    let mut next = Some(from);
    for _ in 0..n {
        let gap = r.varint("an index")?;
        let index = next
            .and_then(|first| first.checked_add(gap))
            .ok_or_else(|| PackedError("an index overflows 64 bits".into()))?;
        indices.push(index);
        next = index.checked_add(1);
    }
    let mut events = Vec::with_capacity(n);
    if tag == RAW {
        for index in indices {
            events.push((index, r.f64("a weight")?));
        }
    } else {
        let k = r.count("the dictionary's size", 8)?;
        let dictionary: Vec<f64> = (0..k)
            .map(|_| r.f64("the dictionary"))
            .collect::<Result<_, _>>()?;
        for index in indices {
            let code = r.varint("a weight's code")?;
            let weight = *dictionary.get(code as usize).ok_or_else(|| {
                PackedError(format!(
                    "weight code {code} is outside the dictionary of {k}"
                ))
            })?;
            events.push((index, weight));
        }
    }
    if r.at != bytes.len() {
        return Err(PackedError(format!(
            "{} bytes left over after {n} events",
            bytes.len() - r.at
        )));
    }
    Ok(events)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(from: u64, events: &[(u64, f64)]) -> Vec<u8> {
        let bytes = pack(from, events);
        let back = unpack(from, &bytes).unwrap();
        assert_eq!(back.len(), events.len());
        for (a, b) in back.iter().zip(events) {
            assert_eq!((a.0, a.1.to_bits()), (b.0, b.1.to_bits()));
        }
        bytes
    }

    #[test]
    fn round_trips_bit_for_bit_in_both_forms() {
        assert_eq!(round_trip(5, &[]), vec![RAW, 0]);
        // Few distinct weights over a dense run: the dictionary, ~2 bytes each.
        let dense: Vec<(u64, f64)> = (1000..11_000)
            .map(|i| (i, [0.25, 1.5e-3, f64::MIN_POSITIVE][(i % 3) as usize]))
            .collect();
        let bytes = round_trip(1000, &dense);
        assert_eq!(bytes[0], DICTIONARY);
        assert!(bytes.len() < 2 * dense.len() + 64, "{}", bytes.len());
        // Every weight distinct: raw, ~9 bytes each.
        let spread: Vec<(u64, f64)> = (0..500)
            .map(|i| (i * 37 + 3, 1.0 / (i as f64 + 1.0)))
            .collect();
        let bytes = round_trip(0, &spread);
        assert_eq!(bytes[0], RAW);
        assert!(bytes.len() <= 500 * 10 + 4);
        // Extreme indices and weights.
        round_trip(
            u64::MAX - 3,
            &[
                (u64::MAX - 3, 0.0),
                (u64::MAX - 1, f64::MAX),
                (u64::MAX, -0.0),
            ],
        );
    }

    #[test]
    fn damaged_input_is_an_error_never_a_panic_or_an_allocation() {
        let good = pack(10, &[(10, 0.5), (12, 0.5), (40, 2.0)]);
        assert!(unpack(10, &good).is_ok());
        for cut in 0..good.len() {
            assert!(unpack(10, &good[..cut]).is_err(), "cut at {cut}");
        }
        let mut longer = good.clone();
        longer.push(0);
        assert!(unpack(10, &longer).unwrap_err().0.contains("left over"));
        assert!(unpack(10, &[7, 0]).unwrap_err().0.contains("unknown tag"));
        // A count of 2^60 events in a few bytes is refused before allocating.
        let mut huge = vec![RAW];
        put_varint(&mut huge, 1 << 60);
        assert!(unpack(0, &huge).unwrap_err().0.contains("only"));
        // An index past u64::MAX.
        let mut over = vec![RAW];
        put_varint(&mut over, 1);
        put_varint(&mut over, 10);
        over.extend_from_slice(&1.0f64.to_le_bytes());
        assert!(unpack(u64::MAX - 2, &over)
            .unwrap_err()
            .0
            .contains("overflows"));
        // A varint of 11 bytes.
        let mut long = vec![RAW, 1];
        long.extend_from_slice(&[0xff; 10]);
        long.push(1);
        assert!(unpack(0, &long).is_err());
        // A dictionary code past the dictionary.
        let mut code = vec![DICTIONARY];
        put_varint(&mut code, 1);
        put_varint(&mut code, 0);
        put_varint(&mut code, 1);
        code.extend_from_slice(&1.0f64.to_le_bytes());
        put_varint(&mut code, 3);
        assert!(unpack(0, &code)
            .unwrap_err()
            .0
            .contains("outside the dictionary"));
    }

    #[test]
    #[should_panic(expected = "increase strictly")]
    fn packing_unsorted_events_is_a_bug() {
        pack(0, &[(5, 1.0), (5, 1.0)]);
    }
}
