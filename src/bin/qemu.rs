//! Firmware for QEMU `mps2-an500` (firmware-in-the-loop): reads its run-time parameters from
//! the semihosting command line, runs start-up and the walk ([`walker_firmware::control::run`])
//! and exits through semihosting with the run's exit code (the one table:
//! `walker_contract::ExitCode`; the board adds the watchdog and panic codes of that table).
//!
//! Parameters: `key=value` tokens after qemu's `-append` (`docs/parameters.md`),
//! e.g. `-append "lockstep model=lipm steps=6"`. A bad token writes the start-up record and a
//! `ConfigRejected` fault record to the log and exits with 2 (the key is printed over defmt).
//! Without a simulator (bus unconnected) every device is missing: exit 11 within ~50 ms of
//! virtual time.
//!
//! Build and run:
//! ```text
//! cargo build --release --no-default-features --features board-qemu --bin qemu
//! scripts/qemu-run.sh target/thumbv7em-none-eabihf/release/qemu
//! ```
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

walker_firmware::host_stub!(
    "this firmware runs on the robot's controller (thumbv7em-none-eabihf) only"
);

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod firmware {

    use cortex_m_rt::entry;
    use walker_firmware::board::Board;
    use walker_firmware::boards::qemu_mps2::{self, QemuBoard, CMDLINE_MAX};
    use walker_firmware::control;
    use walker_firmware::ExitCode;
    use walker_firmware::{params, Config};

    #[entry]
    fn main() -> ! {
        // The stack's unused words painted for the high-water mark logged at exit.
        qemu_mps2::paint_stack();
        let mut cfg = Config::default();
        let mut cmd = [0u8; CMDLINE_MAX];
        // QEMU refuses a command line longer than the buffer: then nothing was read, and the
        // firmware must not run on defaults (it reports the refusal instead, below).
        let read = qemu_mps2::semihosting_cmdline(&mut cmd);
        let n = read.unwrap_or(0);
        let args = params::apply(&mut cfg, cmd.get(..n).unwrap_or(&[]));
        if args.is_err() {
            cfg = Config::default();
        }
        let Some(_core) = cortex_m::Peripherals::take() else {
            qemu_mps2::semihosting_exit(ExitCode::ConfigRejected.status());
        };
        let mut board = QemuBoard::new(&cfg);
        if read.is_none() {
            defmt::error!(
                "command line refused by QEMU (longer than {=usize} bytes)",
                CMDLINE_MAX
            );
            control::report_cmdline_too_long(&mut board, &cfg);
            board.exit(ExitCode::ConfigRejected.status())
        }
        if let Err(e) = args {
            defmt::error!(
                "bad parameter `{=str}` (token {=u8}): {}",
                e.key(),
                e.position,
                e.kind
            );
            control::report_arg_error(&mut board, &cfg, &e);
            board.exit(ExitCode::ConfigRejected.status())
        }
        defmt::info!(
            "lock-step {=bool} (over the host's pipes: {=bool})",
            board.lockstep(),
            board.lockstep_pipe()
        );
        let code = walker_firmware::run_walk(&mut board, &mut cfg).exit_code();
        board.exit(code)
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        qemu_mps2::panic_exit(info)
    }
}
