//! What the two STM32 robot controllers ([`super::opencr`], [`super::opencm`]) share: the crash
//! record in no-init RAM and the panic path, the board state besides the peripherals and the
//! log ring ([`Stm32State`]: µs clock, tick schedule, watchdog flag, bus UART errors, reset
//! flags), the bus UART's send, receive and rate ([`Stm32Bus`] over each board's [`BusUart`]),
//! the trait implementations built on them ([`stm32_board!`]) and the register-block accessors
//! ([`register_blocks!`]).

use core::mem::MaybeUninit;
use cortex_m::peripheral::SCB;

use crate::board::{
    stm32f7_reset_cause, BusError, Clock, CrashCell, CrashCode, ResetCause, TickSchedule, Watchdog,
    WrapClock,
};
use crate::Config;

/// The crash record in RAM that is not zeroed at start-up (`.uninit`, NOLOAD in cortex-m-rt's
/// `link.x`): the loop notes its tick there, a panic records itself, and the next boot logs it
/// ([`crate::control`]). After a power-on its content is random and ignored.
#[link_section = ".uninit.WALKER_CRASH"]
static mut CRASH: MaybeUninit<CrashCell> = MaybeUninit::uninit();

/// The crash record (see [`CRASH`]).
pub(crate) fn crash_cell() -> &'static mut CrashCell {
    // SAFETY: single core; the board (one value, `Peripherals::take` makes it unique) and the
    // panic path (after which nothing else runs) are its only users. Every field is a u32, any
    // bit pattern is a value; `CrashCell` accesses them volatile.
    unsafe { &mut *core::ptr::addr_of_mut!(CRASH).cast::<CrashCell>() }
}

