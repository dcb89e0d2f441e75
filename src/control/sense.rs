//! Sense: the sensor devices' ONE BULK READ a tick (and the board's IMU, where the robot's
//! IMU is the controller board's: its sample turned into the trunk's axes, (I1) of
//! [`ImuAxes`]), each reply checked for plausibility ([`crate::plausible`]) and its freshness
//! decided by the supervisor.

use dxl::table::foot::FootForces;
use dxl::table::imu::ImuSample;
use dxl::table::{foot, imu as imu_table};
use dxl::{BulkReadRequest, DeviceResult};
use gait_core::robot::{BusDescription, ImuAxes, ImuPlace};
use walker_contract::bus_map::{self, SENSOR_SLOTS};
use walker_contract::codes::SensorRejection;

use crate::board::Board;
use crate::bus::BoardMaster;
use crate::plausible::Plausibility;
use crate::record::{FaultKind, LogWriter};
use crate::supervisor::{Freshness, StopReason, Supervisor};

use super::act::fault;

/// The IMU's sensor slot (after the left and the right foot board's).
const IMU_SLOT: usize = 2;

/// The sensor devices read each tick and where their data lands in the bulk-read buffer.
struct Sensors {
    /// Per slot (left foot board, right foot board, IMU): its device, if the robot has one
    /// ([`bus_map::BOARD_IMU`]: the board's IMU).
    ids: [Option<u8>; SENSOR_SLOTS],
    reqs: heapless::Vec<BulkReadRequest, 3>,
    /// Per request: its slot and offset into the buffer.
    slots: heapless::Vec<(usize, usize), 3>,
    buf: [u8; 18 + 18 + 26],
    results: [DeviceResult; 3],
}

impl Sensors {
    fn new(bus: &BusDescription, missing: &[u8]) -> Self {
        let mut s = Sensors {
            ids: bus_map::sensor_ids(bus),
            reqs: heapless::Vec::new(),
            slots: heapless::Vec::new(),
            buf: [0; 62],
            results: [Ok(()); 3],
        };
        let mut off = 0usize;
        for (k, id) in bus_map::sensor_slots(bus).into_iter().enumerate() {
            let Some(id) = id.filter(|id| !missing.contains(id)) else {
                continue;
            };
            let f = if k == IMU_SLOT {
                imu_table::SAMPLE
            } else {
                foot::SAMPLE
            };
            // At most 3 entries: cannot fail.
            let _ = s.reqs.push(BulkReadRequest {
                id,
                addr: f.addr,
                len: f.len,
            });
            let _ = s.slots.push((k, off));
            off += usize::from(f.len);
        }
        s
    }

    /// ONE BULK READ; afterwards `results[i]` is request i's outcome.
    fn read<B: Board>(&mut self, bus: &mut BoardMaster<'_, B>) {
        let n = self.reqs.len();
        if let Some(results) = self.results.get_mut(..n).filter(|_| n > 0) {
            if let Err(e) = bus.master().bulk_read(&self.reqs, &mut self.buf, results) {
                results.iter_mut().for_each(|r| *r = Err(e));
            }
        }
    }

