//! The command port's register handling: the checks of `walker_contract::command_port`'s docs,
//! through whole packets (the master side of the project's codec) and by property tests.

use dxl::instruction::{ErrorCode, Instruction, Status, StatusError};
use dxl::packet::{decode, BROADCAST_ID};
use proptest::prelude::*;
use walker_contract::command_port::*;

/// Sends one instruction to `port`; returns the decoded reply (error code, data), if any.
fn ask(port: &mut CommandPort, id: u8, ins: Instruction<'_>) -> Option<(StatusError, Vec<u8>)> {
    let mut pkt = [0u8; 600];
    let n = ins.encode(&mut pkt, id).unwrap();
    let mut out: Vec<Vec<u8>> = Vec::new();
    port.feed(&pkt[..n], |r| out.push(r.to_vec()));
    assert!(out.len() <= 1, "one reply at most");
    let r = out.pop()?;
    let mut buf = [0u8; 600];
    let p = decode(&r, &mut buf).unwrap();
    let s = Status::from_packet(&p).unwrap();
    assert_eq!(s.id, PORT_ID);
    Some((s.error, s.data.to_vec()))
}

fn write(port: &mut CommandPort, addr: u16, data: &[u8]) -> Option<ErrorCode> {
    let (e, d) = ask(port, PORT_ID, Instruction::Write { addr, data }).unwrap();
    assert!(d.is_empty());
    e.code
}

fn read(port: &mut CommandPort, addr: u16, len: u16) -> Result<Vec<u8>, ErrorCode> {
    let (e, d) = ask(port, PORT_ID, Instruction::Read { addr, len }).unwrap();
    match e.code {
        None => Ok(d),
        Some(c) => Err(c),
    }
}

#[test]
fn ping_answers_model_and_version_also_to_broadcast() {
    let mut p = CommandPort::new();
    let want = vec![0x30, 0x5A, FIRMWARE_VERSION_VALUE];
    assert_eq!(
        ask(&mut p, PORT_ID, Instruction::Ping),
        Some((StatusError::OK, want.clone()))
    );
    assert_eq!(
        ask(&mut p, BROADCAST_ID, Instruction::Ping),
        Some((StatusError::OK, want))
    );
    // Another device's packet: silence.
    assert_eq!(ask(&mut p, 1, Instruction::Ping), None);
}

/// Heartbeat (72) takes any value, counts as a command write and changes no command; the
/// deadman's stop is Mode = stop's (velocity 0, the step list emptied) without counting, and Stop
/// Code reads 13 until a master writes Mode (the supervisor's code first).
#[test]
fn heartbeat_counts_and_the_deadman_stop_reads_back_until_mode_is_written() {
    let mut p = CommandPort::new();
    let mut v = 50i16.to_le_bytes().to_vec();
    v.extend_from_slice(&[0; 4]);
    assert_eq!(write(&mut p, VELOCITY_X.addr, &v), None);
    assert_eq!(write(&mut p, MODE.addr, &[2]), None);
    let entry = StepEntry {
        dx: 10,
        dy: 0,
        dyaw: 0,
        side: 1,
    };
    assert_eq!(write(&mut p, STEP_ENTRY.addr, &entry.to_bytes()), None);
    let cmd = p.table.raw_command();
    for b in [0u8, 1, 0xFF] {
        assert_eq!(write(&mut p, HEARTBEAT.addr, &[b]), None);
    }
    assert_eq!(p.table.raw_command(), cmd);
    assert_eq!(p.table.command_count(), 6);
    // Half of Heartbeat and Yaw Rate: Data Length; a broadcast WRITE counts (no reply).
    assert_eq!(write(&mut p, 71, &[0, 0]), Some(ErrorCode::DataLength));
    let mut pkt = [0u8; 32];
    let n = Instruction::Write {
        addr: HEARTBEAT.addr,
        data: &[7],
    }
    .encode(&mut pkt, BROADCAST_ID)
    .unwrap();
    let mut replies = 0;
    p.feed(&pkt[..n], |_| replies += 1);
    assert_eq!((replies, p.table.command_count()), (0, 7));

    let stop_code = |p: &mut CommandPort| read(p, STOP_CODE.addr, 1).unwrap()[0];
    let status = |code| PortStatus {
        stop_code: code,
        ..PortStatus::default()
    };
    p.table.set_status(&status(0));
    assert_eq!(stop_code(&mut p), 0);
    assert!(!p.table.deadman_stopped());
    p.table.deadman_stop();
    assert_eq!(p.table.mode(), Mode::Stop);
    assert_eq!(p.table.raw_command(), [3, 0, 0, 0]);
    assert_eq!(read(&mut p, STEP_LIST.addr, 1), Ok(vec![0]));
    assert_eq!(p.table.take_step(), None);
    assert_eq!(p.table.command_count(), 7, "not a command write");
    p.table.set_status(&status(0));
    assert_eq!(stop_code(&mut p), walker_contract::StopCode::Deadman.code());
    // The supervisor's stop code comes first.
    p.table.set_status(&status(17));
    assert_eq!(stop_code(&mut p), 17);
    // A heartbeat does not clear it; a Mode write does.
    assert_eq!(write(&mut p, HEARTBEAT.addr, &[0]), None);
    p.table.set_status(&status(0));
    assert_eq!(stop_code(&mut p), 13);
    assert_eq!(write(&mut p, MODE.addr, &[2]), None);
    p.table.set_status(&status(0));
    assert_eq!(stop_code(&mut p), 0);
    assert!(!p.table.deadman_stopped());
}

