//! `walker`: host tools of the walking controller (see `walker --help`).

fn main() {
    // Arguments as `OsString`: a path that is not UTF-8 reaches its option intact.
    std::process::exit(walker_host::cli::main_with(std::env::args_os().skip(1)));
}
