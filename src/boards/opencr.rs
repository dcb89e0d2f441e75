//! ROBOTIS OpenCR 1.0 (STM32F746ZG, Cortex-M7F) as a board, with stm32f7xx-hal 0.8.
//!
//! # Hardware assumptions (from the OpenCR 1.0 Arduino variant sources of ROBOTIS)
//! | what | where | note |
//! | --- | --- | --- |
//! | HSE crystal | 25 MHz | PLL → SYSCLK 216 MHz (HCLK 216, APB1 54, APB2 108) |
//! | Dynamixel TTL/RS-485 bus | **USART3**, PC10 TX / PC11 RX (AF7) | the Arduino core's `Serial3`, which `Dynamixel2Arduino` uses as `DXL_SERIAL` on the OpenCR (the task brief guessed USART6 on PC6/PC7: that is `Serial1`, the Arduino-header UART) |
//! | bus direction (TX enable) | **PC9**, high = transmit | Arduino pin 84, `DXL_DIR_PIN` |
//! | Dynamixel power switch (FET) | **PF15**, high = on | `BDPIN_DXL_PWR_EN` |
//! | operator buttons (the enable) | **PC12** and **PG3**, inputs | `BDPIN_PUSH_SW_1`, `BDPIN_PUSH_SW_2` (the variant sources of different core versions swap the two names); either one enables: the standby takes the level found as released, whatever the polarity |
//! | log UART | **USART6**, PC6 TX / PC7 RX (AF8) at 921 600 baud | Arduino header pins 1 (TX) / 0 (RX), `Serial1`; spare on this robot |
//! | command port | **USART2**, PD5 TX / PD6 RX (AF7) at [`COMMAND_BAUD`], received by DMA1 stream 5 (channel 4) into a [`COMMAND_RX_RING`]-byte ring | the 4-pin "UART" connector of the OpenCR (Arduino `Serial2`, `huart_inst[DRV_UART_NUM_2]` in ROBOTIS' `drv_uart.c`), where ROBOTIS' BT-210/BT-410 modules and a USB–TTL adapter plug in |
//! | tick and µs clock | TIM2, 32-bit, free-running at 1 MHz | extended to 64 bits in software |
//! | watchdog | IWDG (LSI ≈ 32 kHz) | started at boot (`control::run`), fed in the bus and tick waits, the dry run and each tick |
//! | on-board IMU (InvenSense MPU-9250) | **SPI1**: PA5 SCK / PA6 MISO / PB5 MOSI (AF5, pulled up), chip select **PA4** (push-pull, high = idle); SPI1 on APB2 (108 MHz, RCC `SPI1EN`), GPIOA/GPIOB clocked by the HAL | ROBOTIS' variant: `BDPIN_SPI_CS_IMU` / `_CLK_` / `_SDO_` / `_SDI_IMU` (Arduino pins 28, 37, 38, 39), `SPI_IMU` = SPI1 and its pins in `HAL_SPI_MspInit` (`drv_spi.c`) |
//! | IMU SPI frames | mode 3 (CPOL = 1, CPHA = 1), master, MSB first, 8 bits, software NSS; 108 MHz / 128 = 843.75 kHz to start ([`IMU_SPI_REGISTER_HZ`]), / 16 = 6.75 MHz for the samples ([`IMU_SPI_SAMPLE_HZ`]) | ROBOTIS' IMU library, `MPU9250.cpp` `begin`: `SPI_MODE3`, `SPI_CLOCK_DIV128` while it configures, `DIV8` (13.5 MHz) after; the MPU-9250 takes ≤ 1 MHz for every register, ≤ 20 MHz for the sensor registers |
//! | defmt | RTT (probe-rs) | |
//!
//! The pins are the `BUS_*`, `LOG_*` constants' documentation and the concrete pin types in
//! [`OpenCrBoard::new`]; change both together if a board revision differs.
//! Both UARTs are clocked from SYSCLK (216 MHz, oversampling 16), so the bus can run at 1, 2,
//! 3 or 4.5 Mbps (BRR ≥ 16 needs ≤ 13.5 Mbps) and the log at 921 600 baud (−0.16 %).
//!
//! Later OpenCR boards carry an ICM-20648 instead of the MPU-9250 (ROBOTIS' `imu_selector.cpp`
//! tries one, then the other): its WHO_AM_I at 0x75 does not read 0x71, so the start fails
//! with [`ImuError::NotMpu9250`], and a robot whose IMU is the board's stops at start-up as
//! with a missing IMU.
//!
//! # Timing
//! [`TickTimer::wait_tick`](crate::board::TickTimer::wait_tick) busy-waits on TIM2 until `k · period` (deadlines never drift) and
//! meanwhile drains the log ring buffer into USART6 — the log never blocks the loop: a frame
//! that does not fit the 1 KiB ring is dropped whole and counted ([`OpenCrBoard::log_dropped`]).
//!
//! # Exit and panic
//! [`Board::exit`](crate::board::Board::exit) and the panic handler send the broadcast torque-off packet, switch the
//! Dynamixel power FET off as a backup, then reset the MCU (after a reset the firmware does
//! not enable torque until it is told to walk).

