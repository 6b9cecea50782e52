//! Generators stub.
