//! The ROBOTIS OP3: twenty XM430-W350 servos on a 2 Mbps Dynamixel 2.0 bus, an OpenCR 1.0
//! board with its own IMU, no foot sensors.
//!
//! # Sources
//! - MuJoCo Menagerie `robotis_op3/op3.xml` (Apache-2.0): the link frames, joint axes, masses
//!   and inertias, the foot boxes.
//! - ROBOTIS-OP3 `op3_manager/config/OP3.robot`: the IDs (legs 7–18, right before left; arms
//!   1–6; head 19–20) and the bus speed (2,000,000 bit/s).
//!
//! # Geometry (from op3.xml's body positions, zero pose, left leg; m)
//! In `body_link`'s frame the hip yaw joint is at (0, 0.035, 0), the roll link 0.024 behind
//! and 0.0285 below it, the pitch link 0.0241 ahead of that and 0.019 outward: the roll axis
//! (x) and the pitch axis (y) meet at the hip point H = (0.0001, 0.035, −0.0285), 0.1 mm ahead
//! of the yaw axis (neglected: the yaw axis is taken through H). The pelvis point P is the
//! midpoint of the two hip points, so `hip_offset_y` = 0.035 and `hip_yaw_height` = 0.0285.
//! Knee 0.11015 below H (`thigh`), ankle pitch 0.11 below the knee (`calf`); the ankle roll
//! link sits 0.0241 behind and 0.019 inward of the ankle pitch link, so the ankle axes meet
//! under H. The foot boxes (in the ankle roll link: centres (0.024, 0.013, −0.0265) and
//! (0.024, 0.0125, −0.0265), half-sizes (0.0635, 0.028, 0.004) and (0.057, 0.039, 0.004))
//! put the ground 0.0305 below the ankle (`ankle_height`) and the soles' centres 0.0001
//! behind and 0.0125–0.013 outward of it. The sole rectangle is the wider box,
//! 0.114 × 0.078 m, centred 0.0001 behind and 0.0125 outward of the ankle (`sole_offset`);
//! the narrower box reaches 6.5 mm further ahead and behind (support left out, on the safe
//! side).
//!
//! # Masses (op3.xml's inertials; arms held down, see [`OP3`]`.bus.held`)
//! The pendulum models carry three masses per leg and the upper body. The hip yaw and roll
//! links (0.01181 + 0.17886 kg, their servos at the hip) barely move with the leg and count in
//! the upper body with the trunk (1.34928), the head (0.01176 + 0.13631) and the arms
//! (2 × (0.01176 + 0.17758 + 0.04127)): M_u = 2.33991 kg, its CoM 0.0801 above P and 0.0113
//! behind it, J_yy = 0.0113 kg·m² about it. Thigh = the hip pitch link, 0.11543 kg, 0.08408
//! below the hip point (76.33 % of the thigh; 0.6 mm ahead of the line); calf = the knee link,
//! 0.04015 kg, half-way down (2.5 mm inward of the line); sole = the ankle pitch and roll links,
//! 0.2482 kg, 0.0315 above the ground, 0.01467 behind and 0.0031 outward of the ankle (the
//! ankle servo sits behind it): 0.01457 behind and 0.0094 inward of the sole point. Whole
//! robot 3.14747 kg.
//!
//! The inertias ([`super::LinkInertias`]) are the same lumps' about their centres of mass:
//! each link's `diaginertia` turned by its `quat` into the link frame, the lump's links summed
//! with the parallel-axis terms, the diagonal kept (the largest product left out, the upper
//! body's I_xz = −6.6e-4 kg·m², is 4–7 % of its diagonal; gait-core's tests/robots.rs computes
//! them again from op3.xml's numbers).
//!
//! # Joint signs (op3.xml's axes)
//! Left: hip yaw −z, hip roll −x, hip pitch +y, knee +y, ankle pitch −y, ankle roll +x; the
//! right leg's pitch axes are the opposite (hip pitch −y, knee −y, ankle pitch +y).
//!
//! # The OpenCR's IMU in the torso
//! ROBOTIS' own software turns the chip's axes into the robot's as x → −x, y → −y, z → z:
//! the OpenCR's `IMU` library passes the chip's gyro and accelerometer axes through unchanged
//! (`GYRO_ORIENTATION`, `ACC_ORIENTATION` with ROLL = 0, PITCH = 1, YAW = 2), its OP3 firmware
//! (`dxl_hw_op3.cpp`) reports them as `gyro_x/y/z`, `acc_x/y/z`, and `op3_manager`'s
//! `open_cr_module.cpp` negates x and y of both into `body_link`'s frame. The board lies turned
//! half a turn about the vertical ([`OPENCR_IN_TORSO`]).
//!
//! # Shape (assumed: boxes around op3.xml's body and head meshes, by eye)
//! Pelvis box 0.08 × 0.12 × 0.04 m from P up, trunk box 0.09 × 0.12 × 0.14 m (0.04–0.18 m above
//! P, 1 cm behind it), head sphere r 0.045 m at 0.22 m.
//!
//! # Limits and servos (assumed)
//! The joint limits are the walking workspace ([`WALKING_LIMITS`]); the servos are
//! XM430-W350 at 12 V (no-load 4.8 rad/s, 4096 ticks per turn, 2048 = 0 rad).