// Link the runtime and the defmt global logger (RTT) into every binary using this board.
use cortex_m_rt as _;
use defmt_rtt as _;
use dxl::table::imu::ImuSample;
use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType, OutputPin};
use embedded_hal::spi::{ErrorKind, Operation, SpiDevice};
use embedded_storage::nor_flash as nor;
use stm32f7xx_hal::flash::Flash;
use stm32f7xx_hal::gpio::{Output, PinState, PushPull, Speed, PA4, PC9, PF15};
use stm32f7xx_hal::pac;
use stm32f7xx_hal::prelude::*;
use stm32f7xx_hal::rcc::{Clocks, HSEClock, HSEClockMode};
use stm32f7xx_hal::serial::{self, Serial};
use stm32f7xx_hal::watchdog::IndependentWatchdog;

use super::stm32::{self, register_blocks, stm32_board, BusUart, Stm32Bus, Stm32State};
use crate::board::{
    spi_gather, spi_scatter, BusError, Clock, LogRing, Watchdog, IMU_SPI_REGISTER_HZ,
    IMU_SPI_SAMPLE_HZ, TORQUE_OFF_PACKET,
};
use crate::flash_store::FlashStore;
use crate::mpu9250::{ImuError, Mpu9250};
use crate::record::BoardId;
use crate::rx_ring::DmaRxCursor;
use crate::Config;
use walker_contract::lockstep::SPI_MAX;

/// SYSCLK, Hz.
pub const SYSCLK_HZ: u32 = 216_000_000;
/// HSE crystal of the OpenCR 1.0, Hz.
pub const HSE_HZ: u32 = 25_000_000;
/// APB2 (PCLK2), Hz, SPI1's clock: SYSCLK / 2, the most APB2 takes at 216 MHz (the HAL's
/// `freeze` picks it).
pub const APB2_HZ: u32 = 108_000_000;
/// Log UART baud rate.
pub const LOG_BAUD: u32 = 921_600;
pub use crate::board::{COMMAND_BAUD, COMMAND_RX_RING};
/// DMA1 stream and channel of USART2_RX (RM0385, DMA1 request mapping: stream 5, channel 4).
const COMMAND_RX_STREAM: usize = 5;
/// Its channel.
const COMMAND_RX_CHANNEL: u32 = 4;

/// The command port's receive ring (in DTCM with the rest of .bss: the F7's DMAs reach DTCM
/// through the Cortex-M7's AHB slave port).
static COMMAND_RX: stm32::DmaRing<COMMAND_RX_RING> = stm32::DmaRing::new();

/// Starts DMA1 stream 5 copying every byte USART2 receives into [`COMMAND_RX`] in circular
/// mode (peripheral to memory, bytes, memory increment, direct mode), and USART2's receive
/// DMA request with overrun detection off (a byte the DMA was late for is overwritten, not a
/// stopped receiver). Called once, from `OpenCrBoard::new`, after USART2 is up.
fn command_rx_dma_up(dma: &pac::DMA1) {
    // SAFETY: RCC.AHB1ENR read-modify-write (single core, before interrupts are used).
    let rcc = unsafe { &*pac::RCC::ptr() };
    rcc.ahb1enr.modify(|_, w| w.dma1en().set_bit());
    let Some(st) = dma.st.get(COMMAND_RX_STREAM) else {
        return;
    };
    // SAFETY (each raw write below): whole-register values of the stream's CR, PAR, M0AR,
    // NDTR and FCR and of DMA1_HIFCR as RM0385 "DMA controller" defines them; the stream is
    // disabled (EN = 0) while it is configured.
    st.cr.write(|w| unsafe { w.bits(0) });
    let _ = stm32::spin(UART_SPIN_LIMIT, || st.cr.read().bits() & 1 == 0);
    // Stream 5's flags in HIFCR: CFEIF5 (6), CDMEIF5 (8), CTEIF5 (9), CHTIF5 (10), CTCIF5 (11).
    dma.hifcr.write(|w| unsafe { w.bits(0x0F40) });
    let u = usart2();
    st.par
        .write(|w| unsafe { w.bits(core::ptr::addr_of!(u.rdr) as u32) });
    st.m0ar.write(|w| unsafe { w.bits(COMMAND_RX.address()) });
    st.ndtr.write(|w| unsafe { w.bits(COMMAND_RX_RING as u32) });
    st.fcr.write(|w| unsafe { w.bits(0) });
    // CHSEL = 4 (bits 25–27), MINC (10), CIRC (8); DIR = 00 (peripheral to memory), PSIZE =
    // MSIZE = 00 (bytes), priority low.
    let cr = (COMMAND_RX_CHANNEL << 25) | (1 << 10) | (1 << 8);
    st.cr.write(|w| unsafe { w.bits(cr) });
    st.cr.write(|w| unsafe { w.bits(cr | 1) });
    // USART2: OVRDIS (CR3 bit 12, writable only with UE = 0) and DMAR (CR3 bit 6).
    u.cr1.modify(|_, w| w.ue().clear_bit());
    u.cr3
        .modify(|r, w| unsafe { w.bits(r.bits() | (1 << 12) | (1 << 6)) });
    u.cr1.modify(|_, w| w.ue().set_bit());
}
/// Log ring buffer size, bytes (≈ 25 tick records).
pub const LOG_RING: usize = 1024;
/// Longest busy-wait on a bus UART flag (TXE, TC), loop iterations: one iteration is a few
/// cycles (a register read and a compare), so 10⁶ iterations are ≥ 5 ms at 216 MHz, more than
/// a byte at the slowest rate (9600 baud: 1.04 ms). Beyond it the bus is hung:
/// [`BusError::Timeout`].
pub const UART_SPIN_LIMIT: u32 = 1_000_000;

