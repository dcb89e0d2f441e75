//! A ROBOTIS X-series servo in position mode (Operating Mode 3): the control table's position
//! controller, the PWM drive and the DC motor behind the gear train, as the MuJoCo robot's
//! joint actuators ([`super::mujoco`]).
//!
//! # Model
//!
//! Every control period (one physics step) the servo reads its encoder (whole ticks, 4096 per
//! turn), moves its desired position along the velocity-based profile towards Goal Position,
//! and runs the position PID of the e-manual's position-mode block diagram:
//!
//! ```text
//! e    = p_desired − p_present                               (ticks)
//! PWM  = K_PP·e + K_PI·Σe + K_PD·Δe                          (K_PP = P/128, K_PI = I/65536, K_PD = D/16)
//! PWM  ← clamp(PWM, ±PWM Limit)                              (885 = 100 % duty)
//! u    = PWM / 885
//! τ_m  = τ_s·(V/V_n)·u − (τ_s/ω_0)·ω                          (DC motor on its torque–speed line)
//! ```
//!
//! `τ_m` is the torque at the output shaft: the motor's stall torque `τ_s` and no-load speed
//! `ω_0` are the datasheet's at the nominal voltage `V_n`; at supply voltage `V` the line moves
//! parallel (stall torque and no-load speed both scale with `V`), and its slope `τ_s/ω_0` is the
//! back-EMF damping, present whenever the H-bridge drives (torque on; torque off = coasting,
//! `τ_m = 0`). The gear train's viscous and Coulomb friction and the rotor inertia reflected
//! through the gear (armature) are joint properties of the MuJoCo model, where the physics
//! integrates them exactly. Present Current is `τ_m/τ_s·I_stall` (output-torque equivalent).
//!
//! Gear backlash (`backlash`, the play b of the gear train at the output, rad; 0 = none, the
//! model above exactly): the encoder reads the output shaft, as on the X series, and the motor
//! side is a second angle m (output units) with the rotor's reflected inertia J = `armature`.
//! While the motor presses on one flank (m = q ± b/2 and τ_m pushes into it) the gear is
//! engaged: the output gets τ_m as above and m rides on q. Otherwise the output gets no torque
//! and the motor turns freely across the play until it meets a flank,
//!
//! ```text
//! J·m̈ = τ_s·(V/V_n)·u − (τ_s/ω_0)·ṁ,    m − q ∈ [−b/2, b/2]
//! ```
//!
//! (semi-implicit Euler per control period on ṁ and the gap m − q; meeting a flank takes the
//! output's speed). A load
//! that reverses thus leaves the joint limp until the motor has crossed the play, and the
//! output wanders within it — lost motion and the delay it brings; the joint keeps its
//! armature in the MuJoCo model (the rotor's inertia moves with the output when engaged).
//!
//! The profile (Profile Velocity / Profile Acceleration non-zero) is the e-manual's
//! velocity-based trapezoid, simplified to a desired position that chases Goal Position with
//! `|v| ≤ v_profile` and `|a| ≤ a_profile`, braking so that it stops at the goal
//! (`v² ≤ 2·a·|goal − p|`); with both registers 0 (the factory default) the desired position is
//! Goal Position itself (a step).
//!
//! # Sources of the numbers ([`XServoParams::XM430_W350`])
//!
//! * Stall torque 4.1 N·m at 12 V, stall current 2.3 A, no-load speed 46 rpm at 12 V, gear ratio
//!   353.5 : 1: ROBOTIS XM430-W350 datasheet / e-manual "Specifications".
//! * Control-table defaults Position P Gain 800, I 0, D 0, PWM Limit 885, Current Limit 1193,
//!   Velocity Limit 200, Profile Velocity/Acceleration 0; K_PP = P/128, K_PI = I/65536,
//!   K_PD = D/16, PWM full scale 885: ROBOTIS e-manual, XM430-W350 control table and its
//!   "Position P/I/D Gain" section.
//! * Armature 0.045 kg·m², joint damping 1.084 N·m·s/rad (of which `τ_s/ω_0` = 0.851 is the
//!   back-EMF part modelled here; the remaining 0.233 is the gear's viscous friction) and friction
//!   loss 0.03 N·m: MuJoCo Menagerie `robotis_op3/op3.xml`, identified on XM430 servos of the
//!   ROBOTIS OP3. K_PP·τ_s/885 per tick = 18.9 N·m/rad agrees with its identified kp = 21.1.
//! * Control period: 1 physics step (the servo's internal loop is faster than the bus; the
//!   e-manual does not state its period).

