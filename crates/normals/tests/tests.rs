//! Integration tests of `voxreg-normals`, one binary (run in release mode: `cargo test
//! --release -p voxreg-normals --test tests`; `-- --nocapture` prints the measurements).
//!
//! - [`accuracy`]: every estimator against analytic shapes with known normals, errors
//!   shrinking as the grid refines, multi-label configurations known by symmetry.
//! - [`at`]: the Ambrosio-Tortorelli estimator against shapes with known normals and
//!   creases.
//! - [`interrupt`]: every estimator stops at a raised interrupt.

mod accuracy;
mod at;
mod interrupt;
