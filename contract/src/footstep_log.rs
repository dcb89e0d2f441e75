//! The online walk's footsteps and commands in the log: encoded ([`encode_footstep`], by the
//! firmware) and decoded ([`FootstepLog`], by the host's replay and the firmware's tests) here,
//! in one place.
//!
//! Per committed footstep of foot s (1 left, 2 right) the firmware writes `Footstep` fault
//! records, all at one time stamp, in this order:
//!
//! | id | value | when |
//! |---|---|---|
//! | s·16 + 3 | the heading hold's correction of the footprint's yaw, µrad | ≠ 0 only |
//! | s·16 + 4, 5, 6 | an explicit step's travel dx, dy (mm), dyaw (mrad) | a step-list step only |
//! | s·16 + 7, 8 | the position hold's correction of the travel, x, y (µm, support-foot frame) | ≠ 0 only |
//! | s·16 + 0, 1, 2 | the footprint x, y (µm), yaw (µrad) | always, last |
//!
//! Id 0 (no foot) carries the online walk's step period in µs, once when the walk is built.
//! `CommandReceived` records carry each command field as the firmware takes it (id =
//! [`CommandField`] code, value in the command port's units: mode code, mm/s, mrad/s).

use crate::codes::{CommandField, FaultKind};
use crate::command_port::Mode;

/// Footstep record id of the step period (µs).
pub const PERIOD_ID: u8 = 0;
/// Offset (after s·16) of the heading hold's correction.
const TURN: u8 = 3;
/// Offset (after s·16) of an explicit step's first travel component.
const GIVEN: u8 = 4;
/// Offset (after s·16) of the position hold's first correction component.
const SHIFT: u8 = 7;

/// The foot code of the ids: 1 left, 2 right.
pub const fn foot_code(left: bool) -> u8 {
    if left {
        1
    } else {
        2
    }
}

/// Emits the records of one footstep of foot `foot` (1 left, 2 right) as (`Footstep` id,
/// value) in log order: `place` (µm, µm, µrad), `turn` (µrad; not written when 0), `shift`
/// (µm, µm; not written when both are 0), `given` (an explicit step's travel, mm, mm, mrad).
pub fn encode_footstep(
    foot: u8,
    place: [i32; 3],
    turn: i32,
    shift: [i32; 2],
    given: Option<[i32; 3]>,
    mut emit: impl FnMut(u8, i32),
) {
    let base = foot.wrapping_mul(16);
    if turn != 0 {
        emit(base.wrapping_add(TURN), turn);
    }
    if shift != [0, 0] {
        for (c, v) in (0u8..).zip(shift) {
            emit(base.wrapping_add(SHIFT + c), v);
        }
    }
    if let Some(g) = given {
        for (c, v) in (0u8..).zip(g) {
            emit(base.wrapping_add(GIVEN + c), v);
        }
    }
    for (c, v) in (0u8..).zip(place) {
        emit(base.wrapping_add(c), v);
    }
}

/// One footstep as the log tells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoggedFootstep {
    /// The swing foot: 1 left, 2 right.
    pub foot: u8,
    /// The footprint: x, y (µm), yaw (µrad).
    pub place: [i32; 3],
    /// The heading hold's correction, µrad (0: none).
    pub turn: i32,
    /// The position hold's correction of the travel, µm (support-foot frame; 0: none).
    pub shift: [i32; 2],
    /// An explicit step's travel (mm, mm, mrad), if it was a step-list step.
    pub given: Option<[i32; 3]>,
    /// The command in force when the step was logged: mode code, vx, vy (mm/s), yaw rate
    /// (mrad/s).
    pub command: [i32; 4],
}

/// Decodes the footsteps of a log, record by record.
#[derive(Clone, Debug)]
pub struct FootstepLog {
    command: [i32; 4],
    period_us: Option<i32>,
    turn: i32,
    shift: [i32; 2],
    given: [Option<i32>; 3],
    place: [Option<i32>; 3],
    foot: u8,
}

impl Default for FootstepLog {
    fn default() -> Self {
        Self::new()
    }
}

impl FootstepLog {
    /// Before any record: the command is "stand", nothing stepped.
    pub fn new() -> Self {
        FootstepLog {
            command: [i32::from(Mode::Stand.code()), 0, 0, 0],
            period_us: None,
            turn: 0,
            shift: [0; 2],
            given: [None; 3],
            place: [None; 3],
            foot: 0,
        }
    }

