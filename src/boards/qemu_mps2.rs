//! QEMU `mps2-an500` (Cortex-M7; `mps2-an386` Cortex-M4F runs the same ELF) as a board:
//! firmware-in-the-loop with a simulated robot, bit-for-bit deterministic whatever the host load.
//!
//! # Wiring (qemu's `-serial` options map in order to UART0, UART1, UART2)
//! | UART | base | use |
//! | --- | --- | --- |
//! | UART0 | 0x4000_4000 | the servo bus (`-serial tcp:127.0.0.1:PORT,nodelay=on` to the simulator; `null` = unconnected) |
//! | UART1 | 0x4000_5000 | the binary ZMP-response log ([`crate::record`]; to a file or TCP) |
//! | UART2 | 0x4000_6000 | the lock-step channel (TCP to the simulator; unused with the pipes) |
//! | UART3 | 0x4000_7000 | the command port ([`walker_contract::command_port`]; `-serial tcp:…` from the host, or absent) |
//!
//! The command port is the OpenCR's in time: bytes reach the firmware no faster than its line
//! carries them ([`COMMAND_BAUD`], 10 bits a byte) into a ring of the OpenCR's size
//! ([`COMMAND_RX_RING`]), and bytes that find the ring full are lost and logged
//! ([`crate::rx_ring::LineRx`]: qemu's character device would otherwise hold the sender back,
//! hiding a reader too slow for the real line); each reply holds the loop for its bytes' line
//! time, as the OpenCR's transmit loop does.
//!
//! CMSDK APB UART registers: DATA 0x00, STATE 0x04 (bit 0 TX full, bit 1 RX full), CTRL 0x08
//! (bit 0 TX enable, bit 1 RX enable), BAUDDIV 0x10 (≥ 16, 25 MHz clock). defmt goes out over
//! semihosting (stdout of qemu), the exit code through semihosting SYS_EXIT_EXTENDED.
//! `scripts/qemu-run.sh` starts qemu with all of this; see `docs/lockstep.md`.
//!
//! # Lock-step protocol (firmware side; the simulator implements the other end exactly)
//! Lock-step is on when the semihosting command line (qemu `-append`) contains the word
//! `lockstep` (`scripts/qemu-run.sh --lockstep SPEC` adds it: the UART transport below) or
//! `lockstep=PREFIX` (`walker fil`: the pipe transport, [`walker_contract::lockstep`]). Without
//! either the bus is treated as unconnected: packets are written to UART0 and every read times
//! out at once.
//!
//! * **Pipe transport**: the same frames and the bus packets on two named pipes the host
//!   creates, `PREFIX-to-sim` (time frames, then `0x50`, u16 LE length and the packet) and
//!   `PREFIX-to-fw` (`0xA5`, the count, then the reply bytes), opened with semihosting
//!   SYS_OPEN at start-up. A packet with its time frame is one SYS_WRITE, an announcement with
//!   its reply usually one SYS_READ: QEMU makes one host call where the UARTs wake its vCPU for
//!   every byte. The virtual clock counts the same bytes either way, so a run's figures do not
//!   depend on the transport. The rest of this section describes the UART transport.
//!
//! * **Time frames, firmware → simulator on UART2**: `0x5A` followed by the board's virtual
//!   time as u64 little-endian microseconds (9 bytes). Sent at the start of every control tick
//!   and before each instruction packet on the bus; a frame whose time equals the previous
//!   frame's is not repeated. The simulator advances its physics to that time.
//! * **Reply announcements, simulator → firmware on UART2**: after the simulator has read one
//!   complete instruction packet from the bus and written its whole reply on the bus, it
//!   writes `0xA5, n_lo, n_hi` = the number of bytes it wrote on the bus for that
//!   instruction (0 when there is no reply: broadcast SYNC WRITE, a dropped packet in fault
//!   injection, …). Every instruction packet gets exactly one announcement.
//! * The bus transport therefore knows after each packet how many reply bytes will come. It
//!   reads exactly those (blocking, no wall-clock timeout); a read beyond them returns
//!   "timeout" at once and advances the virtual clock to the driver's deadline. A dropped reply
//!   is a deterministic timeout, and a slow host never causes a spurious one. Reply bytes the
//!   driver did not read are drained (they are known to come) before the next packet.
//! * Bytes on UART2 other than `0xA5` where an announcement is due are skipped and
//!   counted ([`QemuBoard::lockstep_errors`]).
//!
//! # Virtual clock ([`Clock::now_us`])
//! Deterministic by construction: it advances only by
//! * modelled bus time: 10 bits per byte at the configured baud (default 1 Mbps) for every byte
//!   sent and every byte received, plus the servo Return Delay Time before the first byte of
//!   each reply ([`crate::Config::return_delay_us`]);
//! * the command port's replies: 10 bits per byte at [`COMMAND_BAUD`];
//! * a timeout: a read past the announced reply jumps to the driver's deadline;
//! * the compute time per tick, charged when the tick's work ends (at
//!   [`TickTimer::wait_tick`]): by default the instructions per tick that `scripts/bench.sh`
//!   measures for this build (worst case over the Table 2 walk, [`super::tick_cost`]) at the
//!   modelled core clock, `instructions ÷ core_mhz` µs, one instruction per cycle
//!   ([`compute_ns`]; `core_mhz` defaults to the OpenCR's 216 MHz, `compute_us=` overrides);
//! * [`TickTimer::wait_tick`] jumping to the next deadline `k · period` (an overrun when it is
//!   already past; deadlines never drift).
//!
//! Why a per-build constant and not the time measured while running: the CPU time QEMU gives
//! depends on how it runs (with `-icount` on the instructions the blocking waits took, without
//! it on the host), so a measured compute time would break bit-for-bit determinism. QEMU's own
//! clock is not read: the lock-step runs go without `-icount` (`scripts/qemu-run.sh
//! --no-icount`), which only costs the host time.
//!
//! # Real time (`realtime`)
//! With the word `realtime` each tick ends no earlier on QEMU's host clock (semihosting
//! SYS_ELAPSED) than its virtual time: the core sleeps in WFI, woken each millisecond by
//! SysTick and by each command-port byte (interrupts masked), taking the command port's bytes
//! as they come, until the host clock has caught up. For any master on the command port (a
//! wall-clock master's heartbeats; the port's bytes, which QEMU's main loop delivers, starve
//! while the core blocks in the lock-step pipes' reads); the virtual clock is not changed by the
//! wait.
//!
//! # Watchdog
//! A virtual watchdog, started at boot: once started, a tick that begins more than the timeout
//! (virtual time) after the last feed (each tick, and each bus receive wait) sends torque off,
//! records itself in the crash cell and exits with [`EXIT_WATCHDOG`].
//!
//! # Bounded waits
//! Transmit spins on UART0 are bounded ([`UART_SPIN_LIMIT`]: `send` fails with
//! `BusError::Timeout`). The lock-step reads (reply announcements and announced reply bytes)
//! block on purpose: the simulator always answers, and a host that is gone ends the run through
//! the host's QEMU timeout (`walker fil --timeout`). A blocking read sleeps (WFI) on the UART's
//! receive interrupt, so that QEMU's vCPU leaves the host's cores to the simulator while it
//! computes the answer (and, when runs share the host's cores, the other runs' simulators).

