//! ROBOTIS OpenCM 9.04 (STM32F103CB: Cortex-M3 at 72 MHz, no FPU, 128 KiB flash, 20 KiB RAM)
//! as a board, on the PAC `stm32f1` at register level (no HAL: the flash budget is 112 KiB).
//! The firmware runs the fixed-point path here (`math=fixed`, set by `src/bin/opencm.rs`).
//!
//! # Hardware assumptions (ROBOTIS' OpenCM 9.04 Arduino core, github ROBOTIS-GIT/OpenCM9.04,
//! `arduino/opencm_arduino/opencm9.04/variants/OpenCM904/`)
//! | what | where | source |
//! | --- | --- | --- |
//! | HSE crystal | 8 MHz | `bsp/opencm/bsp.c`: HSE 8 MHz, PREDIV1 1, PLLMUL 9 → SYSCLK 72 MHz, flash latency 2 |
//! | Dynamixel TTL bus | **USART1 remapped**, PB6 TX / PB7 RX | `variant.cpp` pins 29 "DXL TXD" / 30 "DXL RXD"; `hw/driver/drv_uart.c`: USART1 in DXL mode uses `__HAL_AFIO_REMAP_USART1_ENABLE` on PB6/PB7; the Arduino `Serial1` (Dynamixel2Arduino README: OpenCM9.04 → `Serial1`, direction pin 28) |
//! | bus direction (TX enable) | **PB5**, high = transmit | `variant.cpp` pin 28 "DXL DIR" |
//! | log UART | **USART2**, PA2 TX / PA3 RX at 921 600 baud | `drv_uart.c` (USART2 on PA2/PA3), `variant.cpp` pins 4/5; the Arduino `Serial2` |
//! | command port | **USART3**, PB10 TX / PB11 RX at [`COMMAND_BAUD`], 8N1 | `variant.cpp` pins 24 "UART3_TXD" / 25 "UART3_RXD"; `chip.h`: `BOARD_USART3_TX_PIN 24 //D24 (PB10)`, `BOARD_USART3_RX_PIN 25 //D25 (PB11)`; `drv_uart.c`: `huart_inst[DRV_UART_NUM_3]` = USART3, PB10 `GPIO_MODE_AF_PP`, PB11 `GPIO_MODE_INPUT` with the pull-up of the struct; the Arduino `Serial3` (`UARTClass Serial3(DRV_UART_NUM_3, …)` in `variant.cpp`), spare on this robot |
//! | command port reception | **DMA1 channel 3** (USART3_RX, RM0008 Table 78), circular, into a [`COMMAND_RX_RING`]-byte ring | `drv_uart.c`: "USART3 - RX : DMA1, Channel 3", `DMA_CIRCULAR` into a 256-byte buffer read by CNDTR, as here |
//! | operator button (the enable) | **PC15**, input with pull-down (pressed = high) | `chip.h`: `BOARD_BUTTON_PIN 23 //PC15`; `variant.cpp` pin 23 "USER_BUTTON"; ROBOTIS' examples (`02_Digital/c_Button`) read it as `INPUT_PULLDOWN`, high while pressed; [`Board::enable_button`](crate::board::Board::enable_button) gives the raw level; PC15 is also OSC32_OUT, a GPIO while the LSE is off (this firmware never starts it) |
//! | Dynamixel power switch | **none** the MCU can drive | the 3-pin TTL ports take the board's supply through its slide switch; [`Board::servo_power`](crate::board::Board::servo_power) logs the request only |
//! | application flash | 0x0800_3000, 114 KiB | `bsp/opencm/ldscript/opencm_flash.ld` (the first 12 KiB hold ROBOTIS' USB bootloader) |
//! | RAM | 0x2000_0000, 20 KiB | same linker script |
//! | tick and µs clock | TIM2 (16 bit, 1 MHz) clocking TIM3 (16 bit) = one 32-bit µs counter | extended to 64 bits in software |
//! | watchdog | IWDG (LSI ≈ 40 kHz, ÷ 32) | started at boot (`control::run`), fed in the bus and tick waits |
//! | reset cause | RCC_CSR (RM0008 §7.3.10) | same flag bits as the STM32F7's, without BORRSTF |
//! | defmt | RTT (probe-rs over SWD) | |
//!
//! The memory layout is the top-level `memory.x`'s OpenCM branch (`--defsym=_walker_opencm=1`
//! from build.rs). Register addresses and bits are from RM0008 (STM32F101/2/3 reference
//! manual); the pin choices are the constants below and [`OpenCmBoard::new`].
//!
//! # Clocks and baud rates
//! SYSCLK = HCLK = PCLK2 = 72 MHz, PCLK1 = 36 MHz (APB1 timers at 72 MHz). USART1 (APB2) with
//! oversampling 16: BRR = 72 MHz ÷ baud ≥ 16, so the bus runs at 1, 2, 3 and 4.5 Mbps exactly
//! (4.5 Mbps is the F103's fastest). USART2 (APB1): 36 MHz ÷ 921 600 → BRR 39 (+0.16 %).
//! USART3 (APB1): 36 MHz ÷ 1 Mbps → BRR 36 (2.25, exact).
//!
//! # Command port
//! USART3 receives without the CPU: each byte's DMA request moves it into the ring
//! `COMMAND_RX` (DMA1 channel 3, circular), and
//! [`Board::command_rx`](crate::board::Board::command_rx) takes what arrived since its last
//! call by the channel's CNDTR ([`crate::rx_ring::DmaRxCursor`]). The
//! F103's USART has no overrun disable (OVRDIS): on an overrun (a byte came while RXNE was
//! still set: the DMA was late) ORE is set and "any data received during overrun is lost"
//! (RM0008 §27.3.3 "Overrun error"; in practice the receiver raises no RXNE, hence no DMA
//! request, while ORE is set) until ORE is cleared by a read of SR then of DR (§27.6.1).
//! `command_rx` does that, once, when SR shows ORE: reception stalls for at most one tick,
//! the bytes lost with it fail their packet's CRC and the master asks again. Replies go out
//! byte by byte on TXE, each wait bounded ([`UART_SPIN_LIMIT`]).
//!
//! # Timing
//! [`TickTimer::wait_tick`](crate::board::TickTimer::wait_tick) busy-waits on the µs counter until `k · period` (deadlines never
//! drift) and meanwhile drains the log ring buffer into USART2; a frame that does not fit the
//! ring is dropped whole and counted ([`OpenCmBoard::log_dropped`]).
//!
//! # Exit and panic
//! [`Board::exit`](crate::board::Board::exit) and the panic handler send the broadcast torque-off packet and reset the
//! MCU (after a reset but a power-on the firmware does not walk). There is no power switch to
//! cut as a backup. The panic's log line has its location and a plain message, not a
//! formatted one ([`panic_reset`]: flash).

