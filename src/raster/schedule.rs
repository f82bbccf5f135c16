//! Longest-first dynamic scheduling of independent tasks (the blend's runs of tiles).
//!
//! A tile's cost varies by an order of magnitude across an image (a few splats over a wall,
//! hundreds over an edge), and the blend has few tasks at the pipeline's image sizes (20
//! tiles at 80×60). Splitting an index range in halves, as a parallel iterator does, can
//! leave one thread with most of the expensive tiles; taking the tasks in decreasing order
//! of an estimated cost from a shared counter (the LPT rule: Graham, "Bounds on
//! multiprocessing timing anomalies", 1969, within 4/3 of the best makespan) leaves at
//! most the cheapest task's time unbalanced. Only *which thread* runs a task depends on
//! timing: every task's result goes to its own slot, so the output is the same for any
//! thread count and schedule (SPEC.md §7).

use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// `run(k)` for every task `k < costs.len()`, started in decreasing order of `costs[k]`
/// (ties by index) by every thread of the current pool taking the next from a shared
/// counter; the results in task order.
pub(crate) fn longest_first<R: Send>(costs: &[u64], run: impl Fn(usize) -> R + Sync) -> Vec<R> {
    let n = costs.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_unstable_by_key(|&k| (std::cmp::Reverse(costs[k]), k));
    let next = AtomicUsize::new(0);
    let workers = rayon::current_num_threads().min(n).max(1);
    let done: Vec<Vec<(usize, R)>> = (0..workers)
        .into_par_iter()
        .with_max_len(1)
        .map(|_| {
            let mut mine = Vec::new();
            // An integer counter: it hands out task numbers, never sums a result.
            while let Some(&k) = order.get(next.fetch_add(1, Ordering::Relaxed)) {
                mine.push((k, run(k)));
            }
            mine
        })
        .collect();
    let mut slots: Vec<Option<R>> = (0..n).map(|_| None).collect();
    for (k, r) in done.into_iter().flatten() {
        slots[k] = Some(r);
    }
    slots
        .into_iter()
        .map(|r| r.expect("every task ran once"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_task_runs_once_and_results_keep_task_order() {
        let costs: Vec<u64> = (0..37).map(|k| (k * 7919 % 13) as u64).collect();
        for threads in [1, 2, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let runs = std::sync::Mutex::new(Vec::new());
            let out = pool.install(|| {
                longest_first(&costs, |k| {
                    runs.lock().unwrap().push(k);
                    k * 3
                })
            });
            assert_eq!(out, (0..37).map(|k| k * 3).collect::<Vec<_>>());
            let mut r = runs.into_inner().unwrap();
            r.sort_unstable();
            assert_eq!(r, (0..37).collect::<Vec<_>>());
        }
        assert!(longest_first(&[], |k| k).is_empty());
    }

    #[test]
    fn one_thread_takes_the_costliest_first() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let runs = std::sync::Mutex::new(Vec::new());
        pool.install(|| longest_first(&[1, 5, 3, 5], |k| runs.lock().unwrap().push(k)));
        assert_eq!(runs.into_inner().unwrap(), vec![1, 3, 2, 0]);
    }
}
