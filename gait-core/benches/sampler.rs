//! Host speed of one gait sample per model and solver (criterion): the exact bounded closed
//! form in f32 and f64, the fixed-point sampler, and the Fourier series (N = 24).
//! Run: `cargo bench --target host-tuple -p gait-core --bench sampler`.

use criterion::{criterion_group, criterion_main, Criterion};
use gait_core::fixed_point::FixedSampler;
use gait_core::fourier::FourierCom;
use gait_core::{ForwardWalk, Model, ModelKind, Real, Robot, Sampler};
use std::hint::black_box;

const CAP: usize = 32;

fn sampler<R: Real>(kind: ModelKind) -> Sampler<R, CAP> {
    let plan = ForwardWalk::table2()
        .model_plan::<R, CAP>(&Robot::reference(), kind)
        .expect("plan");
    Sampler::new(plan, 0.005).expect("sampler")
}

fn bench(c: &mut Criterion) {
    for kind in ModelKind::ALL {
        let fresh32 = sampler::<f32>(kind);
        let mut s32 = fresh32.clone();
        c.bench_function(&format!("sample/{}/f32", kind.name()), |b| {
            b.iter(|| {
                if s32.is_done() {
                    s32 = fresh32.clone();
                }
                black_box(s32.next(black_box(0.0)))
            })
        });
        let fresh64 = sampler::<f64>(kind);
        let mut s64 = fresh64.clone();
        c.bench_function(&format!("sample/{}/f64", kind.name()), |b| {
            b.iter(|| {
                if s64.is_done() {
                    s64 = fresh64.clone();
                }
                black_box(s64.next(black_box(0.0)))
            })
        });
        let robot = Robot::reference();
        let walk = ForwardWalk::table2();
        let model = Model::<f32>::new(kind, &robot, walk.z_c).expect("model");
        let plan = walk
            .plan::<f32, CAP>(&robot, walk.params(model))
            .expect("plan");
        let fresh_fx = FixedSampler::new(plan, 0.005).expect("fixed");
        let mut fxs = fresh_fx.clone();
        c.bench_function(&format!("sample/{}/fixed", kind.name()), |b| {
            b.iter(|| {
                if fxs.is_done() {
                    fxs = fresh_fx.clone();
                }
                black_box(fxs.next(black_box(0)))
            })
        });
        let params = walk.params(model);
        let fourier = FourierCom::<f32, 24>::from_params(
            &params,
            walk.step_length as f32,
            -walk.step_width as f32,
            24,
        )
        .expect("fourier");
        let mut t = 0.0f32;
        c.bench_function(&format!("sample/{}/fourier24-f32", kind.name()), |b| {
            b.iter(|| {
                t = if t > 100.0 { 0.0 } else { t + 0.005 };
                black_box(fourier.sample(black_box(t)))
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
