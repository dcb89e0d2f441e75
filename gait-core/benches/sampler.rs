//! Host speed of one gait sample per model and solver (criterion): the exact bounded closed
//! form in f32 and f64, the fixed-point sampler, and the Fourier series (N = 24).
//! Run: `cargo bench --target host-tuple -p gait-core --bench sampler`.

use criterion::{criterion_group, criterion_main, Criterion};
use gait_core::trajectory::fixed_sampler::FixedSampler;
use gait_core::trajectory::fourier::FourierCom;
use gait_core::{ForwardWalk, Model, ModelKind, Real, Robot, Sampler};
use std::hint::black_box;

const CAP: usize = 32;

fn sampler<R: Real>(kind: ModelKind) -> Sampler<R, CAP> {
    let plan = ForwardWalk::table2()
        .model_plan::<R, CAP>(&Robot::reference(), kind)
        .expect("plan");
    Sampler::new(plan, 0.005).expect("sampler")
}

/// Benches `next` on a copy of `fresh`, started again from `fresh` when `is_done`.
fn bench_samples<S: Clone, T>(
    c: &mut Criterion,
    name: &str,
    fresh: &S,
    is_done: impl Fn(&S) -> bool,
    mut next: impl FnMut(&mut S) -> T,
) {
    let mut s = fresh.clone();
    c.bench_function(name, |b| {
        b.iter(|| {
            if is_done(&s) {
                s = fresh.clone();
            }
            black_box(next(&mut s))
        })
    });
}

/// Benches the exact sampler of `kind` in `R` (named `label`).
fn bench_sampler<R: Real>(c: &mut Criterion, kind: ModelKind, label: &str) {
    bench_samples(
        c,
        &format!("sample/{}/{label}", kind.name()),
        &sampler::<R>(kind),
        Sampler::is_done,
        |s| s.next(black_box(R::zero())),
    );
}

fn bench(c: &mut Criterion) {
    for kind in ModelKind::ALL {
        bench_sampler::<f32>(c, kind, "f32");
        bench_sampler::<f64>(c, kind, "f64");
        let robot = Robot::reference();
        let walk = ForwardWalk::table2();
        let model = Model::<f32>::new(kind, &robot, walk.z_c).expect("model");
        let plan = walk
            .plan::<f32, CAP>(&robot, walk.params(model))
            .expect("plan");
        bench_samples(
            c,
            &format!("sample/{}/fixed", kind.name()),
            &FixedSampler::new(plan, 0.005).expect("fixed"),
            FixedSampler::is_done,
            |s| s.next(black_box(0)),
        );
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
