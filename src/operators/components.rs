//! Connected components of the vertex graph of a mesh.

use ndarray::ArrayView2;

/// Connected components of the vertices, two vertices being connected when they share an
/// element (union-find over the rows of `f`).
///
/// Inputs:
///   n  number of vertices
///   f  #F by s element list (any s >= 1; edges, triangles, tets ...), entries in `0..n`
/// Outputs:
///   (count, labels): the number of components and a label in `0..count` per vertex. Labels
///   are numbered in order of each component's smallest vertex (as
///   `scipy.sparse.csgraph.connected_components` does); a vertex referenced by no element is a
///   component of its own.
///
/// Panics if an entry of `f` is `>= n`; callers validate indices first (`check_elements`, or the
/// Python layer's index checks).
pub fn connected_components(n: usize, f: ArrayView2<usize>) -> (usize, Vec<usize>) {
    let mut parent: Vec<usize> = (0..n).collect();
    let mut size = vec![1usize; n];
    for row in f.rows() {
        let mut it = row.iter();
        let Some(&first) = it.next() else { continue };
        for &other in it {
            union(&mut parent, &mut size, first, other);
        }
    }
    let mut label = vec![usize::MAX; n];
    let mut out = vec![0usize; n];
    let mut count = 0;
    for (i, o) in out.iter_mut().enumerate() {
        let r = find(&mut parent, i);
        if label[r] == usize::MAX {
            label[r] = count;
            count += 1;
        }
        *o = label[r];
    }
    (count, out)
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]]; // path halving
        i = parent[i];
    }
    i
}

fn union(parent: &mut [usize], size: &mut [usize], a: usize, b: usize) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra == rb {
        return;
    }
    let (big, small) = if size[ra] >= size[rb] {
        (ra, rb)
    } else {
        (rb, ra)
    };
    parent[small] = big;
    size[big] += size[small];
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn two_triangles_and_an_isolated_vertex() {
        let f = array![[4usize, 5, 6], [0, 2, 3], [6, 7, 4]];
        let (count, labels) = connected_components(8, f.view());
        assert_eq!(count, 3);
        assert_eq!(labels, vec![0, 1, 0, 0, 2, 2, 2, 2]);
        let (count, labels) = connected_components(3, ndarray::Array2::zeros((0, 3)).view());
        assert_eq!((count, labels), (3, vec![0, 1, 2]));
    }
}
