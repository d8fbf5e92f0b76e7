//! No code: this crate only pins dependency features (see its Cargo.toml), so that the quick
//! start's builds share every compiled dependency.