use dxl::table::x_series;
use walker_contract::bus_map::TickMap;

/// Parameters of one servo model (motor, gear and drive).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct XServoParams {
    /// Stall torque at the output at the nominal voltage, N·m.
    pub stall_torque: f64,
    /// No-load speed at the output at the nominal voltage, rad/s.
    pub no_load_speed: f64,
    /// Stall current at the nominal voltage, A.
    pub stall_current: f64,
    /// Nominal (datasheet) voltage, V.
    pub nominal_voltage: f64,
    /// Supply voltage, V.
    pub supply_voltage: f64,
    /// Rotor inertia reflected through the gear (MuJoCo joint armature), kg·m².
    pub armature: f64,
    /// Viscous friction of the gear train (MuJoCo joint damping), N·m·s/rad.
    pub gear_damping: f64,
    /// Coulomb friction of the gear train (MuJoCo joint frictionloss), N·m.
    pub friction_loss: f64,
    /// Factor on the drive's P, I and D gains against the registers (1: the datasheet servo;
    /// the robustness sweep varies it to stand for servos tuned or built differently).
    pub gain_scale: f64,
    /// Play of the gear train at the output, rad (0: none).
    pub backlash: f64,
}

impl XServoParams {
    /// ROBOTIS XM430-W350 at 12 V (sources in the module doc).
    pub const XM430_W350: XServoParams = XServoParams {
        stall_torque: 4.1,
        no_load_speed: 46.0 * core::f64::consts::TAU / 60.0,
        stall_current: 2.3,
        nominal_voltage: 12.0,
        supply_voltage: 12.0,
        armature: 0.045,
        gear_damping: 0.233,
        friction_loss: 0.03,
        gain_scale: 1.0,
        backlash: 0.0,
    };

    /// Back-EMF damping `τ_s/ω_0`, N·m·s/rad.
    pub fn back_emf_damping(&self) -> f64 {
        self.stall_torque / self.no_load_speed
    }

    /// Every number finite, torques, speeds and voltages > 0, the rest ≥ 0.
    pub fn is_valid(&self) -> bool {
        let pos = [
            self.stall_torque,
            self.no_load_speed,
            self.stall_current,
            self.nominal_voltage,
            self.supply_voltage,
            self.gain_scale,
        ];
        let non_neg = [
            self.armature,
            self.gear_damping,
            self.friction_loss,
            self.backlash,
        ];
        pos.iter().all(|v| v.is_finite() && *v > 0.0)
            && non_neg.iter().all(|v| v.is_finite() && *v >= 0.0)
    }
}

/// The control-table registers the position controller reads, in register units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct XServoRegisters {
    /// Torque Enable.
    pub torque_on: bool,
    /// Goal Position, ticks.
    pub goal: i32,
    /// Position P Gain.
    pub p_gain: u16,
    /// Position I Gain.
    pub i_gain: u16,
    /// Position D Gain.
    pub d_gain: u16,
    /// PWM Limit (0..885).
    pub pwm_limit: u16,
    /// Profile Velocity (unit 0.229 rpm; 0 = none).
    pub profile_velocity: u32,
    /// Profile Acceleration (unit 214.577 rev/min²; 0 = none).
    pub profile_acceleration: u32,
}

impl XServoRegisters {
    /// Factory defaults of an XM430-W350 (torque off) holding `goal`.
    pub fn defaults(goal: i32) -> Self {
        XServoRegisters {
            torque_on: false,
            goal,
            p_gain: 800,
            i_gain: 0,
            d_gain: 0,
            pwm_limit: x_series::PWM_FULL_SCALE,
            profile_velocity: 0,
            profile_acceleration: 0,
        }
    }
}

/// What the servo publishes after a control period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct XServoOutput {
    /// Motor torque at the output shaft, N·m.
    pub torque: f64,
    /// Present PWM (±885).
    pub pwm: i16,
    /// Present Current, A (output-torque equivalent).
    pub current: f64,
    /// The PWM is at PWM Limit (the motor gives all it can at this speed).
    pub saturated: bool,
}

