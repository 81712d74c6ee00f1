//! Grid queries against brute force, with the dense array, the hash map and the linear scan.

use super::*;
use crate::field::{norm2, sub};

fn cloud(n: usize, seed: u64) -> ndarray::Array2<f64> {
    let mut s = seed;
    ndarray::Array2::from_shape_fn((n, 3), |(_, k)| {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let u = (s >> 11) as f64 / (1u64 << 53) as f64;
        if k == 2 {
            0.1 * u
        } else {
            u
        }
    })
}

fn check_against_brute_force(x: &ndarray::Array2<f64>, g: &HashGrid<3>, r: f64) {
    let n = x.nrows();
    let pts: Vec<[f64; 3]> = (0..n).map(|i| row(&x.view(), i)).collect();
    for qi in [0usize, 17, 123, n - 1] {
        let q = pts[qi];
        let mut d: Vec<(f64, usize)> = pts
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != qi)
            .map(|(i, p)| (norm2(&sub(p, &q)).sqrt(), i))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let got = g.knn(&q, 9, Some(qi));
        assert_eq!(got.len(), 9);
        for (a, b) in got.iter().zip(&d) {
            assert_eq!(a.1, b.1);
            assert!((a.0 - b.0).abs() < 1e-15);
        }
        let mut got = Vec::new();
        g.radius(&q, r, &mut got);
        got.sort();
        let want: Vec<usize> = (0..n)
            .filter(|&i| norm2(&sub(&pts[i], &q)) <= r * r)
            .collect();
        assert_eq!(got, want);
    }
}

#[test]
fn radius_and_knn_match_brute_force() {
    // Dense cell array.
    let x = cloud(500, 7);
    let g = HashGrid::<3>::auto(x.view(), 3.0).unwrap();
    assert!(g.dense.is_some());
    check_against_brute_force(&x, &g, 0.12);
    // Two clusters far apart: the occupied key box is huge, so the hash map is used.
    let mut y = cloud(400, 11);
    for i in 200..400 {
        for k in 0..3 {
            y[[i, k]] += 1000.0;
        }
    }
    let g = HashGrid::<3>::new(y.view(), 0.05).unwrap();
    assert!(g.dense.is_none());
    check_against_brute_force(&y, &g, 0.12);
    let g = HashGrid::<3>::auto(y.view(), 4.0).unwrap();
    check_against_brute_force(&y, &g, 30.0);
    let kd = knn_distance(x.view(), 9, &mut crate::Silent).unwrap();
    assert_eq!(kd.len(), 500);
    assert!(kd.iter().all(|&v| v > 0.0));
    assert!(knn_distance(x.view(), 500, &mut crate::Silent).is_err());
}

#[test]
fn far_outlier_falls_back_to_a_linear_scan() {
    let mut x = cloud(400, 7);
    x[[0, 0]] = 1e6;
    let g = HashGrid::<3>::auto(x.view(), 4.5).unwrap();
    check_against_brute_force(&x, &g, 0.3);
    let q = [1e9, 0.5, 0.5];
    let near = g.knn(&q, 3, None);
    assert_eq!(near[0].1, 0);
    assert_eq!(near.len(), 3);
}