/// The parameter store's region: sectors 6 and 7 of the F746ZG's single-bank flash (256 KiB
/// each, 0x0808_0000 ..= 0x080F_FFFF, RM0385 "Embedded flash memory"), outside the image:
/// memory.x ends the OpenCR's FLASH region at 0x0808_0000. Offset from the flash base.
pub const STORE_OFFSET: u32 = 0x8_0000;
/// The store region's first sector (slot i is sector 6 + i).
pub const STORE_FIRST_SECTOR: u8 = 6;
/// Bytes per store sector.
pub const STORE_SECTOR_LEN: usize = 256 * 1024;
/// The flash as the CPU reads it (AXIM).
const FLASH_AXIM: u32 = 0x0800_0000;
/// The watchdog's period while the store erases and programs, ms: the CPU fetches nothing
/// from flash while a sector erases (it stalls until the erase ends, seconds for 256 KiB), so
/// nothing can feed a 50 ms watchdog meanwhile.
pub const STORE_WATCHDOG_MS: u32 = 16_000;

/// Sectors 6 and 7 as an `embedded-storage` NOR flash (stm32f7xx-hal 0.8 does not implement
/// the trait): byte reads through AXIM, sector erase and byte programming (x8 parallelism, any
/// supply voltage) through the HAL's flash interface, locked again after each operation.
struct StoreFlash<'a>(&'a mut Flash);

impl nor::ErrorType for StoreFlash<'_> {
    type Error = nor::NorFlashErrorKind;
}

impl nor::ReadNorFlash for StoreFlash<'_> {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        nor::check_read(self, offset, bytes.len())?;
        let base = FLASH_AXIM + STORE_OFFSET + offset;
        for (addr, b) in (base..).zip(bytes.iter_mut()) {
            // SAFETY: `check_read` keeps addr inside sectors 6–7 of the F746ZG's flash,
            // readable memory that no Rust object owns.
            *b = unsafe { core::ptr::read_volatile(addr as *const u8) };
        }
        Ok(())
    }
    fn capacity(&self) -> usize {
        2 * STORE_SECTOR_LEN
    }
}

impl nor::NorFlash for StoreFlash<'_> {
    const WRITE_SIZE: usize = 1;
    const ERASE_SIZE: usize = STORE_SECTOR_LEN;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        nor::check_erase(self, from, to)?;
        let len = STORE_SECTOR_LEN as u32;
        for k in from / len..to / len {
            let sector = STORE_FIRST_SECTOR.saturating_add(k as u8);
            self.0.unlock();
            let r = self.0.blocking_erase_sector(sector);
            self.0.lock();
            r.map_err(|_| nor::NorFlashErrorKind::Other)?;
        }
        Ok(())
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        nor::check_write(self, offset, bytes.len())?;
        self.0.unlock();
        let r = self
            .0
            .blocking_program((STORE_OFFSET + offset) as usize, bytes);
        self.0.lock();
        r.map_err(|_| nor::NorFlashErrorKind::Other)
    }
}

/// The Dynamixel direction pin as an `embedded-hal` 1.0 output (stm32f7xx-hal 0.8 pins only
/// implement embedded-hal 0.2): PC9, high = transmit.
pub struct DxlDir(PC9<Output<PushPull>>);

impl ErrorType for DxlDir {
    type Error = core::convert::Infallible;
}