use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicUsize, Ordering};

use walker_contract::lockstep;

// Link the runtime (vector table, reset handler) and the defmt global logger into every
// binary that uses this board, the on-target tests included.
use cortex_m_rt as _;
use defmt_semihosting as _;

use crate::board::{
    spi_gather, spi_scatter, Board, BusError, Clock, CrashCell, CrashCode, LineTime, LogSink,
    ResetCause, ServoBus, Tick, TickSchedule, TickTimer, Watchdog, COMMAND_BAUD, COMMAND_RX_RING,
    IMU_SPI_REGISTER_HZ, IMU_SPI_SAMPLE_HZ, TORQUE_OFF_PACKET,
};
use crate::mpu9250::{ImuError, Mpu9250};
use crate::record::BoardId;
use crate::rx_ring::LineRx;
use crate::Config;
use dxl::table::imu::ImuSample;
use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};

/// UART / SysTick clock of the mps2 boards, Hz.
pub const SYSCLK_HZ: u32 = 25_000_000;
/// Instructions per control tick charged as compute time for `cfg`: the bench's worst case
/// for this build and arithmetic — hard float on the M7/M4F ELF (either `math`; the
/// fixed-point path is not measured there), soft float on a Cortex-M3 ELF with `math=f32`,
/// the fixed-point path on a Cortex-M3 ELF with `math=fixed` ([`super::tick_cost`]).
pub fn tick_instructions(cfg: &Config) -> u32 {
    #[cfg(target_abi = "eabihf")]
    {
        let _ = cfg;
        super::tick_cost::TICK_INSTRUCTIONS_MAX_FPU
    }
    #[cfg(not(target_abi = "eabihf"))]
    {
        if cfg.arithmetic == crate::config::Arithmetic::Fixed {
            super::tick_cost::TICK_INSTRUCTIONS_MAX_FIXED_SOFT
        } else {
            super::tick_cost::TICK_INSTRUCTIONS_MAX_SOFT
        }
    }
}

/// Compute time charged per tick, ns: `compute_us` when set (non-zero), else
/// [`tick_instructions`] at `core_mhz` (one instruction per cycle: QEMU counts instructions;
/// a real M7 dual-issues some and waits on flash for others).
pub fn compute_ns(cfg: &Config) -> u64 {
    cfg.compute_ns(tick_instructions(cfg))
}
/// Exit code when the virtual watchdog bites.
pub const EXIT_WATCHDOG: i32 = walker_contract::ExitCode::Watchdog.status();
/// Exit code after a panic.
pub const EXIT_PANIC: i32 = walker_contract::ExitCode::Panic.status();

/// Command-port bytes the board holds while asleep in `realtime` ([`QemuBoard`]).
pub const COMMAND_HELD: usize = 1024;

/// Longest spin on a full UART transmit buffer, iterations (the bus `send` fails with
/// [`BusError::Timeout`] beyond it; a chardev drains a byte in far fewer).
pub const UART_SPIN_LIMIT: u32 = 1_000_000;

const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const BAUDDIV: usize = 0x10;
const INTCLEAR: usize = 0x0C;
const STATE_TX_FULL: u32 = 1;
const STATE_RX_FULL: u32 = 2;
const CTRL_TX_RX_ENABLE: u32 = 0b11;
const CTRL_RX_INTEN: u32 = 1 << 3;
const INT_RX: u32 = 1 << 1;
/// SysTick control and status, reload value and current value registers; the Interrupt
/// Control and State Register, and its bit that clears a pending SysTick.
const SYST_CSR: usize = 0xE000_E010;
const SYST_RVR: usize = 0xE000_E014;
const SYST_CVR: usize = 0xE000_E018;
const ICSR: usize = 0xE000_ED04;
const ICSR_PENDSTCLR: u32 = 1 << 25;
/// SysTick enabled, its exception made pending at each wrap, on the core clock.
const SYST_ON_PENDING_CORE_CLOCK: u32 = 0b111;
/// NVIC Interrupt Set-Enable, Clear-Enable and Clear-Pending registers of IRQs 0–31.
const NVIC_ISER0: usize = 0xE000_E100;
const NVIC_ICER0: usize = 0xE000_E180;
const NVIC_ICPR0: usize = 0xE000_E280;

/// One CMSDK APB UART, polled; a blocking read sleeps on its receive interrupt.
#[derive(Clone, Copy)]
struct Uart {
    /// The UART's register block in the mps2 memory map.
    base: usize,
    /// The UART's receive interrupt line on the mps2 boards' NVIC.
    rx_irq: u8,
}

// The mps2 boards' CMSDK UARTs: register blocks and receive interrupt lines (QEMU
// `hw/arm/mps2.c`: UART0–3 RX on IRQ 0, 2, 4, 18).
/// CMSDK UART0: the servo bus.
const UART0: Uart = Uart {
    base: 0x4000_4000,
    rx_irq: 0,
};
/// CMSDK UART1: the log.
const UART1: Uart = Uart {
    base: 0x4000_5000,
    rx_irq: 2,
};
/// CMSDK UART2: the lock-step channel.
const UART2: Uart = Uart {
    base: 0x4000_6000,
    rx_irq: 4,
};
/// CMSDK UART3: the command port.
const UART3: Uart = Uart {
    base: 0x4000_7000,
    rx_irq: 18,
};

