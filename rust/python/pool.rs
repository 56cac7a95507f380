//! Worker pools, and the one way a call leaves the GIL to run in one: [`detach_in_pool`].

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use pyo3::prelude::*;

use crate::error::{Error, Result};

/// A worker pool of `threads` threads (all cores when `None`), started once per size and kept: starting
/// threads costs more than a small fit's search. Results never depend on the pool (see `search`).
fn pool(threads: Option<usize>) -> Result<Arc<rayon::ThreadPool>> {
    static POOLS: OnceLock<Mutex<HashMap<Option<usize>, Arc<rayon::ThreadPool>>>> = OnceLock::new();
    if threads == Some(0) {
        return Err(Error::Value("threads must be >= 1".into()));
    }
    let mut pools = POOLS
        .get_or_init(|| Mutex::new(HashMap::new()))
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(p) = pools.get(&threads) {
        return Ok(p.clone());
    }
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        b = b.num_threads(n);
    }
    let p = Arc::new(
        b.build()
            .map_err(|e| Error::Invalid(format!("cannot start worker threads: {e}")))?,
    );
    pools.insert(threads, p.clone());
    Ok(p)
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