impl OutputPin for DxlDir {
    fn set_low(&mut self) -> Result<(), Self::Error> {
        self.0.set_low();
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Self::Error> {
        self.0.set_high();
        Ok(())
    }
}

/// Configures `usart` on `pins` at `baud` (clocked from SYSCLK) and leaves it configured for
/// the register-level drivers of this board (no DMA requests).
fn uart_up<U: serial::Instance, P: serial::Pins<U>>(usart: U, pins: P, clocks: &Clocks, baud: u32) {
    let config = serial::Config {
        baud_rate: baud.bps(),
        sysclock: true,
        ..Default::default()
    };
    let (u, _pins) = Serial::new(usart, pins, clocks, config).release();
    u.cr3.write(|w| w.dmat().disabled().dmar().disabled());
}

register_blocks! {
    /// The bus UART USART3 (owned by the board after `new`).
    fn usart3() -> pac::usart1::RegisterBlock = pac::USART3;
    /// The log UART USART6 (owned by the board after `new`).
    fn usart6() -> pac::usart1::RegisterBlock = pac::USART6;
    /// The command port USART2 (owned by the board after `new`).
    fn usart2() -> pac::usart1::RegisterBlock = pac::USART2;
    /// The IMU's SPI1 (owned by the board after `new`).
    fn spi1() -> pac::spi1::RegisterBlock = pac::SPI1;
}

/// Best-effort torque off from anywhere (panic handler): direction pin high, the broadcast
/// Torque Enable = 0 packet on USART3 with bounded spins, direction low, then the servo power
/// FET off. Harmless if the board was never initialised (writes then go nowhere).
pub fn panic_torque_off() {
    // SAFETY: register-level access during a panic/exit: nothing else runs any more. GPIOC/F
    // BSRR writes are atomic set/reset of single pins.
    let gpioc = unsafe { &*pac::GPIOC::ptr() };
    let gpiof = unsafe { &*pac::GPIOF::ptr() };
    let u = usart3();
    gpioc.bsrr.write(|w| w.bs9().set_bit());
    'send: for &b in TORQUE_OFF_PACKET.iter() {
        let mut spins = 0u32;
        while u.isr.read().txe().bit_is_clear() {
            spins += 1;
            if spins > 1_000_000 {
                break 'send;
            }
        }
        u.tdr.write(|w| w.tdr().bits(u16::from(b)));
    }
    let mut spins = 0u32;
    while u.isr.read().tc().bit_is_clear() && spins < 1_000_000 {
        spins += 1;
    }
    gpioc.bsrr.write(|w| w.br9().set_bit());
    // Give the servos a moment to act on the packet before cutting their power (~2 ms).
    cortex_m::asm::delay(SYSCLK_HZ / 500);
    gpiof.bsrr.write(|w| w.br15().set_bit());
}

/// Panic path of the OpenCR binary: log, record the panic in no-init RAM, torque off and
/// servo power off, reset (the next boot logs the record and does not walk).
pub fn panic_reset(info: &core::panic::PanicInfo) -> ! {
    stm32::panic_reset(info, panic_torque_off)
}

/// The OpenCR board. `D` is the bus direction pin ([`DxlDir`] on the real board).
pub struct OpenCrBoard<D: OutputPin = DxlDir> {
    dir: D,
    dxl_power: PF15<Output<PushPull>>,
    /// The IMU's chip select (high = idle).
    imu_cs: PA4<Output<PushPull>>,
    /// The IMU once started ([`crate::board::Board::imu_start`]).
    imu: Option<Mpu9250>,
    baud: u32,
    tim: pac::TIM2,
    iwdg: IndependentWatchdog,
    /// The watchdog's period since [`Watchdog::start`], ms.
    watchdog_ms: u32,
    flash: Flash,
    /// Where the loop stopped reading the command port's receive ring.
    command_rx: DmaRxCursor<COMMAND_RX_RING>,
    state: Stm32State,
    ring: LogRing<LOG_RING>,
}

