//! Worker pools, and the one way a call leaves the GIL to run in one: [`detach_in_pool`].

use std::sync::{Arc, Mutex, OnceLock};

use pyo3::prelude::*;

use crate::error::{Error, Result};

/// How many pools of different sizes are kept: a program that fits on many thread counts keeps the
/// most recently used few, and an older pool's threads end once its last running call returns.
pub(crate) const KEPT_POOLS: usize = 4;

type Pools = Mutex<Vec<(Option<usize>, Arc<rayon::ThreadPool>)>>;

fn pools() -> &'static Pools {
    static POOLS: OnceLock<Pools> = OnceLock::new();
    POOLS.get_or_init(|| Mutex::new(Vec::new()))
}

/// A worker pool of `threads` threads (all cores when `None`), started once per size and kept (the
/// [`KEPT_POOLS`] most recently used sizes): starting threads costs more than a small fit's search.
/// Results never depend on the pool (see `search`).
fn pool(threads: Option<usize>) -> Result<Arc<rayon::ThreadPool>> {
    if threads == Some(0) {
        return Err(Error::Value("threads must be >= 1".into()));
    }
    let mut pools = pools().lock().unwrap_or_else(|e| e.into_inner());
    // Most recently used last.
    if let Some(i) = pools.iter().position(|(n, _)| *n == threads) {
        let entry = pools.remove(i);
        let p = entry.1.clone();
        pools.push(entry);
        return Ok(p);
    }
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        b = b.num_threads(n);
    }
    let p = Arc::new(
        b.build()
            .map_err(|e| Error::Invalid(format!("cannot start worker threads: {e}")))?,
    );
    if pools.len() >= KEPT_POOLS {
        pools.remove(0); // dropped once no call runs in it: rayon then ends its threads
    }
    pools.push((threads, p.clone()));
    Ok(p)
}

/// The thread counts of the pools kept now, least recently used first (`None`: all cores).
pub(crate) fn kept_pools() -> Vec<Option<usize>> {
    let pools = pools().lock().unwrap_or_else(|e| e.into_inner());
    pools.iter().map(|(n, _)| *n).collect()
}

/// Run `f` without the GIL inside the pool of `threads` threads (see [`pool`]).
pub(crate) fn detach_in_pool<T, F>(py: Python<'_>, threads: Option<usize>, f: F) -> PyResult<T>
where
    T: Send,
    F: FnOnce() -> T + Send,
{
    let pool = pool(threads)?;
    Ok(py.detach(|| pool.install(f)))
}