impl Uart {
    fn reg(self, off: usize) -> *mut u32 {
        (self.base + off) as *mut u32
    }
    fn read(self, off: usize) -> u32 {
        // SAFETY: `base` is one of the CMSDK UART blocks of the mps2 memory map; the register
        // offsets are those of the CMSDK APB UART. Volatile 32-bit access, no aliasing state.
        unsafe { read_volatile(self.reg(off)) }
    }
    fn write(self, off: usize, v: u32) {
        // SAFETY: as in `read`.
        unsafe { write_volatile(self.reg(off), v) }
    }
    fn init(self, baud: u32) {
        let div = (SYSCLK_HZ / baud.max(1)).max(16);
        self.write(BAUDDIV, div);
        self.write(CTRL, CTRL_TX_RX_ENABLE);
    }
    fn tx_full(self) -> bool {
        self.read(STATE) & STATE_TX_FULL != 0
    }
    fn rx_full(self) -> bool {
        self.read(STATE) & STATE_RX_FULL != 0
    }
    fn put(self, b: u8) {
        while self.tx_full() {}
        self.write(DATA, u32::from(b));
    }
    /// Bounded-spin write ([`UART_SPIN_LIMIT`] iterations): false if the UART never drains.
    fn put_bounded(self, b: u8) -> bool {
        let mut spins = 0u32;
        while self.tx_full() {
            spins += 1;
            if spins > UART_SPIN_LIMIT {
                return false;
            }
        }
        self.write(DATA, u32::from(b));
        true
    }
    /// The next received byte: at once if one is waiting, else with the core asleep until one
    /// comes (QEMU hands a UART one byte at a time).
    fn get(self) -> u8 {
        if !self.rx_full() {
            self.sleep_until_rx();
        }
        (self.read(DATA) & 0xFF) as u8
    }

    /// Waits for a received byte with the core asleep (WFI), so that QEMU's vCPU does not spin
    /// while the simulator computes its answer. With interrupts masked (PRIMASK) the receive
    /// interrupt only wakes the core, no handler runs; it is armed (UART and NVIC) for this
    /// wait only and cleared (UART, NVIC enable and pending) before the mask is lifted, so no
    /// interrupt is ever taken. The flag is tested after arming: a byte that came earlier ends
    /// the wait at once, a later one raises the interrupt.
    fn sleep_until_rx(self) {
        let bit = 1u32 << (self.rx_irq & 31);
        cortex_m::interrupt::free(|_| {
            // SAFETY: NVIC registers of the Cortex-M system control space (32-bit, write-one
            // to set/clear): enables, then disables and unpends this UART's line only.
            let nvic = |reg: usize| unsafe { write_volatile(reg as *mut u32, bit) };
            self.write(CTRL, CTRL_TX_RX_ENABLE | CTRL_RX_INTEN);
            nvic(NVIC_ISER0);
            while !self.rx_full() {
                cortex_m::asm::wfi();
            }
            self.write(CTRL, CTRL_TX_RX_ENABLE);
            self.write(INTCLEAR, INT_RX);
            nvic(NVIC_ICER0);
            nvic(NVIC_ICPR0);
        });
    }
}

/// Semihosting SYS_EXIT_EXTENDED with `code` (qemu exits with that status).
pub fn semihosting_exit(code: i32) -> ! {
    // ADP_Stopped_ApplicationExit, then the exit code.
    let block: [usize; 2] = [0x20026, code as u32 as usize];
    loop {
        // SAFETY: 0x20 = SYS_EXIT_EXTENDED, whose argument block is two words (reason, code).
        unsafe {
            cortex_m_semihosting::syscall(0x20, &block);
        }
    }
}

/// QEMU's host clock since it started, in its ticks (semihosting SYS_ELAPSED; `None` when
/// the host does not give it).
fn host_elapsed_ticks() -> Option<u64> {
    let mut block: [usize; 2] = [0, 0];
    let p = block.as_mut_ptr();
    // SAFETY: 0x30 = SYS_ELAPSED: the host writes the 64-bit tick count into the two words
    // (low, high) of the block, passed by raw pointer and read back volatile.
    let (r, lo, hi) = unsafe {
        let r = cortex_m_semihosting::syscall1(0x30, p as usize);
        (r, read_volatile(p), read_volatile(p.add(1)))
    };
    (r == 0).then_some((hi as u64) << 32 | lo as u64)
}

/// The host clock's ticks per second (semihosting SYS_TICKFREQ; `None` when not given).
fn host_tick_hz() -> Option<u64> {
    // SAFETY: 0x31 = SYS_TICKFREQ takes no argument and returns the tick rate (−1: none).
    let hz = unsafe { cortex_m_semihosting::syscall1(0x31, 0) };
    (hz as isize > 0).then_some(hz as u64)
}

/// Bytes below the stack pointer at boot that [`paint_stack`] fills with [`STACK_PAINT`]: far
/// more than any QEMU build's worst case (`scripts/stack-depth.py`: ≈ 27 KB), far less than the
/// board's 4 MiB of RAM.
pub const STACK_PAINT_BYTES: usize = 128 * 1024;
/// The pattern of the stack's unused words.
pub const STACK_PAINT: u32 = 0xC0DE_57AC;

/// The top of the stack (cortex-m-rt's `_stack_start`, the initial stack pointer).
fn stack_top() -> usize {
    extern "C" {
        static _stack_start: u32;
    }
    // Only the symbol's address is taken (the linker script defines it); nothing is read
    // through it.
    core::ptr::addr_of!(_stack_start) as usize
}

/// Fills the [`STACK_PAINT_BYTES`] below the present stack pointer (less 64 bytes for this
/// function's own frame) with [`STACK_PAINT`], so that [`stack_high_water`] can tell how deep
/// the stack went. First thing in the QEMU binary's `main`.
#[inline(never)]
pub fn paint_stack() {
    let sp = cortex_m::register::msp::read() as usize;
    let from = stack_top().saturating_sub(STACK_PAINT_BYTES);
    let to = sp.saturating_sub(64) & !3;
    let mut a = from;
    while a < to {
        // SAFETY: [from, to) is RAM below the live stack (4 MiB at 0x2000_0000, the stack at
        // its top; static RAM is tens of bytes at its bottom), not used by anything yet; word
        // aligned writes, no call in this loop moves the stack pointer below `to`.
        unsafe { write_volatile(a as *mut u32, STACK_PAINT) };
        a += 4;
    }
}