/// One servo's controller state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct XServo {
    /// Desired position of the profile, ticks (continuous).
    desired: f64,
    /// Desired velocity of the profile, ticks/s.
    desired_rate: f64,
    /// Σe of the I term, ticks·periods.
    integral: f64,
    /// Last error (for the D term), ticks.
    last_error: f64,
    /// Whether the last period had torque on.
    was_on: bool,
    /// The motor side behind the gear's play (only with backlash).
    motor: Option<MotorSide>,
}

/// The motor side of a gear train with play: where it stands in the play and its speed, in
/// output units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct MotorSide {
    /// m − q, rad (within ±b/2).
    gap: f64,
    /// Speed ṁ, rad/s.
    md: f64,
    /// The flank it presses on: +1 (m = q + b/2), −1 (m = q − b/2), 0 free in the play.
    flank: f64,
}

/// The encoder's reading of the servo's angle `q` (its own direction: the caller applies the
/// joint's mounting sign): whole ticks (the contract's rad ↔ tick map).
pub fn encoder_ticks(q: f64) -> i32 {
    TickMap::reference().servo_tick_f64(q)
}

impl XServo {
    /// One control period of `dt` seconds at joint angle `q` (rad) and speed `qd` (rad/s).
    pub fn update(
        &mut self,
        params: &XServoParams,
        regs: &XServoRegisters,
        q: f64,
        qd: f64,
        dt: f64,
    ) -> XServoOutput {
        let present = f64::from(encoder_ticks(q));
        if !regs.torque_on {
            *self = XServo {
                desired: present,
                ..XServo::default()
            };
            return XServoOutput::default();
        }
        if !self.was_on {
            // Torque on: the profile starts at the present position, at rest.
            self.desired = present;
            self.desired_rate = 0.0;
            self.integral = 0.0;
            self.last_error = 0.0;
            self.was_on = true;
        }
        self.advance_profile(regs, dt);
        let e = self.desired - present;
        self.integral += e;
        let g = params.gain_scale;
        let kp = g * f64::from(regs.p_gain) / 128.0;
        let ki = g * f64::from(regs.i_gain) / 65536.0;
        let kd = g * f64::from(regs.d_gain) / 16.0;
        let limit = f64::from(regs.pwm_limit.min(x_series::PWM_FULL_SCALE));
        let raw = kp * e + ki * self.integral + kd * (e - self.last_error);
        self.last_error = e;
        let pwm = raw.clamp(-limit, limit);
        let saturated = raw.abs() >= limit;
        if saturated && ki > 0.0 {
            // Anti-windup: the integral does not grow while the output is clamped.
            self.integral -= e;
        }
        let u = pwm / f64::from(x_series::PWM_FULL_SCALE);
        let v = params.supply_voltage / params.nominal_voltage;
        let torque = if params.backlash > 0.0 {
            self.through_play(params, params.stall_torque * v * u, qd, dt)
        } else {
            params.stall_torque * v * u - params.back_emf_damping() * qd
        };
        XServoOutput {
            torque,
            pwm: pwm.round() as i16,
            current: torque / params.stall_torque * params.stall_current,
            saturated,
        }
    }

    /// The torque at the output through the gear's play (module doc) for the motor's drive
    /// torque `drive` (before the back-EMF) this period, the output at speed `qd`.
    fn through_play(&mut self, params: &XServoParams, drive: f64, qd: f64, dt: f64) -> f64 {
        let half = 0.5 * params.backlash;
        let k_e = params.back_emf_damping();
        let engaged = drive - k_e * qd;
        let state = self.motor.get_or_insert(MotorSide {
            gap: 0.0,
            md: qd,
            flank: 0.0,
        });
        if state.flank != 0.0 {
            if state.flank * engaged > 0.0 {
                // Pressing on its flank: the motor rides on the output.
                state.md = qd;
                return engaged;
            }
            // The drive turned away from the flank: free from it at the output's speed.
            state.flank = 0.0;
            state.md = qd;
        }
        // Free: the rotor alone across the play (the output moves on meanwhile), until it
        // meets a flank.
        let j = params.armature.max(1e-6);
        let md = state.md + dt * (drive - k_e * state.md) / j;
        let gap = state.gap + dt * (md - qd);
        *state = if gap >= half {
            MotorSide {
                gap: half,
                md: qd,
                flank: 1.0,
            }
        } else if gap <= -half {
            MotorSide {
                gap: -half,
                md: qd,
                flank: -1.0,
            }
        } else {
            MotorSide {
                gap,
                md,
                flank: 0.0,
            }
        };
        0.0
    }

