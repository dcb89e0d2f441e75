//! How fast the MuJoCo robot runs alone (no firmware, no bus): the reference robot standing in a
//! crouch with its 12 servo models holding it, stepped for 15 s of simulated time, on a flat floor
//! and on the ±5 mm tiled floor. Prints steps per second and the real-time factor
//! (simulated / wall time). Run by `scripts/bench-sim.sh`:
//! `cargo run --release --target host-tuple -p walker-host --example physics_rate`.

use std::time::Instant;

use dxl::instruction::encode_sync_write;
use dxl::table::x_series;
use walker_contract::bus_map::TickMap;
use walker_host::sim::{EnvConfig, SimConfig, Simulator};

fn run(name: &str, env: EnvConfig) {
    let leg = [0.0, 0.0, -0.3, 0.6, -0.3, 0.0];
    let mut q = [0.0; 12];
    q[..6].copy_from_slice(&leg);
    q[6..].copy_from_slice(&leg);
    let cfg = SimConfig {
        initial_q: q,
        env,
        ..SimConfig::default()
    };
    let mut sim = Simulator::new(&cfg).expect("simulator");
    let goals: Vec<[u8; 4]> = q
        .iter()
        .enumerate()
        .map(|(j, &a)| TickMap::reference().tick_f64(j, a).to_le_bytes())
        .collect();
    let mut buf = [0u8; 256];
    for (field, data) in [
        (
            x_series::GOAL_POSITION,
            goals.iter().map(|g| g.to_vec()).collect::<Vec<_>>(),
        ),
        (x_series::TORQUE_ENABLE, vec![vec![1u8]; 12]),
    ] {
        let entries: Vec<(u8, &[u8])> = (0..12).map(|j| (j as u8 + 1, &data[j][..])).collect();
        let n = encode_sync_write(&mut buf, field.addr, field.len, &entries).expect("encode");
        sim.feed(&buf[..n]);
    }
    let sim_s = 15.0;
    let start = Instant::now();
    sim.advance_to((sim_s * 1e6) as u64).expect("advance");
    let wall = start.elapsed().as_secs_f64();
    let steps = sim.summary().physics_steps;
    println!(
        "{name}: {steps} physics steps of {} µs in {wall:.3} s wall: {:.0} steps/s, real-time factor {:.1}",
        cfg.physics_dt_us,
        steps as f64 / wall,
        sim_s / wall
    );
}

fn main() {
    run("flat floor", EnvConfig::default());
    run(
        "±5 mm tiled floor",
        EnvConfig {
            step_height_m: 0.005,
            ..EnvConfig::default()
        },
    );
}