// Link the runtime and the defmt global logger (RTT) into every binary using this board.
use cortex_m_rt as _;
use defmt_rtt as _;
use stm32f1::stm32f103 as pac;

use super::stm32::{self, register_blocks, stm32_board, BusUart, Stm32Bus, Stm32State};
use crate::board::{BusError, Clock, CrashCode, LogRing, Watchdog, TORQUE_OFF_PACKET};
use crate::record::BoardId;
use crate::rx_ring::DmaRxCursor;
use crate::Config;

/// SYSCLK (= HCLK = PCLK2, the bus UART's clock), Hz.
pub const SYSCLK_HZ: u32 = 72_000_000;
/// PCLK1 (the log UART's clock), Hz.
pub const PCLK1_HZ: u32 = 36_000_000;
/// HSE crystal of the OpenCM 9.04, Hz.
pub const HSE_HZ: u32 = 8_000_000;
/// Log UART baud rate.
pub const LOG_BAUD: u32 = 921_600;
/// Log ring buffer size, bytes (the RAM budget is 16 KiB of static RAM).
pub const LOG_RING: usize = 1024;
/// Longest busy-wait on a UART or clock flag, loop iterations (≥ 4 ms at 72 MHz, more than a
/// byte at 9600 baud); beyond it the peripheral is hung ([`BusError::Timeout`]).
pub const UART_SPIN_LIMIT: u32 = 300_000;
/// Bus direction pin: PB5 (Arduino pin 28, "DXL DIR").
pub const BUS_DIR_PIN: u32 = 5;
/// Command port baud rate (USART3: BRR 36 exactly).
pub use crate::board::COMMAND_BAUD;
/// The command port's receive ring, bytes: DMA1 channel 3 fills it from USART3 without the CPU.
/// 256 bytes are 2.56 ms of an unbroken 1 Mbps line, less than a 5 ms tick, but a Dynamixel
/// master sends its next instruction only after the reply to the last (or its timeout), and
/// the port's instructions are short (its longest WRITE, Param Key + Value + Op, is 53 bytes
/// on the wire): what waits between two reads is one instruction, or a few repeats of one
/// while the loop is busy elsewhere, well within the ring and within the loop's
/// [`RX_PER_TICK`](crate::control::commanded::RX_PER_TICK) = 64 bytes a tick. The board's
/// 20 KiB of RAM beside the worst-case stack leave no room for the OpenCR's 1 KiB.
pub const COMMAND_RX_RING: usize = 256;
/// The button's pin on GPIOC: PC15 (Arduino pin 23, `BOARD_BUTTON_PIN`).
pub const BUTTON_PIN: u32 = 15;