/// Stack bytes used since [`paint_stack`]: from the stack's top to the lowest word that no
/// longer holds the pattern (the measured worst case; a value the program wrote equal to the
/// pattern would hide at most that word).
pub fn stack_high_water() -> u32 {
    let top = stack_top();
    let mut a = top.saturating_sub(STACK_PAINT_BYTES);
    // SAFETY: reads of the painted region (RAM, word aligned) below the stack top.
    while a < top && unsafe { read_volatile(a as *const u32) } == STACK_PAINT {
        a += 4;
    }
    (top - a) as u32
}

/// Longest semihosting command line read, bytes (qemu refuses SYS_GET_CMDLINE when the line,
/// kernel file name first, does not fit the buffer; the host checks it before QEMU starts).
pub use walker_contract::params::CMDLINE_MAX;

/// Reads the semihosting command line (qemu `-append`, after the kernel's file name) into
/// `buf`; returns its length (None when qemu refuses, e.g. `buf` is too small).
pub fn semihosting_cmdline(buf: &mut [u8]) -> Option<usize> {
    let mut block: [usize; 2] = [buf.as_mut_ptr() as usize, buf.len()];
    let p = block.as_mut_ptr();
    // SAFETY: 0x15 = SYS_GET_CMDLINE: the block is (buffer address, buffer size); the host
    // writes at most `size` bytes into the buffer and the length into block[1]. The block is
    // passed by raw pointer and read back volatile, as the host writes it behind our back.
    let (r, len) = unsafe {
        let r = cortex_m_semihosting::syscall1(0x15, p as usize);
        (r, core::ptr::read_volatile(p.add(1)))
    };
    if r == 0 {
        Some(len.min(buf.len()))
    } else {
        None
    }
}

fn contains_word(hay: &[u8], word: &[u8]) -> bool {
    hay.split(|&b| b == b' ' || b == b'\t' || b == 0)
        .any(|w| w == word)
}

/// Longest path prefix of the parameter store's files, bytes.
const STORE_PATH_MAX: usize = 200;

/// The value of the first `key=value` token of `key` (the board's words, not parameters).
fn word_value<'a>(hay: &'a [u8], key: &[u8]) -> Option<&'a [u8]> {
    hay.split(|&b| b == b' ' || b == b'\t' || b == 0)
        .find_map(|w| w.strip_prefix(key)?.strip_prefix(b"="))
}

/// The parameter store on the host through semihosting (`store=PATH` on the command line:
/// slot `i` is the file `PATH{i}`; none without the word). A slot is written as a whole file
/// (truncate, then write: the erase and the program of a flash sector); a missing or short
/// file reads erased (`0xFF`) beyond what it holds.
struct HostStore {
    prefix: [u8; STORE_PATH_MAX],
    len: usize,
    /// Fault injection: the next write stops after this many bytes and the firmware exits (a
    /// power cut).
    cut: Option<u32>,
}

/// Semihosting SYS_OPEN modes (ARM's semihosting specification, the `fopen` modes).
const OPEN_RB: usize = 1;
const OPEN_WB: usize = 5;

impl HostStore {
    /// Opens slot `slot`'s file (`PATH0`, `PATH1`) in `mode`; the handle.
    fn open(&self, slot: usize, mode: usize) -> Option<usize> {
        let digit = match slot {
            0 => b"0",
            1 => b"1",
            _ => return None,
        };
        let (p, n) = host_path(self.prefix.get(..self.len)?, digit)?;
        sys_open(p.get(..n)?, mode)
    }

    fn read(&self, slot: usize, buf: &mut [u8]) -> bool {
        buf.fill(0xFF);
        let Some(h) = self.open(slot, OPEN_RB) else {
            return true; // never written: erased
        };
        // The host writes at most `len` bytes; the rest of a short file's buffer keeps its 0xFF.
        let _ = sys_read(h, buf);
        sys_close(h);
        true
    }

    fn write(&mut self, slot: usize, data: &[u8]) -> bool {
        let Some(h) = self.open(slot, OPEN_WB) else {
            return false;
        };
        let (n, cut) = match self.cut.take() {
            Some(c) => ((c as usize).min(data.len()), true),
            None => (data.len(), false),
        };
        let done = sys_write(h, data.get(..n).unwrap_or(data));
        sys_close(h);
        if cut {
            defmt::warn!(
                "power cut after {=usize} bytes of parameter slot {=usize}",
                n,
                slot
            );
            semihosting_exit(EXIT_POWER_CUT);
        }
        done
    }
}

/// Longest host path the board opens, with its NUL: a prefix of up to
/// [`lockstep::PREFIX_MAX`] (and [`STORE_PATH_MAX`]) bytes and a short suffix.
const HOST_PATH_MAX: usize = lockstep::PREFIX_MAX + 16;

/// `prefix`, `suffix` and a NUL in a buffer, and their length with the NUL (`None` when over
/// [`HOST_PATH_MAX`]).
fn host_path(prefix: &[u8], suffix: &[u8]) -> Option<([u8; HOST_PATH_MAX], usize)> {
    let mut p = [0u8; HOST_PATH_MAX];
    let n = prefix.len() + suffix.len();
    p.get_mut(..prefix.len())?.copy_from_slice(prefix);
    p.get_mut(prefix.len()..n)?.copy_from_slice(suffix);
    *p.get_mut(n)? = 0;
    Some((p, n + 1))
}

/// Semihosting SYS_OPEN of the NUL-terminated `path` in `mode`; the handle.
fn sys_open(path: &[u8], mode: usize) -> Option<usize> {
    if path.last() != Some(&0) {
        return None;
    }
    let args = [path.as_ptr() as usize, mode, path.len() - 1];
    // SAFETY: SYS_OPEN (0x01) with its three-word block: a NUL-terminated path that lives for
    // the call, the mode, the path's length without the NUL.
    let h = unsafe { cortex_m_semihosting::syscall(0x01, &args) };
    (h as isize >= 0).then_some(h)
}

