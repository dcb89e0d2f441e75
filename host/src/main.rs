//! `walker`: host tools of the walking controller (see `walker --help`).

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    std::process::exit(walker_host::cli::main_with(&args));
}
