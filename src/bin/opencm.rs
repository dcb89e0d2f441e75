//! Firmware for the ROBOTIS OpenCM 9.04 (STM32F103CB, Cortex-M3 at 72 MHz, no FPU): the same
//! control loop as the OpenCR's ([`walker_firmware::boards::run_then_idle`]) with the
//! fixed-point path (`math=fixed`: fixed-point sampler, integer-only IK and tick conversion),
//! the board's pins and memory layout in [`walker_firmware::boards::opencm`].
//!
//! Build: `cargo build --profile release-m3 --target thumbv7m-none-eabi --no-default-features --features board-opencm --bin opencm`
//! (the size-oriented profile keeps it under 112 KiB of flash). Flash over SWD with probe-rs
//! (`probe-rs run --chip STM32F103CB target/thumbv7m-none-eabi/release-m3/opencm`); this
//! overwrites ROBOTIS' USB bootloader only if the image is placed at 0x0800_0000 — the link
//! places it at 0x0800_3000, after the bootloader, as ROBOTIS' own linker script does.
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
            ..Config::default()
        },
        board: OpenCmBoard::new,
        panic: panic_reset,
    }
}
