//! Forward kinematics of a bone forest (libigl's `forward_kinematics` convention).
//!
//! Bone `b` runs from joint `BE[b, 0]` to joint `BE[b, 1]` (directed parent -> child). Its
//! parent bone is the bone ending where `b` starts. Each bone carries a relative rotation `dQ_b`
//! about its rest start joint `r_b = C[BE[b, 0]]`; the absolute transform composes parent first:
//! `T_b = T_parent(b) o (x -> dQ_b (x - r_b) + r_b)`, i.e. `Q_b = Q_p dQ_b` and
//! `t_b = t_p + Q_p r_b - Q_b r_b`.

use std::collections::HashMap;

use ndarray::{Array3, ArrayView2};

use super::quat::{mul, norm, rotate, to_matrix, Quat};
use crate::error::SkinResult;
use crate::invalid;

/// Largest accepted `| |q| - 1 |` for an input rotation; within it `q` is normalised.
pub const UNIT_TOL: f64 = 1e-3;

/// Parent bone of each bone from directed edges.
///
/// Inputs: `be (m, 2)` directed bone edges (parent joint -> child joint), `n_joints` the number
/// of joints. Output: `parent[b]`, `None` for a root. Errors when a joint ends two bones (not a
/// forest), on a bone from a joint to itself, or on a cycle.
pub fn bone_parents(be: ArrayView2<'_, usize>, n_joints: usize) -> SkinResult<Vec<Option<usize>>> {
    if be.ncols() != 2 {
        return invalid!("BE must have 2 columns, got shape {:?}", be.dim());
    }
    let m = be.nrows();
    // Keyed by joint: memory follows the bones, not `n_joints` (which the caller chooses).
    let mut ends_at: HashMap<usize, usize> = HashMap::with_capacity(m);
    for b in 0..m {
        let (s, e) = (be[[b, 0]], be[[b, 1]]);
        if s >= n_joints || e >= n_joints {
            return invalid!("BE row {b} = [{s}, {e}] references a joint outside 0..{n_joints}");
        }
        if s == e {
            return invalid!("BE row {b} joins joint {s} to itself");
        }
        if let Some(&other) = ends_at.get(&e) {
            return invalid!(
                "joint {e} is the child end of bones {other} and {b}: a skeleton tree gives each \
                 joint at most one parent bone (check the edge directions of BE)"
            );
        }
        ends_at.insert(e, b);
    }
    let parent: Vec<Option<usize>> = (0..m).map(|b| ends_at.get(&be[[b, 0]]).copied()).collect();
    // Walk each parent chain once (linear in m): meeting a bone of the current walk is a cycle.
    const NEW: u8 = 0;
    const WALKING: u8 = 1;
    const DONE: u8 = 2;
    let mut state = vec![NEW; m];
    let mut walk = Vec::new();
    for b0 in 0..m {
        let mut b = Some(b0);
        while let Some(q) = b {
            match state[q] {
                DONE => break,
                WALKING => {
                    return invalid!(
                        "BE has a cycle through bone {q}; bones must form a tree or forest"
                    )
                }
                _ => {
                    state[q] = WALKING;
                    walk.push(q);
                    b = parent[q];
                }
            }
        }
        for q in walk.drain(..) {
            state[q] = DONE;
        }
    }
    Ok(parent)
}

