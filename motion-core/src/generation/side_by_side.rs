//! Samples generated side by side, each on a single-threaded worker of its own.
//!
//! One batch of every sample keeps every core busy only in the denoiser's products: candle runs
//! the element-wise operations, the constraint terms and autograd's bookkeeping of each step on
//! one thread, while the other cores wait. With one sample per worker every core runs a
//! sample's whole step, and a sample's optimised motion depends on its seed and index alone,
//! not on how many samples run beside it.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;

/// The workers [`side_by_side`] runs `samples` on from the current rayon pool: one per sample,
/// at most one per thread (1: the samples run one after the other on the pool).
pub fn workers(samples: usize) -> usize {
    samples.min(rayon::current_num_threads()).max(1)
}

/// Runs `job(i, report)` for every sample `i` in `0..samples` and returns the results in
/// sample order.
///
/// With two or more samples and two or more threads in the current rayon pool, the jobs run on
/// `min(samples, threads)` workers, each a rayon pool of one thread, which takes the next
/// sample when it is done with one; every message a job passes to `report` reaches `on` (with
/// the sample's index) on the calling thread while the jobs run. Otherwise the samples run one
/// after the other on the current pool. A job that panics panics the caller.
pub fn side_by_side<T: Send, P: Send>(
    samples: usize,
    job: impl Fn(usize, &mut dyn FnMut(P)) -> T + Sync,
    mut on: impl FnMut(usize, P),
) -> Result<Vec<T>, rayon::ThreadPoolBuildError> {
    let workers = workers(samples);
    if workers <= 1 {
        return Ok((0..samples).map(|i| job(i, &mut |p| on(i, p))).collect());
    }
    let pools: Vec<rayon::ThreadPool> =
        (0..workers).map(|_| rayon::ThreadPoolBuilder::new().num_threads(1).build()).collect::<Result<_, _>>()?;
    let next = AtomicUsize::new(0);
    let (sender, messages) = mpsc::channel();
    let mut done: Vec<(usize, T)> = std::thread::scope(|scope| {
        let handles: Vec<_> = pools
            .iter()
            .map(|pool| {
                let (sender, job, next) = (sender.clone(), &job, &next);
                scope.spawn(move || {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= samples {
                            return done;
                        }
                        // A closed channel means the caller is unwinding; the message is moot.
                        let out = pool.install(|| job(i, &mut |p| sender.send((i, p)).unwrap_or(())));
                        done.push((i, out));
                    }
                })
            })
            .collect();
        drop(sender);
        for (i, p) in messages {
            on(i, p);
        }
        handles.into_iter().flat_map(|h| h.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))).collect()
    });
    done.sort_by_key(|&(i, _)| i);
    Ok(done.into_iter().map(|(_, out)| out).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn in_pool<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(f)
    }

    #[test]
    fn every_sample_runs_once_on_a_one_thread_worker_and_its_messages_reach_the_caller() {
        let caller = std::thread::current().id();
        let mut seen = Vec::new();
        let out = in_pool(2, || {
            side_by_side(
                5,
                |i, report: &mut dyn FnMut((usize, std::thread::ThreadId))| {
                    report((rayon::current_num_threads(), std::thread::current().id()));
                    i * 10
                },
                |i, (threads, worker)| seen.push((i, threads, worker)),
            )
            .unwrap()
        });
        assert_eq!(out, vec![0, 10, 20, 30, 40]);
        seen.sort_by_key(|s| s.0);
        assert_eq!(seen.iter().map(|s| s.0).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4]);
        assert!(seen.iter().all(|&(_, threads, worker)| threads == 1 && worker != caller));
    }

    #[test]
    fn one_sample_or_one_thread_runs_in_place_on_the_current_pool() {
        for (threads, samples) in [(2, 1), (1, 3)] {
            let (out, pools) = in_pool(threads, || {
                let mut pools = Vec::new();
                let out = side_by_side(
                    samples,
                    |i, report| {
                        report(rayon::current_num_threads());
                        i
                    },
                    |_, n| pools.push(n),
                )
                .unwrap();
                (out, pools)
            });
            assert_eq!(out, (0..samples).collect::<Vec<_>>());
            assert_eq!(pools, vec![threads; samples]);
        }
    }

    #[test]
    #[should_panic(expected = "sample 3 failed")]
    fn a_panicking_job_panics_the_caller() {
        in_pool(2, || {
            side_by_side(
                4,
                |i, _: &mut dyn FnMut(())| {
                    if i == 3 {
                        panic!("sample {i} failed");
                    }
                },
                |_, _| {},
            )
        })
        .unwrap();
    }
}