#[test]
fn velocity_write_reaches_the_command_in_si_units() {
    let mut p = CommandPort::new();
    let mut v = Vec::new();
    v.extend_from_slice(&50i16.to_le_bytes());
    v.extend_from_slice(&(-30i16).to_le_bytes());
    v.extend_from_slice(&349i16.to_le_bytes());
    assert_eq!(write(&mut p, VELOCITY_X.addr, &v), None);
    // Mode stand: the gait sees 0.
    assert_eq!(p.table.velocity().vx, 0.0);
    assert_eq!(write(&mut p, MODE.addr, &[2]), None);
    let c = p.table.velocity();
    assert_eq!((c.vx, c.vy, c.yaw_rate), (0.05, -0.03, 0.349));
    assert_eq!(read(&mut p, VELOCITY_X.addr, 6), Ok(v));
    assert_eq!(p.table.command_count(), 2);
    assert_eq!(read(&mut p, COMMAND_COUNT.addr, 2), Ok(vec![2, 0]));
    // Stop clears the velocity.
    assert_eq!(write(&mut p, MODE.addr, &[3]), None);
    assert_eq!(read(&mut p, VELOCITY_X.addr, 6), Ok(vec![0; 6]));
    assert_eq!(p.table.mode(), Mode::Stop);
}

