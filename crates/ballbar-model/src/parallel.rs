//! The one place the project makes worker threads: a scoped pool over an index range, std only.
//! The fit (a QR per run), the diagnosis (candidate blocks per run) and the CLI (reading input
//! files) use it; anything else that wants to work in parallel should too, so that a thread count
//! means the same everywhere.

use std::sync::atomic::{AtomicUsize, Ordering};

/// Run `f` over `0..n` on up to `threads` scoped worker threads; results in index order.
pub fn par_map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let mut out: Vec<Option<T>> = (0..n).map(|_| None).collect();
    std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads.clamp(1, n.max(1)))
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed);
                        if k >= n {
                            break;
                        }
                        done.push((k, f(k)));
                    }
                    done
                })
            })
            .collect();
        for w in workers {
            for (k, v) in w.join().expect("a worker thread panicked") {
                out[k] = Some(v);
            }
        }
    });
    out.into_iter().map(|v| v.expect("every index done")).collect()
}

#[cfg(test)]
mod tests {
    use super::par_map;

    #[test]
    fn results_come_in_index_order_whatever_the_threads() {
        for threads in [0, 1, 2, 7, 100] {
            assert_eq!(par_map(10, threads, |k| k * k), (0..10).map(|k| k * k).collect::<Vec<_>>());
        }
        assert!(par_map(0, 4, |k| k).is_empty());
    }
}
