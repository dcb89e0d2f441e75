//! On-target benchmark: instructions per call of the library stages of the control tick, and per
//! tick and per stage of the firmware's own control loop (`control::run` on the fake robot, the
//! stages marked by the controller: [`Stage`]), counted in QEMU with `-icount shift=0`
//! (1 instruction = 1 virtual ns).
//!
//! Build and run (`scripts/bench.sh` does all of this and rewrites BENCHMARKS.md):
//! ```text
//! cargo build --release --no-default-features --features board-qemu,fake-robot --bin bench
//! scripts/qemu-run.sh target/thumbv7em-none-eabihf/release/bench --raw     # mps2-an500
//! cargo build --release --no-default-features --features board-qemu,fake-robot --bin bench \
//!     --target thumbv7m-none-eabi
//! scripts/qemu-run.sh target/thumbv7m-none-eabi/release/bench --raw        # mps2-an385
//! ```
//!
//! # Method
//! SysTick runs free at 25 MHz from reload 0xFF_FFFF; under `-icount shift=0` one count is 40
//! instructions, exactly, run after run. Each figure comes from a loop of K calls
//! ([`measure`]): the counter is read before and after every call. The **average** is the
//! telescoped sum of the counts from the end of one call to the end of the next (so the
//! 40-instruction granularity falls out, K·40 instructions ≥ …), minus the loop's own
//! overhead per iteration measured with an empty call; the **max** is the largest count
//! between the two reads around a single call, times 40 (resolution one count = 40
//! instructions; it includes the call and the two reads). The control loop's figures are per
//! walking tick and per stage of it, the board's own code (the emulated bus and devices, the
//! log sink) left out.
//! Inputs that a stage takes from an earlier stage (the IK's gait samples) are computed
//! beforehand into RAM, so that each stage is timed alone.
//!
//! Output: one `key value` pair per line on semihosting stdout (`hprintln!`; defmt stays
//! silent in this binary), then `done 1` and exit code 0.
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]

