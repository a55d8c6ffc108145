"""The package version (one place; the Rust crate has the same number in Cargo.toml)."""

__version__ = "0.1.0"
