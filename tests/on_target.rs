//! On-target tests: run on the emulated Cortex-M7 (QEMU mps2-an500) with defmt-test.
//!
//! Run:
//! ```text
//! CARGO_TARGET_THUMBV7EM_NONE_EABIHF_RUNNER=scripts/qemu-run.sh \
//!     cargo test --release --no-default-features --features board-qemu --test on_target
//! ```
//! (or `cargo qemu-test`). The runner's exit status is the firmware's: 0 when every test
//! passed (defmt-test exits through semihosting), 101 on the first failure (panic handler).
#![no_std]
#![no_main]

use walker_firmware::boards::qemu_mps2;

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    qemu_mps2::panic_exit(info)
}

/// A Dynamixel 2.0 PING instruction packet to `id`.
fn ping(id: u8) -> [u8; 10] {
    let mut p = [0xFF, 0xFF, 0xFD, 0x00, id, 3, 0, 0x01, 0, 0];
    let crc = dxl::crc::crc16(&p[..8]);
    p[8] = (crc & 0xFF) as u8;
    p[9] = (crc >> 8) as u8;
    p
}

#[defmt_test::tests]
mod tests {
    use core::hint::black_box;
    use defmt::assert;
    use walker_firmware::board::{
        Board, Clock, CrashCode, CrashNote, ResetCause, ServoBus, TickTimer, TORQUE_OFF_PACKET,
    };
    use walker_firmware::boards::qemu_mps2::QemuBoard;
    use walker_firmware::imu::{PitchAccel, PitchAccelConfig, TiltEstimator};
    use walker_firmware::record::{self as log, Record, RecordDecoder, TickRecord};
    use walker_firmware::supervisor::{safe_targets, JointMap};
    use walker_firmware::Config;

    #[init]
    fn init() -> QemuBoard {
        let cp = cortex_m::Peripherals::take();
        assert!(cp.is_some());
        match cp {
            Some(_core) => QemuBoard::new(&Config::default()),
            None => walker_firmware::boards::qemu_mps2::semihosting_exit(2),
        }
    }

    #[test]
    fn fpu_is_enabled_and_right() {
        // CPACR: CP10 and CP11 full access (cortex-m-rt enables the FPU on eabihf).
        // SAFETY: read-only access to the always-present CPACR register.
        let cpacr = unsafe { core::ptr::read_volatile(0xE000_ED88 as *const u32) };
        assert!((cpacr >> 20) & 0xF == 0xF, "CPACR = {=u32:#x}", cpacr);
        let x = black_box(1.5f32) * black_box(2.25f32) + black_box(0.125f32);
        assert!(x == 3.5);
        let q = black_box(1.0f32) / black_box(3.0f32);
        assert!((q - 0.333_333_34).abs() < 1e-7);
        assert!((libm::sqrtf(black_box(2.0)) - core::f32::consts::SQRT_2).abs() < 1e-6);
        assert!((libm::sinf(black_box(0.3)) - 0.295_520_2).abs() < 1e-6);
        assert!(
            (libm::atan2f(black_box(1.0), black_box(1.0)) - core::f32::consts::FRAC_PI_4).abs()
                < 1e-6
        );
    }

    #[test]
    fn vsqrt_matches_libm_bit_for_bit() {
        // `fastmath::sqrt` is VSQRT.F32 on this target; both it and libm's software sqrtf are
        // correctly rounded, so they must agree exactly.
        let mut bits = 0x0080_0000u32;
        for _ in 0..4_000 {
            let x = black_box(f32::from_bits(bits));
            let (a, b) = (gait_core::maths::fastmath::sqrt(x), libm::sqrtf(x));
            assert!(
                a.to_bits() == b.to_bits(),
                "sqrt({=f32}) {=f32} vs {=f32}",
                x,
                a,
                b
            );
            bits = bits.wrapping_add(0x0007_F3A1) % 0x7F00_0000;
        }
        assert!(gait_core::maths::fastmath::sqrt(black_box(-1.0)).is_nan());
        assert!(gait_core::maths::fastmath::sqrt(black_box(0.0)) == 0.0);
    }

    #[test]
    fn reference_robot_validates() {
        let r = gait_core::Robot::reference();
        assert!(r.validate().is_ok());
        assert!((r.masses.total() - 4.95).abs() < 1e-9);
    }

    #[test]
    fn log_round_trip() {
        let mut rec = TickRecord {
            seq: 7,
            time_us: 1_234_567,
            ..TickRecord::default()
        };
        rec.set_zmp_ref_m(0.012, -0.0451);
        rec.set_com_m(-1.5, 29.0);
        rec.set_tau_nm(0.042);
        let rec = Record::Tick(rec);
        let mut buf = [0u8; log::MAX_FRAME * 2];
        let n = log::encode(&rec, &mut buf);
        assert!(n == log::TICK_FRAME_LEN);
        // Start mid-frame: the partial copy is rejected, the full one decoded.
        let mut stream = [0u8; 3 * log::TICK_FRAME_LEN];
        stream[..n].copy_from_slice(&buf[..n]);
        stream[n..2 * n].copy_from_slice(&buf[..n]);
        let mut d = RecordDecoder::new();
        let mut found = 0;
        d.feed(&stream[5..2 * n], |r| {
            if let Ok(r) = r {
                assert!(r == rec);
                found += 1;
            }
        });
        assert!(found == 1);
        assert!(d.stats().rejected == 1);
    }

