//! Process-wide settings for long numeric runs.

/// Keep freed memory in the process instead of returning it to the OS after every frame.
///
/// A training iteration allocates and frees buffers of a few MB to tens of MB (projected
/// splats, tile lists, per-Gaussian gradients). With glibc's defaults, blocks above a
/// (dynamic) threshold are `mmap`ed and `munmap`ed each time: every iteration then pays
/// page faults on fresh pages and, with worker threads, TLB-shootdown interrupts (a
/// profile of `unseen train` showed ~20 % of the samples in the kernel). This raises
/// glibc's `M_MMAP_THRESHOLD` to its maximum (32 MiB on 64-bit) and its `M_TRIM_THRESHOLD`
/// to 1 GiB, so such buffers are reused from the heap. It changes no result, only where
/// memory comes from; peak resident memory may grow by the reused blocks. A no-op on other
/// platforms and C libraries. Call it once, at the start of `main`. [`release_freed_memory`]
/// returns what is kept between stages.
pub fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            fn mallopt(param: i32, value: i32) -> i32;
        }
        const M_TRIM_THRESHOLD: i32 = -1;
        const M_MMAP_THRESHOLD: i32 = -3;
        // SAFETY: `mallopt` only changes allocator parameters; it is called before any
        // other thread exists (the start of `main`) and with values glibc documents.
        unsafe {
            mallopt(M_MMAP_THRESHOLD, 32 << 20);
            mallopt(M_TRIM_THRESHOLD, 1 << 30);
        }
    }
}

/// Return the freed memory [`keep_freed_memory`] keeps to the OS (glibc `malloc_trim(0)`),
/// e.g. between pipeline steps, so that each step's peak resident memory is its own
/// (`io::CostMeter` calls it when a stage starts). Changes no result; a no-op elsewhere.
pub fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            fn malloc_trim(pad: usize) -> i32;
        }
        // SAFETY: `malloc_trim` only returns free heap pages to the OS; it takes the
        // allocator's own locks and is safe to call from any thread at any time.
        unsafe {
            malloc_trim(0);
        }
    }
}

/// The stack of every worker thread the crate starts. Rust's default is 2 MiB; the lane
/// kernels' frames exceed it in unoptimized builds (`backward_range_avx2` needs 2–4 MiB at
/// opt-level 0, so `cargo run` without `--release` overflowed while training). 16 MiB of
/// address space, touched only as far as used.
pub const WORKER_STACK_BYTES: usize = 16 << 20;

/// Give the global pool [`WORKER_STACK_BYTES`] stacks. Call once before any parallel work
/// (the command line's `main` does); later calls, or a global pool already running, change
/// nothing.
pub fn init_global_pool() {
    let _ = rayon::ThreadPoolBuilder::new()
        .stack_size(WORKER_STACK_BYTES)
        .build_global();
}

/// Run `f` in a pool of `threads` threads (`None`: the global pool). Results never depend on
/// the count (SPEC.md §6); only the wall time does.
pub fn with_threads<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> T + Send,
) -> crate::error::Result<T> {
    match threads {
        None => Ok(f()),
        Some(n) => {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .stack_size(WORKER_STACK_BYTES)
                .build()
                .map_err(|e| {
                    crate::error::Error::invalid(format!("cannot start {n} threads: {e}"))
                })?;
            Ok(pool.install(f))
        }
    }
}

#[cfg(test)]
mod tests {
    /// A worker of [`super::with_threads`] holds a 3 MiB frame (more than Rust's 2 MiB default
    /// thread stack): what the unoptimized lane kernels need.
    #[test]
    fn workers_have_room_for_unoptimized_kernel_frames() {
        let sum = super::with_threads(Some(2), || {
            rayon::join(
                || {
                    let big = std::hint::black_box([1u8; 3 << 20]);
                    big.iter().map(|&b| b as usize).sum::<usize>()
                },
                || 0,
            )
            .0
        })
        .unwrap();
        assert_eq!(sum, 3 << 20);
    }
}