    /// Moves the desired position one period along the profile towards the goal.
    fn advance_profile(&mut self, regs: &XServoRegisters, dt: f64) {
        let goal = f64::from(regs.goal);
        let rpm_to_ticks = f64::from(x_series::TICKS_PER_TURN) / 60.0;
        let v_max = f64::from(regs.profile_velocity)
            * f64::from(x_series::VELOCITY_UNIT_RPM)
            * rpm_to_ticks;
        let a_max = f64::from(regs.profile_acceleration)
            * f64::from(x_series::ACCELERATION_UNIT_RPM2)
            * f64::from(x_series::TICKS_PER_TURN)
            / 3600.0;
        if v_max <= 0.0 && a_max <= 0.0 {
            self.desired = goal;
            self.desired_rate = 0.0;
            return;
        }
        let to_go = goal - self.desired;
        let dir = to_go.signum();
        // Fastest speed towards the goal that can still stop there.
        let mut v_target = if a_max > 0.0 {
            dir * (2.0 * a_max * to_go.abs()).sqrt()
        } else {
            dir * f64::INFINITY
        };
        if v_max > 0.0 {
            v_target = v_target.clamp(-v_max, v_max);
        }
        let mut v = v_target;
        if a_max > 0.0 {
            let dv = (v_target - self.desired_rate).clamp(-a_max * dt, a_max * dt);
            v = self.desired_rate + dv;
        }
        let step = v * dt;
        if step.abs() >= to_go.abs() || !step.is_finite() {
            self.desired = goal;
            self.desired_rate = 0.0;
        } else {
            self.desired += step;
            self.desired_rate = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torque_off_coasts_and_torque_on_holds_without_a_kick() {
        let p = XServoParams::XM430_W350;
        let mut s = XServo::default();
        let mut r = XServoRegisters::defaults(2048);
        let out = s.update(&p, &r, 0.3, 1.0, 1e-3);
        assert_eq!(out, XServoOutput::default());
        r.torque_on = true;
        r.goal = encoder_ticks(0.3);
        let out = s.update(&p, &r, 0.3, 0.0, 1e-3);
        assert_eq!(out.pwm, 0);
    }

    /// An XM430-W350 at the centre tick with its torque on.
    fn powered_at_centre() -> (XServoParams, XServo, XServoRegisters) {
        let mut r = XServoRegisters::defaults(2048);
        r.torque_on = true;
        (XServoParams::XM430_W350, XServo::default(), r)
    }

    #[test]
    fn stiffness_matches_the_gain_and_the_stall_torque() {
        // 10 ticks of error at rest: PWM = 800/128·10 = 62.5 → τ = 4.1·62.5/885.
        let (p, mut s, mut r) = powered_at_centre();
        s.update(&p, &r, 0.0, 0.0, 1e-3);
        r.goal = 2058;
        let out = s.update(&p, &r, 0.0, 0.0, 1e-3);
        assert!((out.torque - 4.1 * 62.5 / 885.0).abs() < 1e-12);
        // Saturation: a large error gives the stall torque minus the back-EMF torque.
        r.goal = 4000;
        let out = s.update(&p, &r, 0.0, 2.0, 1e-3);
        assert!(out.saturated);
        assert!((out.torque - (4.1 - 4.1 / p.no_load_speed * 2.0)).abs() < 1e-12);
    }

    #[test]
    fn profile_reaches_the_goal_within_its_limits() {
        let (p, mut s, mut r) = powered_at_centre();
        r.profile_velocity = 100; // 22.9 rpm
        r.profile_acceleration = 50;
        s.update(&p, &r, 0.0, 0.0, 1e-3);
        r.goal = 2048 + 1000;
        let v_max = 100.0 * 0.229 * 4096.0 / 60.0;
        let a_max = 50.0 * 214.577 * 4096.0 / 3600.0;
        let (mut last, mut last_v) = (2048.0, 0.0);
        for _ in 0..5000 {
            s.update(&p, &r, 0.0, 0.0, 1e-3);
            let v = (s.desired - last) / 1e-3;
            assert!(v <= v_max * (1.0 + 1e-6), "{v} > {v_max}");
            assert!(
                (v - last_v).abs() <= a_max * 1e-3 * (1.0 + 1e-6) + 1e-6 || s.desired == 3048.0
            );
            last = s.desired;
            last_v = v;
        }
        assert_eq!(s.desired, 3048.0);
    }

    /// Gear backlash: the output held still at the centre, the goal 100 ticks ahead. The motor
    /// first crosses half the play with the output limp, then the output gets the drive's
    /// torque; with the goal reversed the output is limp again while the motor crosses the whole
    /// play. Crossing times against the rotor's free acceleration from rest, s = τ·t²/(2J)
    /// (the back-EMF only slows it: at most half as long again).
    #[test]
    fn backlash_leaves_the_output_limp_while_the_motor_crosses_the_play() {
        let (mut p, mut s, mut r) = powered_at_centre();
        let b = 0.5f64.to_radians();
        p.backlash = b;
        let dt = 1e-3;
        let q = TickMap::reference().rad_f64(0, 2048);
        let limp_run = |s: &mut XServo, r: &XServoRegisters| {
            let mut n = 0;
            loop {
                let out = s.update(&p, r, q, 0.0, dt);
                if out.torque != 0.0 {
                    return (n, out.torque);
                }
                n += 1;
                assert!(n < 1000, "never engaged");
            }
        };
        let free_time = |play: f64, torque: f64| (2.0 * play * p.armature / torque.abs()).sqrt();
        // Without play: the torque at once.
        let mut plain = XServo::default();
        r.goal = 2148;
        let stiff = plain
            .update(&XServoParams::XM430_W350, &r, q, 0.0, dt)
            .torque;
        assert!(stiff > 2.0, "{stiff}");
        let (n, torque) = limp_run(&mut s, &r);
        assert!((torque - stiff).abs() < 1e-9, "{torque} against {stiff}");
        let t = free_time(b / 2.0, stiff) / dt;
        assert!(
            n as f64 >= t.floor() && n as f64 <= 1.5 * t + 2.0,
            "{n} ticks, free {t:.1}"
        );
        // Engaged: it stays so while the drive pushes the same way.
        for _ in 0..10 {
            assert!((s.update(&p, &r, q, 0.0, dt).torque - stiff).abs() < 1e-9);
        }
        // Reversed: limp across the whole play, then the reversed torque.
        r.goal = 1948;
        let (n, torque) = limp_run(&mut s, &r);
        assert!((torque + stiff).abs() < 1e-9, "{torque}");
        let t = free_time(b, stiff) / dt;
        assert!(
            n as f64 >= t.floor() && n as f64 <= 1.5 * t + 2.0,
            "{n} ticks, free {t:.1}"
        );
    }

    /// Gear backlash under a load that overruns the goal: a pendulum (1 N·m of gravity at 1 rad,
    /// 0.01 kg·m² plus the armature, the gear's viscous friction) whose goal ramps 0.5 rad in
    /// 0.5 s. With 0.5° of play it still comes to rest at its goal, within the half play plus
    /// its sag under the load (sin 0.5 N·m at 18.9 N·m/rad ≈ 0.025 rad), as without play.
    #[test]
    fn a_servo_with_play_still_brakes_an_overrunning_load_to_its_goal() {
        let map = TickMap::reference();
        let rest = |backlash_deg: f64| {
            let p = XServoParams {
                backlash: backlash_deg.to_radians(),
                ..XServoParams::XM430_W350
            };
            let mut s = XServo::default();
            let mut r = XServoRegisters::defaults(2048);
            r.torque_on = true;
            let q0 = map.rad_f64(0, 2048);
            let (mut q, mut qd) = (q0, 0.0);
            let dt = 1e-3;
            for k in 0..3000 {
                let t = f64::from(k) * dt;
                r.goal = map.tick_f64(0, q0 + 0.5 * (t / 0.5).min(1.0));
                let out = s.update(&p, &r, q, qd, dt);
                let tau = out.torque + (q - q0).sin() - p.gear_damping * qd;
                qd += dt * tau / (0.01 + p.armature);
                q += dt * qd;
            }
            (q - q0 - 0.5, qd)
        };
        let (e0, _) = rest(0.0);
        let (e, qd) = rest(0.5);
        assert!(e0.abs() < 0.03, "without play: {e0}");
        assert!(
            e.abs() < 0.25f64.to_radians() + 0.03 && qd.abs() < 0.05,
            "with play: {e} rad off, {qd} rad/s"
        );
    }
}