#[test]
fn bad_writes_get_the_protocol_errors_and_change_nothing() {
    let mut p = CommandPort::new();
    let before = read(&mut p, 0, TABLE_LEN as u16).unwrap();
    // Out of range values: mode 4, vx 201 mm/s, vx −101, vy 101, yaw 601.
    assert_eq!(write(&mut p, MODE.addr, &[4]), Some(ErrorCode::DataRange));
    assert_eq!(
        write(&mut p, 66, &201i16.to_le_bytes()),
        Some(ErrorCode::DataRange)
    );
    assert_eq!(
        write(&mut p, 66, &(-101i16).to_le_bytes()),
        Some(ErrorCode::DataRange)
    );
    assert_eq!(
        write(&mut p, 68, &101i16.to_le_bytes()),
        Some(ErrorCode::DataRange)
    );
    assert_eq!(
        write(&mut p, 70, &601i16.to_le_bytes()),
        Some(ErrorCode::DataRange)
    );
    // A valid vx with an invalid vy in the same write: nothing is stored.
    let mut v = 50i16.to_le_bytes().to_vec();
    v.extend_from_slice(&500i16.to_le_bytes());
    assert_eq!(write(&mut p, 66, &v), Some(ErrorCode::DataRange));
    // Half a register.
    assert_eq!(write(&mut p, 66, &[1]), Some(ErrorCode::DataLength));
    assert_eq!(write(&mut p, 67, &[1]), Some(ErrorCode::DataLength));
    // Read-only: model number, ID, state, step count.
    assert_eq!(write(&mut p, 0, &[1, 2]), Some(ErrorCode::Access));
    assert_eq!(write(&mut p, 7, &[9]), Some(ErrorCode::Access));
    assert_eq!(write(&mut p, STATE.addr, &[1]), Some(ErrorCode::Access));
    // Unknown addresses (a gap, beyond the table).
    assert_eq!(write(&mut p, 65, &[0]), Some(ErrorCode::DataRange));
    assert_eq!(write(&mut p, 100, &[0]), Some(ErrorCode::DataRange));
    assert_eq!(write(&mut p, 400, &[0]), Some(ErrorCode::DataRange));
    // Reads beyond the table.
    assert_eq!(read(&mut p, 200, 20), Err(ErrorCode::DataRange));
    // A READ with a bad parameter length.
    let mut pkt = [0u8; 32];
    let n = dxl::packet::encode(&mut pkt, PORT_ID, dxl::opcode::READ, &[64, 0, 1]).unwrap();
    let mut out = Vec::new();
    p.feed(&pkt[..n], |r| out.push(r.to_vec()));
    let mut buf = [0u8; 32];
    let s = decode(&out[0], &mut buf).unwrap();
    assert_eq!(
        Status::from_packet(&s).unwrap().error.code,
        Some(ErrorCode::DataLength)
    );
    // Unsupported instructions.
    let e = ask(&mut p, PORT_ID, Instruction::Reboot).unwrap().0.code;
    assert_eq!(e, Some(ErrorCode::Instruction));
    assert_eq!(read(&mut p, 0, TABLE_LEN as u16).unwrap(), before);
    assert_eq!(p.table.command_count(), 0);
}

#[test]
fn step_list_appends_checks_and_fills() {
    let mut p = CommandPort::new();
    let e = StepEntry {
        dx: 40,
        dy: -10,
        dyaw: 100,
        side: 1,
    };
    for k in 0..STEP_LIST_LEN {
        assert_eq!(write(&mut p, STEP_ENTRY.addr, &e.to_bytes()), None);
        assert_eq!(read(&mut p, STEP_LIST.addr, 1), Ok(vec![k as u8 + 1]));
    }
    assert_eq!(
        write(&mut p, STEP_ENTRY.addr, &e.to_bytes()),
        Some(ErrorCode::DataLimit)
    );
    let bad = [
        StepEntry { side: 3, ..e },
        StepEntry { dx: 81, ..e },
        StepEntry { dyaw: -601, ..e },
    ];
    for b in bad {
        assert_eq!(
            write(&mut p, STEP_ENTRY.addr, &b.to_bytes()),
            Some(ErrorCode::DataRange)
        );
    }
    assert_eq!(p.table.take_step(), Some(e));
    assert_eq!(read(&mut p, STEP_LIST.addr, 1), Ok(vec![7]));
    assert_eq!(
        write(&mut p, STEP_ENTRY.addr, &e.to_bytes()[..6]),
        Some(ErrorCode::DataLength)
    );
}

