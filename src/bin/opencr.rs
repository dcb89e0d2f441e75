//! Firmware for the real robot: ROBOTIS OpenCR 1.0 (STM32F746ZG). This phase's minimal main:
//! brings the board up, prints the board name (defmt over RTT), writes the start-up record on
//! the log UART, then runs the tick loop idle (torque never enabled; the watchdog is started
//! only when walking begins, in a later phase).
//!
//! Build: `cargo build --release --no-default-features --features board-opencr --bin opencr`
//! Flash and run (needs probe-rs and a probe on the SWD header): `cargo run --release --bin opencr`
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

/// On the host (workspace-wide `cargo test`/`clippy --all-targets`) this binary is a stub.
#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!("this firmware runs on the robot's controller (thumbv7em-none-eabihf) only");
}

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod firmware {

    use cortex_m_rt::entry;
    use walker_firmware::board::{Board, TickTimer};
    use walker_firmware::boards::opencr::{self, OpenCrBoard};
    use walker_firmware::log::LogWriter;
    use walker_firmware::{startup_record, Config};

    #[entry]
    fn main() -> ! {
        let cfg = Config::default();
        let Some(dp) = stm32f7xx_hal::pac::Peripherals::take() else {
            cortex_m::peripheral::SCB::sys_reset();
        };
        let mut board = OpenCrBoard::new(dp, &cfg);
        defmt::info!(
            "walker-firmware {=str} on {=str}: tick {=u32} us, bus {=u32} baud",
            env!("CARGO_PKG_VERSION"),
            <OpenCrBoard as Board>::NAME,
            cfg.tick_period_us,
            cfg.bus_baud
        );
        let mut log = LogWriter::new();
        let rec = startup_record(&board, &cfg, None);
        log.write(&mut board, rec);
        loop {
            let tick = board.wait_tick();
            if tick.overrun {
                defmt::warn!("overrun at tick {=u64}", tick.index);
            }
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        opencr::panic_reset(info)
    }
}
