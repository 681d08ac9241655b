//! The allocator settings of the command: glibc's `malloc` keeps large freed blocks for reuse.
//!
//! By default glibc serves every block above its mmap threshold (at most 32 MiB, adjusted as
//! the program runs) with a fresh `mmap` and returns it with `munmap` when it is freed, and it
//! gives the top of its heap back to the system past a trim threshold. A field evaluation
//! allocates and frees tensors of tens of megabytes for each chunk of rays, so every chunk
//! faulted in fresh zeroed pages: page faults and their locks were a fifth of the profile of
//! `export`, which renders whole views (flex, 2 cores). Raising both thresholds keeps those
//! blocks in the process: an export ran in 0.72 of the time, a whole run in 0.81, for 5 to 7%
//! more peak memory (docs/usage.md, "Memory"). `GB_MALLOC_DEFAULTS=1` keeps glibc's defaults
//! (the benchmark's reference, `tools/bench/malloc_ab.py`).

/// The mmap threshold: blocks below it come from the heap, where freed ones are reused.
const MMAP_THRESHOLD: i32 = 1 << 30;
/// The free memory at the top of the heap that is kept rather than returned to the system.
const TRIM_THRESHOLD: i32 = i32::MAX;

/// Sets glibc's thresholds (module docs) unless `GB_MALLOC_DEFAULTS` is `1`; returns whether
/// both were taken. Elsewhere than Linux with glibc it does nothing and returns `false`.
pub fn keep_large_blocks() -> bool {
    if std::env::var("GB_MALLOC_DEFAULTS").is_ok_and(|v| v == "1") {
        return false;
    }
    set_thresholds()
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn set_thresholds() -> bool {
    // SAFETY: mallopt only changes the allocator's parameters; it is called before any
    // other thread exists, and glibc answers an out-of-range value with 0, not an error.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
            && libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn set_thresholds() -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glibc_takes_both_thresholds() {
        // the test binary's own allocator: the same glibc the command links
        assert_eq!(
            set_thresholds(),
            cfg!(all(target_os = "linux", target_env = "gnu"))
        );
    }
}
