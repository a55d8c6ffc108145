//! Criterion benches of the sweep engine: the TSQR reduction, the fit of every structure from R,
//! and free-run simulation (one structure at a time vs. side by side in SIMD lanes).
//!
//! `cargo bench --bench sweep` (sizes are smaller than `benches/sweep_vs_numpy.py`, which prints
//! the ratios against numpy baselines at 200,000 samples).

use std::hint::black_box;

use arxid::arx::reduce::reduce;
use arxid::arx::structure::usable_rows;
use arxid::simulate::lanes::{free_run_rms_lanes, input_columns, LANES};
use arxid::simulate::score::free_run_rms_linear;
use arxid::sweep::least_squares::{envelope, sweep, SweepOptions};
use arxid::{Data, Structure};
use criterion::{criterion_group, criterion_main, Criterion};

fn data(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut s = seed;
    let mut rnd = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let u: Vec<f64> = (0..n).map(|_| rnd()).collect();
    let mut y = vec![0.0; n];
    for t in 4..n {
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u[t - 3] + 0.25 * u[t - 4] + 0.05 * rnd();
    }
    (y, u)
}

fn grid(na: usize, nb: usize, nk: usize) -> Vec<Structure> {
    let mut g = Vec::new();
    for a in 1..=na {
        for b in 1..=nb {
            for k in 0..=nk {
                g.push(Structure::new(a, vec![b], vec![k], vec![]).unwrap());
            }
        }
    }
    g
}

fn benches(c: &mut Criterion) {
    let n = 50_000;
    let (y, u) = data(n, 1);
    let (yv, uv) = data(n, 2);
    let starts = [0];
    let d = Data::new(&y, &u, 1, &starts).unwrap();
    let v = Data::new(&yv, &uv, 1, &starts).unwrap();
    let g = grid(10, 10, 10);
    let env = envelope(&g).unwrap();
    let lag = env.max_lag();
    let (rows, _) = usable_rows(&d, &env, lag);

    let mut grp = c.benchmark_group("sweep_50k");
    grp.sample_size(10);
    grp.bench_function("tsqr_reduce_envelope", |b| b.iter(|| black_box(reduce(&d, &env, &rows, true))));
    let fit_only = SweepOptions { simulate_estimation: false, horizon: None, parallel: true, chunk: 64, top: None };
    grp.bench_function("fit_1100_structures", |b| {
        b.iter(|| black_box(sweep(&d, None, &g, &fit_only, &|_| {}).unwrap()))
    });
    grp.bench_function("fit_and_simulate_1100_structures", |b| {
        b.iter(|| black_box(sweep(&d, Some(&v), &g, &fit_only, &|_| {}).unwrap()))
    });

    // Eight structures with na = 4: one at a time vs. side by side.
    let eight: Vec<Structure> = (0..LANES).map(|k| Structure::new(4, vec![3], vec![k], vec![]).unwrap()).collect();
    let theta = [-1.5, 0.7, 0.01, -0.001, 0.5, 0.25, 0.01];
    let models: Vec<(&Structure, &[f64])> = eight.iter().map(|s| (s, &theta[..])).collect();
    let ucol = input_columns(&v);
    grp.bench_function("simulate_8_one_at_a_time", |b| {
        let mut fir = Vec::new();
        b.iter(|| {
            for (s, th) in &models {
                black_box(free_run_rms_linear(&v, s, th, lag, 1e6, &mut fir));
            }
        })
    });
    grp.bench_function("simulate_8_in_lanes", |b| {
        b.iter(|| black_box(free_run_rms_lanes(&v, &ucol, &models, lag, 1e6)))
    });
    grp.finish();
}

criterion_group!(sweep_benches, benches);
criterion_main!(sweep_benches);