#[test]
fn status_registers_read_back_in_wire_units() {
    let mut p = CommandPort::new();
    p.table.set_status(&PortStatus {
        state: PortState::Walking,
        support: 2,
        step_count: 513,
        zmp_m: Some([0.0125, -0.047]),
        stop_code: 0,
        fault_kind: 3,
        walk_velocity: [0.05, 0.0, -0.2],
        queued: 3,
        servo_stiffness_cnm: 1133,
        supply_dv: 119,
    });
    let d = read(&mut p, STATE.addr, 24).unwrap();
    // Step List Length: none in the port, 3 taken by the walk.
    assert_eq!(d[11], 3);
    assert_eq!(d[0], 2);
    assert_eq!(d[1], 2);
    assert_eq!(u16::from_le_bytes([d[2], d[3]]), 513);
    assert_eq!(i16::from_le_bytes([d[4], d[5]]), 13);
    assert_eq!(i16::from_le_bytes([d[6], d[7]]), -47);
    assert_eq!(d[8], 1);
    assert_eq!(d[10], 3);
    assert_eq!(i16::from_le_bytes([d[12], d[13]]), 50);
    assert_eq!(i16::from_le_bytes([d[16], d[17]]), -200);
    // Servo Stiffness 0.01 N·m/rad, Supply Voltage 0.1 V.
    assert_eq!(u16::from_le_bytes([d[20], d[21]]), 1133);
    assert_eq!(u16::from_le_bytes([d[22], d[23]]), 119);
    assert_eq!(p.table.state(), PortState::Walking);
    // The master's decoder reads the same block back.
    let b = StatusBlock::decode(
        read(&mut p, STATUS_BLOCK.addr, STATUS_BLOCK.len)
            .unwrap()
            .as_slice(),
    )
    .unwrap();
    assert_eq!(
        b,
        StatusBlock {
            state: Some(PortState::Walking),
            support: 2,
            step_count: 513,
            zmp_mm: Some([13, -47]),
            stop_code: 0,
            fault_kind: 3,
            step_list: 3,
            walk_velocity: [50, 0, -200],
            command_count: 0,
            servo_stiffness: 1133,
            supply_dv: 119,
        }
    );
    assert_eq!(StatusBlock::decode(&d[..23]), None);
    // The block ends at Supply Voltage; the parameter registers end the table.
    assert_eq!(
        usize::from(STATUS_BLOCK.addr + STATUS_BLOCK.len),
        usize::from(SUPPLY_VOLTAGE.addr + SUPPLY_VOLTAGE.len)
    );
    assert_eq!(usize::from(PARAM_COUNT.addr + PARAM_COUNT.len), TABLE_LEN);
}

#[test]
fn sync_and_bulk_reach_the_port_entry_only() {
    let mut p = CommandPort::new();
    // SYNC WRITE of Mode to devices 3 and PORT_ID.
    let raw = [3u8, 1, PORT_ID, 2];
    let sw = dxl::SyncWrite::from_raw(MODE.addr, 1, &raw).unwrap();
    assert_eq!(ask(&mut p, BROADCAST_ID, Instruction::SyncWrite(sw)), None);
    assert_eq!(p.table.mode(), Mode::Walk);
    // SYNC READ answers when listed.
    let ids = [PORT_ID];
    let (e, d) = ask(
        &mut p,
        BROADCAST_ID,
        Instruction::SyncRead {
            addr: MODEL_NUMBER.addr,
            len: 2,
            ids: &ids,
        },
    )
    .unwrap();
    assert_eq!((e, d), (StatusError::OK, vec![0x30, 0x5A]));
    // BULK READ of two bytes at 64.
    let mut buf = [0u8; 64];
    let n = dxl::encode_bulk_read(
        &mut buf,
        &[dxl::BulkReadRequest {
            id: PORT_ID,
            addr: MODE.addr,
            len: 1,
        }],
    )
    .unwrap();
    let mut out = Vec::new();
    p.feed(&buf[..n], |r| out.push(r.to_vec()));
    let mut b2 = [0u8; 64];
    let s = decode(&out[0], &mut b2).unwrap();
    assert_eq!(Status::from_packet(&s).unwrap().data, &[2]);
}

fn arb_write() -> impl Strategy<Value = (u16, Vec<u8>)> {
    (0u16..200, proptest::collection::vec(any::<u8>(), 0..24))
}

