//! Rough timing of the LBS kernels without Python (development aid):
//! `cargo run --release --example lbs_timing`.
use ndarray::{Array2, Array3};
use std::time::Instant;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1_000_000);
    let reps: usize = std::env::args()
        .nth(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10);
    let m = 16;
    let k = 4;
    let v = Array2::<f64>::from_shape_fn((n, 3), |(i, j)| ((i * 3 + j) as f64).sin());
    let w = Array2::<f64>::from_shape_fn((n, m), |(i, j)| ((i * 7 + j) as f64).cos().abs());
    let idx = Array2::<i64>::from_shape_fn((n, k), |(i, j)| ((i * 5 + j * 3) % m) as i64);
    let wk = Array2::<f64>::from_shape_fn((n, k), |(i, j)| ((i * 7 + j) as f64).cos().abs());
    let t =
        Array3::<f64>::from_shape_fn((m, 3, 4), |(a, b, c)| ((a * 12 + b * 4 + c) as f64).sin());
    let dense = skinrs_weights_dense(&w);
    let packed = _skinrs::skin::Weights::Packed {
        index: idx.view(),
        weight: wk.view(),
    };
    let mut u = Array2::<f64>::zeros((n, 3));
    for (name, wts) in [("dense", dense), ("packed", packed)] {
        let mut best = f64::INFINITY;
        for _ in 0..reps {
            let t0 = Instant::now();
            _skinrs::skin::lbs_into(v.view(), &wts, t.view(), None, u.view_mut(), None).unwrap();
            best = best.min(t0.elapsed().as_secs_f64());
        }
        println!(
            "{name}: {:.2} ms ({:.1} ns/vertex)",
            best * 1e3,
            best / n as f64 * 1e9
        );
    }
}

fn skinrs_weights_dense(w: &Array2<f64>) -> _skinrs::skin::Weights<'_> {
    _skinrs::skin::Weights::Dense(w.view())
}
