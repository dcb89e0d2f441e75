//! Firmware for the real robot: ROBOTIS OpenCR 1.0 (STM32F746ZG). Brings the board up and,
//! with the compiled-in [`walker_firmware::Config`] (its defaults and `wait_enable`), waits
//! with torque off for the operator's enable on the command port (a Mode write of stand or
//! walk), then runs start-up and the walk ([`walker_firmware::control::run_on_enable`]:
//! probe, Return Delay Time, torque on, 1.5 s move to the initial pose, standing for commands,
//! the stop); after every stop the port keeps answering (State stopped, Stop Code, Fault
//! Kind) and a new run needs a new enable. Each run logs the reset cause (RCC_CSR) and any
//! panic or watchdog record left in no-init RAM; after any reset but a power-on (brown-out,
//! watchdog, panic's software reset, the reset button or the debugger) a run does NOT walk:
//! torque off (confirmed), servo power off, stop `NotPowerOn` (exit 22), until the board is
//! power-cycled.
//!
//! Build: `cargo build --release --no-default-features --features board-opencr --bin opencr`
//! (a ROBOTIS OP3's OpenCR: `--features robot-op3`, [`walker_firmware::control::BUILD_ROBOT`])
//! Flash and run (needs probe-rs and a probe on the SWD header): `cargo run --release --bin opencr`
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

walker_firmware::host_stub!(
    "this firmware runs on the robot's controller (thumbv7em-none-eabihf) only"
);

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod firmware {
    use walker_firmware::boards::opencr::{panic_reset, OpenCrBoard};
    use walker_firmware::Config;

    walker_firmware::stm32_firmware! {
        peripherals: stm32f7xx_hal::pac::Peripherals::take(),
        config: Config {
            wait_enable: true,
            ..walker_firmware::control::build_defaults()
        },
        board: OpenCrBoard::new,
        panic: panic_reset,
    }
}
