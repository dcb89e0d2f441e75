//! `walker`: host tools of the walking controller (see `walker --help`).

fn main() {
    // A panic in any thread (the simulator's bus server, a capture reader) ends the process, as
    // the release profile's `panic = "abort"` has it, also in the dev build the tests run: a run
    // with a dead thread must not wait on it. The dev profile unwinds so that its tests and
    // binaries share one build of the dependencies.
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        report(info);
        std::process::abort();
    }));
    // Arguments as `OsString`: a path that is not UTF-8 reaches its option intact.
    std::process::exit(walker_host::cli::main_with(std::env::args_os().skip(1)));
}