/// Declares each `fn name() -> &'static Block` accessor of a peripheral's register block
/// (`fn name() -> Block = Peripheral;`), with who owns it after the board's `new` in the
/// accessor's own docs.
macro_rules! register_blocks {
    ($($(#[$meta:meta])* fn $name:ident() -> $block:ty = $periph:ty;)+) => {
        $(
            $(#[$meta])*
            fn $name() -> &'static $block {
                // SAFETY: a peripheral's register block is always mapped at its fixed address;
                // the accessor's docs say who writes it after the board's `new` (the panic path
                // uses it on purpose, after which nothing else runs).
                unsafe { &*<$periph>::ptr() }
            }
        )+
    };
}
pub(crate) use register_blocks;

/// Panic path of an STM32 board: log, record the panic in no-init RAM, the board's
/// `torque_off` (bounded, from anywhere), reset (the next boot logs the record and does not
/// walk). The log has the panic's location and its message when that is a plain string, not
/// a formatted one: formatting it would link the formatting of every library message that
/// can reach it (flash the OP3's bootloader image does not have).
// Inline: the board's panic handler is this (no call through a pointer for `torque_off`).
// The OpenCM 9.04 has its own (its torque off needs no board).
#[inline(always)]
#[cfg_attr(feature = "board-opencm", allow(dead_code))]
pub(crate) fn panic_reset(info: &core::panic::PanicInfo, torque_off: impl FnOnce()) -> ! {
    let message = info.message().as_str().unwrap_or("");
    let (file, line) = info.location().map_or(("", 0), |l| (l.file(), l.line()));
    defmt::error!("panic: {=str} at {=str}:{=u32}", message, file, line);
    crash_cell().record(CrashCode::Panic);
    torque_off();
    SCB::sys_reset()
}

/// The state of an STM32 board besides its peripherals and its log ring (a field of the board
/// itself, so that its kilobyte is cleared in place rather than built on the stack and copied).
pub(crate) struct Stm32State {
    /// The µs counter extended to 64 bits.
    pub(crate) clock: WrapClock,
    /// Tick deadlines and overruns.
    pub(crate) schedule: TickSchedule,
    /// The watchdog was started ([`crate::board::Watchdog::start`]).
    pub(crate) watchdog_running: bool,
    /// Overrun/framing/noise errors seen on the bus UART.
    pub(crate) uart_errors: u32,
    /// RCC_CSR as read at start-up (its reset flags).
    pub(crate) reset_csr: u32,
}

impl Stm32State {
    /// The state at start-up: ticks of `cfg.tick_period_us`, the watchdog not started, the
    /// reset flags `reset_csr` (RCC_CSR).
    pub(crate) fn new(cfg: &Config, reset_csr: u32) -> Self {
        Stm32State {
            clock: WrapClock::new(),
            schedule: TickSchedule::new(cfg.tick_period_us),
            watchdog_running: false,
            uart_errors: 0,
            reset_csr,
        }
    }

    /// The reset cause and the raw flags: RCC_CSR of the F103 has the F7's flags at the same
    /// bits (PINRSTF 26, PORRSTF 27, SFTRSTF 28, IWDGRSTF 29, WWDGRSTF 30, LPWRRSTF 31) and no
    /// BORRSTF (a brown-out is a power-on reset there).
    pub(crate) fn reset_cause(&self) -> (ResetCause, u32) {
        (stm32f7_reset_cause(self.reset_csr), self.reset_csr >> 24)
    }

    /// Counts one error seen on the bus UART.
    pub(crate) fn count_uart_error(&mut self) {
        self.uart_errors = self.uart_errors.saturating_add(1);
    }
}

/// Waits (bounded: `limit` loop iterations) until `ready` holds; `Err(Timeout)` otherwise (the
/// peripheral is hung).
pub(crate) fn spin(limit: u32, ready: impl Fn() -> bool) -> Result<(), BusError> {
    for _ in 0..limit {
        if ready() {
            return Ok(());
        }
    }
    Err(BusError::Timeout)
}

/// A USART's BRR for `baud` from its kernel clock `clock_hz` (oversampling 16), if it is in
/// 16..=0xFFFF.
pub(crate) fn brr(clock_hz: u32, baud: u32) -> Option<u32> {
    let div = clock_hz.checked_div(baud)?;
    (16..=0xFFFF).contains(&div).then_some(div)
}

/// A board's bus UART as [`Stm32Bus`] drives it: the F103's USART and the F746's differ in
/// their registers' names and in how error flags clear, not in what the bus code does.
pub(crate) trait BusUart {
    /// Longest busy-wait on a flag (TXE, TC), loop iterations.
    const SPIN_LIMIT: u32;
    /// The UART's kernel clock, Hz (its BRR divides it).
    const CLOCK_HZ: u32;
    /// TXE: the transmit data register is free.
    fn tx_empty(&self) -> bool;
    /// TC: the last byte has left the line.
    fn tx_complete(&self) -> bool;
    /// Puts `b` in the transmit data register.
    fn write(&self, b: u8);
    /// One status read: (an overrun, framing or noise error is flagged, a received byte waits);
    /// a UART whose flags clear by a write clears them here.
    fn status(&self) -> (bool, bool);
    /// The received byte (after [`BusUart::status`]: on the F103 this read clears the flags).
    fn read(&self) -> u8;
    /// Clears the error flags and drops any pending input; whether an error was flagged.
    fn discard(&self) -> bool;
    /// The UART disabled (UE clear), BRR = `div` (in 16..=0xFFFF), enabled again.
    fn set_divider(&self, div: u32);
}

/// The servo bus of an STM32 board on its [`BusUart`]: `send` and `recv` of
/// [`crate::board::ServoBus`], the watchdog fed once per call.
pub(crate) trait Stm32Bus: Clock + Watchdog {
    /// The bus UART.
    type Uart: BusUart;
    /// The bus UART's registers.
    fn bus_uart(&self) -> Self::Uart;
    /// Drives the bus direction pin: transmit (`true`) or receive.
    fn bus_direction(&mut self, transmit: bool);
    /// The board's state (its UART error counter).
    fn stm32_state(&mut self) -> &mut Stm32State;

    /// Clears the bus UART's error flags (counting them) and drops any pending input.
    fn discard_input(&mut self) {
        if self.bus_uart().discard() {
            self.stm32_state().count_uart_error();
        }
    }

    /// [`crate::board::ServoBus::send`]: the packet out with the line driven, each byte when
    /// TXE, then TC (bounded waits: [`BusError::Timeout`]); input before and the transceiver's
    /// echo after are dropped.
    fn bus_send(&mut self, packet: &[u8]) -> Result<(), BusError> {
        self.feed();
        self.discard_input();
        let u = self.bus_uart();
        self.bus_direction(true);
        let mut sent = Ok(());
        for &b in packet {
            sent = spin(Self::Uart::SPIN_LIMIT, || u.tx_empty());
            if sent.is_err() {
                break;
            }
            u.write(b);
        }
        let done = sent.and_then(|()| spin(Self::Uart::SPIN_LIMIT, || u.tx_complete()));
        self.bus_direction(false);
        // Whatever the transceiver echoed while we were driving the line is not a reply.
        self.discard_input();
        done
    }

    /// [`crate::board::ServoBus::recv`]: bytes until `buf` is full or `timeout_us` has passed
    /// on the board's µs clock, UART errors counted.
    fn bus_recv(&mut self, buf: &mut [u8], timeout_us: u32) -> Result<usize, BusError> {
        // Bounded by `timeout_us`; the watchdog is fed once per wait.
        self.feed();
        let u = self.bus_uart();
        let deadline = self.now_us() + u64::from(timeout_us);
        let mut n = 0;
        while n < buf.len() {
            let (error, ready) = u.status();
            if error {
                self.stm32_state().count_uart_error();
            }
            if ready {
                if let Some(slot) = buf.get_mut(n) {
                    *slot = u.read();
                }
                n += 1;
            } else if self.now_us() >= deadline {
                break;
            }
        }
        Ok(n)
    }

    /// The rate part of [`crate::board::ServoBus::set_baud`]: the bus UART's divider for
    /// `baud` ([`BusError::UnsupportedBaud`] out of 16..=0xFFFF), set once the last byte has
    /// left the line (bounded wait: [`BusError::Timeout`]).
    fn bus_set_baud(&mut self, baud: u32) -> Result<(), BusError> {
        let div = brr(Self::Uart::CLOCK_HZ, baud).ok_or(BusError::UnsupportedBaud)?;
        let u = self.bus_uart();
        spin(Self::Uart::SPIN_LIMIT, || u.tx_complete())?;
        u.set_divider(div);
        Ok(())
    }
}

/// The parts an STM32 board shares with the other one, for a board struct with the fields
/// `state` ([`Stm32State`]), `ring` ([`crate::board::LogRing`]) and `baud` (the bus rate), the
/// methods `pump_log` (moves log bytes from the ring to the log UART while it is free),
/// `now_us` ([`crate::board::Clock`]) and `feed` ([`crate::board::Watchdog`]), and
/// [`Stm32Bus`]: its [`crate::board::ServoBus`] (on [`Stm32Bus`]), its
/// [`crate::board::TickTimer`] (busy-waits for the tick, draining the log meanwhile),
/// [`crate::board::LogSink`] (into the ring), the log and error counters, and its
/// [`crate::board::Board`] with `name`, `id` and the board's own items (`servo_power`, `exit`,
/// …; `exit` ends with `shut_down`).
macro_rules! stm32_board {
    (
        impl<$($g:ident: $bound:path),*> for $board:ty {
            name: $name:literal,
            id: $id:expr,
            $($own:tt)*
        }
    ) => {
        impl<$($g: $bound),*> $board {
            /// Log frames dropped because the ring was full.
            pub fn log_dropped(&self) -> u32 {
                self.ring.dropped()
            }

            /// Overrun/framing/noise errors seen on the bus UART.
            pub fn uart_errors(&self) -> u32 {
                self.state.uart_errors
            }

            /// Torque off, the log drained (bounded: ≤ 1 KiB of ring at 921 600 baud ≈ 11 ms,
            /// 20 ms at most), the board's panic-path torque off, reset.
            fn shut_down(&mut self, panic_torque_off: impl FnOnce()) -> ! {
                use $crate::board::{Board, Clock};
                self.torque_off_best_effort();
                let start = self.now_us();
                while !self.ring.is_empty() && self.now_us() < start + 20_000 {
                    self.pump_log();
                }
                panic_torque_off();
                cortex_m::peripheral::SCB::sys_reset()
            }
        }

        impl<$($g: $bound),*> $crate::board::ServoBus for $board {
            fn send(&mut self, packet: &[u8]) -> Result<(), $crate::board::BusError> {
                self.bus_send(packet)
            }

            fn recv(
                &mut self,
                buf: &mut [u8],
                timeout_us: u32,
            ) -> Result<usize, $crate::board::BusError> {
                self.bus_recv(buf, timeout_us)
            }

            fn baud(&self) -> u32 {
                self.baud
            }

            fn set_baud(&mut self, baud: u32) -> Result<(), $crate::board::BusError> {
                self.bus_set_baud(baud)?;
                self.baud = baud;
                Ok(())
            }
        }

        impl<$($g: $bound),*> $crate::board::TickTimer for $board {
            fn period_us(&self) -> u32 {
                self.state.schedule.period_us()
            }

            fn wait_tick(&mut self) -> $crate::board::Tick {
                use $crate::board::{Clock, Watchdog};
                let plan = self.state.schedule.plan(self.now_us());
                if let Some(t) = plan.wait_until_us {
                    // Bounded by the tick period; fed once per wait.
                    self.feed();
                    while self.now_us() < t {
                        self.pump_log();
                    }
                }
                self.pump_log();
                plan.tick
            }

            fn overruns(&self) -> u32 {
                self.state.schedule.overruns()
            }
        }

        impl<$($g: $bound),*> $crate::board::LogSink for $board {
            fn write_log(&mut self, bytes: &[u8]) {
                self.ring.push(bytes);
                self.pump_log();
            }
        }

        impl<$($g: $bound),*> $crate::board::Board for $board {
            const NAME: &'static str = $name;
            const ID: $crate::record::BoardId = $id;

            fn torque_off_best_effort(&mut self) {
                use $crate::board::ServoBus;
                let _ = self.send(&$crate::board::TORQUE_OFF_PACKET);
            }

            fn reset_cause(&self) -> ($crate::board::ResetCause, u32) {
                self.state.reset_cause()
            }

            fn crash_cell(&mut self) -> &mut $crate::board::CrashCell {
                $crate::boards::stm32::crash_cell()
            }

            $($own)*
        }
    };
}
pub(crate) use stm32_board;

/// A command port's receive ring that a DMA stream (channel) fills in circular mode: its bytes,
/// written only by the DMA once the board has started it, read only through
/// [`DmaRing::take`] with volatile loads ([`crate::rx_ring::DmaRxCursor`] keeps the reader's
/// place).
pub(crate) struct DmaRing<const N: usize>(core::cell::UnsafeCell<[u8; N]>);

// SAFETY: the one writer is the DMA, the one reader the control loop (volatile loads of single
// bytes: a byte is never torn).
unsafe impl<const N: usize> Sync for DmaRing<N> {}

impl<const N: usize> DmaRing<N> {
    /// A zeroed ring (a static in .bss).
    pub(crate) const fn new() -> Self {
        DmaRing(core::cell::UnsafeCell::new([0; N]))
    }

    /// Its address, the DMA's memory address register's value.
    pub(crate) fn address(&self) -> u32 {
        self.0.get() as u32
    }

    /// Copies the bytes the DMA wrote since `cursor`'s last call into `out`; how many.
    /// `remaining` is the stream's remaining-transfer count (NDTR / CNDTR), read by the caller
    /// just before.
    pub(crate) fn take(
        &self,
        cursor: &mut crate::rx_ring::DmaRxCursor<N>,
        remaining: usize,
        out: &mut [u8],
    ) -> usize {
        // The bytes before the DMA's position are written before the count moved past them.
        core::sync::atomic::compiler_fence(core::sync::atomic::Ordering::Acquire);
        let ring = self.0.get() as *const u8;
        cursor.take(
            remaining,
            |i| {
                // SAFETY: i < N (the cursor's invariant, clamped again); a volatile byte load
                // of memory only the DMA writes.
                unsafe { core::ptr::read_volatile(ring.add(i.min(N.saturating_sub(1)))) }
            },
            out,
        )
    }
}