// RM0008 register bits.
const RCC_CR_HSEON: u32 = 1 << 16;
const RCC_CR_HSERDY: u32 = 1 << 17;
const RCC_CR_PLLON: u32 = 1 << 24;
const RCC_CR_PLLRDY: u32 = 1 << 25;
/// CFGR: SW = PLL, HPRE ÷ 1, PPRE1 ÷ 2, PPRE2 ÷ 1, PLLSRC = HSE, PLLXTPRE ÷ 1, PLLMUL × 9.
const RCC_CFGR_72MHZ: u32 = 0b10 | (0b100 << 8) | (1 << 16) | (0b0111 << 18);
const RCC_CFGR_SWS_PLL: u32 = 0b10 << 2;
const RCC_CSR_RMVF: u32 = 1 << 24;
/// APB2ENR: AFIO, IOPA, IOPB, IOPC, USART1.
const RCC_APB2_ENABLE: u32 = 1 | (1 << 2) | (1 << 3) | (1 << 4) | (1 << 14);
/// APB1ENR: TIM2, TIM3, USART2, USART3.
const RCC_APB1_ENABLE: u32 = 1 | (1 << 1) | (1 << 17) | (1 << 18);
/// AHBENR: DMA1.
const RCC_AHB_DMA1: u32 = 1;
/// FLASH_ACR: 2 wait states (48 < SYSCLK ≤ 72 MHz), prefetch on.
const FLASH_ACR_72MHZ: u32 = 0b010 | (1 << 4);
const AFIO_MAPR_USART1_REMAP: u32 = 1 << 2;
const USART_SR_FE: u32 = 1 << 1;
const USART_SR_NE: u32 = 1 << 2;
const USART_SR_ORE: u32 = 1 << 3;
const USART_SR_RXNE: u32 = 1 << 5;
const USART_SR_TC: u32 = 1 << 6;
const USART_SR_TXE: u32 = 1 << 7;
/// CR1: UE, TE, RE (8N1, oversampling 16).
const USART_CR1_ON: u32 = (1 << 13) | (1 << 3) | (1 << 2);
const USART_CR1_UE: u32 = 1 << 13;
/// CR3: DMAR (a DMA request for each received byte).
const USART_CR3_DMAR: u32 = 1 << 6;
/// DMA CCR: MINC (7), CIRC (5); DIR = 0 (peripheral to memory), PSIZE = MSIZE = 00 (bytes),
/// PL = 00 (low), no interrupts.
const DMA_CCR_RX: u32 = (1 << 7) | (1 << 5);
const DMA_CCR_EN: u32 = 1;
/// DMA IFCR: channel 3's CGIF3, CTCIF3, CHTIF3, CTEIF3 (bits 8–11).
const DMA_IFCR_CH3: u32 = 0xF << 8;
const IWDG_KEY_UNLOCK: u32 = 0x5555;
const IWDG_KEY_START: u32 = 0xCCCC;
const IWDG_KEY_FEED: u32 = 0xAAAA;
/// IWDG clock: LSI ≈ 40 kHz ÷ 32 = 1.25 counts per ms.
const IWDG_PRESCALER_DIV32: u32 = 3;

