//! Integration tests of `rtloop::search`: the paper's DE (`rand1bin`), L-SHADE / jSO with the Nelder–Mead
//! polish (`lshade`), and L-SHADE from a given start (`start`). Expected values come from the test functions'
//! definitions (their known minima, `defs`), never from earlier runs. Run with `cargo test --test search`.

mod defs;
mod lshade;
mod rand1bin;
mod start;
#[path = "../common/test_functions.rs"]
mod test_functions;