    #[test]
    fn imu_filter_on_synthetic_signal() {
        let dt = 1e-3f32;
        let mut f = PitchAccel::new(PitchAccelConfig::reference(dt));
        // Constant rate → τ → 0.
        for _ in 0..500 {
            f.update(0.7);
        }
        assert!(f.torque().abs() < 1e-6);
        // 5 Hz sinusoid (200 samples per period): fitted amplitude matches |H|.
        let hz = 5.0f32;
        let a = 0.5f32;
        let (mut s, mut c) = (0.0f32, 0.0f32);
        for k in 0..1400 {
            let ph = core::f32::consts::TAU * hz * dt * (k % 200) as f32;
            let y = f.update(a * libm::sinf(ph));
            if k >= 600 {
                s += y * libm::sinf(ph);
                c += y * libm::cosf(ph);
            }
        }
        let amp = 2.0 * libm::sqrtf(s * s + c * c) / 800.0;
        let (g, _) = f.response(hz);
        assert!(
            (amp / (a * g) - 1.0).abs() < 0.01,
            "amp {=f32} vs {=f32}",
            amp,
            a * g
        );
        // NaN never propagates.
        assert!(f.update(f32::NAN).is_finite());
        let mut t = TiltEstimator::new();
        assert!((t.update([0.0, 0.0, 9.8]).tilt).abs() < 1e-6);
    }

    #[test]
    fn safe_targets_reject_nan() {
        let map = JointMap::from_robot(&gait_core::Robot::reference());
        let mut prev = [2048i32; 12];
        prev[4] = 2222;
        let mut t = [0.1f32; 12];
        t[4] = f32::NAN;
        t[3] = 9.0;
        match safe_targets(&t, &map, &prev) {
            Ok(_) => assert!(false, "NaN accepted"),
            Err(e) => {
                assert!(e.non_finite == 1 << 4);
                assert!(e.ticks[4] == 2222);
                assert!(e.clamped == 1 << 3);
                assert!(e.ticks.iter().all(|&x| (0..=4095).contains(&x)));
            }
        }
    }

    #[test]
    fn virtual_clock_is_modelled(board: &mut QemuBoard) {
        // Unconnected bus (no lock-step): sending costs 10 bits per byte at 1 Mbps, a read
        // times out at once and jumps to the deadline; the tick lands on k · period.
        if board.lockstep() {
            defmt::info!("simulator attached: unconnected-bus test skipped");
            return;
        }
        let t0 = board.now_us();
        assert!(board.send(&TORQUE_OFF_PACKET).is_ok());
        assert!(board.now_us() - t0 == 130);
        let mut buf = [0u8; 11];
        assert!(board.recv(&mut buf, 500) == Ok(0));
        assert!(board.now_us() - t0 == 630);
        let tick = board.wait_tick();
        assert!(tick.nominal_us.is_multiple_of(1000));
        assert!(board.now_us() == tick.nominal_us);
        let next = board.wait_tick();
        assert!(next.index == tick.index + 1 && !next.overrun);
    }

    #[test]
    fn power_on_servo_power_and_the_crash_cell(board: &mut QemuBoard) {
        // Every QEMU run is a power-on; the servo power switch is a logged no-op; the crash
        // cell keeps the last tick noted and a panic mark (volatile stores on the target).
        assert!(board.reset_cause() == (ResetCause::PowerOn, 0));
        board.servo_power(false);
        board.crash_cell().note_tick(5);
        board.crash_cell().record(CrashCode::Panic);
        let note = board.crash_cell().take();
        assert!(
            note == Some(CrashNote {
                code: Some(CrashCode::Panic),
                tick: 5
            })
        );
        assert!(board.crash_cell().take().is_none());
    }

    /// Only with a simulator attached (`--bus … --lockstep …`); a no-op otherwise. The
    /// simulator must answer a PING to id 1 with its 14-byte status packet and drop the PING
    /// to id 2 (fault injection), announcing 14 and 0 bytes.
    #[test]
    fn lockstep_bus_round_trip(board: &mut QemuBoard) {
        if !board.lockstep() {
            defmt::info!("no simulator attached: lock-step test skipped");
            return;
        }
        let t0 = board.now_us();
        assert!(board.send(&super::ping(1)).is_ok());
        assert!(board.now_us() - t0 == 100);
        let mut buf = [0u8; 14];
        assert!(board.recv(&mut buf, 1000) == Ok(14));
        assert!(buf[..5] == [0xFF, 0xFF, 0xFD, 0x00, 1] && buf[7] == 0x55);
        assert!(board.now_us() - t0 == 240);
        // Nothing more was announced: an immediate, deterministic timeout.
        assert!(board.recv(&mut buf[..1], 300) == Ok(0));
        assert!(board.now_us() - t0 == 540);
        // Dropped reply (fault injection in the simulator): timeout at the deadline exactly.
        assert!(board.send(&super::ping(2)).is_ok());
        assert!(board.recv(&mut buf, 1000) == Ok(0));
        assert!(board.now_us() - t0 == 540 + 100 + 1000);
        // Broadcast: no reply announced.
        assert!(board.send(&TORQUE_OFF_PACKET).is_ok());
        assert!(board.recv(&mut buf, 200) == Ok(0));
        assert!(board.now_us() - t0 == 1640 + 130 + 200);
        assert!(board.lockstep_errors() == 0);
    }
}