/// Semihosting SYS_CLOSE of a handle [`sys_open`] returned.
fn sys_close(h: usize) {
    // SAFETY: SYS_CLOSE (0x02) of a handle SYS_OPEN returned.
    unsafe {
        cortex_m_semihosting::syscall1(0x02, h);
    }
}

/// Semihosting SYS_WRITE of all of `data` to handle `h`; false when the host wrote less.
fn sys_write(h: usize, data: &[u8]) -> bool {
    let args = [h, data.as_ptr() as usize, data.len()];
    // SAFETY: SYS_WRITE (0x05): handle, `len` readable bytes of `data`, `len`; it returns the
    // count of bytes not written.
    let left = unsafe { cortex_m_semihosting::syscall(0x05, &args) };
    left == 0
}

/// Semihosting SYS_READ into `buf` from handle `h` (one host `read`: on a pipe, what is there,
/// waiting for at least a byte); the count read (0 at the end of the file), `None` on an error.
fn sys_read(h: usize, buf: &mut [u8]) -> Option<usize> {
    let len = buf.len();
    let args = [h, buf.as_mut_ptr() as usize, len];
    // SAFETY: SYS_READ (0x06): handle, a buffer of `len` writable bytes, `len`. The host writes
    // at most `len` bytes and returns the count it did not read.
    let left = unsafe { cortex_m_semihosting::syscall(0x06, &args) };
    (left <= len).then(|| len - left)
}

/// Bytes of the lock-step pipe's receive buffer: an announcement and a reply this long come in
/// one host call, a longer reply in more.
const PIPE_RX: usize = 512;
/// Bytes of the lock-step pipe's transmit buffer: a time frame, a packet header and a packet
/// this long go out in one host call, a longer packet in more.
const PIPE_TX: usize = 512;
/// [`PIPE_TO_SIM`] when no pipe is open.
const NO_HANDLE: usize = usize::MAX;
/// The handle of the open `PREFIX-to-sim` pipe, for the panic path's torque off.
static PIPE_TO_SIM: AtomicUsize = AtomicUsize::new(NO_HANDLE);

/// The lock-step pipes on the host (`lockstep=PREFIX`: [`walker_contract::lockstep`]).
struct HostPipe {
    to_sim: usize,
    to_fw: usize,
    rx: [u8; PIPE_RX],
    rx_at: usize,
    rx_len: usize,
    tx: [u8; PIPE_TX],
    tx_len: usize,
}

impl HostPipe {
    /// Opens `prefix` + `-to-sim` for writing, then `prefix` + `-to-fw` for reading (the
    /// order the simulator expects; each open returns once the host holds the other end).
    fn open(prefix: &[u8]) -> Option<Self> {
        let (p, n) = host_path(prefix, lockstep::TO_SIM_SUFFIX.as_bytes())?;
        let to_sim = sys_open(p.get(..n)?, OPEN_WB)?;
        let (p, n) = host_path(prefix, lockstep::TO_FIRMWARE_SUFFIX.as_bytes())?;
        let Some(to_fw) = p.get(..n).and_then(|p| sys_open(p, OPEN_RB)) else {
            sys_close(to_sim);
            return None;
        };
        PIPE_TO_SIM.store(to_sim, Ordering::Relaxed);
        Some(HostPipe {
            to_sim,
            to_fw,
            rx: [0; PIPE_RX],
            rx_at: 0,
            rx_len: 0,
            tx: [0; PIPE_TX],
            tx_len: 0,
        })
    }

    /// Adds `bytes` to the transmit buffer (writing it out whenever it fills).
    fn queue(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            let room = PIPE_TX - self.tx_len;
            if room == 0 {
                self.flush();
                continue;
            }
            let (now, later) = bytes.split_at(room.min(bytes.len()));
            if let Some(d) = self.tx.get_mut(self.tx_len..self.tx_len + now.len()) {
                d.copy_from_slice(now);
            }
            self.tx_len += now.len();
            bytes = later;
        }
    }

    /// Writes the transmit buffer out.
    fn flush(&mut self) {
        let n = self.tx_len;
        self.tx_len = 0;
        if n > 0 && !sys_write(self.to_sim, self.tx.get(..n).unwrap_or(&[])) {
            Self::closed();
        }
    }

    /// The simulator is gone (a host call failed, or it closed its end): in lock-step nothing
    /// moves the robot any more, and a firmware left running would tick on through reply
    /// timeouts with nobody to stop QEMU. It exits ([`walker_contract::ExitCode::SimulatorGone`]).
    fn closed() -> ! {
        defmt::error!("lock-step pipe closed: the simulator is gone");
        semihosting_exit(walker_contract::ExitCode::SimulatorGone.status())
    }

    /// The next byte from the simulator (waiting for it).
    fn byte(&mut self) -> u8 {
        if self.rx_at >= self.rx_len {
            match sys_read(self.to_fw, &mut self.rx) {
                Some(n) if n > 0 => {
                    self.rx_at = 0;
                    self.rx_len = n;
                }
                _ => Self::closed(),
            }
        }
        let b = self.rx.get(self.rx_at).copied().unwrap_or(0);
        self.rx_at += 1;
        b
    }
}

/// Exit code of the injected power cut during a parameter save (`cut_save`).
pub const EXIT_POWER_CUT: i32 = 99;

/// Best-effort torque off from anywhere (panic handler): the broadcast Torque Enable = 0
/// packet on the lock-step pipe when one is open, else on UART0 with bounded spins so that a
/// stuck UART cannot hang the panic path.
pub fn panic_torque_off() {
    let h = PIPE_TO_SIM.load(Ordering::Relaxed);
    if h != NO_HANDLE {
        let len = u16::try_from(TORQUE_OFF_PACKET.len()).unwrap_or(u16::MAX);
        let _ = sys_write(h, &lockstep::packet_header(len)) && sys_write(h, &TORQUE_OFF_PACKET);
        return;
    }
    for &b in TORQUE_OFF_PACKET.iter() {
        if !UART0.put_bounded(b) {
            return;
        }
    }
}

/// Panic path shared by the QEMU binary and the on-target tests: log, torque off, exit 101.
pub fn panic_exit(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    panic_torque_off();
    semihosting_exit(EXIT_PANIC)
}