proptest! {
    /// Whatever the firmware publishes (in wire units), a master's READ of the status block
    /// decodes to it.
    #[test]
    fn the_status_block_decodes_what_was_published(
        state in 0u8..5, support in 0u8..3, steps: u16, zmp in proptest::option::of([-3000i16..3000, -3000i16..3000]),
        stop: u8, fault: u8, queued in 0usize..9, v in [-200i16..=200, -100i16..=100, -600i16..=600],
        stiffness: u16, supply: u16,
    ) {
        let mut t = CommandTable::new();
        let m = |x: i16| f32::from(x) / 1000.0;
        t.set_status(&PortStatus {
            state: PortState::from_code(state).unwrap(),
            support,
            step_count: steps,
            zmp_m: zmp.map(|[x, y]| [m(x), m(y)]),
            stop_code: stop,
            fault_kind: fault,
            walk_velocity: v.map(m),
            queued,
            servo_stiffness_cnm: stiffness,
            supply_dv: supply,
        });
        let b = StatusBlock::decode(t.read(STATUS_BLOCK.addr, STATUS_BLOCK.len).unwrap()).unwrap();
        prop_assert_eq!(b.state, PortState::from_code(state));
        prop_assert_eq!(b.support, support);
        prop_assert_eq!(b.step_count, steps);
        prop_assert_eq!(b.zmp_mm, zmp);
        prop_assert_eq!((b.stop_code, b.fault_kind), (stop, fault));
        prop_assert_eq!(usize::from(b.step_list), queued);
        prop_assert_eq!(b.walk_velocity, v);
        prop_assert_eq!(b.command_count, 0);
        prop_assert_eq!(b.servo_stiffness, stiffness);
        prop_assert_eq!(b.supply_dv, supply);
    }

    /// Any write: either accepted (and then every written register holds a value in its
    /// range, the command count advanced by one) or rejected with the table unchanged.
    #[test]
    fn any_write_is_all_or_nothing_and_in_range(writes in proptest::collection::vec(arb_write(), 1..12)) {
        let mut t = CommandTable::new();
        for (addr, data) in writes {
            let before = t.clone();
            let count = t.command_count();
            let before_mem = before.read(0, TABLE_LEN as u16).unwrap().to_vec();
            match t.write(addr, &data) {
                Ok(()) => {
                    prop_assert_eq!(t.command_count(), count.wrapping_add(1));
                    // Only writable registers, wholly covered.
                    let (s, e) = (usize::from(addr), usize::from(addr) + data.len());
                    for r in WRITABLE {
                        let (rs, re) = (usize::from(r.addr), usize::from(r.addr + r.len));
                        prop_assert!(re <= s || rs >= e || (rs >= s && re <= e));
                    }
                    prop_assert!(Mode::from_code(t.read(MODE.addr, 1).unwrap()[0]).is_some());
                    let c = t.velocity();
                    for (v, (lo, hi)) in [c.vx, c.vy, c.yaw_rate].iter().zip(VELOCITY_RANGE) {
                        prop_assert!(v.is_finite());
                        prop_assert!(*v >= f32::from(lo) * 1e-3 - 1e-6 && *v <= f32::from(hi) * 1e-3 + 1e-6);
                    }
                    for (i, b) in before_mem.iter().enumerate() {
                        let inside = i >= s && i < e;
                        let derived = [COMMAND_COUNT, STEP_LIST, VELOCITY_X, VELOCITY_Y, YAW_RATE]
                            .iter().any(|r| (usize::from(r.addr)..usize::from(r.addr + r.len)).contains(&i));
                        if !inside && !derived {
                            prop_assert_eq!(t.read(i as u16, 1).unwrap()[0], *b);
                        }
                    }
                }
                Err(e) => {
                    prop_assert!(matches!(e, ErrorCode::DataRange | ErrorCode::DataLength | ErrorCode::Access | ErrorCode::DataLimit));
                    prop_assert_eq!(t.read(0, TABLE_LEN as u16).unwrap(), &before_mem[..]);
                    prop_assert_eq!(t.command_count(), count);
                }
            }
        }
    }

    /// Any byte stream into the port: no panic, every reply a well-formed status packet of
    /// the port's ID.
    #[test]
    fn any_bytes_get_well_formed_replies(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut p = CommandPort::new();
        let mut replies = Vec::new();
        p.feed(&bytes, |r| replies.push(r.to_vec()));
        for r in replies {
            let mut buf = [0u8; 600];
            let s = decode(&r, &mut buf).unwrap();
            let s = Status::from_packet(&s).unwrap();
            prop_assert_eq!(s.id, PORT_ID);
        }
    }

    /// Any well-formed WRITE packet to the port is answered, OK exactly when the table accepts it.
    #[test]
    fn write_packets_answer_the_table_verdict((addr, data) in arb_write()) {
        let mut p = CommandPort::new();
        let mut t = CommandTable::new();
        let want = t.write(addr, &data).err();
        let got = ask(&mut p, PORT_ID, Instruction::Write { addr, data: &data }).unwrap().0.code;
        prop_assert_eq!(got, want);
    }
}