/// Forward kinematics: absolute bone transforms from relative rotations.
///
/// Inputs:
/// * `c`  `(n, 3)` rest joint positions
/// * `be` `(m, 2)` directed bone edges (see [`bone_parents`])
/// * `q`  `(m, 4)` relative rotations as unit quaternions `(w, x, y, z)`, about each bone's rest
///   start joint; normalised when within [`UNIT_TOL`] of unit length, an error otherwise
///
/// Output: `(m, 3, 4)` transforms `[R | t]` (`x -> R x + t`), ready for LBS/DQS. The identity
/// pose gives exactly `[I | 0]`.
pub fn forward_kinematics(
    c: ArrayView2<'_, f64>,
    be: ArrayView2<'_, usize>,
    q: ArrayView2<'_, f64>,
) -> SkinResult<Array3<f64>> {
    if c.ncols() != 3 {
        return invalid!("C must have shape (n, 3), got {:?}", c.dim());
    }
    if c.iter().any(|x| !x.is_finite()) {
        return invalid!("C has a NaN or infinite entry");
    }
    let m = be.nrows();
    if q.dim() != (m, 4) {
        return invalid!(
            "Q has shape {:?}, expected ({m}, 4): one quaternion (w, x, y, z) per bone",
            q.dim()
        );
    }
    let parent = bone_parents(be, c.nrows())?;
    let mut dq: Vec<Quat> = Vec::with_capacity(m);
    for b in 0..m {
        let qb = [q[[b, 0]], q[[b, 1]], q[[b, 2]], q[[b, 3]]];
        let len = norm(&qb);
        if !len.is_finite() || (len - 1.0).abs() > UNIT_TOL {
            return invalid!(
                "Q row {b} = {qb:?} is not a unit quaternion (norm {len}); rotations must be unit \
                 quaternions (w, x, y, z)"
            );
        }
        dq.push(if len == 1.0 {
            qb
        } else {
            [qb[0] / len, qb[1] / len, qb[2] / len, qb[3] / len]
        });
    }

    // Memoised parent-first evaluation (the parent chains are acyclic, checked above).
    let mut abs: Vec<Option<(Quat, [f64; 3])>> = vec![None; m];
    let mut stack = Vec::new();
    for b0 in 0..m {
        let mut b = b0;
        while abs[b].is_none() {
            stack.push(b);
            match parent[b] {
                Some(p) => b = p,
                None => break,
            }
        }
        while let Some(b) = stack.pop() {
            let j = be[[b, 0]];
            let r = [c[[j, 0]], c[[j, 1]], c[[j, 2]]];
            let (qp, tp) = parent[b]
                .and_then(|p| abs[p])
                .unwrap_or(([1.0, 0.0, 0.0, 0.0], [0.0; 3]));
            let qb = mul(&qp, &dq[b]);
            let (a, bb) = (rotate(&qp, &r), rotate(&qb, &r));
            let tb = [
                tp[0] + (a[0] - bb[0]),
                tp[1] + (a[1] - bb[1]),
                tp[2] + (a[2] - bb[2]),
            ];
            abs[b] = Some((qb, tb));
        }
    }

    let mut t = Array3::<f64>::zeros((m, 3, 4));
    for (b, st) in abs.iter().enumerate() {
        let Some((qb, tb)) = st else {
            return Err(crate::SkinError::Numerical(format!(
                "internal: bone {b} not evaluated"
            )));
        };
        let r = to_matrix(qb);
        for a in 0..3 {
            for k in 0..3 {
                t[[b, a, k]] = r[a][k];
            }
            t[[b, a, 3]] = tb[a];
        }
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn identity_pose_is_rest() {
        let c = array![
            [0.1, 0.2, 0.3],
            [1.0, 0.5, -0.2],
            [2.0, 1.0, 0.0],
            [1.0, -1.0, 0.7]
        ];
        let be = array![[0usize, 1], [1, 2], [1, 3]];
        let q = array![
            [1.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0]
        ];
        let t = forward_kinematics(c.view(), be.view(), q.view()).unwrap();
        for b in 0..3 {
            for a in 0..3 {
                for k in 0..4 {
                    assert_eq!(t[[b, a, k]], if a == k { 1.0 } else { 0.0 });
                }
            }
        }
    }

    #[test]
    fn forest_cycles_and_two_parents() {
        let be = array![[0usize, 1], [2, 3]];
        assert_eq!(bone_parents(be.view(), 4).unwrap(), vec![None, None]);
        let be = array![[0usize, 1], [1, 0]];
        assert!(bone_parents(be.view(), 2).is_err());
        let be = array![[0usize, 2], [1, 2]];
        assert!(bone_parents(be.view(), 3).is_err());
        let be = array![[2usize, 3], [0, 1], [1, 2]];
        assert_eq!(
            bone_parents(be.view(), 4).unwrap(),
            vec![Some(2), None, Some(1)]
        );
    }
}