/// The QEMU mps2 board.
pub struct QemuBoard {
    bus: Uart,
    log: Uart,
    lockstep_uart: Uart,
    command: Uart,
    /// The command port in time: the OpenCR's line rate and receive ring.
    command_line: LineRx<COMMAND_RX_RING>,
    /// Command-port bytes taken from the UART while asleep (`realtime`), not yet arrived in
    /// [`Self::command_line`]: the host socket's buffer, which QEMU's one-byte UART cannot be.
    command_held: heapless::Deque<u8, COMMAND_HELD>,
    lockstep: bool,
    line: LineTime,
    return_delay_ns: u64,
    compute_ns: u64,
    virt_ns: u64,
    last_sync_us: Option<u64>,
    pending_reply: usize,
    reply_started: bool,
    lockstep_errors: u32,
    schedule: TickSchedule,
    watchdog_ms: Option<u32>,
    last_feed_ns: u64,
    crash: CrashCell,
    /// The parameter store on the host (`store=PATH`), if given.
    store: Option<HostStore>,
    /// The lock-step pipes (`lockstep=PREFIX`), if given: the bus and the lock-step frames
    /// go through them instead of UART0 and UART2.
    pipe: Option<HostPipe>,
    /// `realtime`: the host clock's tick rate; each tick ends no earlier on QEMU's host clock
    /// than its virtual time.
    realtime_hz: Option<u64>,
    /// The board's IMU once started: the simulator's chip on the lock-step pipes.
    imu: Option<Mpu9250>,
}

impl QemuBoard {
    /// Sets up the UARTs; reads the semihosting command line for `lockstep`, `lockstep=PREFIX`
    /// (opening the pipes) and `store=PATH`.
    pub fn new(cfg: &Config) -> Self {
        let (bus, log, ls, command) = (UART0, UART1, UART2, UART3);
        command.init(COMMAND_BAUD);
        bus.init(cfg.bus_baud);
        log.init(921_600);
        ls.init(SYSCLK_HZ / 16);

        let mut cmd = [0u8; CMDLINE_MAX];
        let line = semihosting_cmdline(&mut cmd).and_then(|n| cmd.get(..n));
        let pipe = match line.and_then(|c| word_value(c, lockstep::PIPE_WORD.as_bytes())) {
            Some(prefix) => match prefix
                .len()
                .le(&lockstep::PREFIX_MAX)
                .then(|| HostPipe::open(prefix))
                .flatten()
            {
                Some(p) => Some(p),
                None => {
                    defmt::error!(
                        "lock-step pipes {=[u8]:a} not opened",
                        prefix
                            .get(..prefix.len().min(lockstep::PREFIX_MAX))
                            .unwrap_or(&[])
                    );
                    semihosting_exit(walker_contract::ExitCode::ConfigRejected.status())
                }
            },
            None => None,
        };
        let lockstep = pipe.is_some()
            || line.is_some_and(|c| contains_word(c, lockstep::PIPE_WORD.as_bytes()));
        let realtime_word = walker_contract::params::REALTIME_WORD.as_bytes();
        let realtime_hz = if line.is_some_and(|c| contains_word(c, realtime_word)) {
            let hz = host_tick_hz().filter(|_| host_elapsed_ticks().is_some());
            if hz.is_none() {
                defmt::warn!("realtime: the host gives no clock (SYS_ELAPSED): not paced");
            }
            hz
        } else {
            None
        };
        let store_word = walker_contract::params::STORE_WORD.as_bytes();
        let store = line
            .and_then(|c| word_value(c, store_word))
            .filter(|p| !p.is_empty() && p.len() <= STORE_PATH_MAX)
            .map(|p| {
                let mut prefix = [0u8; STORE_PATH_MAX];
                if let Some(d) = prefix.get_mut(..p.len()) {
                    d.copy_from_slice(p);
                }
                HostStore {
                    prefix,
                    len: p.len(),
                    cut: cfg.fault_cut_save,
                }
            });

        QemuBoard {
            bus,
            log,
            lockstep_uart: ls,
            command,
            command_line: LineRx::new(COMMAND_BAUD),
            command_held: heapless::Deque::new(),
            lockstep,
            line: LineTime { baud: cfg.bus_baud },
            return_delay_ns: u64::from(cfg.return_delay_us) * 1000,
            compute_ns: compute_ns(cfg),
            virt_ns: 0,
            last_sync_us: None,
            pending_reply: 0,
            reply_started: false,
            lockstep_errors: 0,
            schedule: TickSchedule::new(cfg.tick_period_us),
            watchdog_ms: None,
            last_feed_ns: 0,
            crash: CrashCell::new(),
            store,
            pipe,
            realtime_hz,
            imu: None,
        }
    }

    /// One SPI transfer with the simulator's IMU chip on the pipes (a time frame first):
    /// `mosi` out, as many bytes back into `miso`; the virtual clock charged 8 bits a byte at
    /// `hz`. False when the simulator's answer is not one byte for each byte out.
    fn spi_transfer(&mut self, mosi: &[u8], miso: &mut [u8], hz: u32) -> bool {
        let Ok(len) = u16::try_from(mosi.len()) else {
            return false;
        };
        self.sync_time(true);
        let Some(p) = &mut self.pipe else {
            return false;
        };
        p.queue(&lockstep::spi_header(len));
        p.queue(mosi);
        p.flush();
        let n = self.read_announcement();
        let ls = self.lockstep_uart;
        for k in 0..n {
            let b = self.lockstep_byte(ls);
            if let Some(slot) = miso.get_mut(k) {
                *slot = b;
            }
        }
        self.virt_ns += u64::from(len) * 8 * 1_000_000_000 / u64::from(hz.max(1));
        if n != mosi.len() {
            self.lockstep_errors = self.lockstep_errors.saturating_add(1);
            return false;
        }
        true
    }

    /// True when the lock-step channel is in use.
    pub fn lockstep(&self) -> bool {
        self.lockstep
    }

    /// True when lock-step goes over the host's pipes (`lockstep=PREFIX`).
    pub fn lockstep_pipe(&self) -> bool {
        self.pipe.is_some()
    }

    /// The compute time charged per tick, ns ([`compute_ns`] of the configuration).
    pub fn compute_ns(&self) -> u64 {
        self.compute_ns
    }

    /// Protocol errors seen on the lock-step channel.
    pub fn lockstep_errors(&self) -> u32 {
        self.lockstep_errors
    }

