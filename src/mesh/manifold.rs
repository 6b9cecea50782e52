//! Whether a checked linear mesh can be curved: the topological preconditions of `curve`.
//!
//! Input: a [`LinearMesh`] and its [`Topology`]. Output: `Ok(())`, or one line naming the
//! problem and the first elements involved (0-based, as `info` and the report count them).
//!
//! Refused (each can be listed by `info`, none has a well-defined spline space):
//! * duplicated elements (two elements on the same vertex set, in any order);
//! * facets shared by more than two elements;
//! * 3D boundary edges on other than two boundary faces, and vertices whose elements do not
//!   form one fan (2D: boundary vertices without exactly two boundary edges);
//! * a mesh without boundary facets (a doubled mesh, each element glued to its twin).

use super::{LinearMesh, Topology};

/// How many elements a message names at most.
const NAMED: usize = 6;

fn list(elements: impl IntoIterator<Item = u32>) -> String {
    let mut all: Vec<u32> = elements.into_iter().collect();
    all.sort_unstable();
    all.dedup();
    let mut s = all
        .iter()
        .take(NAMED)
        .map(|e| e.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    if all.len() > NAMED {
        s.push_str(&format!(", … ({} in all)", all.len()));
    }
    s
}

/// Elements that have every vertex of `vs`.
fn elements_with(mesh: &LinearMesh, topo: &Topology, vs: &[u32]) -> Vec<u32> {
    let npe = mesh.nodes_per_element();
    topo.elements_at_vertex(vs[0] as usize)
        .iter()
        .copied()
        .filter(|&e| {
            let el = &mesh.elements[e as usize * npe..(e as usize + 1) * npe];
            vs.iter().all(|v| el.contains(v))
        })
        .collect()
}

/// Elements on the vertex set of an earlier element: (earlier, later) pairs in element order.
///
/// Each element's sorted vertices (padded to 8 with `u32::MAX`) are sorted with the element
/// ids in parallel; a run of equal keys is one vertex set, its first element the earlier one
/// of each pair. No per-element allocation or hash map: at a million hexes this check ran
/// serially for a good part of the topology stage.
pub fn duplicate_elements(mesh: &LinearMesh) -> Vec<(u32, u32)> {
    use rayon::prelude::*;
    let npe = mesh.nodes_per_element();
    let ne = mesh.n_elements();
    let mut keyed: Vec<([u32; 8], u32)> = (0..ne)
        .into_par_iter()
        .map(|e| {
            let mut key = [u32::MAX; 8];
            key[..npe].copy_from_slice(&mesh.elements[e * npe..(e + 1) * npe]);
            key[..npe].sort_unstable();
            (key, e as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    let mut pairs: Vec<(u32, u32)> = keyed
        .par_iter()
        .enumerate()
        .filter(|&(i, (key, _))| i > 0 && keyed[i - 1].0 == *key)
        .map(|(i, &(key, e))| {
            // The run's first entry: its smallest element (entries sort by key, then id).
            let first = keyed[..i].partition_point(|(k, _)| *k < key);
            (keyed[first].1, e)
        })
        .collect();
    pairs.par_sort_unstable_by_key(|&(_, e)| e);
    pairs
}

/// Refuse what `curve` cannot treat (see the module documentation).
pub fn check_curvable(mesh: &LinearMesh, topo: &Topology) -> Result<(), String> {
    let ne = mesh.n_elements();
    // Duplicates first: they also make every shared facet look interior or non-manifold.
    let pairs = duplicate_elements(mesh);
    if !pairs.is_empty() {
        let shown: Vec<String> = pairs
            .iter()
            .take(NAMED)
            .map(|(a, b)| format!("{b} duplicates {a}"))
            .collect();
        return Err(format!(
            "{} duplicated element{} (same vertices as an earlier one): element {}",
            pairs.len(),
            if pairs.len() == 1 { "" } else { "s" },
            shown.join(", ")
        ));
    }
    let nm = &topo.non_manifold;
    if !nm.facets.is_empty() {
        let facet_vertices = |f: u32| -> Vec<u32> {
            if topo.dim == 2 {
                topo.edges[f as usize].to_vec()
            } else {
                topo.faces[f as usize].to_vec()
            }
        };
        let elements = nm
            .facets
            .iter()
            .flat_map(|&f| elements_with(mesh, topo, &facet_vertices(f)));
        return Err(format!(
            "{} {} shared by more than two elements (non-manifold): elements {}",
            nm.facets.len(),
            if topo.dim == 2 { "edge(s)" } else { "face(s)" },
            list(elements)
        ));
    }
    if !nm.edges.is_empty() {
        let elements = nm
            .edges
            .iter()
            .flat_map(|&e| elements_with(mesh, topo, &topo.edges[e as usize]));
        return Err(format!(
            "{} boundary edge(s) on other than two boundary faces (non-manifold): elements {}",
            nm.edges.len(),
            list(elements)
        ));
    }
    if !nm.vertices.is_empty() {
        let elements = nm
            .vertices
            .iter()
            .flat_map(|&v| topo.elements_at_vertex(v as usize).iter().copied());
        return Err(format!(
            "{} non-manifold vertex(es) (elements around them not one fan{}): vertex {}; elements {}",
            nm.vertices.len(),
            if topo.dim == 2 {
                ", or a boundary vertex without exactly two boundary edges"
            } else {
                ""
            },
            nm.vertices
                .iter()
                .take(NAMED)
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            list(elements)
        ));
    }
    if topo.boundary_facets.is_empty() && ne > 0 {
        return Err(
            "the mesh has no boundary (every facet is shared by two elements, e.g. a doubled mesh); a quad or hex mesh to curve must bound a region"
                .into(),
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pairwise comparison of the sorted vertex sets (quadratic: the oracle).
    fn brute_force(mesh: &LinearMesh) -> Vec<(u32, u32)> {
        let npe = mesh.nodes_per_element();
        let set = |e: usize| {
            let mut v = mesh.elements[e * npe..(e + 1) * npe].to_vec();
            v.sort_unstable();
            v
        };
        let mut pairs = Vec::new();
        for e in 0..mesh.n_elements() {
            if let Some(first) = (0..e).find(|&f| set(f) == set(e)) {
                pairs.push((first as u32, e as u32));
            }
        }
        pairs
    }

    #[test]
    fn duplicates_pair_each_later_element_with_the_first_on_its_vertex_set() {
        // Hexes on pseudo-random vertex sets of few vertices (so that sets repeat), each in a
        // rotated order; a set three times, and one vertex repeated within an element.
        let mut elements = Vec::new();
        let mut x = 7u32;
        for e in 0..400u32 {
            let mut el: Vec<u32> = (0..8)
                .map(|_| {
                    x = x.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                    (x >> 16) % 11
                })
                .collect();
            el.rotate_left(e as usize % 8);
            elements.extend(el);
        }
        let first: Vec<u32> = elements[..8].to_vec();
        for r in [3, 5] {
            let mut el = first.clone();
            el.rotate_left(r);
            elements.extend(el);
        }
        elements.extend([1, 1, 2, 3, 4, 5, 6, 7, 7, 6, 5, 4, 3, 2, 1, 1]);
        let mesh = LinearMesh {
            dim: 3,
            coords: vec![[0.0; 3]; 11],
            elements,
            ..Default::default()
        };
        let want = brute_force(&mesh);
        assert!(want.len() >= 3, "the test mesh has duplicates: {want:?}");
        assert!(want.contains(&(0, 400)) && want.contains(&(0, 401)));
        assert_eq!(duplicate_elements(&mesh), want);
        // Quads: two distinct, then the first again reversed.
        let quads = LinearMesh {
            dim: 2,
            coords: vec![[0.0; 3]; 6],
            elements: vec![0, 1, 2, 3, 1, 4, 5, 2, 3, 2, 1, 0],
            ..Default::default()
        };
        assert_eq!(duplicate_elements(&quads), vec![(0, 2)]);
    }
}
