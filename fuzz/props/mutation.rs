//! The random edits that the property tests of the file readers share (`tests/fuzz_props.rs`
//! in `plenoptic-io`, `colmap-io` and `splat-core`, which include this file by path): byte
//! changes, insertions, deletions, cuts, and numbers in the text replaced by values that make
//! readers misbehave when they trust a file. The stable-toolchain companion of the mutations
//! libFuzzer makes in the cargo-fuzz targets beside this folder (`docs/fuzzing.md`).

use proptest::prelude::*;

const NASTY_NUMBERS: &[&str] = &[
    "0",
    "-1",
    "255",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "1000000000000",
    "nan",
    "inf",
    "1e309",
];

/// One random edit of a file.
#[derive(Debug, Clone)]
pub enum Edit {
    /// Sets the byte at (position mod length).
    Set(usize, u8),
    /// Inserts bytes at (position mod length + 1).
    Insert(usize, Vec<u8>),
    /// Removes up to n bytes at (position mod length).
    Remove(usize, usize),
    /// Cuts the file at (position mod length + 1).
    Truncate(usize),
    /// Replaces the k-th run of ASCII digits (mod their number) with a nasty number.
    Number(usize, usize),
}

pub fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Edit::Set(p, b)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(p, b)| Edit::Insert(p, b)),
        (any::<usize>(), 1usize..64).prop_map(|(p, n)| Edit::Remove(p, n)),
        any::<usize>().prop_map(Edit::Truncate),
        (any::<usize>(), 0..NASTY_NUMBERS.len()).prop_map(|(k, n)| Edit::Number(k, n)),
    ]
}

pub fn apply(mut data: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let len = data.len().max(1);
        match e {
            Edit::Set(p, b) => {
                if !data.is_empty() {
                    data[p % len] = *b;
                }
            }
            Edit::Insert(p, b) => {
                let at = (p % len + 1).min(data.len());
                data.splice(at..at, b.iter().copied());
            }
            Edit::Remove(p, n) => {
                let at = (p % len).min(data.len());
                let end = (at + n).min(data.len());
                data.drain(at..end);
            }
            Edit::Truncate(p) => data.truncate(p % len + 1),
            Edit::Number(k, n) => {
                let runs: Vec<(usize, usize)> = digit_runs(&data);
                if !runs.is_empty() {
                    let (start, end) = runs[k % runs.len()];
                    data.splice(start..end, NASTY_NUMBERS[*n].bytes());
                }
            }
        }
    }
    data
}

/// Byte ranges of the runs of ASCII digits.
fn digit_runs(data: &[u8]) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut start = None;
    for (i, b) in data.iter().enumerate() {
        match (b.is_ascii_digit(), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                runs.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        runs.push((s, data.len()));
    }
    runs
}
