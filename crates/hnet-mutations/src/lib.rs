//! What every property test of a file reader needs, written once: random byte edits that damage a
//! valid file ([`edits`], [`mutate`]), the number of cases CI runs ([`cases`], overridden by
//! `PROPTEST_CASES`), and [`CappedAllocator`], which makes a file claiming a huge size fail its
//! test visibly instead of exhausting the machine's memory. A dev-dependency only.

use proptest::prelude::*;
use proptest::test_runner::Config;

/// `ci` cases, or `PROPTEST_CASES` when set (a longer local run).
pub fn cases(ci: u32) -> Config {
    Config::with_cases(
        std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(ci),
    )
}

/// One edit of a file's bytes; positions wrap around the file's length.
#[derive(Debug, Clone)]
pub enum Edit {
    /// Overwrite a byte.
    Replace(usize, u8),
    /// Insert a byte.
    Insert(usize, u8),
    /// Remove a byte.
    Remove(usize),
    /// Cut the file short.
    Truncate(usize),
}

/// One to seven edits writing any byte.
pub fn edits() -> impl Strategy<Value = Vec<Edit>> {
    edits_writing(any::<u8>())
}

/// One to seven edits writing bytes drawn from `byte` (for example digits and punctuation, so
/// that a text file's edits land as other numbers and shapes).
pub fn edits_writing(byte: impl Strategy<Value = u8> + Clone) -> impl Strategy<Value = Vec<Edit>> {
    let edit = prop_oneof![
        4 => (any::<usize>(), byte.clone()).prop_map(|(i, b)| Edit::Replace(i, b)),
        2 => (any::<usize>(), byte).prop_map(|(i, b)| Edit::Insert(i, b)),
        2 => any::<usize>().prop_map(Edit::Remove),
        1 => any::<usize>().prop_map(Edit::Truncate),
    ];
    proptest::collection::vec(edit, 1..8)
}

/// `bytes` with `edits` applied anywhere.
pub fn mutate(bytes: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    mutate_near_start(bytes, edits, usize::MAX)
}

/// `bytes` with `edits` applied, every other one within the first `window` bytes (a header and
/// its metadata, where a flip changes what the file claims rather than one stored value).
pub fn mutate_near_start(mut bytes: Vec<u8>, edits: &[Edit], window: usize) -> Vec<u8> {
    for (k, edit) in edits.iter().enumerate() {
        let n = bytes.len();
        let span = if k % 2 == 0 { n.min(window) } else { n };
        match *edit {
            Edit::Replace(i, b) if span > 0 => bytes[i % span] = b,
            Edit::Insert(i, b) => bytes.insert(i % (span + 1), b),
            Edit::Remove(i) if span > 0 => {
                bytes.remove(i % span);
            }
            Edit::Truncate(i) => bytes.truncate(i % (n + 1)),
            _ => {}
        }
    }
    bytes
}

/// The largest single allocation [`CappedAllocator`] grants, bytes (2 GiB).
pub const ALLOCATION_CAP: usize = 2 << 30;

/// The system allocator, refusing any single allocation above [`ALLOCATION_CAP`]: a test binary
/// that installs it (`#[global_allocator] static A: CappedAllocator = CappedAllocator;`) aborts
/// on a file whose header claims a huge size, a visible failure, instead of exhausting memory.
pub struct CappedAllocator;

// SAFETY: forwards to the system allocator; refusing (a null pointer) is allowed by `GlobalAlloc`.
unsafe impl std::alloc::GlobalAlloc for CappedAllocator {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        if layout.size() > ALLOCATION_CAP {
            return std::ptr::null_mut();
        }
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        if layout.size() > ALLOCATION_CAP {
            return std::ptr::null_mut();
        }
        unsafe { std::alloc::System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new: usize) -> *mut u8 {
        if new > ALLOCATION_CAP {
            return std::ptr::null_mut();
        }
        unsafe { std::alloc::System.realloc(ptr, layout, new) }
    }
}