    /// Takes one fault record (kind, id, value); a footstep when it completes one. Records of
    /// other kinds are ignored.
    pub fn push(&mut self, kind: FaultKind, id: u8, value: i32) -> Option<LoggedFootstep> {
        match kind {
            FaultKind::CommandReceived => {
                if let (Ok(_), Some(slot)) = (
                    CommandField::try_from(id),
                    self.command.get_mut(usize::from(id)),
                ) {
                    *slot = value;
                }
                None
            }
            FaultKind::Footstep if id == PERIOD_ID => {
                self.period_us = Some(value);
                None
            }
            FaultKind::Footstep => {
                let (foot, k) = (id >> 4, id & 15);
                match k {
                    TURN => self.turn = value,
                    7..=8 => {
                        if let Some(c) = self.shift.get_mut(usize::from(k - SHIFT)) {
                            *c = value;
                        }
                    }
                    4..=6 => {
                        if let Some(g) = self.given.get_mut(usize::from(k - GIVEN)) {
                            *g = Some(value);
                        }
                    }
                    0..=2 => {
                        if let Some(p) = self.place.get_mut(usize::from(k)) {
                            *p = Some(value);
                        }
                        if k == 0 {
                            self.foot = foot;
                        }
                    }
                    _ => {}
                }
                let [Some(x), Some(y), Some(yaw)] = self.place else {
                    return None;
                };
                let given = match self.given {
                    [Some(a), Some(b), Some(c)] => Some([a, b, c]),
                    _ => None,
                };
                let step = LoggedFootstep {
                    foot: self.foot,
                    place: [x, y, yaw],
                    turn: self.turn,
                    shift: self.shift,
                    given,
                    command: self.command,
                };
                self.turn = 0;
                self.shift = [0; 2];
                self.given = [None; 3];
                self.place = [None; 3];
                Some(step)
            }
            _ => None,
        }
    }

    /// The step period the walk logged (µs), once it has.
    pub fn period_us(&self) -> Option<i32> {
        self.period_us
    }

    /// The command in force (mode code, vx, vy mm/s, yaw rate mrad/s).
    pub fn command(&self) -> [i32; 4] {
        self.command
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A footstep's fields: foot, place, turn, shift, given.
    type Step = (u8, [i32; 3], i32, [i32; 2], Option<[i32; 3]>);

    fn log_of(steps: &[Step]) -> heapless::Vec<(u8, i32), 64> {
        let mut out = heapless::Vec::new();
        for &(foot, place, turn, shift, given) in steps {
            encode_footstep(foot, place, turn, shift, given, |id, v| {
                let _ = out.push((id, v));
            });
        }
        out
    }

    #[test]
    fn encoded_footsteps_decode_to_themselves() {
        let steps = [
            (1, [40_960, 45_000, 0], 0, [0, 0], None),
            (2, [123_099, -44_800, 4_880], 4_880, [0, 0], None),
            (1, [218_485, 45_851, 8_722], 0, [0, 0], Some([30, 0, -100])),
            (
                2,
                [313_007, -45_700, -41_278],
                -50_000,
                [0, 0],
                Some([-10, 20, 300]),
            ),
            (1, [400_100, 44_000, -40_000], 1_200, [-5_300, 0], None),
            (2, [480_000, -46_000, -40_500], 0, [0, 170], None),
        ];
        let recs = log_of(&steps);
        // The ids of the table in the module docs.
        assert_eq!(recs.first(), Some(&(16, 40_960)));
        assert_eq!(recs.get(3), Some(&(32 + 3, 4_880)));
        assert_eq!(recs.get(7), Some(&(16 + 4, 30)));
        // The position hold's: 16 + 7, 8 after the turn, both written when one is not 0.
        let n = recs.len();
        assert_eq!(
            recs.get(n - 11..n - 6),
            Some(
                &[
                    (16 + 3, 1_200),
                    (16 + 7, -5_300),
                    (16 + 8, 0),
                    (16, 400_100),
                    (17, 44_000)
                ][..]
            )
        );
        assert_eq!(
            recs.get(n - 5..n - 3),
            Some(&[(32 + 7, 0), (32 + 8, 170)][..])
        );
        let mut log = FootstepLog::new();
        assert_eq!(log.push(FaultKind::Footstep, PERIOD_ID, 640_000), None);
        assert_eq!(log.push(FaultKind::CommandReceived, 1, 50), None);
        assert_eq!(log.push(FaultKind::CommandReceived, 0, 2), None);
        // An unknown command field changes nothing.
        assert_eq!(log.push(FaultKind::CommandReceived, 9, 7), None);
        let mut got = heapless::Vec::<LoggedFootstep, 8>::new();
        for &(id, v) in &recs {
            if let Some(s) = log.push(FaultKind::Footstep, id, v) {
                let _ = got.push(s);
            }
            // Other records between them change nothing.
            assert_eq!(log.push(FaultKind::DeviceHolding, 111, 1), None);
        }
        assert_eq!(log.period_us(), Some(640_000));
        assert_eq!(log.command(), [2, 50, 0, 0]);
        assert_eq!(got.len(), steps.len());
        for (g, &(foot, place, turn, shift, given)) in got.iter().zip(&steps) {
            assert_eq!(
                *g,
                LoggedFootstep {
                    foot,
                    place,
                    turn,
                    shift,
                    given,
                    command: [2, 50, 0, 0]
                }
            );
        }
    }
}
