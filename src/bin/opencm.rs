//! Firmware for the ROBOTIS OpenCM 9.04 (STM32F103CB, Cortex-M3 at 72 MHz, no FPU): the same
//! control loop as the OpenCR's ([`walker_firmware::boards::run_then_idle`]) with the
//! fixed-point path (`math=fixed`: fixed-point sampler, integer-only IK and tick conversion),
//! the board's pins and memory layout in [`walker_firmware::boards::opencm`].
//!
//! As the OpenCR's (`wait_enable`), it waits with torque off for the operator's enable — a
//! Mode write of stand or walk on the command port (USART3: PB10 TX / PB11 RX, ROBOTIS'
//! `Serial3`, 1 Mbps 8N1) or a 50 ms press of the user button (PC15) — then runs start-up and
//! the walk ([`walker_firmware::control::run_on_enable`]); after every stop the port keeps
//! answering and a new run needs a new enable. After any reset but a power-on a run does not
//! walk (torque off, stop `NotPowerOn`) until the board is power-cycled. The run-time
//! parameters are not in this build (no flash for them): the port answers a parameter op
//! "not in this board's build".
//!
//! Build: `cargo build --profile release-m3 --target thumbv7m-none-eabi --no-default-features --features board-opencm --bin opencm`
//! (the size-oriented profile keeps it under 112 KiB of flash). Flash over SWD with probe-rs
//! (`probe-rs run --chip STM32F103CB target/thumbv7m-none-eabi/release-m3/opencm`); this
//! overwrites ROBOTIS' USB bootloader only if the image is placed at 0x0800_0000 — the link
//! places it at 0x0800_3000, after the bootloader, as ROBOTIS' own linker script does. Without
//! a probe, through that bootloader (hold USER while plugging USB in):
//! `walker flash --board opencm --serial /dev/ttyACM0 target/thumbv7m-none-eabi/release-m3/opencm`
//! (host/src/opencm_boot.rs).
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

walker_firmware::host_stub!("this firmware runs on the OpenCM 9.04 (thumbv7m-none-eabi) only");

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod firmware {
    use walker_firmware::boards::opencm::{panic_reset, OpenCmBoard};
    use walker_firmware::config::Arithmetic;
    use walker_firmware::Config;

    walker_firmware::stm32_firmware! {
        peripherals: stm32f1::stm32f103::Peripherals::take(),
        // No FPU: the board selects the fixed-point path.
        config: Config {
            arithmetic: Arithmetic::Fixed,
            wait_enable: true,
            ..Config::default()
        },
        board: OpenCmBoard::new,
        panic: panic_reset,
    }
}
