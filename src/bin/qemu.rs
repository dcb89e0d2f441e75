//! Firmware for QEMU `mps2-an500` (firmware-in-the-loop). This phase's minimal main: boots,
//! prints the board name (defmt over semihosting), writes one start-up record on UART1 (the
//! log) and exits 0 through semihosting.
//!
//! Build and run:
//! ```text
//! cargo build --release --no-default-features --features board-qemu --bin qemu
//! scripts/qemu-run.sh target/thumbv7em-none-eabihf/release/qemu
//! ```
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

/// On the host (workspace-wide `cargo test`/`clippy --all-targets`) this binary is a stub.
#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!("this firmware runs on the robot's controller (thumbv7em-none-eabihf) only");
}

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod firmware {

    use cortex_m_rt::entry;
    use walker_firmware::board::{Board, Clock, LogSink};
    use walker_firmware::boards::qemu_mps2::{self, QemuBoard};
    use walker_firmware::log::LogWriter;
    use walker_firmware::{startup_record, Config};

    #[entry]
    fn main() -> ! {
        let cfg = Config::default();
        let Some(cp) = cortex_m::Peripherals::take() else {
            qemu_mps2::semihosting_exit(2);
        };
        let mut board = QemuBoard::new(cp.SYST, &cfg);
        defmt::info!(
            "walker-firmware {=str} on {=str}: tick {=u32} us, bus {=u32} baud, lockstep {=bool}",
            env!("CARGO_PKG_VERSION"),
            QemuBoard::NAME,
            cfg.tick_period_us,
            cfg.bus_baud,
            board.lockstep()
        );

        let mut log = LogWriter::new();
        // The bus is not probed in this phase: the record says so (probed = false).
        let rec = startup_record(&board, &cfg, None);
        log.write(&mut board, rec);
        board.write_log(&[]);
        defmt::info!(
            "start-up record written at t = {=u64} us; exiting",
            board.now_us()
        );
        board.exit(0)
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        qemu_mps2::panic_exit(info)
    }
}