use super::{
    BodyShape, BusDescription, Geometry, HeldServo, ImuAxes, ImuPlace, LinkInertias, Masses, Robot,
    ServoLimits, LEG_JOINTS, WALKING_LIMITS,
};

/// The arm and head servos, held while walking: arms hanging 0.27 rad out from the body
/// (shoulder roll ±1.3 rad from op3.xml's T-pose), elbows straight, head straight ahead.
/// The OpenCR's IMU chip in the OP3's torso: half a turn about z (see the module docs).
pub const OPENCR_IN_TORSO: ImuAxes = ImuAxes {
    axis: [0, 1, 2],
    sign: [-1, -1, 1],
};

const HELD: [HeldServo; 8] = [
    HeldServo {
        name: "r_sho_pitch",
        id: 1,
        angle: 0.0,
    },
    HeldServo {
        name: "l_sho_pitch",
        id: 2,
        angle: 0.0,
    },
    HeldServo {
        name: "r_sho_roll",
        id: 3,
        angle: -1.3,
    },
    HeldServo {
        name: "l_sho_roll",
        id: 4,
        angle: 1.3,
    },
    HeldServo {
        name: "r_el",
        id: 5,
        angle: 0.0,
    },
    HeldServo {
        name: "l_el",
        id: 6,
        angle: 0.0,
    },
    HeldServo {
        name: "head_pan",
        id: 19,
        angle: 0.0,
    },
    HeldServo {
        name: "head_tilt",
        id: 20,
        angle: 0.0,
    },
];

/// The ROBOTIS OP3.
pub const OP3: Robot = Robot {
    name: "op3",
    masses: Masses {
        upper_body: 2.33991,
        upper_body_height: 0.0801,
        thigh: 0.11543,
        calf: 0.04015,
        sole: 0.2482,
        sole_height: 0.0315,
        upper_body_inertia: 0.0113,
        upper_body_forward: -0.0113,
        thigh_com: 0.7633,
        calf_com: 0.5,
        sole_com: [-0.01457, -0.0094],
        inertias: Some(&LinkInertias {
            upper_body_roll_yaw: [0.017102, 0.0094562],
            thigh: [1.0499e-4, 9.6130e-5, 2.4930e-5],
            calf: [3.715e-5, 2.751e-5, 1.511e-5],
            sole: [1.7095e-4, 3.0257e-4, 2.4914e-4],
        }),
    },
    geometry: Geometry {
        hip_offset_y: 0.035,
        thigh: 0.11015,
        calf: 0.11,
        ankle_height: 0.0305,
        sole_offset: [-0.0001, 0.0125],
        hip_yaw_height: 0.0285,
        sole_length: 0.114,
        sole_width: 0.078,
        // No foot sensors (`bus.foot_boards` is `None`): nothing reads these.
        force_sensors: [[0.0; 2]; 4],
    },
    joint_limits: WALKING_LIMITS,
    servo: ServoLimits {
        max_speed: 4.8,
        ticks_per_turn: 4096,
        zero_tick: 2048,
    },
    mounting: [-1, -1, 1, 1, -1, 1, -1, -1, -1, -1, 1, 1],
    // ROBOTIS' home position: every joint at 0 rad reads 2048 (robotis-japan-support
    // `joints_op3.md`); a robot's own calibration (op3_manager's offset.yaml) goes here.
    zero_offsets: [0; LEG_JOINTS],
    bus: BusDescription {
        baud: 2_000_000,
        legs: [8, 10, 12, 14, 16, 18, 7, 9, 11, 13, 15, 17],
        foot_boards: None,
        imu: ImuPlace::Board(OPENCR_IN_TORSO),
        held: &HELD,
    },
    shape: &BodyShape {
        pelvis: [[0.04, 0.06, 0.02], [0.0, 0.0, 0.02]],
        trunk: [[0.045, 0.06, 0.07], [-0.01, 0.0, 0.11]],
        head: [0.045, 0.22],
    },
    gravity: 9.80665,
};