impl OpenCrBoard<DxlDir> {
    /// Brings the board up: 216 MHz clocks, Dynamixel power on, USART3 bus at
    /// `cfg.bus_baud`, USART6 log at [`LOG_BAUD`], TIM2 at 1 MHz. The watchdog is not started.
    pub fn new(dp: pac::Peripherals, cfg: &Config) -> Self {
        // The reset flags first, then clear them (RMVF) so that the next boot sees its own.
        let reset_csr = dp.RCC.csr.read().bits();
        dp.RCC.csr.modify(|_, w| w.rmvf().set_bit());
        let rcc = dp.RCC.constrain();
        let clocks = rcc
            .cfgr
            .hse(HSEClock::new(HSE_HZ.Hz(), HSEClockMode::Oscillator))
            .sysclk(SYSCLK_HZ.Hz())
            .freeze();

        let gpioa = dp.GPIOA.split();
        let gpiob = dp.GPIOB.split();
        let gpioc = dp.GPIOC.split();
        let gpiod = dp.GPIOD.split();
        let gpiof = dp.GPIOF.split();
        let gpiog = dp.GPIOG.split();
        // The operator buttons, read as raw levels by `enable_button` (the board pulls them).
        let _buttons = (
            gpioc.pc12.into_floating_input(),
            gpiog.pg3.into_floating_input(),
        );

        let mut dir = gpioc.pc9.into_push_pull_output();
        dir.set_low();
        let mut power = gpiof.pf15.into_push_pull_output();
        power.set_high();

        let bus_pins = (
            gpioc.pc10.into_alternate::<7>(),
            gpioc.pc11.into_alternate::<7>(),
        );
        uart_up(dp.USART3, bus_pins, &clocks, cfg.bus_baud);
        let log_pins = (
            gpioc.pc6.into_alternate::<8>(),
            gpioc.pc7.into_alternate::<8>(),
        );
        uart_up(dp.USART6, log_pins, &clocks, LOG_BAUD);
        let cmd_pins = (
            gpiod.pd5.into_alternate::<7>(),
            gpiod.pd6.into_alternate::<7>(),
        );
        uart_up(dp.USART2, cmd_pins, &clocks, COMMAND_BAUD);
        command_rx_dma_up(&dp.DMA1);

        // The IMU: its chip select high first, then SPI1's pins (pulled up as ROBOTIS'
        // `HAL_SPI_MspInit` has them: SCK idles high in mode 3 while SPI1 is off, and MISO
        // reads 0xFF without a chip). SPI1 itself is set up by `imu_start`.
        let imu_cs = gpioa.pa4.into_push_pull_output_in_state(PinState::High);
        let _imu_spi = (
            gpioa
                .pa5
                .into_alternate::<5>()
                .set_speed(Speed::High)
                .internal_pull_up(true),
            gpioa.pa6.into_alternate::<5>().internal_pull_up(true),
            gpiob
                .pb5
                .into_alternate::<5>()
                .set_speed(Speed::High)
                .internal_pull_up(true),
        );

        // TIM2: 32-bit free-running µs counter. APB1 timers run at 2 × PCLK1.
        // SAFETY: enabling the TIM2 clock in RCC.APB1ENR and SPI1's in RCC.APB2ENR
        // (read-modify-writes, single core, before interrupts are used).
        let rcc_regs = unsafe { &*pac::RCC::ptr() };
        rcc_regs.apb1enr.modify(|_, w| w.tim2en().set_bit());
        rcc_regs.apb2enr.modify(|_, w| w.spi1en().set_bit());
        let tim = dp.TIM2;
        let prescale = (clocks.timclk1().raw() / 1_000_000).saturating_sub(1);
        tim.psc.write(|w| w.psc().bits(prescale.min(0xFFFF) as u16));
        tim.arr.write(|w| w.bits(u32::MAX));
        tim.egr.write(|w| w.ug().set_bit());
        tim.cr1.modify(|_, w| w.cen().set_bit());

        let iwdg = IndependentWatchdog::new(dp.IWDG);

        OpenCrBoard {
            dir: DxlDir(dir),
            dxl_power: power,
            imu_cs,
            imu: None,
            baud: cfg.bus_baud,
            tim,
            iwdg,
            watchdog_ms: 0,
            flash: Flash::new(dp.FLASH),
            command_rx: DmaRxCursor::new(),
            state: Stm32State::new(cfg, reset_csr),
            ring: LogRing::new(),
        }
    }
}

impl<D: OutputPin> OpenCrBoard<D> {
    /// A running watchdog's period set to `ms` (the counter reloaded once the new prescaler and
    /// reload value are in force: IWDG_SR clear, at most 10 ms); nothing when it is not running.
    fn watchdog_period(&mut self, ms: u32) {
        if !self.state.watchdog_running {
            return;
        }
        self.iwdg.start(ms.max(1).millis());
        // SAFETY: a read of IWDG_SR (PVU, RVU: an update of PR or RLR under way).
        let iwdg = unsafe { &*pac::IWDG::ptr() };
        let start = self.now_us();
        while iwdg.sr.read().bits() & 0b11 != 0 && self.now_us() < start + 10_000 {}
        self.iwdg.feed();
    }

    /// Busy-waits until `until_us` on the µs clock, feeding a running watchdog meanwhile (the
    /// IMU's 100 ms waits at start-up outlast its period; the wait itself is bounded).
    #[inline(never)]
    fn wait_fed(&mut self, until_us: u64) {
        while self.now_us() < until_us {
            self.feed();
        }
    }

    /// Moves log bytes from the ring to USART6 while its data register is free.
    fn pump_log(&mut self) {
        let u = usart6();
        while u.isr.read().txe().bit_is_set() {
            let Some(b) = self.ring.pop() else {
                break;
            };
            u.tdr.write(|w| w.tdr().bits(u16::from(b)));
        }
    }
}

