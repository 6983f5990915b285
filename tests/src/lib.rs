//! End-to-end tests across hullcut's crates live in `tests/`; this library is empty.