/// `milli_i16` as it was written with float clamps (the reference).
fn milli_reference(v: f32) -> i16 {
    if !v.is_finite() {
        return 0;
    }
    let m = libm::roundf(v * 1000.0);
    libm::fmaxf(-32768.0, libm::fminf(32767.0, m)) as i16
}

#[test]
fn milli_i16_rounds_half_away_saturates_and_zeroes_non_finite() {
    assert_eq!(milli_i16(0.0125), 13);
    assert_eq!(milli_i16(-0.0125), -13);
    assert_eq!(milli_i16(0.0004999), 0);
    assert_eq!(milli_i16(-0.047), -47);
    assert_eq!(milli_i16(32.767), 32_767);
    assert_eq!(milli_i16(40.0), i16::MAX);
    assert_eq!(milli_i16(-40.0), i16::MIN);
    assert_eq!(milli_i16(f32::MAX), i16::MAX);
    assert_eq!(milli_i16(f32::MIN), i16::MIN);
    for v in [
        0.0,
        -0.0,
        f32::NAN,
        -f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ] {
        assert_eq!(milli_i16(v), 0, "{v}");
    }
    // Every 4093rd bit pattern of f32 (≈ 1 M values: subnormals, the rounding edges, beyond
    // the i16 range) as the float-clamp formula gives it.
    for bits in (0..=u32::MAX).step_by(4093) {
        let v = f32::from_bits(bits);
        assert_eq!(milli_i16(v), milli_reference(v), "{v:e} ({bits:#x})");
    }
}

proptest! {
    #[test]
    fn milli_i16_agrees_with_the_float_clamp_formula(v in -40.0f32..40.0) {
        prop_assert_eq!(milli_i16(v), milli_reference(v));
    }
}

/// One parameter op through the table as a master writes it (key, value, op in one WRITE),
/// served against `cfg`; the status and Param Value's text.
fn param_op(
    t: &mut CommandTable,
    cfg: ParamAccess<'_>,
    key: &str,
    value: &str,
    op: ParamOp,
) -> (ParamStatus, String) {
    let mut data = vec![0u8; 41];
    data[..key.len()].copy_from_slice(key.as_bytes());
    data[24..24 + value.len()].copy_from_slice(value.as_bytes());
    data[40] = op.code();
    t.write(PARAM_KEY.addr, &data).unwrap();
    let pending = t.read(PARAM_STATUS.addr, 1).unwrap()[0];
    assert_eq!(
        ParamStatus::try_from(pending).ok(),
        Some(ParamStatus::Pending)
    );
    let s = t.serve_param(cfg).expect("an op was pending");
    assert_eq!(
        t.serve_param(ParamAccess::ReadOnly(&walker_contract::Config::default())),
        None
    );
    let read = t.read(PARAM_STATUS.addr, 1).unwrap()[0];
    assert_eq!(ParamStatus::try_from(read).ok(), Some(s));
    (s, text(t.read(PARAM_VALUE.addr, PARAM_VALUE.len).unwrap()))
}