/// A USART of the F746 (the bus UART USART3 for the shared bus code, the command port USART2).
pub(crate) struct Usart(&'static pac::usart1::RegisterBlock);

impl Usart {
    /// Clears the error flags (ICR) if any is set; whether one was.
    fn clear_errors(&self, isr: &pac::usart1::isr::R) -> bool {
        let error = isr.ore().bit_is_set() || isr.fe().bit_is_set() || isr.nf().bit_is_set();
        if error {
            self.0
                .icr
                .write(|w| w.orecf().set_bit().fecf().set_bit().ncf().set_bit());
        }
        error
    }
}

impl BusUart for Usart {
    const SPIN_LIMIT: u32 = UART_SPIN_LIMIT;
    const CLOCK_HZ: u32 = SYSCLK_HZ;
    fn tx_empty(&self) -> bool {
        self.0.isr.read().txe().bit_is_set()
    }
    fn tx_complete(&self) -> bool {
        self.0.isr.read().tc().bit_is_set()
    }
    fn write(&self, b: u8) {
        self.0.tdr.write(|w| w.tdr().bits(u16::from(b)));
    }
    fn status(&self) -> (bool, bool) {
        let isr = self.0.isr.read();
        (self.clear_errors(&isr), isr.rxne().bit_is_set())
    }
    fn read(&self) -> u8 {
        (self.0.rdr.read().bits() & 0xFF) as u8
    }
    fn discard(&self) -> bool {
        let error = self.clear_errors(&self.0.isr.read());
        while self.0.isr.read().rxne().bit_is_set() {
            let _ = self.0.rdr.read().bits();
        }
        error
    }
    fn set_divider(&self, div: u32) {
        self.0.cr1.modify(|_, w| w.ue().clear_bit());
        // SAFETY: any 16-bit value is a valid BRR; `div` is in 16..=0xFFFF.
        self.0.brr.write(|w| unsafe { w.bits(div) });
        self.0.cr1.modify(|_, w| w.ue().set_bit());
    }
}

impl<D: OutputPin> Stm32Bus for OpenCrBoard<D> {
    type Uart = Usart;
    fn bus_uart(&self) -> Usart {
        Usart(usart3())
    }
    fn bus_direction(&mut self, transmit: bool) {
        let _ = if transmit {
            self.dir.set_high()
        } else {
            self.dir.set_low()
        };
    }
    fn stm32_state(&mut self) -> &mut Stm32State {
        &mut self.state
    }
}

impl<D: OutputPin> Clock for OpenCrBoard<D> {
    fn now_us(&self) -> u64 {
        let cnt = self.tim.cnt.read().bits();
        self.state.clock.extend(cnt)
    }
}

impl<D: OutputPin> Watchdog for OpenCrBoard<D> {
    fn start(&mut self, timeout_ms: u32) {
        if !self.state.watchdog_running {
            self.iwdg.start(timeout_ms.max(1).millis());
            self.watchdog_ms = timeout_ms;
            self.state.watchdog_running = true;
        }
    }
    fn feed(&mut self) {
        if self.state.watchdog_running {
            self.iwdg.feed();
        }
    }
}

stm32_board! {
    impl<D: OutputPin> for OpenCrBoard<D> {
        name: "opencr-1.0",
        id: BoardId::OpenCr,

        fn servo_power(&mut self, on: bool) {
            // The Dynamixel power enable is PF15 (`BDPIN_DXL_PWR_EN`, high = on) per the OpenCR
            // 1.0 documentation: ROBOTIS e-Manual "OpenCR 1.0" (schematic, OpenCR_REV1.0) and
            // the OpenCR Arduino core's variant.h. Low switches the FET off: the servos lose
            // power.
            if on {
                self.dxl_power.set_high();
            } else {
                self.dxl_power.set_low();
            }
            defmt::warn!("servo power {=bool} (PF15)", on);
        }

        fn command_rx(&mut self, buf: &mut [u8]) -> usize {
            // SAFETY: a read of DMA1 stream 5's NDTR (the stream belongs to the command port).
            let dma = unsafe { &*pac::DMA1::ptr() };
            let remaining = dma
                .st
                .get(COMMAND_RX_STREAM)
                .map_or(usize::MAX, |st| (st.ndtr.read().bits() & 0xFFFF) as usize);
            COMMAND_RX.take(&mut self.command_rx, remaining, buf)
        }

        fn enable_button(&mut self) -> Option<bool> {
            // SAFETY: reads of GPIOC/GPIOG's input data registers (PC12 and PG3 are inputs
            // since `OpenCrBoard::new`).
            let (gpioc, gpiog) = unsafe { (&*pac::GPIOC::ptr(), &*pac::GPIOG::ptr()) };
            let c = gpioc.idr.read().idr12().bit_is_set();
            let g = gpiog.idr.read().idr3().bit_is_set();
            Some(c || g)
        }

        fn command_tx(&mut self, bytes: &[u8]) {
            // ≤ 312 bytes at 1 Mbps ≈ 3.1 ms, each wait bounded.
            let u = usart2();
            for &b in bytes {
                if stm32::spin(UART_SPIN_LIMIT, || u.isr.read().txe().bit_is_set()).is_err() {
                    return;
                }
                u.tdr.write(|w| w.tdr().bits(u16::from(b)));
            }
        }

        fn store_read(&mut self, slot: usize, buf: &mut [u8]) -> bool {
            FlashStore::new(StoreFlash(&mut self.flash)).is_some_and(|mut s| s.read(slot, buf))
        }

        fn store_write(&mut self, slot: usize, data: &[u8]) -> bool {
            self.watchdog_period(STORE_WATCHDOG_MS);
            let ok = FlashStore::new(StoreFlash(&mut self.flash))
                .is_some_and(|mut s| s.write(slot, data));
            self.watchdog_period(self.watchdog_ms);
            defmt::info!("parameter store: slot {=usize} written {=bool}", slot, ok);
            ok
        }

        fn imu_start(&mut self) -> Option<Result<(), ImuError>> {
            // As ROBOTIS' `cMPU9250::begin`: the chip's power-up time, then the chip checked,
            // reset and configured at the register rate, the samples at the faster one.
            self.imu = None;
            imu_spi_up(IMU_BR_REGISTER);
            self.wait_fed(IMU_POWER_UP_US);
            let started = Mpu9250::start(&mut ImuPort { board: self });
            Some(started.map(|imu| {
                imu_spi_up(IMU_BR_SAMPLE);
                self.imu = Some(imu);
            }))
        }

        fn imu_sample(&mut self) -> Option<Result<ImuSample, ImuError>> {
            let mut imu = self.imu.take()?;
            let s = imu.sample(&mut ImuPort { board: self });
            self.imu = Some(imu);
            Some(s)
        }

        fn exit(&mut self, code: i32) -> ! {
            defmt::warn!("exit({=i32}): torque off, servo power off, reset", code);
            self.shut_down(panic_torque_off)
        }
    }
}

/// SPI1's CR1.BR for `hz`: f_SCK = f_PCLK2 / 2^(BR + 1) (RM0385 SPI_CR1); exact only for a
/// power-of-two divider of [`APB2_HZ`] (checked below).
const fn spi1_br(hz: u32) -> u8 {
    // log2(f_PCLK2 / hz) ≤ 31 fits a u8; 0 for a rate of 0 or above f_PCLK2.
    match APB2_HZ.checked_div(hz) {
        Some(div) => match div.checked_ilog2() {
            Some(log2) => log2.saturating_sub(1) as u8,
            None => 0,
        },
        None => 0,
    }
}
/// SPI1's BR while the IMU starts (every register: ≤ 1 MHz).
const IMU_BR_REGISTER: u8 = spi1_br(IMU_SPI_REGISTER_HZ);
/// SPI1's BR for the IMU's samples (sensor registers: ≤ 20 MHz).
const IMU_BR_SAMPLE: u8 = spi1_br(IMU_SPI_SAMPLE_HZ);
const _: () = assert!(APB2_HZ / 128 == IMU_SPI_REGISTER_HZ && IMU_BR_REGISTER == 0b110);
const _: () = assert!(APB2_HZ / 16 == IMU_SPI_SAMPLE_HZ && IMU_BR_SAMPLE == 0b011);

/// Longest busy-wait on an SPI1 flag (TXE, RXNE, BSY), loop iterations: one iteration is at
/// least a few cycles (a peripheral read and a compare), so 10⁴ are ≥ 0.1 ms at 216 MHz, more
/// than ten bytes at the slowest rate (8 bits at 843.75 kHz: 9.5 µs), while a hung SPI costs
/// a tick a millisecond or two (one timeout ends the transfer).
const IMU_SPIN_LIMIT: u32 = 10_000;

/// Time from power-up before the MPU-9250's registers answer, µs (its start-up time for
/// register access, ≤ 100 ms; ROBOTIS' `begin` waits 100 ms too): `imu_start` waits until the
/// µs clock, started in `new`, reads it.
const IMU_POWER_UP_US: u64 = 100_000;

/// Empties SPI1's receive FIFO (≤ 4 bytes) and so clears an overrun (a DR read, then an SR
/// read): bytes a transfer that timed out left there.
fn imu_spi_drain(spi: &pac::spi1::RegisterBlock) {
    for _ in 0..4 {
        if spi.sr.read().rxne().bit_is_clear() {
            break;
        }
        // SAFETY: an 8-bit read of SPI1_DR (a byte out of the receive FIFO), the one
        // access size that takes one 8-bit frame (RM0385 "Data packing").
        let _ = unsafe { core::ptr::read_volatile(spi.dr.as_ptr().cast::<u8>()) };
    }
}

/// SPI1 set up for the IMU at f_PCLK2 / 2^(`br` + 1) and enabled (RM0385 "Serial peripheral
/// interface", "Configuration of SPI", "Procedure for disabling the SPI"): first disabled once
/// its last frame is out (BSY clear, bounded) and its receive FIFO emptied; CR1 = master
/// (MSTR), mode 3 (CPOL = 1: SCK idles high; CPHA = 1: data captured on the second, rising
/// edge, where the MPU-9250 latches), `br`, MSB first, full duplex, software NSS held high
/// (SSM = SSI = 1: no mode fault; PA4 selects the chip), no CRC; CR2 = 8-bit frames
/// (DS = 0111) with RXNE at one byte in the FIFO (FRXTH = 1), no NSS output, no interrupts, no
/// DMA; then SPE.
#[inline(never)]
fn imu_spi_up(br: u8) {
    let spi = spi1();
    let _ = imu_spi_until(|sr| sr.bsy().bit_is_clear());
    spi.cr1.modify(|_, w| w.spe().disabled());
    imu_spi_drain(spi);
    spi.cr1.write(|w| {
        w.cpha()
            .second_edge()
            .cpol()
            .idle_high()
            .mstr()
            .master()
            .br()
            .bits(br)
            .lsbfirst()
            .msbfirst()
            .ssi()
            .slave_not_selected()
            .ssm()
            .enabled()
    });
    spi.cr2.write(|w| w.ds().eight_bit().frxth().quarter());
    spi.cr1.modify(|_, w| w.spe().enabled());
}

/// One full-duplex frame on SPI1 (the chip selected), in place: each byte of `frame` written
/// when TXE and replaced by the byte clocked in when RXNE, then BSY clear; every wait bounded.
fn imu_spi_frame(frame: &mut [u8]) -> Result<(), BusError> {
    let dr = spi1().dr.as_ptr().cast::<u8>();
    for b in frame.iter_mut() {
        imu_spi_until(|sr| sr.txe().bit_is_set())?;
        // SAFETY: 8-bit accesses of SPI1_DR, the size that moves one 8-bit frame (a 16-bit
        // access would pack two, RM0385 "Data packing"); SPI1 belongs to the board.
        unsafe { core::ptr::write_volatile(dr, *b) };
        imu_spi_until(|sr| sr.rxne().bit_is_set())?;
        // SAFETY: as above.
        *b = unsafe { core::ptr::read_volatile(dr) };
    }
    imu_spi_until(|sr| sr.bsy().bit_is_clear())
}

/// Waits (bounded: [`IMU_SPIN_LIMIT`]) until SPI1_SR satisfies `ready`.
#[inline(never)]
fn imu_spi_until(ready: fn(&pac::spi1::sr::R) -> bool) -> Result<(), BusError> {
    stm32::spin(IMU_SPIN_LIMIT, || ready(&spi1().sr.read()))
}

/// The board's SPI1 to its IMU, at the rate `imu_spi_up` set, and its wait (TIM2's µs, the
/// watchdog fed).
struct ImuPort<'a, D: OutputPin> {
    board: &'a mut OpenCrBoard<D>,
}