    fn now_us_inner(&self) -> u64 {
        self.virt_ns / 1000
    }

    /// Sends a time frame if the time changed since the last one: on UART2, or queued on the
    /// pipe (written out at once unless a packet follows: `then_packet`).
    fn sync_time(&mut self, then_packet: bool) {
        if !self.lockstep {
            return;
        }
        let now = self.now_us_inner();
        if self.last_sync_us == Some(now) {
            return;
        }
        self.last_sync_us = Some(now);
        let frame = lockstep::time_frame(now);
        match &mut self.pipe {
            Some(p) => {
                p.queue(&frame);
                if !then_packet {
                    p.flush();
                }
            }
            None => frame.iter().for_each(|&b| self.lockstep_uart.put(b)),
        }
    }

    /// The next byte of the simulator's side: from the pipe, else from `uart` (UART0 for
    /// reply bytes, UART2 for announcements).
    fn lockstep_byte(&mut self, uart: Uart) -> u8 {
        match &mut self.pipe {
            Some(p) => p.byte(),
            None => uart.get(),
        }
    }

    /// Reads one reply announcement.
    fn read_announcement(&mut self) -> usize {
        let ls = self.lockstep_uart;
        while self.lockstep_byte(ls) != lockstep::REPLY {
            self.lockstep_errors = self.lockstep_errors.saturating_add(1);
        }
        let lo = self.lockstep_byte(ls);
        let hi = self.lockstep_byte(ls);
        lockstep::header_count(lo, hi)
    }

    /// Writes raw bytes on UART0 (bounded spins).
    fn bus_write(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        let ok = bytes.iter().all(|&b| self.bus.put_bounded(b));
        if ok {
            Ok(())
        } else {
            Err(BusError::Timeout)
        }
    }

    /// Lets the command port's bytes arrive in the line model's ring (at the present virtual
    /// time; see [`LineRx::arrive`]): first those held while asleep, then what the UART holds;
    /// warns about bytes lost to a full ring.
    fn take_command_bytes(&mut self) {
        let now = self.now_us();
        let uart = self.command;
        let lost = self.command_line.lost();
        let held = &mut self.command_held;
        self.command_line.arrive(now, || {
            held.pop_front()
                .or_else(|| uart.rx_full().then(|| (uart.read(DATA) & 0xFF) as u8))
        });
        if self.command_line.lost() != lost {
            defmt::warn!(
                "command port: {=u32} bytes lost to a full receive ring",
                self.command_line.lost()
            );
        }
    }

    /// Sleeps (WFI) until QEMU's host clock (ticks at `tick_hz`) reaches the virtual time,
    /// holding the command port's bytes as they come ([`COMMAND_HELD`]; they arrive in the
    /// line model at the next tick, as if they had waited in the host's socket): SysTick at
    /// 1 ms and the command UART's receive interrupt wake the core, with interrupts masked so
    /// that no handler runs (both armed for this wait only, their pending state cleared after
    /// each wake-up and at the end). QEMU's main loop, which hands the UART its bytes one at a
    /// time, runs meanwhile.
    fn sleep_until_host_clock(&mut self, tick_hz: u64) {
        let due = u128::from(self.virt_ns) * u128::from(tick_hz) / 1_000_000_000;
        let uart = self.command;
        let bit = 1u32 << (uart.rx_irq & 31);
        let reg = |a: usize| a as *mut u32;
        cortex_m::interrupt::free(|_| {
            // SAFETY: SysTick, ICSR and NVIC registers of the Cortex-M system control space
            // (32-bit; write-one to set/clear); nothing else on this board uses SysTick, and
            // only this UART's line is enabled, then disabled and unpended.
            let arm = |on: bool| unsafe {
                write_volatile(reg(SYST_RVR), SYSCLK_HZ / 1000 - 1);
                write_volatile(reg(SYST_CVR), 0);
                write_volatile(
                    reg(SYST_CSR),
                    if on { SYST_ON_PENDING_CORE_CLOCK } else { 0 },
                );
                write_volatile(reg(if on { NVIC_ISER0 } else { NVIC_ICER0 }), bit);
            };
            // SAFETY: as above.
            let clear = || unsafe {
                write_volatile(reg(ICSR), ICSR_PENDSTCLR);
                write_volatile(reg(NVIC_ICPR0), bit);
            };
            uart.write(CTRL, CTRL_TX_RX_ENABLE | CTRL_RX_INTEN);
            arm(true);
            loop {
                while !self.command_held.is_full() && uart.rx_full() {
                    let _ = self.command_held.push_back((uart.read(DATA) & 0xFF) as u8);
                }
                uart.write(INTCLEAR, INT_RX);
                clear();
                if host_elapsed_ticks().is_none_or(|t| u128::from(t) >= due) {
                    break;
                }
                if !uart.rx_full() || self.command_held.is_full() {
                    cortex_m::asm::wfi();
                }
            }
            uart.write(CTRL, CTRL_TX_RX_ENABLE);
            uart.write(INTCLEAR, INT_RX);
            arm(false);
            clear();
        });
    }

    fn check_watchdog(&mut self) {
        if let Some(ms) = self.watchdog_ms {
            if self.virt_ns.saturating_sub(self.last_feed_ns) > u64::from(ms) * 1_000_000 {
                defmt::error!("virtual watchdog expired at {} us", self.now_us_inner());
                self.crash.record(CrashCode::Watchdog);
                self.torque_off_best_effort();
                semihosting_exit(EXIT_WATCHDOG);
            }
        }
    }
}