walker_firmware::host_stub!(
    "the bench runs in QEMU only: bash scripts/bench.sh \
         (thumbv7em-none-eabihf on mps2-an500/an386, thumbv7m-none-eabi on mps2-an385)"
);

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod firmware {
    use core::hint::black_box;
    use core::mem::MaybeUninit;

    use cortex_m::peripheral::{syst::SystClkSource, SYST};
    use cortex_m_rt::entry;
    use cortex_m_semihosting::hprintln;

    use dxl::table::foot::FootForces;
    use dxl::table::imu::ImuSample;
    use dxl::table::{foot, imu, x_series};
    use dxl::{BulkReadRequest, Decoder, Status, StatusError};
    use gait_core::feedback::stabilizer::{Stabilizer, StabilizerInput};
    use gait_core::kinematics::fixed_ik::{self, FixedLegKinematics};
    use gait_core::kinematics::leg::LegKinematics;
    use gait_core::kinematics::pipeline::joint_targets;
    use gait_core::kinematics::wholebody::WholeBody;
    use gait_core::maths::fixed_point::Fx;
    use gait_core::measure::zmp::{FixedZmpMeter, ForceReading, ZmpMeter};
    use gait_core::trajectory::fixed_sampler::{FixedSample, FixedSampler};
    use gait_core::trajectory::fourier::FourierCom;
    use gait_core::trajectory::plan::SwingShape;
    use gait_core::trajectory::swing::swing_foot;
    use gait_core::{
        ForwardWalk, GaitParams, GaitSample, Model, ModelKind, Place, Plan, Robot, Sampler,
    };
    use walker_firmware::board::{ServoBus, Stage, Tick, TickTimer};
    use walker_firmware::boards::qemu_mps2::semihosting_exit;
    use walker_firmware::bus_map;
    use walker_firmware::config::Arithmetic;
    use walker_firmware::control::{self, support_of, Compensation, RunEnd, SupportCache};
    use walker_firmware::fake_robot::{FakeRobot, Feet, ImuMotion, Observer};
    use walker_firmware::imu::{FixedPitchAccel, PitchAccel, PitchAccelConfig};
    use walker_firmware::supervisor::StopReason;
    use walker_firmware::Config;

    /// Plan capacity (Table 2 has 14 steps).
    const CAP: usize = 16;
    /// Servo period of the bench: the firmware's tick ([`Config::default`]).
    const DT_S: f64 = Config::default_config().tick_period_us as f64 * 1e-6;
    /// Room for every tick of the Table 2 walk at 1 kHz (12.16 s) or slower.
    const MAX_TICKS: usize = 12_800;
    /// Calls in the loops that do not walk the plan.
    const K: u32 = 4_096;
    /// SysTick counts per instruction under `-icount shift=0` at 25 MHz.
    const INSN_PER_COUNT: u64 = 40;
    const MASK: u32 = 0x00FF_FFFF;
    /// Foot-board and IMU ids on the bus.
    const FOOT_L: u8 = bus_map::FOOT_LEFT;
    const FOOT_R: u8 = bus_map::FOOT_RIGHT;
    const IMU: u8 = bus_map::IMU;
    /// A foot counts for the measured ZMP from this load on, N.
    const MIN_LOAD_N: f32 = 2.0;

    /// The gait samples of one walk, computed before the stages that consume them are timed.
    static mut SAMPLES: MaybeUninit<[GaitSample<f32>; MAX_TICKS]> = MaybeUninit::uninit();
    /// The same walk from the fixed-point sampler (input of the fixed-point IK stage).
    static mut FX_SAMPLES: MaybeUninit<[FixedSample; MAX_TICKS]> = MaybeUninit::uninit();

    fn now() -> u32 {
        SYST::get_current()
    }

    /// Result of one timed loop, in SysTick counts.
    #[derive(Clone, Copy)]
    struct Stat {
        n: u32,
        total: u64,
        max: u32,
    }

    /// Times `n` calls of `f(i)`, i = 0..n (see the module doc).
    #[inline(never)]
    fn measure(n: u32, f: &mut dyn FnMut(u32)) -> Stat {
        let mut total = 0u64;
        let mut max = 0u32;
        let mut prev = now();
        for i in 0..n {
            let a = now();
            f(i);
            let b = now();
            let d = a.wrapping_sub(b) & MASK;
            if d > max {
                max = d;
            }
            total += u64::from(prev.wrapping_sub(b) & MASK);
            prev = b;
        }
        Stat { n, total, max }
    }

    /// Prints `name.avg` (instructions per call, one decimal, loop overhead removed),
    /// `name.max` (instructions, resolution 40) and `name.n`.
    fn report(name: &str, s: Stat, overhead_milli: u64) {
        let n = u64::from(s.n.max(1));
        let milli = (s.total * INSN_PER_COUNT * 1000 / n).saturating_sub(overhead_milli);
        let tenths = (milli + 50) / 100;
        hprintln!("{}.avg {}.{}", name, tenths / 10, tenths % 10);
        hprintln!("{}.max {}", name, u64::from(s.max) * INSN_PER_COUNT);
        hprintln!("{}.n {}", name, s.n);
    }

    fn walk_plan(kind: ModelKind) -> (GaitParams<f32>, Plan<f32, CAP>) {
        let robot = Robot::reference();
        let walk = ForwardWalk::table2();
        let Ok(model) = Model::<f32>::new(kind, &robot, walk.z_c) else {
            fail("model")
        };
        let params = walk.params(model);
        let Ok(plan) = walk.plan::<f32, CAP>(&robot, params) else {
            fail("plan")
        };
        (params, plan)
    }

    fn fail(what: &str) -> ! {
        hprintln!("error {}", what);
        semihosting_exit(1)
    }

    /// Fills `buf` with the samples `next` yields (until `None` or full); the filled part.
    fn record<T>(
        buf: &mut [MaybeUninit<T>; MAX_TICKS],
        mut next: impl FnMut() -> Option<T>,
    ) -> &[T] {
        let mut n = 0;
        for slot in buf.iter_mut() {
            match next() {
                Some(s) => {
                    slot.write(s);
                    n += 1;
                }
                None => break,
            }
        }
        // SAFETY: the first `n` elements were initialised just above; MaybeUninit<T> has the
        // layout of T; the slice borrows `buf` for its lifetime.
        unsafe { core::slice::from_raw_parts(buf.as_ptr().cast::<T>(), n) }
    }

    /// A static sample buffer as an array of `MaybeUninit` (call once per buffer).
    ///
    /// # Safety
    /// `buf` must not be referred to anywhere else while the result lives.
    unsafe fn slots<T>(
        buf: *mut MaybeUninit<[T; MAX_TICKS]>,
    ) -> &'static mut [MaybeUninit<T>; MAX_TICKS] {
        // SAFETY: (caller) exclusive; an array of MaybeUninit needs no initialisation and has
        // the layout of the uninitialised array.
        unsafe { &mut *buf.cast::<[MaybeUninit<T>; MAX_TICKS]>() }
    }

    /// The stabilizer's per-tick call in `control::run`: the (cached) support polygon of the
    /// reference sample, then `Stabilizer::update` with the measured ZMP and the gyro.
    fn stab_step(
        robot: &Robot,
        stab: &mut Stabilizer<f32>,
        cache: &mut SupportCache,
        reference: &GaitSample<f32>,
        zmp_meas: Option<[f32; 2]>,
        gyro: Option<[f32; 2]>,
    ) -> [f32; 2] {
        stab.update(&StabilizerInput {
            zmp_ref: reference.zmp,
            zmp_meas,
            gyro,
            support: cache.get(robot, reference),
        })
    }

    /// The firmware's stabilizer ([`Config::default_config`] gains, the bench's tick).
    fn new_stabilizer(robot: &Robot) -> Stabilizer<f32> {
        let cfg = Config::default_config();
        Stabilizer::new(&cfg.stabilizer, DT_S, robot.masses.upper_body_height)
    }

    /// The BULK READ of one tick: both foot boards' and the IMU's sample blocks.
    const BULK: [BulkReadRequest; 3] = [
        BulkReadRequest {
            id: FOOT_L,
            addr: foot::SAMPLE.addr,
            len: foot::SAMPLE.len,
        },
        BulkReadRequest {
            id: FOOT_R,
            addr: foot::SAMPLE.addr,
            len: foot::SAMPLE.len,
        },
        BulkReadRequest {
            id: IMU,
            addr: imu::SAMPLE.addr,
            len: imu::SAMPLE.len,
        },
    ];

    /// The three status replies to [`BULK`] as they arrive on the bus (both feet loaded).
    fn reply_stream(buf: &mut [u8; 160]) -> (usize, [usize; 3]) {
        let left = FootForces {
            forces_mn: [4_100, 3_900, 4_300, 3_700],
            counter: 17,
        };
        let right = FootForces {
            forces_mn: [3_800, 4_200, 3_600, 4_400],
            counter: 17,
        };
        let imu_s = ImuSample::from_si([0.012, -0.034, 0.002], [0.15, -0.08, 9.79], 17);
        let mut at = 0;
        let mut lens = [0usize; 3];
        let parts: [(u8, &[u8]); 3] = [
            (FOOT_L, &left.to_bytes()),
            (FOOT_R, &right.to_bytes()),
            (IMU, &imu_s.to_bytes()),
        ];
        for (k, (id, data)) in parts.iter().enumerate() {
            let Some(rest) = buf.get_mut(at..) else {
                fail("reply buffer")
            };
            let Ok(n) = dxl::encode_status(rest, *id, StatusError::OK, data) else {
                fail("encode_status")
            };
            lens[k] = n;
            at += n;
        }
        (at, lens)
    }

    /// What the tick decodes from the bus.
    #[derive(Clone, Copy, Default)]
    struct Sensors {
        feet: [FootForces; 2],
        imu: ImuSample,
    }

    /// Decodes the reply stream byte by byte into `out`; the number of packets accepted.
    fn decode_replies(dec: &mut Decoder<64>, bytes: &[u8], out: &mut Sensors) -> u32 {
        let mut got = 0;
        for &b in bytes {
            if let Some(Ok(p)) = dec.push(b) {
                got += store_reply(&p, out);
            }
        }
        got
    }

    /// Decodes the reply stream with block feeds (`Decoder::feed`, as the bus master does
    /// with its block reads) into `out`; the number of packets accepted.
    fn decode_replies_block(dec: &mut Decoder<64>, bytes: &[u8], out: &mut Sensors) -> u32 {
        let mut got = 0;
        let mut rest = bytes;
        while !rest.is_empty() {
            let (used, ev) = dec.feed(rest);
            if let Some(Ok(p)) = ev {
                got += store_reply(&p, out);
            }
            rest = rest.get(used..).unwrap_or(&[]);
        }
        got
    }

    /// Parses one status packet into `out`; 1 if it was one of the three replies.
    fn store_reply(p: &dxl::Packet<'_>, out: &mut Sensors) -> u32 {
        let Ok(st) = Status::from_packet(p) else {
            return 0;
        };
        match st.id {
            FOOT_L => FootForces::from_bytes(st.data).map(|f| out.feet[0] = f),
            FOOT_R => FootForces::from_bytes(st.data).map(|f| out.feet[1] = f),
            IMU => ImuSample::from_bytes(st.data).map(|s| out.imu = s),
            _ => None,
        }
        .map_or(0, |()| 1)
    }

    /// Encodes the SYNC WRITE of the 12 goal positions (ticks); its length.
    fn encode_goals(buf: &mut [u8; 128], goals: &[i32; 12]) -> usize {
        let bytes: [[u8; 4]; 12] = goals.map(|g| g.to_le_bytes());
        let mut entries: [(u8, &[u8]); 12] = [(0, &[]); 12];
        for (k, e) in entries.iter_mut().enumerate() {
            *e = (bus_map::LEGS[k], &bytes[k][..]);
        }
        dxl::encode_sync_write(
            buf,
            x_series::GOAL_POSITION.addr,
            x_series::GOAL_POSITION.len,
            &entries,
        )
        .unwrap_or(0)
    }

    fn encode_bulk(buf: &mut [u8; 64]) -> usize {
        dxl::encode_bulk_read(buf, &BULK).unwrap_or(0)
    }

    /// `report(name, measure(n, f), ovh)`: `n` calls of `f`, without the loop overhead `ovh`.
    fn bench(name: &str, n: u32, ovh: u64, f: &mut dyn FnMut(u32)) {
        report(name, measure(n, f), ovh)
    }

    #[entry]
    fn main() -> ! {
        let Some(mut cp) = cortex_m::Peripherals::take() else {
            semihosting_exit(2)
        };
        cp.SYST.set_clock_source(SystClkSource::Core);
        cp.SYST.set_reload(MASK);
        cp.SYST.clear_current();
        cp.SYST.enable_counter();

        hprintln!(
            "target {}",
            if cfg!(target_abi = "eabihf") {
                "thumbv7em-none-eabihf"
            } else {
                "thumbv7m-none-eabi"
            }
        );
        hprintln!("tick_us {}", Config::default_config().tick_period_us);
        hprintln!("bus_baud {}", Config::default_config().bus_baud);
        // `BENCH_CONTROL_ONLY=1` at build time: the control loop alone (`=fixed`: its
        // fixed-point path alone); scripts/tick-profile.sh, never scripts/bench.sh.
        if let Some(only) = option_env!("BENCH_CONTROL_ONLY") {
            #[cfg(feature = "fixed-gait")]
            if only == "fixed" {
                let cfg = bench_config(ModelKind::Tlipfm, Arithmetic::Fixed, false);
                let board = control_run(&cfg, "control_fixed");
                report("control.tick_fixed", board.folded, 0);
                hprintln!("done 1");
                semihosting_exit(0)
            }
            let _ = only;
            control_loop();
            hprintln!("done 1");
            semihosting_exit(0)
        }

        // Loop overhead: an empty call, once per loop shape.
        let empty = measure(K, &mut |i| {
            black_box(i);
        });
        let ovh = empty.total * INSN_PER_COUNT * 1000 / u64::from(empty.n);
        let t = (ovh + 50) / 100;
        hprintln!("overhead.avg {}.{}", t / 10, t % 10);
        hprintln!("overhead.max {}", u64::from(empty.max) * INSN_PER_COUNT);

        primitives(ovh);
        codec(ovh);
        imu_filters(ovh);
        for kind in ModelKind::ALL {
            per_model(kind, ovh);
        }
        control_loop();

        hprintln!("done 1");
        semihosting_exit(0)
    }

    /// Maths primitives, f32 and fixed point.
    fn primitives(ovh: u64) {
        let xs: [f32; 16] = core::array::from_fn(|k| 0.05 + 0.37 * k as f32);
        let x = |i: u32| black_box(xs[(i % 16) as usize]);
        bench("prim.expf", K, ovh, &mut |i| {
            black_box(libm::expf(-x(i)));
        });
        bench("prim.sqrtf", K, ovh, &mut |i| {
            black_box(libm::sqrtf(x(i)));
        });
        bench("prim.atan2f", K, ovh, &mut |i| {
            black_box(libm::atan2f(x(i) - 1.7, 0.9));
        });
        bench("prim.sqrt_fast", K, ovh, &mut |i| {
            black_box(gait_core::maths::fastmath::sqrt(x(i)));
        });
        bench("prim.atan2_fast", K, ovh, &mut |i| {
            black_box(gait_core::maths::fastmath::atan2(x(i) - 1.7, 0.9));
        });
        bench("prim.sin_cos_fast", K, ovh, &mut |i| {
            black_box(gait_core::maths::fastmath::sin_cos(x(i)));
        });
        bench("prim.sinf_libm", K, ovh, &mut |i| {
            black_box(libm::sinf(x(i)));
        });
        bench("prim.fmul", K, ovh, &mut |i| {
            black_box(x(i) * x(i + 1));
        });
        bench("prim.fdiv", K, ovh, &mut |i| {
            black_box(x(i) / x(i + 1));
        });

        let fxs: [Fx; 16] = core::array::from_fn(|k| Fx::from_bits(3_000 + 9_001 * k as i32));
        let fxx = |i: u32| black_box(fxs[(i % 16) as usize]);
        bench("prim.fx_exp_neg", K, ovh, &mut |i| {
            black_box(gait_core::maths::fixed_point::exp_neg(fxx(i)));
        });
        bench("prim.fx_sin_cos", K, ovh, &mut |i| {
            black_box(gait_core::maths::fixed_point::sin_cos(fxx(i)));
        });
        bench("prim.fx_sqrt", K, ovh, &mut |i| {
            black_box(fixed_ik::sqrt(fxx(i)));
        });
        bench("prim.fx_atan2", K, ovh, &mut |i| {
            let y = i64::from(fxx(i).to_bits()) << 14;
            black_box(fixed_ik::atan2(
                black_box(y - (1 << 29)),
                black_box(1 << 29),
            ));
        });
    }

    /// The Dynamixel codec: the tick's packets' sizes, encoders, decoders, CRC.
    fn codec(ovh: u64) {
        let mut replies = [0u8; 160];
        let (rlen, rlens) = reply_stream(&mut replies);
        let replies = &replies[..rlen];
        let mut swb = [0u8; 128];
        let mut brb = [0u8; 64];
        let sw_len = encode_goals(&mut swb, &[x_series::CENTER_TICK; 12]);
        let br_len = encode_bulk(&mut brb);
        hprintln!("bytes.bulk_read {}", br_len);
        hprintln!("bytes.status_foot_left {}", rlens[0]);
        hprintln!("bytes.status_foot_right {}", rlens[1]);
        hprintln!("bytes.status_imu {}", rlens[2]);
        hprintln!("bytes.sync_write {}", sw_len);

        let goal_sets: [[i32; 12]; 16] = core::array::from_fn(|k| {
            core::array::from_fn(|j| 1_500 + ((k * 37 + j * 101) % 1_000) as i32)
        });
        bench("dxl.sync_write12", K, ovh, &mut |i| {
            black_box(encode_goals(
                &mut swb,
                black_box(&goal_sets[(i % 16) as usize]),
            ));
        });
        bench("dxl.bulk_read3", K, ovh, &mut |_| {
            black_box(encode_bulk(black_box(&mut brb)));
        });
        let mut dec = Decoder::<64>::new();
        let mut sensors = Sensors::default();
        bench("dxl.decode3", K, ovh, &mut |_| {
            let got = decode_replies(&mut dec, black_box(replies), &mut sensors);
            black_box(got);
        });
        if decode_replies(&mut dec, replies, &mut sensors) != 3 {
            fail("decode");
        }
        bench("dxl.decode3_block", K, ovh, &mut |_| {
            let got = decode_replies_block(&mut dec, black_box(replies), &mut sensors);
            black_box(got);
        });
        if decode_replies_block(&mut dec, replies, &mut sensors) != 3 {
            fail("decode_block");
        }
        // The decoder alone: block feeds of the three replies, packets counted, not parsed.
        let feed3 = |dec: &mut Decoder<64>, bytes: &[u8]| {
            let mut got = 0u32;
            let mut rest = bytes;
            while !rest.is_empty() {
                let (used, ev) = dec.feed(rest);
                got += u32::from(matches!(ev, Some(Ok(_))));
                rest = rest.get(used..).unwrap_or(&[]);
            }
            got
        };
        bench("dxl.feed3", K, ovh, &mut |_| {
            black_box(feed3(&mut dec, black_box(replies)));
        });
        if feed3(&mut dec, replies) != 3 {
            fail("feed3");
        }
        // The decoder alone, byte by byte (`Decoder::push`).
        let push3 = |dec: &mut Decoder<64>, bytes: &[u8]| {
            let mut got = 0u32;
            for &b in bytes {
                got += u32::from(matches!(dec.push(b), Some(Ok(_))));
            }
            got
        };
        bench("dxl.push3", K, ovh, &mut |_| {
            black_box(push3(&mut dec, black_box(replies)));
        });
        if push3(&mut dec, replies) != 3 {
            fail("push3");
        }
        let crc_in: [u8; 72] = core::array::from_fn(|k| (k as u8).wrapping_mul(29) ^ 0x5A);
        bench("dxl.crc16_72", K, ovh, &mut |_| {
            black_box(dxl::crc::crc16(black_box(&crc_in[..])));
        });
    }

    /// The IMU's pitch filters and the swing foot alone.
    fn imu_filters(ovh: u64) {
        let xs: [f32; 16] = core::array::from_fn(|k| 0.05 + 0.37 * k as f32);
        let x = |i: u32| black_box(xs[(i % 16) as usize]);
        let mut pitch = PitchAccel::new(PitchAccelConfig::reference(DT_S as f32));
        bench("imu.pitch_accel", K, ovh, &mut |i| {
            black_box(pitch.update(x(i)));
            black_box(pitch.torque());
        });
        let mut pitch_fx = FixedPitchAccel::new(PitchAccelConfig::reference(DT_S as f32));
        bench("imu.pitch_accel_fixed", K, ovh, &mut |i| {
            pitch_fx.update(Some((x(i) * 1.0e6) as i32));
            black_box(pitch_fx.torque_mnm());
        });
        // The swing foot alone (cycloid, one single support).
        let (params, _) = walk_plan(ModelKind::Tlipfm);
        let from = Place::<f32>::new(0.0, 0.045, 0.0);
        let to = Place::<f32>::new(0.04, 0.045, 0.0);
        let shape: SwingShape<f32> = params.swing;
        bench("swing.cycloid", K, ovh, &mut |i| {
            let u = black_box(i as f32 / K as f32);
            black_box(swing_foot(&shape, &from, &to, u, 1.0));
        });
    }

    /// Per model: the samplers, the Fourier CoM, the IKs, the measured ZMP, the support
    /// polygon and the stabilizer on the walk's own samples, then the firmware's control loop
    /// walking it ([`control_walk`]): f32, f32 with whole-body compensation and the
    /// stabilizer, and (with the fixed-point path built in) fixed point.
    fn per_model(kind: ModelKind, ovh: u64) {
        let m = kind.name();
        let robot = Robot::reference();
        let (params, plan) = walk_plan(kind);
        let Ok(fresh) = Sampler::<f32, CAP>::new(plan.clone(), DT_S) else {
            fail("sampler")
        };
        let mut s = fresh.clone();
        let mut n = 0u32;
        while !s.is_done() {
            black_box(s.next(0.0));
            n += 1;
        }
        hprintln!("walk.{}.ticks {}", m, n);

        let mut s = fresh.clone();
        let mut name = Name::new();
        bench(name.set("sample.f32.", m), n, ovh, &mut |_| {
            black_box(s.next(black_box(0.0)));
        });
        let Ok(fresh_fx) = FixedSampler::<CAP>::new(plan.clone(), DT_S) else {
            fail("fixed sampler")
        };
        let mut fs = fresh_fx.clone();
        bench(name.set("sample.fixed.", m), n, ovh, &mut |_| {
            black_box(fs.next(black_box(0)));
        });
        let walk = ForwardWalk::table2();
        let Ok(fourier) = FourierCom::<f32, 24>::from_params(
            &params,
            walk.step_length as f32,
            -walk.step_width as f32,
            24,
        ) else {
            fail("fourier")
        };
        bench(name.set("fourier24.", m), n, ovh, &mut |i| {
            black_box(fourier.sample(black_box(i as f32 * DT_S as f32)));
        });

        // SAFETY: taken once per call, here; nothing else refers to the buffer while
        // `samples` lives (the calls run one after the other).
        let buf = unsafe { slots(core::ptr::addr_of_mut!(SAMPLES)) };
        let mut s = fresh.clone();
        let samples = record(buf, || (!s.is_done()).then(|| s.next(0.0)));
        f32_stages(m, &robot, samples, ovh);

        // SAFETY: as above, for the fixed-point samples.
        let fx_buf = unsafe { slots(core::ptr::addr_of_mut!(FX_SAMPLES)) };
        let mut fs = fresh_fx.clone();
        let fx_samples = record(fx_buf, || (!fs.is_done()).then(|| fs.next(0)));
        let fkin = FixedLegKinematics::new(&robot);
        bench(
            name.set("ik.fixed.", m),
            fx_samples.len() as u32,
            ovh,
            &mut |i| {
                black_box(fixed_ik::joint_targets(
                    &fkin,
                    black_box(&fx_samples[i as usize]),
                ));
            },
        );
        // The measured ZMP in fixed point on the fixed-point samples' soles.
        let meter = FixedZmpMeter::new(&robot, MIN_LOAD_N);
        let (lf, rf) = ([4_100, 3_900, 4_300, 3_700], [3_800, 4_200, 3_600, 4_400]);
        bench(
            name.set("mzmp.fixed.", m),
            fx_samples.len() as u32,
            ovh,
            &mut |i| {
                let smp = black_box(&fx_samples[i as usize]);
                black_box(meter.zmp(
                    (&smp.feet[0], black_box(Some(lf))),
                    (&smp.feet[1], black_box(Some(rf))),
                ));
            },
        );

        // The firmware's control loop walking this model's plan.
        control_walk(kind, Arithmetic::F32, false, name.set("tick.f32.", m));
        control_walk(kind, Arithmetic::F32, true, name.set("tick.comp_stab.", m));
        #[cfg(feature = "fixed-gait")]
        control_walk(kind, Arithmetic::Fixed, false, name.set("tick.fixed.", m));
    }

    /// The f32 library stages on the walk's samples: the IK, whole-body compensation, the
    /// support polygon, the stabilizer and the measured ZMP.
    fn f32_stages(m: &str, robot: &Robot, samples: &[GaitSample<f32>], ovh: u64) {
        let n = samples.len() as u32;
        let kin = LegKinematics::<f32>::new(robot);
        let wholebody = WholeBody::<f32>::new(robot, control::WHOLEBODY_ITERATIONS);
        let mut name = Name::new();
        bench(name.set("ik.", m), n, ovh, &mut |i| {
            black_box(joint_targets(&kin, black_box(&samples[i as usize])));
        });
        bench(name.set("wholebody.", m), n, ovh, &mut |i| {
            black_box(wholebody.joint_targets(black_box(&samples[i as usize])));
        });
        bench(name.set("support.", m), n, ovh, &mut |i| {
            black_box(support_of(robot, black_box(&samples[i as usize])));
        });
        // The stabilizer on the walk: the measured ZMP off the reference by a deterministic
        // ±12 mm pattern (saturation, rate limit and the support-polygon limit all take
        // part), a constant gyro.
        let mut stab = new_stabilizer(robot);
        let mut cache = SupportCache::default();
        bench(name.set("stab.", m), n, ovh, &mut |i| {
            let smp = black_box(&samples[i as usize]);
            let e = ((i % 64) as f32 - 31.5) * 4e-4;
            let meas = Some([smp.zmp[0] + e, smp.zmp[1] - 0.5 * e]);
            black_box(stab_step(
                robot,
                &mut stab,
                &mut cache,
                smp,
                meas,
                black_box(Some([0.02, -0.01])),
            ));
        });
        let lf = ForceReading::new([4.1f32, 3.9, 4.3, 3.7]);
        let rf = ForceReading::new([3.8f32, 4.2, 3.6, 4.4]);
        let zmp_meter = ZmpMeter::new(robot, MIN_LOAD_N);
        bench(name.set("mzmp.", m), n, ovh, &mut |i| {
            let smp = black_box(&samples[i as usize]);
            black_box(zmp_meter.zmp(
                (&smp.feet[0], black_box(&lf)),
                (&smp.feet[1], black_box(&rf)),
            ));
        });
    }

    // ---- the firmware's control loop on the fake robot ----

    /// The bench's observer of the fake robot: it meters the firmware's CPU work per tick,
    /// SysTick from the return of one `wait_tick` to the next call, minus the time spent inside
    /// the board's own code (the device emulation behind `send`, the byte queue behind `recv`,
    /// the log sink; the calls themselves are counted), and the same per stage of the tick
    /// (the controller's [`Stage`] marks), and counts the log bytes.
    struct TickMeter {
        mark: Option<u32>,
        paused_at: u32,
        excluded: u32,
        /// The stage running, where it began and the board time excluded until then.
        stage: Option<(usize, u32, u32)>,
        /// This tick's counts per stage.
        stages: [u32; STAGES],
        seen: u32,
        recent: heapless::Deque<(u32, [u32; STAGES]), 4>,
        folded: Stat,
        folded_stages: [Stat; STAGES],
        log_bytes: u32,
    }

    /// Stages of the tick ([`Stage::ALL`]).
    const STAGES: usize = Stage::ALL.len();

    /// Ticks left out of the statistics at the start (first tick, ramp) and end (final hold,
    /// torque off).
    const SKIP_FIRST: u32 = 2;

    const NO_STAT: Stat = Stat {
        n: 0,
        total: 0,
        max: 0,
    };

    impl TickMeter {
        fn new() -> Self {
            TickMeter {
                mark: None,
                paused_at: 0,
                excluded: 0,
                stage: None,
                stages: [0; STAGES],
                seen: 0,
                recent: heapless::Deque::new(),
                folded: NO_STAT,
                folded_stages: [NO_STAT; STAGES],
                log_bytes: 0,
            }
        }

        /// Closes the running stage at SysTick `t`.
        fn close_stage(&mut self, t: u32) {
            if let Some((k, start, excluded)) = self.stage.take() {
                let c = (start.wrapping_sub(t) & MASK).saturating_sub(self.excluded - excluded);
                if let Some(slot) = self.stages.get_mut(k) {
                    *slot += c;
                }
            }
        }

        /// Folds one tick's counts into the statistics, leaving out the first
        /// [`SKIP_FIRST`] ticks and (by holding the last four back) the last four.
        fn record_tick(&mut self, counts: u32) {
            self.seen += 1;
            if self.recent.is_full() {
                if let Some((c, st)) = self.recent.pop_front() {
                    if self.seen > SKIP_FIRST + 4 {
                        fold(&mut self.folded, c);
                        for (f, c) in self.folded_stages.iter_mut().zip(st) {
                            fold(f, c);
                        }
                    }
                }
            }
            let _ = self.recent.push_back((counts, self.stages));
            self.stages = [0; STAGES];
        }
    }

    /// Adds one count to `s`.
    fn fold(s: &mut Stat, c: u32) {
        s.n += 1;
        s.total += u64::from(c);
        s.max = s.max.max(c);
    }

    impl Observer for TickMeter {
        #[cfg_attr(feature = "tick-profile", inline(never))]
        fn tick_start(&mut self) {
            let t = now();
            self.close_stage(t);
            if let Some(m) = self.mark {
                let c = (m.wrapping_sub(t) & MASK).saturating_sub(self.excluded);
                self.record_tick(c);
            }
        }

        #[cfg_attr(feature = "tick-profile", inline(never))]
        fn tick(&mut self, _tick: Tick) {
            self.excluded = 0;
            self.mark = Some(now());
        }

        fn stage(&mut self, stage: Stage) {
            let t = now();
            self.close_stage(t);
            let k = Stage::ALL.iter().position(|&s| s == stage).unwrap_or(0);
            // The mark's own work is the bench's, not the tick's: left out like the board's.
            self.excluded += t.wrapping_sub(now()) & MASK;
            self.stage = Some((k, now(), self.excluded));
        }

        fn log(&mut self, bytes: &[u8]) {
            self.log_bytes = self.log_bytes.wrapping_add(bytes.len() as u32);
        }

        #[cfg_attr(feature = "tick-profile", inline(never))]
        fn enter(&mut self) {
            self.paused_at = now();
        }

        #[cfg_attr(feature = "tick-profile", inline(never))]
        fn leave(&mut self) {
            self.excluded += self.paused_at.wrapping_sub(now()) & MASK;
        }

        fn exit(&mut self, code: i32) -> ! {
            semihosting_exit(code)
        }
    }

    /// The fake robot as the bench runs it: the configuration's baud, tick and compute time
    /// (the QEMU board's), constant foot loads and an alternating pitch rate (0.02 / -0.01
    /// rad/s).
    fn bench_robot(cfg: &Config) -> FakeRobot<TickMeter> {
        let mut board = FakeRobot::reference(TickMeter::new()).with_period(cfg.tick_period_us);
        let _ = board.set_baud(cfg.bus_baud);
        board.compute_ns = walker_firmware::boards::qemu_mps2::compute_ns(cfg);
        board.feet = Feet::Constant([[4_100, 3_900, 4_300, 3_700], [3_800, 4_200, 3_600, 4_400]]);
        board.imu_motion = ImuMotion::Alternating {
            even: 0.02,
            odd: -0.01,
        };
        board
    }

    /// `control::run` with the default configuration (ramp and final hold cut to one tick) on
    /// the in-memory bus: instructions per walking tick of the real control loop
    /// (`control.tick`) and of each of its stages (`control.stage.<stage>`); in a build with
    /// the `fixed-gait` feature also with the fixed-point path, `math=fixed`
    /// (`control.tick_fixed`, `control_fixed.stage.<stage>`).
    fn control_loop() {
        let cfg = bench_config(ModelKind::Tlipfm, Arithmetic::F32, false);
        let board = control_run(&cfg, "control");
        report("control.tick", board.folded, 0);
        report_stages("control", &board);
        #[cfg(feature = "fixed-gait")]
        {
            let cfg = bench_config(ModelKind::Tlipfm, Arithmetic::Fixed, false);
            let board = control_run(&cfg, "control_fixed");
            report("control.tick_fixed", board.folded, 0);
            report_stages("control_fixed", &board);
        }
    }

    /// The control loop walking Table 2 with `model` and `arithmetic` (with whole-body
    /// compensation and the stabilizer when `comp_stab`): instructions per walking tick as
    /// `key`.
    fn control_walk(model: ModelKind, arithmetic: Arithmetic, comp_stab: bool, key: &str) {
        let cfg = bench_config(model, arithmetic, comp_stab);
        let board = control_run(&cfg, key);
        report(key, board.folded, 0);
    }

    /// The bench's configuration: the defaults with `model`, `arithmetic`, autostart, and the
    /// ramp and the final hold one tick each; `comp=wholebody stab=on` when `comp_stab`.
    fn bench_config(model: ModelKind, arithmetic: Arithmetic, comp_stab: bool) -> Config {
        let mut cfg = Config::default_config();
        cfg.ramp_us = cfg.tick_period_us;
        cfg.final_hold_us = cfg.tick_period_us;
        cfg.arithmetic = arithmetic;
        cfg.model = model;
        cfg.autostart = true;
        if comp_stab {
            cfg.compensation = Compensation::WholeBody;
            cfg.stabilizer_on = true;
        }
        cfg
    }

    /// One `control::run` of `cfg` on the bench robot (ends the bench unless the plan is
    /// done); its counts under `key.*`.
    fn control_run(cfg: &Config, key: &str) -> FakeRobot<TickMeter> {
        let mut board = bench_robot(cfg);
        let end = control::run(&mut board, cfg);
        if end != RunEnd::Stopped(StopReason::PlanDone) {
            hprintln!("error {}.run ended with exit code {}", key, end.exit_code());
            semihosting_exit(1);
        }
        hprintln!("{}.model {}", key, cfg.model.name());
        hprintln!("{}.ticks {}", key, board.seen);
        hprintln!("{}.log_bytes {}", key, board.log_bytes);
        hprintln!("{}.overruns {}", key, board.overruns());
        board
    }

    /// The stages' counts of `board`'s run as `key.stage.<stage>`.
    fn report_stages(key: &str, board: &FakeRobot<TickMeter>) {
        let mut name = Name::new();
        for (stage, stat) in Stage::ALL.iter().zip(board.folded_stages) {
            let mut prefix = Name::new();
            let p = prefix.set(key, ".stage.");
            report(name.set(p, stage.name()), stat, 0);
        }
    }

    /// A small stack string for `prefix + model` keys.
    struct Name {
        buf: [u8; 48],
    }

    impl Name {
        fn new() -> Self {
            Name { buf: [0; 48] }
        }
        fn set(&mut self, prefix: &str, model: &str) -> &str {
            let mut n = 0;
            for &b in prefix.as_bytes().iter().chain(model.as_bytes()) {
                if let Some(slot) = self.buf.get_mut(n) {
                    *slot = b;
                    n += 1;
                }
            }
            core::str::from_utf8(&self.buf[..n]).unwrap_or("?")
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        hprintln!("panic {}", info);
        semihosting_exit(101)
    }
}
