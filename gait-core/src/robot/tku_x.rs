//! The TKU-X class reference robot of `shared/reference-robot.md`: masses from seed 000
//! Table 1, the geometry, servo and bus facts assumed there.
//!
//! | quantity | value |
//! | --- | --- |
//! | hip joints (all three axes intersect) | (0, ±0.045, 0) m from P |
//! | thigh, calf | 0.100 m, 0.100 m |
//! | ankle above the sole; sole point | 0.030 m; under the ankle |
//! | sole | 0.100 × 0.060 m; force sensors at (±0.040, ±0.025) m |
//! | masses | M_u 3.05 kg at l_u 0.09 m; thigh 0.20, calf 0.50 kg (each in its link's middle), sole 0.25 kg (0.015 m above the sole point) |
//! | bus | 1 Mbps; legs 1–6 (left), 7–12 (right); foot boards 111, 112; IMU board 200 |
//! | mounting | every joint +1 |
//! | shape (assumed) | pelvis box 0.07 × 0.14 × 0.04 m, trunk box 0.09 × 0.16 × 0.2 m (0.03–0.23 m above P), head r 0.045 m at 0.29 m |

use super::{
    BodyShape, BusDescription, Geometry, ImuPlace, Masses, Robot, ServoLimits, LEG_JOINTS,
    WALKING_LIMITS,
};

/// The TKU-X class reference robot.
pub const TKU_X: Robot = Robot {
    name: "tku-x",
    masses: Masses {
        upper_body: 3.05,
        upper_body_height: 0.09,
        thigh: 0.20,
        calf: 0.50,
        sole: 0.25,
        sole_height: 0.015,
        upper_body_inertia: 0.026,
        upper_body_forward: 0.0,
        thigh_com: 0.5,
        calf_com: 0.5,
        sole_com: [0.0, 0.0],
        inertias: None,
    },
    geometry: Geometry {
        hip_offset_y: 0.045,
        thigh: 0.100,
        calf: 0.100,
        ankle_height: 0.030,
        sole_offset: [0.0, 0.0],
        hip_yaw_height: 0.0,
        sole_length: 0.100,
        sole_width: 0.060,
        force_sensors: [
            [0.040, 0.025],
            [0.040, -0.025],
            [-0.040, 0.025],
            [-0.040, -0.025],
        ],
    },
    joint_limits: WALKING_LIMITS,
    servo: ServoLimits {
        max_speed: 4.8,
        ticks_per_turn: 4096,
        zero_tick: 2048,
    },
    mounting: [1; LEG_JOINTS],
    zero_offsets: [0; LEG_JOINTS],
    bus: BusDescription {
        baud: 1_000_000,
        legs: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12],
        foot_boards: Some([111, 112]),
        imu: ImuPlace::Bus(200),
        held: &[],
    },
    shape: &BodyShape {
        pelvis: [[0.035, 0.07, 0.02], [0.0, 0.0, 0.005]],
        trunk: [[0.045, 0.08, 0.1], [0.0, 0.0, 0.13]],
        head: [0.045, 0.29],
    },
    gravity: 9.80665,
};
