//! Criterion benchmark of one two-leg inverse kinematics (f32 and f64).

use criterion::{criterion_group, criterion_main, Criterion};
use gait_core::kinematics::leg::{legs_ik, LegKinematics, Pose};
use gait_core::Robot;
use std::hint::black_box;

fn poses<R: gait_core::Real>() -> (Pose<R>, Pose<R>, Pose<R>) {
    let p = |v: [f64; 6]| {
        Pose::new(
            R::of(v[0]),
            R::of(v[1]),
            R::of(v[2]),
            R::of(v[3]),
            R::of(v[4]),
            R::of(v[5]),
        )
    };
    (
        p([0.01, 0.005, 0.217, 0.03, -0.05, 0.1]),
        p([0.03, 0.05, 0.02, 0.0, 0.05, 0.15]),
        p([-0.02, -0.045, 0.0, 0.0, 0.0, 0.1]),
    )
}

fn bench_ik(c: &mut Criterion) {
    let robot = Robot::reference();
    let (pelvis32, l32, r32) = poses::<f32>();
    let (pelvis64, l64, r64) = poses::<f64>();
    c.bench_function("legs_ik_f32", |b| {
        b.iter(|| {
            legs_ik(
                black_box(&robot),
                black_box(&pelvis32),
                black_box(&l32),
                black_box(&r32),
            )
        })
    });
    c.bench_function("legs_ik_f64", |b| {
        b.iter(|| {
            legs_ik(
                black_box(&robot),
                black_box(&pelvis64),
                black_box(&l64),
                black_box(&r64),
            )
        })
    });
    let k32 = LegKinematics::<f32>::new(&robot);
    c.bench_function("legs_ik_f32_precomputed", |b| {
        b.iter(|| black_box(&k32).legs_ik(black_box(&pelvis32), black_box(&l32), black_box(&r32)))
    });
    let k64 = LegKinematics::<f64>::new(&robot);
    c.bench_function("legs_ik_f64_precomputed", |b| {
        b.iter(|| black_box(&k64).legs_ik(black_box(&pelvis64), black_box(&l64), black_box(&r64)))
    });
}

criterion_group!(benches, bench_ik);
criterion_main!(benches);
