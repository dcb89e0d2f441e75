//! Act: what the controller writes to the bus and the log outside the tick's data flow — the
//! servos' goals, the confirmed torque off, the stop record, fault records.

use dxl::table::x_series;
use gait_core::robot::LEG_JOINTS;
use walker_contract::bus_map::{servo_slot_id, servo_slots, MAX_HELD};

use crate::board::{Board, BROADCAST_ID, TORQUE_ENABLE_ADDR};
use crate::bus::BoardMaster;
use crate::record::{FaultKind, FaultRecord, LogWriter, Record, StopRecord};
use crate::supervisor::StopReason;
use crate::Config;

/// A fault record of `kind` at `time_us` (µs since boot) with its id and value.
pub(crate) fn fault(time_us: u64, kind: FaultKind, id: u8, value: i32) -> Record {
    Record::Fault(FaultRecord {
        seq: 0,
        time_us: time_us as u32,
        kind,
        id,
        value,
    })
}

/// The stop that stops: up to [`Config::torque_off_attempts`] rounds of broadcast Torque
/// Enable = 0 (the board's best-effort raw packet if the master cannot send it) followed by a
/// READ of Torque Enable from every servo (the legs, then the held ones) not yet confirmed at
/// 0; then the servo power is
/// cut ([`Board::servo_power`]) whatever the outcome. Servos never confirmed are logged
/// (`TorqueOffUnconfirmed`). The watchdog is fed after each round (a dead bus costs
/// `attempts` × 12 reply timeouts, 36 ms by default).
pub(crate) fn torque_off<B: Board>(
    bus: &mut BoardMaster<'_, B>,
    log: &mut LogWriter,
    cfg: &Config,
) {
    let devices = bus.devices();
    let id_of = |k: usize| servo_slot_id(devices, k);
    let mut off = [false; LEG_JOINTS + MAX_HELD];
    // The slots past the robot's servos count as confirmed.
    for d in off.iter_mut().skip(servo_slots(devices)) {
        *d = true;
    }
    for _ in 0..cfg.torque_off_attempts.max(1) {
        if bus
            .master()
            .write(BROADCAST_ID, TORQUE_ENABLE_ADDR, &[0])
            .is_err()
        {
            bus.board().torque_off_best_effort();
        }
        for (k, done) in off.iter_mut().enumerate() {
            let Some(id) = id_of(k) else {
                continue;
            };
            if !*done {
                let mut v = [0xFFu8; 1];
                *done = bus.master().read(id, TORQUE_ENABLE_ADDR, &mut v).is_ok() && v == [0];
            }
        }
        bus.board().feed();
        if off.iter().all(|&d| d) {
            break;
        }
    }
    let unconfirmed = off.iter().filter(|&&d| !d).count();
    if let Some(id) = off.iter().position(|&d| !d).and_then(id_of) {
        crate::fw_log!(
            error,
            "torque off not confirmed by {} servo(s), first {}",
            unconfirmed,
            id
        );
        let now = bus.board().now_us();
        let rec = fault(now, FaultKind::TorqueOffUnconfirmed, id, unconfirmed as i32);
        log.write(bus.board(), rec);
    }
    bus.board().servo_power(false);
}

pub(crate) fn write_stop<B: Board>(
    bus: &mut BoardMaster<'_, B>,
    log: &mut LogWriter,
    reason: StopReason,
) {
    let b = bus.board();
    let rec = Record::Stop(StopRecord {
        seq: 0,
        time_us: b.now_us() as u32,
        reason,
    });
    log.write(b, rec);
}

/// ONE SYNC WRITE of the 12 Goal Positions.
pub(crate) fn write_goals<B: Board>(bus: &mut BoardMaster<'_, B>, ticks: &[i32; LEG_JOINTS]) {
    let mut data = [[0u8; 4]; LEG_JOINTS];
    for (d, t) in data.iter_mut().zip(ticks.iter()) {
        *d = t.to_le_bytes();
    }
    let mut entries: [(u8, &[u8]); LEG_JOINTS] = [(0, &[]); LEG_JOINTS];
    let legs = bus.devices().legs;
    for ((e, &id), d) in entries.iter_mut().zip(legs.iter()).zip(data.iter()) {
        *e = (id, d.as_slice());
    }
    let f = x_series::GOAL_POSITION;
    // A failed broadcast is counted in the master's stats; nothing else to do this tick.
    let _ = bus.master().sync_write(f.addr, f.len, &entries);
}
