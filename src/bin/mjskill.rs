//! The `mjskill` binary: see `mjskill --help`.
fn main() {
    std::process::exit(mjskill::cli::main());
}