impl<D: OutputPin> embedded_hal::spi::ErrorType for ImuPort<'_, D> {
    type Error = ErrorKind;
}

impl<D: OutputPin> SpiDevice for ImuPort<'_, D> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
        // The bytes out, then in their place the bytes in.
        let mut buf = [0u8; SPI_MAX];
        let n = spi_gather(ops, &mut buf).ok_or(ErrorKind::Other)?;
        let frame = buf.get_mut(..n).ok_or(ErrorKind::Other)?;
        imu_spi_drain(spi1());
        self.board.imu_cs.set_low();
        let clocked = imu_spi_frame(frame);
        // CS held ≥ 500 ns after the last SCK edge (the MPU-9250's t_HD.CS): ≥ 1 µs here.
        cortex_m::asm::delay(SYSCLK_HZ / 1_000_000);
        self.board.imu_cs.set_high();
        clocked.map_err(|_| ErrorKind::Other)?;
        spi_scatter(ops, frame);
        Ok(())
    }
}

impl<D: OutputPin> DelayNs for ImuPort<'_, D> {
    fn delay_ns(&mut self, ns: u32) {
        // One more µs: the counter's resolution.
        let until = self.board.now_us() + u64::from(ns.div_ceil(1_000)) + 1;
        self.board.wait_fed(until);
    }
}
