//! The one integration-test binary; the suites live in `tests/suite/`.
mod suite;