/// Waits (bounded, [`UART_SPIN_LIMIT`]) until `ready` holds; `Err(Timeout)` otherwise.
fn spin(ready: impl Fn() -> bool) -> Result<(), BusError> {
    stm32::spin(UART_SPIN_LIMIT, ready)
}

register_blocks! {
    /// The bus UART USART1 (owned by the board after `new`).
    fn usart1() -> pac::usart1::RegisterBlock = pac::USART1;
    /// The log UART USART2 (owned by the board after `new`).
    fn usart2() -> pac::usart1::RegisterBlock = pac::USART2;
    /// GPIOB: only BSRR (atomic single-pin set/reset) is written after `new`.
    fn gpiob() -> pac::gpioa::RegisterBlock = pac::GPIOB;
    /// The command port USART3 (owned by the board after `new`; its DR is DMA1 channel 3's
    /// source).
    fn usart3() -> pac::usart1::RegisterBlock = pac::USART3;
    /// DMA1: channel 3 belongs to the command port; only its CNDTR is read after `new`.
    fn dma1() -> pac::dma1::RegisterBlock = pac::DMA1;
    /// GPIOC: only IDR (the button, PC15) is read after `new`.
    fn gpioc() -> pac::gpioa::RegisterBlock = pac::GPIOC;
}

/// The command port's receive ring (in .bss; the F103's DMA reaches all of its SRAM).
static COMMAND_RX: stm32::DmaRing<COMMAND_RX_RING> = stm32::DmaRing::new();

/// Starts DMA1 channel 3 (USART3_RX's, RM0008 Table 78) copying every byte USART3 receives
/// into [`COMMAND_RX`] in circular mode, then USART3 at [`COMMAND_BAUD`] with its receive DMA
/// request (DMAR) before its receiver, so that no byte arrives before the channel takes it.
/// Called once, from `OpenCmBoard::new`, with the DMA1 and USART3 clocks on.
fn command_rx_dma_up(dma: &pac::DMA1, usart: &pac::USART3) {
    let ch = &dma.ch3;
    // SAFETY (each raw write below): whole-register values of the channel's CCR, CPAR, CMAR and
    // CNDTR, of DMA_IFCR and of USART3's BRR, CR3 and CR1 as RM0008 §13.4 and §27.6 define
    // them; the channel is disabled (EN = 0) while it is configured.
    ch.cr.write(|w| unsafe { w.bits(0) });
    dma.ifcr.write(|w| unsafe { w.bits(DMA_IFCR_CH3) });
    ch.par
        .write(|w| unsafe { w.bits(core::ptr::addr_of!(usart.dr) as u32) });
    ch.mar.write(|w| unsafe { w.bits(COMMAND_RX.address()) });
    ch.ndtr.write(|w| unsafe { w.bits(COMMAND_RX_RING as u32) });
    ch.cr.write(|w| unsafe { w.bits(DMA_CCR_RX) });
    ch.cr.write(|w| unsafe { w.bits(DMA_CCR_RX | DMA_CCR_EN) });
    usart
        .brr
        .write(|w| unsafe { w.bits(PCLK1_HZ / COMMAND_BAUD) });
    usart.cr3.write(|w| unsafe { w.bits(USART_CR3_DMAR) });
    usart.cr1.write(|w| unsafe { w.bits(USART_CR1_ON) });
}