    /// The sensor slots read this tick: the BULK READ's, then the IMU's when it is the
    /// board's (`board`).
    fn read_slots(&self, board: bool) -> impl Iterator<Item = usize> + '_ {
        self.slots
            .iter()
            .map(|&(k, _)| k)
            .chain(board.then_some(IMU_SLOT))
    }

    fn data(&self, req: usize, len: usize) -> Option<&[u8]> {
        let &(_, off) = self.slots.get(req)?;
        self.buf.get(off..off + len)
    }

    /// Parses and checks every reply of the last [`Sensors::read`] ([`crate::plausible`]);
    /// accepted samples are recorded in `checks` at `now_us`.
    /// `feet`: the robot has foot boards (a constant on a real board's build: without them
    /// the foot samples' checks fold away).
    /// `board_sample`: the board IMU's sample of this tick (trunk axes), if it gave one.
    fn check(
        &self,
        checks: &mut Plausibility<3>,
        now_us: u64,
        feet: bool,
        board_sample: Option<ImuSample>,
    ) -> Checked {
        let mut out = Checked {
            feet: [None; 2],
            imu: None,
            rejected: [None; 3],
        };
        // The IMU's sample of this tick, from the bus or from the board (a robot has one IMU).
        let mut imu = board_sample.map(Ok);
        for (i, &(k, _)) in self.slots.iter().enumerate() {
            if !self.results.get(i).is_some_and(|r| r.is_ok()) {
                continue;
            }
            if k == IMU_SLOT {
                imu = Some(
                    self.data(i, usize::from(imu_table::SAMPLE.len))
                        .and_then(ImuSample::from_bytes)
                        .ok_or(SensorRejection::Malformed),
                );
                continue;
            }
            if !feet {
                continue;
            }
            let f = self
                .data(i, usize::from(foot::SAMPLE.len))
                .and_then(FootForces::from_bytes);
            let verdict = match (f, out.feet.get_mut(k)) {
                (Some(f), Some(slot)) => checks.foot(k, &f).map(|()| *slot = Some(f)),
                _ => Err(SensorRejection::Malformed),
            };
            if let (Err(r), Some(slot)) = (verdict, out.rejected.get_mut(k)) {
                *slot = Some(r);
            }
        }
        if let Some(sample) = imu {
            match sample.and_then(|s| checks.imu(IMU_SLOT, &s).map(|()| s)) {
                Ok(s) => out.imu = Some(s),
                Err(r) => {
                    if let Some(slot) = out.rejected.get_mut(IMU_SLOT) {
                        *slot = Some(r);
                    }
                }
            }
        }
        if let ([Some(a), Some(b)], true) = (&out.feet, feet) {
            if let Err(r) = checks.feet_together(a, b) {
                out.feet = [None; 2];
                for slot in out.rejected.iter_mut().take(2) {
                    *slot = Some(r);
                }
            }
        }
        for (k, f) in out.feet.iter().enumerate() {
            if let Some(f) = f {
                checks.accept(k, f.counter, now_us);
            }
        }
        if let Some(s) = out.imu {
            checks.accept(IMU_SLOT, s.counter, now_us);
        }
        out
    }
}

/// The replies of one tick that passed the plausibility checks, and why the others failed.
struct Checked {
    /// Accepted foot samples (index = side).
    feet: [Option<FootForces>; 2],
    /// Accepted IMU sample.
    imu: Option<ImuSample>,
    /// Per sensor slot: why its reply was rejected (a reply that never came is `None`).
    rejected: [Option<SensorRejection>; 3],
}

impl Checked {
    /// True when sensor slot `k`'s reply was accepted.
    fn accepted(&self, k: usize) -> bool {
        match k {
            IMU_SLOT => self.imu.is_some(),
            _ => self.feet.get(k).is_some_and(|f| f.is_some()),
        }
    }
}

/// Last good sensor values.
struct SensorState {
    feet: [Option<FootForces>; 2],
    held: [u16; 3],
    /// Per sensor: its last reply was rejected (the fault record is written once per run).
    rejecting: [bool; 3],
}

/// The sensors' side of the tick: the devices read, their last good values, the checks.
pub(super) struct Sense {
    sensors: Sensors,
    state: SensorState,
    plausible: Plausibility<3>,
}

impl Sense {
    /// The sensors of `bus` ([`bus_map::sensor_ids`]: left foot board, right foot board,
    /// IMU) but the `missing` ones, checked by `plausible`.
    pub(super) fn new(bus: &BusDescription, missing: &[u8], plausible: Plausibility<3>) -> Self {
        Sense {
            sensors: Sensors::new(bus, missing),
            state: SensorState {
                feet: [None; 2],
                held: [0; 3],
                rejecting: [false; 3],
            },
            plausible,
        }
    }

