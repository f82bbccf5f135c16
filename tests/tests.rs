//! The command-line package's integration tests (package `unseen-cli`, test `tests`): the
//! suites of `tests/suite/` run the `unseen` program, and use the library for their inputs
//! and checks. The suites that use only the library are the engine's (`tests/engine/`);
//! both include the helpers of `tests/support/`.
mod suite;
mod support;
