//! Exact recovery on noise-free data: Markov parameters, D, the initial state and the order.

use std::sync::atomic::AtomicBool;

use faer::Mat;

use super::input_matrices::{input_matrices, Unknowns};
use super::response::{respond, StateSpaceRef};
use super::*;

fn noise(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
}

struct Truth {
    a: Mat<f64>,
    b: Mat<f64>,
    c: Mat<f64>,
    d: Mat<f64>,
}

fn truth() -> Truth {
    Truth {
        a: faer::mat![[0.8, 0.3, 0.0], [-0.3, 0.8, 0.0], [0.0, 0.0, 0.5]],
        b: faer::mat![[1.0, 0.0], [0.0, 0.5], [0.7, -1.0]],
        c: faer::mat![[1.0, 0.0, 1.0], [0.0, 2.0, -0.5]],
        d: faer::mat![[0.1, 0.0], [0.0, -0.2]],
    }
}

fn markov(a: &Mat<f64>, b: &Mat<f64>, c: &Mat<f64>, k: usize) -> Mat<f64> {
    let mut p = b.clone();
    for _ in 0..k {
        p = a * &p;
    }
    c * p
}

fn data(t: &Truth, n: usize, x0: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut seed = 7;
    let u: Vec<f64> = (0..2 * n).map(|_| if noise(&mut seed) > 0.0 { 1.0 } else { -1.0 }).collect();
    let m = StateSpaceRef { a: t.a.as_ref(), b: t.b.as_ref(), c: t.c.as_ref(), d: t.d.as_ref() };
    let (y, _) = respond(m, x0, &u, &AtomicBool::new(false)).unwrap();
    (u, y)
}

#[test]
fn every_weighting_recovers_the_markov_parameters_and_the_order_of_exact_data() {
    let t = truth();
    let x0 = [3.0, -2.0, 1.0];
    let (u, y) = data(&t, 2000, &x0);
    let segments = [(0, 2000)];
    let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &segments };
    let never = AtomicBool::new(false);
    for weighting in [Weighting::N4sid, Weighting::Moesp, Weighting::Cva] {
        let options =
            SubspaceOptions { horizons: Horizons { past: 6, future: 6 }, weighting, order: None, max_order: 8 };
        let id = identify(&s, options, true, &never).unwrap();
        assert_eq!(id.order, 3, "{weighting:?}: {:?}", id.canonical_correlations);
        let unknowns = Unknowns { feedthrough: true, initial_state: true };
        let fit = input_matrices(id.a.as_ref(), id.c.as_ref(), &s, unknowns, &never).unwrap();
        for k in 0..6 {
            let (want, got) = (markov(&t.a, &t.b, &t.c, k), markov(&id.a, &fit.b, &id.c, k));
            for i in 0..2 {
                for j in 0..2 {
                    assert!((want[(i, j)] - got[(i, j)]).abs() < 1e-8, "{weighting:?} k={k}");
                    assert!((t.d[(i, j)] - fit.d[(i, j)]).abs() < 1e-8);
                }
            }
        }
        // The initial state lives in the model's own coordinates: compare its free response C Aᵗ x0.
        for k in 0..5 {
            let mut want = Mat::from_fn(3, 1, |i, _| x0[i]);
            let mut got = Mat::from_fn(3, 1, |i, _| fit.x0[0][i]);
            for _ in 0..k {
                want = &t.a * &want;
                got = &id.a * &got;
            }
            let (want, got) = (&t.c * want, &id.c * got);
            assert!((want[(0, 0)] - got[(0, 0)]).abs() < 1e-8 && (want[(1, 0)] - got[(1, 0)]).abs() < 1e-8);
        }
    }
}

#[test]
fn several_segments_each_get_their_own_initial_state() {
    let t = truth();
    let (u1, y1) = data(&t, 500, &[1.0, 0.0, 0.0]);
    let (u2, y2) = data(&t, 400, &[0.0, -4.0, 2.0]);
    let u: Vec<f64> = u1.iter().chain(&u2).copied().collect();
    let y: Vec<f64> = y1.iter().chain(&y2).copied().collect();
    let segments = [(0, 500), (500, 900)];
    let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &segments };
    let never = AtomicBool::new(false);
    let options = SubspaceOptions {
        horizons: Horizons { past: 5, future: 5 },
        weighting: Weighting::Moesp,
        order: Some(3),
        max_order: 8,
    };
    let id = identify(&s, options, false, &never).unwrap();
    let fit =
        input_matrices(id.a.as_ref(), id.c.as_ref(), &s, Unknowns { feedthrough: true, initial_state: true }, &never)
            .unwrap();
    assert_eq!(fit.x0.len(), 2);
    let m = StateSpaceRef { a: id.a.as_ref(), b: fit.b.as_ref(), c: id.c.as_ref(), d: fit.d.as_ref() };
    let (sim, _) = respond(m, &fit.x0[1], &u2, &never).unwrap();
    assert!(sim.iter().zip(&y2).all(|(a, b)| (a - b).abs() < 1e-8));
}

#[test]
fn bad_requests_are_errors() {
    let t = truth();
    let (u, mut y) = data(&t, 300, &[0.0; 3]);
    let segments = [(0, 300)];
    let never = AtomicBool::new(false);
    let options = |order| SubspaceOptions {
        horizons: Horizons { past: 4, future: 4 },
        weighting: Weighting::Cva,
        order,
        max_order: 8,
    };
    let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &segments };
    assert!(matches!(identify(&s, options(Some(7)), false, &never), Err(ArxError::InvalidStructure(_))));
    let short = [(0, 10)];
    let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &short };
    assert!(matches!(identify(&s, options(Some(2)), false, &never), Err(ArxError::TooFewSamples { .. })));
    y[5] = f64::NAN;
    let s = Signals { u: &u, y: &y, n_inputs: 2, n_outputs: 2, segments: &segments };
    assert!(matches!(identify(&s, options(Some(2)), false, &never), Err(ArxError::InvalidStructure(_))));
    assert!(Weighting::parse("pca").is_err());
}