/// The bus UART's BRR for `baud` (72 MHz ÷ baud, oversampling 16), if it is in 16..=0xFFFF.
pub fn bus_brr(baud: u32) -> Option<u32> {
    stm32::brr(SYSCLK_HZ, baud)
}

/// Bus direction: transmit (PB5 high) or receive (low).
fn bus_dir(transmit: bool) {
    let bit = if transmit {
        1 << BUS_DIR_PIN
    } else {
        1 << (BUS_DIR_PIN + 16)
    };
    // SAFETY: BSRR writes set/reset single pins atomically; any value is valid.
    gpiob().bsrr.write(|w| unsafe { w.bits(bit) });
}

/// Best-effort torque off from anywhere (panic handler): the broadcast Torque Enable = 0
/// packet on USART1 with bounded spins, direction pin back to receive. Harmless if the board
/// was never initialised (the writes then go nowhere).
pub fn panic_torque_off() {
    let u = usart1();
    bus_dir(true);
    for &b in TORQUE_OFF_PACKET.iter() {
        if spin(|| u.sr.read().bits() & USART_SR_TXE != 0).is_err() {
            break;
        }
        // SAFETY: DR takes any 9-bit value; a byte is one.
        u.dr.write(|w| unsafe { w.bits(u32::from(b)) });
    }
    let _ = spin(|| u.sr.read().bits() & USART_SR_TC != 0);
    bus_dir(false);
}

/// Panic path of the OpenCM binary: log, record the panic in no-init RAM, torque off, reset
/// (the next boot logs the record and does not walk). The log has the panic's location and
/// its message when that is a plain string, not a formatted one: formatting it would link
/// `core::fmt`'s machinery, ≈ 1.3 KB of the board's flash.
pub fn panic_reset(info: &core::panic::PanicInfo) -> ! {
    let message = info.message().as_str().unwrap_or("");
    let (file, line) = info.location().map_or(("", 0), |l| (l.file(), l.line()));
    defmt::error!("panic: {=str} at {=str}:{=u32}", message, file, line);
    stm32::crash_cell().record(CrashCode::Panic);
    panic_torque_off();
    cortex_m::peripheral::SCB::sys_reset()
}

/// The OpenCM 9.04 board.
pub struct OpenCmBoard {
    tim_low: pac::TIM2,
    tim_high: pac::TIM3,
    iwdg: pac::IWDG,
    baud: u32,
    /// Where the loop stopped reading the command port's receive ring.
    command_rx: DmaRxCursor<COMMAND_RX_RING>,
    state: Stm32State,
    ring: LogRing<LOG_RING>,
}

