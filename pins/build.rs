//! Empty: cargo resolves a package's build dependencies (here the pinned `syn`) only when the
//! package has a build script.
fn main() {}