fn text(b: &[u8]) -> String {
    let n = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8(b[..n].to_vec()).unwrap()
}

#[test]
fn parameters_read_and_write_through_the_port_with_the_tables_checks() {
    use walker_contract::params::{find, PARAMS};
    use walker_contract::Config;
    let mut t = CommandTable::new();
    let count = t.read(PARAM_COUNT.addr, 2).unwrap();
    assert_eq!(
        usize::from(u16::from_le_bytes([count[0], count[1]])),
        PARAMS.len()
    );
    let mut cfg = Config::default();
    // Get: the default's text, as the parameter writes it.
    let (s, v) = param_op(
        &mut t,
        ParamAccess::ReadOnly(&cfg),
        "catch_gain",
        "",
        ParamOp::Get,
    );
    assert_eq!(s, ParamStatus::Done);
    let p = find("catch_gain").unwrap();
    let mut want = String::new();
    p.write_value(p.value(&cfg).unwrap(), &mut want).unwrap();
    assert_eq!(v, want);
    // Set between runs: in force; a get reads it back.
    let (s, _) = param_op(
        &mut t,
        ParamAccess::Settable(&mut cfg),
        "gyro_ankle",
        "0.04",
        ParamOp::Set,
    );
    assert_eq!(s, ParamStatus::Done);
    let mut direct = Config::default();
    walker_contract::params::apply(&mut direct, b"elf gyro_ankle=0.04").unwrap();
    assert_eq!(format!("{cfg:?}"), format!("{direct:?}"));
    let (_, v) = param_op(
        &mut t,
        ParamAccess::ReadOnly(&cfg),
        "gyro_ankle",
        "",
        ParamOp::Get,
    );
    assert_eq!(v, "0.04");
    // Refusals change nothing: while a run goes, out of range, bad value, unknown key.
    let before = format!("{cfg:?}");
    let cases = [
        ("gyro_ankle", "0.02", ParamStatus::Running, true),
        ("gyro_ankle", "1e9", ParamStatus::OutOfRange, false),
        ("gyro_ankle", "fast", ParamStatus::BadValue, false),
        ("no_such_key", "1", ParamStatus::UnknownKey, false),
        ("wait_enable", "2", ParamStatus::BadValue, false),
    ];
    for (key, value, want, running) in cases {
        let access = if running {
            ParamAccess::ReadOnly(&cfg)
        } else {
            ParamAccess::Settable(&mut cfg)
        };
        let (s, _) = param_op(&mut t, access, key, value, ParamOp::Set);
        assert_eq!(s, want, "{key}={value}");
    }
    assert_eq!(format!("{cfg:?}"), before);
    // By index: every parameter's key and value, as the table has them.
    for (i, p) in PARAMS.iter().enumerate() {
        t.write(PARAM_INDEX.addr, &(i as u16).to_le_bytes())
            .unwrap();
        t.write(PARAM_OP.addr, &[ParamOp::GetByIndex.code()])
            .unwrap();
        assert_eq!(
            t.serve_param(ParamAccess::ReadOnly(&cfg)),
            Some(ParamStatus::Done)
        );
        assert_eq!(text(t.read(PARAM_KEY.addr, PARAM_KEY.len).unwrap()), p.key);
        let mut want = String::new();
        if let Some(v) = p.value(&cfg) {
            p.write_value(v, &mut want).unwrap();
        }
        assert!(
            want.len() <= 16,
            "{} = {want}: longer than Param Value",
            p.key
        );
        assert_eq!(
            text(t.read(PARAM_VALUE.addr, PARAM_VALUE.len).unwrap()),
            want,
            "{}",
            p.key
        );
    }
    t.write(PARAM_INDEX.addr, &(PARAMS.len() as u16).to_le_bytes())
        .unwrap();
    t.write(PARAM_OP.addr, &[ParamOp::GetByIndex.code()])
        .unwrap();
    assert_eq!(
        t.serve_param(ParamAccess::ReadOnly(&cfg)),
        Some(ParamStatus::UnknownKey)
    );
    // An op code outside 1 ..= 4 is Data Range; Param Status and Count are read-only.
    assert_eq!(
        t.write(PARAM_OP.addr, &[5]),
        Err(dxl::instruction::ErrorCode::DataRange)
    );
    assert_eq!(
        t.write(PARAM_STATUS.addr, &[0]),
        Err(dxl::instruction::ErrorCode::Access)
    );
    assert_eq!(
        t.write(PARAM_COUNT.addr, &[0, 0]),
        Err(dxl::instruction::ErrorCode::Access)
    );
    assert_eq!(t.serve_param(ParamAccess::ReadOnly(&cfg)), None);
}