    /// ONE BULK READ of the sensor devices (the board's IMU is read by
    /// [`Sense::supervise`]).
    pub(super) fn read<B: Board>(&mut self, bus: &mut BoardMaster<'_, B>) {
        self.sensors.read(bus);
    }

    /// The last read's replies checked: a rejection logged at the first of a run, each device's
    /// freshness reported to `sup` (a board without an accepted sample for longer than
    /// `sensor_stale_ms` stops), recoveries and holds logged, fresh foot samples kept. Returns
    /// the fresh IMU sample.
    pub(super) fn supervise<B: Board>(
        &mut self,
        bus: &mut BoardMaster<'_, B>,
        log: &mut LogWriter,
        sup: &mut Supervisor<3>,
    ) -> Option<ImuSample> {
        let now = bus.board().now_us();
        let devices = bus.devices();
        let feet = devices.foot_boards.is_some();
        let board = match devices.imu {
            ImuPlace::Board(axes) => Some(axes),
            ImuPlace::Bus(_) => None,
        };
        let board_sample = board.and_then(|axes| board_imu_sample(bus, axes));
        let checked = self
            .sensors
            .check(&mut self.plausible, now, feet, board_sample);
        let state = &mut self.state;
        let mut imu_fresh = None;
        for k in self.sensors.read_slots(board.is_some()) {
            let Some(id) = self.sensors.ids.get(k).copied().flatten() else {
                continue;
            };
            let t = bus.board().now_us();
            let rejected = checked.rejected.get(k).copied().flatten();
            if let (Some(r), Some(seen)) = (rejected, state.rejecting.get_mut(k)) {
                if !*seen {
                    crate::fw_log!(warn, "sensor {} reply rejected: {}", id, r.code());
                    let rec = fault(t, FaultKind::SensorRejected, id, i32::from(r.code()));
                    log.write(bus.board(), rec);
                }
                *seen = true;
            }
            let ok = checked.accepted(k);
            if ok {
                if let Some(seen) = state.rejecting.get_mut(k) {
                    *seen = false;
                }
            }
            let fresh = sup.report(id, ok);
            if let Some(age_ms) = self.plausible.stale(k, now) {
                crate::fw_log!(error, "sensor {} stale for {} ms", id, age_ms);
                sup.stop(StopReason::SensorStale { id, age_ms });
            }
            match (fresh, state.held.get_mut(k)) {
                (Freshness::Fresh, Some(h)) => {
                    if *h > 0 {
                        let rec = fault(t, FaultKind::DeviceRecovered, id, i32::from(*h));
                        log.write(bus.board(), rec);
                    }
                    *h = 0;
                    if k == IMU_SLOT {
                        imu_fresh = checked.imu;
                    } else if let (Some(slot), Some(f)) =
                        (state.feet.get_mut(k), checked.feet.get(k))
                    {
                        *slot = *f;
                    }
                }
                (Freshness::Held(n), Some(h)) => {
                    *h = n;
                    if n == 1 {
                        log.write(bus.board(), fault(t, FaultKind::DeviceHolding, id, 1));
                    }
                }
                _ => {}
            }
        }
        imu_fresh
    }

    /// The feet's last good samples (left, right).
    pub(super) fn feet(&self) -> &[Option<FootForces>; 2] {
        &self.state.feet
    }
}

/// The board IMU's sample, read now, turned into the trunk's axes ((I1) of [`ImuAxes`]);
/// `None` when it gave none.
fn board_imu_sample<B: Board>(bus: &mut BoardMaster<'_, B>, axes: ImuAxes) -> Option<ImuSample> {
    let s = bus.board().imu_sample()?.ok()?;
    Some(ImuSample {
        gyro_urad_s: axes.to_trunk_i32(s.gyro_urad_s),
        accel_um_s2: axes.to_trunk_i32(s.accel_um_s2),
        counter: s.counter,
    })
}