impl OpenCmBoard {
    /// Brings the board up: 72 MHz from the 8 MHz crystal, USART1 (remapped to PB6/PB7) bus
    /// at `cfg.bus_baud` (1 Mbps when the rate cannot be generated), PB5 direction low, USART2
    /// log at [`LOG_BAUD`], the USART3 command port at [`COMMAND_BAUD`] received by DMA1
    /// channel 3, the button PC15 an input, TIM2 → TIM3 as a 32-bit 1 MHz counter. The
    /// watchdog is not started.
    pub fn new(dp: pac::Peripherals, cfg: &Config) -> Self {
        let rcc = &dp.RCC;
        // The reset flags first, then clear them (RMVF) so that the next boot sees its own.
        let reset_csr = rcc.csr.read().bits();
        // SAFETY (all raw register writes below): values composed from RM0008's bit fields
        // for these registers; reserved bits are kept by the read-modify-writes.
        rcc.csr
            .modify(|r, w| unsafe { w.bits(r.bits() | RCC_CSR_RMVF) });

        // 72 MHz: HSE on, flash wait states, PLL × 9, switch. A crystal that never starts
        // leaves the board on the 8 MHz HSI (bounded waits; the UART rates are then wrong and
        // the start-up finds no servo, which stops the run).
        rcc.cr
            .modify(|r, w| unsafe { w.bits(r.bits() | RCC_CR_HSEON) });
        if spin(|| rcc.cr.read().bits() & RCC_CR_HSERDY != 0).is_ok() {
            dp.FLASH.acr.write(|w| unsafe { w.bits(FLASH_ACR_72MHZ) });
            rcc.cfgr
                .write(|w| unsafe { w.bits(RCC_CFGR_72MHZ & !0b11) });
            rcc.cr
                .modify(|r, w| unsafe { w.bits(r.bits() | RCC_CR_PLLON) });
            if spin(|| rcc.cr.read().bits() & RCC_CR_PLLRDY != 0).is_ok() {
                rcc.cfgr.write(|w| unsafe { w.bits(RCC_CFGR_72MHZ) });
                let _ = spin(|| rcc.cfgr.read().bits() & (0b11 << 2) == RCC_CFGR_SWS_PLL);
            }
        }
        rcc.apb2enr
            .modify(|r, w| unsafe { w.bits(r.bits() | RCC_APB2_ENABLE) });
        rcc.apb1enr
            .modify(|r, w| unsafe { w.bits(r.bits() | RCC_APB1_ENABLE) });
        rcc.ahbenr
            .modify(|r, w| unsafe { w.bits(r.bits() | RCC_AHB_DMA1) });

        // USART1 on PB6/PB7 (remap), SWJ configuration untouched.
        dp.AFIO
            .mapr
            .modify(|r, w| unsafe { w.bits(r.bits() | AFIO_MAPR_USART1_REMAP) });
        // GPIOB CRL nibbles (MODE[1:0] CNF[1:0]): PB5 push-pull output 50 MHz (0x3), PB6
        // alternate push-pull 50 MHz (0xB), PB7 input with pull-up (0x8, ODR7 = 1).
        bus_dir(false);
        dp.GPIOB.crl.modify(|r, w| unsafe {
            w.bits((r.bits() & 0x000F_FFFF) | (0x3 << 20) | (0xB << 24) | (0x8 << 28))
        });
        dp.GPIOB.bsrr.write(|w| unsafe { w.bits(1 << 7) });
        // GPIOA CRL: PA2 alternate push-pull (0xB), PA3 floating input (0x4).
        dp.GPIOA
            .crl
            .modify(|r, w| unsafe { w.bits((r.bits() & 0xFFFF_00FF) | (0xB << 8) | (0x4 << 12)) });
        // GPIOB CRH: PB10 alternate push-pull 50 MHz (0xB), PB11 input with pull-up (0x8, ODR11
        // = 1: the line idles high with nothing plugged in, as ROBOTIS configures it).
        dp.GPIOB.bsrr.write(|w| unsafe { w.bits(1 << 11) });
        dp.GPIOB
            .crh
            .modify(|r, w| unsafe { w.bits((r.bits() & 0xFFFF_00FF) | (0xB << 8) | (0x8 << 12)) });
        // GPIOC CRH: PC15 input with pull-down (0x8, ODR15 = 0): the button reads high pressed.
        dp.GPIOC
            .bsrr
            .write(|w| unsafe { w.bits(1 << (BUTTON_PIN + 16)) });
        dp.GPIOC
            .crh
            .modify(|r, w| unsafe { w.bits((r.bits() & 0x0FFF_FFFF) | (0x8 << 28)) });

        let baud = if bus_brr(cfg.bus_baud).is_some() {
            cfg.bus_baud
        } else {
            1_000_000
        };
        let bus_div = bus_brr(baud).map_or(72, |d| d);
        dp.USART1.brr.write(|w| unsafe { w.bits(bus_div) });
        dp.USART1.cr1.write(|w| unsafe { w.bits(USART_CR1_ON) });
        dp.USART2
            .brr
            .write(|w| unsafe { w.bits(PCLK1_HZ / LOG_BAUD) });
        dp.USART2.cr1.write(|w| unsafe { w.bits(USART_CR1_ON) });
        command_rx_dma_up(&dp.DMA1, &dp.USART3);

        // TIM2: 72 MHz ÷ 72 = 1 MHz, update event as TRGO (CR2.MMS = 010); TIM3 counts TIM2's
        // update events (SMCR: TS = ITR1 = TIM2, SMS = external clock mode 1).
        let (t2, t3) = (&dp.TIM2, &dp.TIM3);
        t2.psc
            .write(|w| unsafe { w.bits(SYSCLK_HZ / 1_000_000 - 1) });
        t2.arr.write(|w| unsafe { w.bits(0xFFFF) });
        t2.cr2.write(|w| unsafe { w.bits(0b010 << 4) });
        t3.psc.write(|w| unsafe { w.bits(0) });
        t3.arr.write(|w| unsafe { w.bits(0xFFFF) });
        t3.smcr.write(|w| unsafe { w.bits((0b001 << 4) | 0b111) });
        t3.cr1.write(|w| unsafe { w.bits(1) });
        t2.egr.write(|w| unsafe { w.bits(1) });
        t3.cnt.write(|w| unsafe { w.bits(0) });
        t2.cr1.write(|w| unsafe { w.bits(1) });

        OpenCmBoard {
            tim_low: dp.TIM2,
            tim_high: dp.TIM3,
            iwdg: dp.IWDG,
            baud,
            command_rx: DmaRxCursor::new(),
            state: Stm32State::new(cfg, reset_csr),
            ring: LogRing::new(),
        }
    }