#[test]
fn a_build_without_parameters_answers_a_pending_op_unsupported_once_and_touches_nothing() {
    let mut t = CommandTable::new();
    // Nothing pending: no answer, Param Status as it was.
    assert_eq!(t.answer_param(ParamStatus::Unsupported), None);
    assert_eq!(
        t.read(PARAM_STATUS.addr, 1).unwrap(),
        [ParamStatus::Done.code()]
    );
    for op in ParamOp::ALL {
        let mut data = vec![0u8; 41];
        data[..10].copy_from_slice(b"catch_gain");
        data[24..27].copy_from_slice(b"0.5");
        data[40] = op.code();
        t.write(PARAM_KEY.addr, &data).unwrap();
        assert_eq!(
            t.read(PARAM_STATUS.addr, 1).unwrap(),
            [ParamStatus::Pending.code()]
        );
        assert_eq!(
            t.answer_param(ParamStatus::Unsupported),
            Some(ParamStatus::Unsupported),
            "{op:?}"
        );
        assert_eq!(
            t.read(PARAM_STATUS.addr, 1).unwrap(),
            [ParamStatus::Unsupported.code()]
        );
        // Param Key and Param Value as the master wrote them.
        assert_eq!(
            text(t.read(PARAM_KEY.addr, PARAM_KEY.len).unwrap()),
            "catch_gain"
        );
        assert_eq!(
            text(t.read(PARAM_VALUE.addr, PARAM_VALUE.len).unwrap()),
            "0.5"
        );
        // Answered once: no second answer, nothing left to serve, no save taken.
        assert_eq!(t.answer_param(ParamStatus::Unsupported), None);
        assert_eq!(
            t.serve_param(ParamAccess::ReadOnly(&walker_contract::Config::default())),
            None
        );
        assert!(!t.take_save());
    }
    assert_eq!(
        ParamStatus::try_from(7).map(ParamStatus::reason),
        Ok("not in this board's build")
    );
}

proptest! {
    /// Any value text for any parameter: a set either is refused and changes nothing, or it
    /// sets exactly what the command line's parser sets for the same token.
    #[test]
    fn a_set_over_the_port_equals_the_command_line(i in 0usize..200, value in "[-a-z0-9.e]{0,15}") {
        use walker_contract::params::PARAMS;
        use walker_contract::Config;
        let p = &PARAMS[i % PARAMS.len()];
        let mut t = CommandTable::new();
        let mut cfg = Config::default();
        let (s, _) = param_op(&mut t, ParamAccess::Settable(&mut cfg), p.key, &value, ParamOp::Set);
        let mut line = Config::default();
        let token = format!("elf {}={}", p.key, value);
        let r = walker_contract::params::apply(&mut line, token.as_bytes());
        prop_assert_eq!(s == ParamStatus::Done, r.is_ok(), "{} -> {:?} / {:?}", token, s, r);
        if s == ParamStatus::Done {
            prop_assert_eq!(format!("{cfg:?}"), format!("{line:?}"));
        } else {
            prop_assert_eq!(format!("{cfg:?}"), format!("{:?}", Config::default()));
        }
    }
}
