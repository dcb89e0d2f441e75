//! Board support: one module per board, compiled only for the bare-metal ARM target with its
//! feature (`board-qemu` → [`qemu_mps2`], `board-opencr` → [`opencr`], `board-opencm` →
//! [`opencm`]).

#[cfg(feature = "board-opencm")]
pub mod opencm;
#[cfg(feature = "board-opencr")]
pub mod opencr;
#[cfg(feature = "board-qemu")]
pub mod qemu_mps2;
#[cfg(any(feature = "board-opencr", feature = "board-opencm"))]
mod stm32;
#[cfg(feature = "board-qemu")]
pub mod tick_cost;

/// The main of a real robot controller: the board brought up by `bring_up` from its
/// `peripherals` (a reset when they were taken already) and `cfg`, then [`run_then_idle`].
#[cfg(any(feature = "board-opencr", feature = "board-opencm"))]
// Inline: the board is then brought up in the binary's main, as before this helper.
#[inline(always)]
pub fn start<P, B: crate::board::Board>(
    peripherals: Option<P>,
    cfg: &mut crate::Config,
    bring_up: impl FnOnce(P, &crate::Config) -> B,
) -> ! {
    let Some(p) = peripherals else {
        cortex_m::peripheral::SCB::sys_reset();
    };
    // The board reads (and clears) the reset flags; `control::run` decides from them.
    let mut board = bring_up(p, cfg);
    run_then_idle(&mut board, cfg)
}

/// The `main` and panic handler of a real robot controller's firmware binary (the STM32 boards):
/// [`crate::boards::start`] with the `peripherals` taken, the configuration `config` and the board's `board`
/// bring-up; a panic goes to the board's `panic` path (torque off, then a reset).
#[cfg(any(feature = "board-opencr", feature = "board-opencm"))]
#[macro_export]
macro_rules! stm32_firmware {
    (peripherals: $take:expr, config: $cfg:expr, board: $new:path, panic: $panic:path $(,)?) => {
        #[cortex_m_rt::entry]
        fn main() -> ! {
            let mut cfg = $cfg;
            $crate::boards::start($take, &mut cfg, $new)
        }

        #[panic_handler]
        fn panic(info: &core::panic::PanicInfo) -> ! {
            $panic(info)
        }
    };
}

/// The main of a real robot controller after its board is up: logs the start-up line, then
/// with [`crate::Config::wait_enable`] (the OpenCR and OpenCM 9.04 builds) waits for the
/// operator's enable (on the command port or the board's button) before every run and answers
/// the port between runs, for ever ([`crate::control::run_on_enable`]); without it runs
/// [`crate::control::run`] once (probe, torque on, ramp, walk, stop; after any reset but a
/// power-on it does not walk). When the run or the wait ends it idles: torque stays off, the
/// tick keeps running and the watchdog is fed, so the board does not reset into a new walk.
#[cfg(any(feature = "board-opencr", feature = "board-opencm"))]
pub fn run_then_idle<B: crate::board::Board>(board: &mut B, cfg: &mut crate::Config) -> ! {
    let end = loop {
        let end = crate::run_walk(board, cfg);
        if !cfg.wait_enable {
            break end;
        }
        defmt::info!("Mode = torque off while waiting: waiting again");
    };
    defmt::warn!(
        "run ended (exit code {=i32}); torque off, idling",
        end.exit_code()
    );
    loop {
        let tick = board.wait_tick();
        if tick.overrun {
            defmt::warn!("overrun at tick {=u64}", tick.index);
        }
        board.feed();
    }
}