    /// The 32-bit µs counter: TIM3 (high half) and TIM2 (low half), read high-low-high until
    /// the high half is stable (bounded: it changes once per 65.5 ms).
    fn counter_us(&self) -> u32 {
        let mut high = self.tim_high.cnt.read().bits() & 0xFFFF;
        for _ in 0..4 {
            let low = self.tim_low.cnt.read().bits() & 0xFFFF;
            let again = self.tim_high.cnt.read().bits() & 0xFFFF;
            if again == high {
                return (high << 16) | low;
            }
            high = again;
        }
        high << 16
    }

    /// Moves log bytes from the ring to USART2 while its data register is free.
    fn pump_log(&mut self) {
        let u = usart2();
        while u.sr.read().bits() & USART_SR_TXE != 0 {
            let Some(b) = self.ring.pop() else {
                break;
            };
            // SAFETY: DR takes any 9-bit value.
            u.dr.write(|w| unsafe { w.bits(u32::from(b)) });
        }
    }
}

/// The bus UART, USART1, for the shared bus code.
pub(crate) struct BusUsart1(&'static pac::usart1::RegisterBlock);

impl BusUart for BusUsart1 {
    const SPIN_LIMIT: u32 = UART_SPIN_LIMIT;
    const CLOCK_HZ: u32 = SYSCLK_HZ;
    fn tx_empty(&self) -> bool {
        self.0.sr.read().bits() & USART_SR_TXE != 0
    }
    fn tx_complete(&self) -> bool {
        self.0.sr.read().bits() & USART_SR_TC != 0
    }
    fn write(&self, b: u8) {
        // SAFETY: DR takes any 9-bit value.
        self.0.dr.write(|w| unsafe { w.bits(u32::from(b)) });
    }
    fn status(&self) -> (bool, bool) {
        let sr = self.0.sr.read().bits();
        (
            sr & (USART_SR_ORE | USART_SR_FE | USART_SR_NE) != 0,
            sr & USART_SR_RXNE != 0,
        )
    }
    fn read(&self) -> u8 {
        // Reading DR also clears ORE/FE/NE after the SR read of `status`.
        (self.0.dr.read().bits() & 0xFF) as u8
    }
    /// SR then DR read (RM0008 §27.6.1): the flags cleared, the pending byte dropped.
    fn discard(&self) -> bool {
        let sr = self.0.sr.read().bits();
        if sr & (USART_SR_ORE | USART_SR_FE | USART_SR_NE | USART_SR_RXNE) != 0 {
            let _ = self.0.dr.read().bits();
        }
        sr & (USART_SR_ORE | USART_SR_FE | USART_SR_NE) != 0
    }
    fn set_divider(&self, div: u32) {
        // SAFETY: CR1 without UE, then BRR (any 16-bit value; `div` is in 16..=0xFFFF), then
        // CR1 with UE again.
        self.0
            .cr1
            .write(|w| unsafe { w.bits(USART_CR1_ON & !USART_CR1_UE) });
        self.0.brr.write(|w| unsafe { w.bits(div) });
        self.0.cr1.write(|w| unsafe { w.bits(USART_CR1_ON) });
    }
}

impl Stm32Bus for OpenCmBoard {
    type Uart = BusUsart1;
    fn bus_uart(&self) -> BusUsart1 {
        BusUsart1(usart1())
    }
    fn bus_direction(&mut self, transmit: bool) {
        bus_dir(transmit);
    }
    fn stm32_state(&mut self) -> &mut Stm32State {
        &mut self.state
    }
}

impl Clock for OpenCmBoard {
    fn now_us(&self) -> u64 {
        let cnt = self.counter_us();
        self.state.clock.extend(cnt)
    }
}

impl Watchdog for OpenCmBoard {
    fn start(&mut self, timeout_ms: u32) {
        if !self.state.watchdog_running {
            // Counts at 1.25 per ms; RLR is 12 bits (≤ 3.27 s).
            let reload = (timeout_ms.max(1).saturating_mul(5) / 4).clamp(1, 0x0FFF);
            // SAFETY: the IWDG key sequence of RM0008 §19.3 (unlock, PR, RLR, start); the
            // values fit their fields.
            self.iwdg.kr.write(|w| unsafe { w.bits(IWDG_KEY_UNLOCK) });
            self.iwdg
                .pr
                .write(|w| unsafe { w.bits(IWDG_PRESCALER_DIV32) });
            self.iwdg.rlr.write(|w| unsafe { w.bits(reload) });
            self.iwdg.kr.write(|w| unsafe { w.bits(IWDG_KEY_START) });
            self.state.watchdog_running = true;
        }
    }
    fn feed(&mut self) {
        if self.state.watchdog_running {
            // SAFETY: the reload key.
            self.iwdg.kr.write(|w| unsafe { w.bits(IWDG_KEY_FEED) });
        }
    }
}

stm32_board! {
    impl<> for OpenCmBoard {
        name: "opencm-9.04",
        id: BoardId::OpenCm,

        fn servo_power(&mut self, on: bool) {
            // The OpenCM 9.04 feeds its Dynamixel ports from the board supply through a manual
            // slide switch: there is no MCU-driven power switch (see the module table).
            defmt::warn!(
                "servo power {=bool} requested: the OpenCM 9.04 has no switch for it",
                on
            );
        }

        fn command_rx(&mut self, buf: &mut [u8]) -> usize {
            // An overrun stops reception until SR then DR are read (module docs "Command
            // port"); the DR read may take one byte from the DMA, lost with the overrun's.
            let u = usart3();
            if u.sr.read().bits() & USART_SR_ORE != 0 {
                let _ = u.dr.read().bits();
            }
            let remaining = (dma1().ch3.ndtr.read().bits() & 0xFFFF) as usize;
            COMMAND_RX.take(&mut self.command_rx, remaining, buf)
        }

        fn enable_button(&mut self) -> Option<bool> {
            Some(gpioc().idr.read().bits() & (1 << BUTTON_PIN) != 0)
        }

        fn command_tx(&mut self, bytes: &[u8]) {
            // 10 µs a byte at 1 Mbps, each wait bounded.
            let u = usart3();
            for &b in bytes {
                if spin(|| u.sr.read().bits() & USART_SR_TXE != 0).is_err() {
                    return;
                }
                // SAFETY: DR takes any 9-bit value; a byte is one.
                u.dr.write(|w| unsafe { w.bits(u32::from(b)) });
            }
        }

        fn exit(&mut self, code: i32) -> ! {
            defmt::warn!("exit({=i32}): torque off, reset", code);
            self.shut_down(panic_torque_off)
        }
    }
}