impl ServoBus for QemuBoard {
    fn send(&mut self, packet: &[u8]) -> Result<(), BusError> {
        if packet.len() > usize::from(u16::MAX) {
            return Err(BusError::TooLong);
        }
        // Unread reply bytes of the previous packet are known to come: drain them.
        let bus = self.bus;
        for _ in 0..self.pending_reply {
            let _ = self.lockstep_byte(bus);
        }
        self.pending_reply = 0;
        self.sync_time(true);
        match &mut self.pipe {
            Some(p) => {
                let len = u16::try_from(packet.len()).map_err(|_| BusError::TooLong)?;
                p.queue(&lockstep::packet_header(len));
                p.queue(packet);
                p.flush();
            }
            None => self.bus_write(packet)?,
        }
        self.virt_ns += self.line.bytes_ns(packet.len());
        self.reply_started = false;
        self.pending_reply = if self.lockstep {
            self.read_announcement()
        } else {
            0
        };
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], timeout_us: u32) -> Result<usize, BusError> {
        let start = self.virt_ns;
        let n = buf.len().min(self.pending_reply);
        if n > 0 {
            if !self.reply_started {
                self.virt_ns += self.return_delay_ns;
                self.reply_started = true;
            }
            let bus = self.bus;
            for slot in buf.iter_mut().take(n) {
                *slot = self.lockstep_byte(bus);
            }
            self.pending_reply -= n;
            self.virt_ns += self.line.bytes_ns(n);
        }
        if n < buf.len() {
            self.virt_ns = self.virt_ns.max(start + u64::from(timeout_us) * 1000);
        }
        // A bus wait: the watchdog is fed (it still bites a tick that starts late).
        self.feed();
        Ok(n)
    }

    fn baud(&self) -> u32 {
        self.line.baud
    }

    fn set_baud(&mut self, baud: u32) -> Result<(), BusError> {
        // The CMSDK UART needs BAUDDIV ≥ 16 (`init` clamps it), but its speed is irrelevant
        // over a chardev: any rate the servos support is accepted and only modelled.
        if baud == 0 {
            return Err(BusError::UnsupportedBaud);
        }
        self.line = LineTime { baud };
        self.bus.init(baud);
        Ok(())
    }
}

impl Clock for QemuBoard {
    fn now_us(&self) -> u64 {
        self.now_us_inner()
    }
}

impl TickTimer for QemuBoard {
    fn period_us(&self) -> u32 {
        self.schedule.period_us()
    }

    fn wait_tick(&mut self) -> Tick {
        // The tick's work ends: charge the modelled compute time.
        self.virt_ns += self.compute_ns;
        let plan = self.schedule.plan(self.now_us_inner());
        if let Some(t) = plan.wait_until_us {
            self.virt_ns = self.virt_ns.max(t * 1000);
        }
        if let Some(hz) = self.realtime_hz {
            self.sleep_until_host_clock(hz);
        }
        self.check_watchdog();
        self.sync_time(false);
        plan.tick
    }

    fn overruns(&self) -> u32 {
        self.schedule.overruns()
    }
}

impl LogSink for QemuBoard {
    fn write_log(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.log.put(b);
        }
    }
}

impl Watchdog for QemuBoard {
    fn start(&mut self, timeout_ms: u32) {
        self.watchdog_ms = Some(timeout_ms.max(1));
        self.last_feed_ns = self.virt_ns;
    }
    fn feed(&mut self) {
        self.last_feed_ns = self.virt_ns;
    }
}

impl Board for QemuBoard {
    const NAME: &'static str = "qemu-mps2-an500";
    const ID: BoardId = BoardId::QemuMps2;

    fn torque_off_best_effort(&mut self) {
        if self.pipe.is_some() {
            // Through the bus transport, so that its announcement is read like any other.
            let _ = self.send(&TORQUE_OFF_PACKET);
        } else {
            panic_torque_off();
        }
    }

    fn reset_cause(&self) -> (ResetCause, u32) {
        // Every QEMU run starts from power-on.
        (ResetCause::PowerOn, 0)
    }

    fn crash_cell(&mut self) -> &mut CrashCell {
        &mut self.crash
    }

    fn servo_power(&mut self, on: bool) {
        // No power switch on the emulated board: the request is only logged.
        defmt::info!(
            "servo power {=bool} (no switch on this board: nothing done)",
            on
        );
    }

    fn command_rx(&mut self, buf: &mut [u8]) -> usize {
        self.take_command_bytes();
        self.command_line.read(buf)
    }

    fn command_tx(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if !self.command.put_bounded(b) {
                break;
            }
        }
        // The real board's transmitter holds the loop for the bytes' line time.
        self.virt_ns += LineTime { baud: COMMAND_BAUD }.bytes_ns(bytes.len());
    }

    fn store_read(&mut self, slot: usize, buf: &mut [u8]) -> bool {
        match &self.store {
            Some(s) => s.read(slot, buf),
            None => false,
        }
    }

    fn store_write(&mut self, slot: usize, data: &[u8]) -> bool {
        match &mut self.store {
            Some(s) => s.write(slot, data),
            None => false,
        }
    }

    fn imu_start(&mut self) -> Option<Result<(), ImuError>> {
        // The simulated chip answers on the pipes only.
        self.pipe.as_ref()?;
        let started = Mpu9250::start(&mut ChipPort {
            board: self,
            hz: IMU_SPI_REGISTER_HZ,
        });
        Some(started.map(|imu| self.imu = Some(imu)))
    }

    fn imu_sample(&mut self) -> Option<Result<ImuSample, ImuError>> {
        let mut imu = self.imu.take()?;
        let s = imu.sample(&mut ChipPort {
            board: self,
            hz: IMU_SPI_SAMPLE_HZ,
        });
        self.imu = Some(imu);
        Some(s)
    }

    fn exit(&mut self, code: i32) -> ! {
        defmt::info!(
            "stack high-water mark {=u32} B (painted at boot, scripts/stack-depth.py bounds it)",
            stack_high_water()
        );
        semihosting_exit(code)
    }
}

/// The board's SPI to the simulator's IMU chip, at `hz`, and its wait (virtual time).
struct ChipPort<'a> {
    board: &'a mut QemuBoard,
    hz: u32,
}

impl ErrorType for ChipPort<'_> {
    type Error = ErrorKind;
}

impl SpiDevice for ChipPort<'_> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
        let mut mosi = [0u8; lockstep::SPI_MAX];
        let mut miso = [0u8; lockstep::SPI_MAX];
        let n = spi_gather(ops, &mut mosi).ok_or(ErrorKind::Other)?;
        let (Some(out), Some(back)) = (mosi.get(..n), miso.get_mut(..n)) else {
            return Err(ErrorKind::Other);
        };
        if !self.board.spi_transfer(out, back, self.hz) {
            return Err(ErrorKind::Other);
        }
        spi_scatter(ops, back);
        Ok(())
    }
}

impl embedded_hal::delay::DelayNs for ChipPort<'_> {
    fn delay_ns(&mut self, ns: u32) {
        self.board.virt_ns += u64::from(ns);
    }
}
