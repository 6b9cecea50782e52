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
use std::collections::HashMap;

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
pub fn duplicate_elements(mesh: &LinearMesh) -> Vec<(u32, u32)> {
    let npe = mesh.nodes_per_element();
    let ne = mesh.n_elements();
    let mut seen: HashMap<Vec<u32>, u32> = HashMap::with_capacity(ne);
    let mut pairs = Vec::new();
    for e in 0..ne {
        let mut key = mesh.elements[e * npe..(e + 1) * npe].to_vec();
        key.sort_unstable();
        if let Some(&first) = seen.get(&key) {
            pairs.push((first, e as u32));
        } else {
            seen.insert(key, e as u32);
        }
    }
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
