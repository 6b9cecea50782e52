//! Kinks of the boundary grid lines: where a C¹ spline cannot follow the input's parametrisation.
//!
//! A spline element is C¹ across its facets, so along a smooth boundary it can follow the
//! input's vertices only where the boundary grid lines themselves are smooth. Block-structured
//! meshes break this: on a cubed sphere the grid lines crossing the 12 block arcs turn by up to
//! 55° within the surface there, although the surface is smooth. A C¹ map cannot reproduce such
//! a C⁰ parametrisation and keeps an O(h²) error along the whole arc, however good the fit's
//! targets are. The elements touching such vertices are made constrained Q2 elements
//! ([`super::Q2Reason::BoundaryKink`]), which are only C⁰ there.
//!
//! Input: a hex mesh, its topology, the kink angle and a per-vertex `exclude` mask (vertices
//! left to other handling, e.g. sharp features). Output: [`Kinks`], a per-vertex mask and the
//! set of elements touching a marked vertex. 2D meshes have no kinks (the boundary is a single
//! grid line; a corner of it is a sharp feature).
//!
//! At a regular boundary vertex v (four boundary faces, so two grid lines a–v–b cross there)
//! the **geodesic turning** of a line is the signed angle between v − a and b − v after both
//! are projected onto the tangent plane of v (outward normal). A line kinks at v when
//! * its turning at v differs by more than the vertex's threshold from its turning at each of
//!   its two neighbours on the line that have one, and is the largest in magnitude of them (a
//!   peak: a polar grid with equal turning at every vertex has no kink), or
//! * the edge lengths on either side of v differ by more than [`SPACING_RATIO`].
//!
//! The threshold scales with the mesh: it is the larger **normal turning** ν of v's two lines
//! (the change of their elevation over the tangent plane, ≈ curvature × edge length), kept
//! between [`MIN_KINK_ANGLE_DEG`] and the kink angle. A kink of turning jump δ left to a C¹
//! element displaces the map within the surface by O(δh), which moves the surface off by
//! O(κδh²); with δ ≤ ν = O(κh) that is O(h³), so the fit keeps third order where a fixed angle
//! leaves a fixed length of each kinked curve C¹ and falls back to second order (the cubed
//! sphere's block arcs, whose turning jump grows from 0 at an arc's middle).
//!
//! Regular vertices that share a boundary face with an **irregular boundary vertex** (not four
//! boundary faces, e.g. a cubed sphere's eight corners) count as kinks too: the spline
//! element diagonal to such a vertex stays at second order otherwise (measured on the cubed
//! sphere: 4.0e-5, 1.6e-5, 9.3e-6 at 16, 24, 32 cube divisions).
//!
//! Vertices inside planar boundary patches are never kinks: a planar patch is reproduced
//! exactly by any map that keeps its vertices in the plane, whatever its grid lines do.

use crate::math::linalg::{DVec3, unit};
use crate::mesh::topology::NONE;
use crate::mesh::{LinearMesh, Topology};

/// Edge-length ratio along a grid line above which its vertex is a kink.
pub const SPACING_RATIO: f64 = 2.5;

/// Smallest kink threshold (degrees): turning jumps below it are noise on nearly flat patches,
/// where a kink moves the surface by little.
pub const MIN_KINK_ANGLE_DEG: f64 = 1.0;

/// Relative distance from the vertex's tangent plane (to its fan's size) below which every
/// vertex of a fan counts as coplanar.
const PLANAR_TOLERANCE: f64 = 1e-6;

/// The kinks found.
#[derive(Clone, Debug, Default)]
pub struct Kinks {
    /// Per vertex: a boundary grid line kinks there.
    pub vertices: Vec<bool>,
    /// Per element: it touches a kink vertex.
    pub elements: Vec<bool>,
    pub n_vertices: usize,
    pub n_elements: usize,
}

/// The boundary fan of a regular vertex: its outward unit normal and the two grid lines
/// through it, each as (vertex before, vertex after).
#[derive(Clone, Copy, Debug)]
struct Fan {
    normal: DVec3,
    lines: [[u32; 2]; 2],
    planar: bool,
}

/// Find the kinks of the boundary grid lines of `mesh` (see the module docs). `angle_deg` is
/// the largest threshold (degrees) on the jump of the geodesic turning; `exclude` (per vertex,
/// or empty) marks vertices that are never kinks and whose turning is not compared against.
pub fn detect(mesh: &LinearMesh, topo: &Topology, angle_deg: f64, exclude: &[bool]) -> Kinks {
    let nv = mesh.n_vertices();
    let mut kinks = Kinks {
        vertices: vec![false; nv],
        elements: vec![false; mesh.n_elements()],
        ..Default::default()
    };
    if topo.dim != 3 || angle_deg.is_nan() || angle_deg >= 180.0 {
        return kinks;
    }
    let fans = regular_fans(mesh, topo);
    let excluded = |v: usize| exclude.get(v).copied().unwrap_or(false);
    let x = |v: u32| DVec3::from_array(mesh.coords[v as usize]);
    // Turning of the line through `v` that arrives from `a` and leaves to `b`.
    let turning = |v: usize, a: u32, b: u32| -> f64 {
        let n = fans[v].as_ref().unwrap().normal;
        let xv = DVec3::from_array(mesh.coords[v]);
        let d1 = tangential(xv - x(a), n);
        let d2 = tangential(x(b) - xv, n);
        n.dot(d1.cross(d2)).atan2(d1.dot(d2))
    };
    // Turning at `w` of its line that contains the edge w–`towards`, oriented to leave to it.
    let neighbour_turning = |w: u32, towards: u32, leaving: bool| -> Option<f64> {
        let w = w as usize;
        if excluded(w) {
            return None;
        }
        let fan = fans[w].as_ref()?;
        fan.lines.iter().find_map(|&[p, q]| {
            let (p, q) = match (leaving, p == towards, q == towards) {
                (true, _, true) | (false, true, _) => (p, q),
                (true, true, _) | (false, _, true) => (q, p),
                _ => return None,
            };
            Some(turning(w, p, q))
        })
    };
    let max_threshold = angle_deg.to_radians();
    let min_threshold = MIN_KINK_ANGLE_DEG.to_radians().min(max_threshold);
    for v in 0..nv {
        let Some(fan) = fans[v] else { continue };
        if excluded(v) || fan.planar {
            continue;
        }
        let xv = DVec3::from_array(mesh.coords[v]);
        // Normal turning of the line a–v–b: change of the edges' elevation over the tangent
        // plane.
        let elevation = |d: DVec3| fan.normal.dot(unit(d)).clamp(-1.0, 1.0).asin();
        let normal_turning = |[a, b]: [u32; 2]| (elevation(xv - x(a)) - elevation(x(b) - xv)).abs();
        let nu = normal_turning(fan.lines[0]).max(normal_turning(fan.lines[1]));
        let threshold = nu.clamp(min_threshold, max_threshold);
        for [a, b] in fan.lines {
            let (la, lb) = ((xv - x(a)).length(), (x(b) - xv).length());
            let spacing = la.max(lb) > SPACING_RATIO * la.min(lb);
            let kv = turning(v, a, b);
            let around = [
                neighbour_turning(a, v as u32, true),
                neighbour_turning(b, v as u32, false),
            ];
            let mut compared = 0;
            let mut peak = true;
            for k in around.into_iter().flatten() {
                compared += 1;
                peak &= (kv - k).abs() > threshold && kv.abs() >= k.abs();
            }
            if spacing || (compared > 0 && peak) {
                kinks.vertices[v] = true;
            }
        }
    }
    // Regular vertices next to an irregular boundary vertex.
    let faces_at = topo.boundary_facets_at_vertices();
    for (v, faces) in faces_at.iter().enumerate() {
        if faces.is_empty() || fans[v].is_some() || excluded(v) {
            continue;
        }
        for &f in faces {
            for &w in topo.facet_vertices(f as usize) {
                let w = w as usize;
                if fans[w].is_some_and(|fan| !fan.planar) && !excluded(w) {
                    kinks.vertices[w] = true;
                }
            }
        }
    }
    for v in 0..nv {
        if kinks.vertices[v] {
            kinks.n_vertices += 1;
            for &e in topo.elements_at_vertex(v) {
                kinks.elements[e as usize] = true;
            }
        }
    }
    kinks.n_elements = kinks.elements.iter().filter(|&&k| k).count();
    kinks
}

impl Kinks {}

/// Turning (degrees) of an interior grid line at a regular interior vertex above which the
/// elements at the vertex are made Q2 ([`interior_kink_elements`]) by the smooth fit's redo,
/// where it is asked for (`--interior-kink-angle 35`; off by default until the tests whose
/// premises it changes are re-measured: the automatic knots' single-pass, skip and warm-start
/// rules on small generated meshes, the post-fit Q2 choice on a structured airfoil O-grid;
/// on the test suite's torus it lowers the boundary error at every level, BENCHMARKS.md).
///
/// Chosen on the real meshes (`BENCHMARKS.md`, "Interior grid lines that turn sharply"): on
/// hsphere8 the lines turn by 47.8° one edge from the valence-3 line and by 36.7° two edges
/// from it, and both rings must be C⁰ (with only the first, 40–45°, the fit bends the next
/// ring and the blend holds back 22 %; with both, none); 30° also takes acoustics_mesh3d's and
/// cylinder-hex's smoothly curved lines.
pub const INTERIOR_KINK_ANGLE_DEG: f64 = 35.0;

/// The elements touching a regular interior vertex where an interior grid line turns by more
/// than `angle_deg` degrees: the angle between the line's two edges at the vertex, v − a and
/// b − v, for the opposite edges a–v and v–b (edges at v that share no element).
///
/// Why: a spline element is C¹ across its facets, so, as at the boundary's kinks, a grid line
/// that turns sharply at a regular vertex is one the spline cannot follow. Block-structured
/// shells are the case: in a cubed-sphere shell the lines crossing a block arc next to the
/// valence-3 line of a block corner turn by 48° at every shell layer (sfepy's hsphere8), and
/// the C¹ fit slides those elements' midpoints by a tenth of their shortest edge within the
/// layer, which the blend's quality rules reject. Made Q2, the elements at such vertices are
/// only C⁰ there and take the input's shape.
///
/// The rule reads the vertex's own elements only (every element at an interior vertex is in
/// each rank's mesh that holds one of them with its ghost ring), so it marks the same
/// elements on every process. Vertices on the boundary (a periodic seam's included) are not
/// interior vertices of `topo`; `angle_deg` ≥ 180 (or NaN) finds none.
pub fn interior_kink_elements(mesh: &LinearMesh, topo: &Topology, angle_deg: f64) -> Vec<bool> {
    use rayon::prelude::*;
    let ne = mesh.n_elements();
    if angle_deg.is_nan() || angle_deg >= 180.0 {
        return vec![false; ne];
    }
    let (full, edges_per) = if topo.dim == 3 { (8, 12) } else { (4, 4) };
    let cos_max = angle_deg.to_radians().cos();
    let x = |v: u32| DVec3::from_array(mesh.coords[v as usize]);
    let kinked: Vec<bool> = (0..mesh.n_vertices())
        .into_par_iter()
        .map(|v| {
            let at = topo.elements_at_vertex(v);
            if topo.vertex_on_boundary[v] || at.len() != full {
                return false;
            }
            // The edges at v, and per element its edges at v (3 in a hex, 2 in a quad).
            let mut ids: Vec<u32> = Vec::with_capacity(2 * topo.dim);
            let mut together: Vec<[usize; 3]> = Vec::with_capacity(full);
            for &e in at {
                let e = e as usize;
                let mut own = [usize::MAX; 3];
                let mut k = 0;
                for &id in &topo.element_edges[e * edges_per..(e + 1) * edges_per] {
                    if !topo.edges[id as usize].contains(&(v as u32)) {
                        continue;
                    }
                    let i = match ids.iter().position(|&d| d == id) {
                        Some(i) => i,
                        None => {
                            ids.push(id);
                            ids.len() - 1
                        }
                    };
                    if k < 3 {
                        own[k] = i;
                    }
                    k += 1;
                }
                if k != topo.dim {
                    return false;
                }
                together.push(own);
            }
            if ids.len() != 2 * topo.dim {
                return false;
            }
            let far = |id: u32| {
                let [a, b] = topo.edges[id as usize];
                if a as usize == v { b } else { a }
            };
            let xv = DVec3::from_array(mesh.coords[v]);
            (0..ids.len()).any(|i| {
                // The one edge at v that shares no element with edge i: the line's other half.
                let mut apart = (0..ids.len()).filter(|&j| {
                    j != i && !together.iter().any(|t| t.contains(&i) && t.contains(&j))
                });
                let (Some(j), None) = (apart.next(), apart.next()) else {
                    return false;
                };
                let d1 = unit(xv - x(far(ids[i])));
                let d2 = unit(x(far(ids[j])) - xv);
                d1.dot(d2) < cos_max
            })
        })
        .collect();
    let mut out = vec![false; ne];
    for (v, _) in kinked.iter().enumerate().filter(|(_, k)| **k) {
        for &e in topo.elements_at_vertex(v) {
            out[e as usize] = true;
        }
    }
    out
}

/// Boundary vertices of a hex mesh where a boundary facet's normal is more than `angle_deg`
/// from the vertex normal (sharp features), and non-manifold vertices: an `exclude` mask for
/// [`detect`].
pub fn feature_vertices(mesh: &LinearMesh, topo: &Topology, angle_deg: f64) -> Vec<bool> {
    let nv = mesh.n_vertices();
    if topo.dim != 3 {
        return vec![false; nv];
    }
    let mut out = topo.non_manifold_vertex_mask();
    let normals: Vec<DVec3> = topo
        .boundary_facets
        .iter()
        .map(|&f| unit(facet_normal(mesh, topo, f as usize)))
        .collect();
    let mut vertex_normal = vec![DVec3::ZERO; nv];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        for &v in topo.facet_vertices(f as usize) {
            vertex_normal[v as usize] += normals[i];
        }
    }
    let cos_max = angle_deg.to_radians().cos();
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        for &v in topo.facet_vertices(f as usize) {
            let n = unit(vertex_normal[v as usize]);
            if n.dot(normals[i]).is_nan() || n.dot(normals[i]) < cos_max {
                out[v as usize] = true;
            }
        }
    }
    out
}

/// The fans of the regular boundary vertices (four boundary quads, four distinct neighbours,
/// each in exactly two of the quads); `None` elsewhere.
fn regular_fans(mesh: &LinearMesh, topo: &Topology) -> Vec<Option<Fan>> {
    let nv = mesh.n_vertices();
    let faces_at = topo.boundary_facets_at_vertices();
    let non_manifold = topo.non_manifold_vertex_mask();
    (0..nv)
        .map(|v| {
            let faces = &faces_at[v];
            if faces.len() != 4 || non_manifold[v] {
                return None;
            }
            // The two neighbours of v in each quad.
            let mut pairs = [[0u32; 2]; 4];
            let mut normal = DVec3::ZERO;
            for (p, &f) in pairs.iter_mut().zip(faces) {
                let q = topo.facet_vertices(f as usize);
                let i = q.iter().position(|&w| w as usize == v)?;
                *p = [q[(i + 3) % 4], q[(i + 1) % 4]];
                normal += unit(facet_normal(mesh, topo, f as usize));
            }
            let mut ws: Vec<u32> = pairs.iter().flatten().copied().collect();
            ws.sort_unstable();
            ws.dedup();
            if ws.len() != 4 {
                return None;
            }
            let in_pair = |w: u32| pairs.iter().filter(|p| p.contains(&w)).count();
            if ws.iter().any(|&w| in_pair(w) != 2) {
                return None;
            }
            // Opposite neighbours share no quad.
            let opposite = |w: u32| {
                ws.iter()
                    .copied()
                    .find(|&u| u != w && !pairs.iter().any(|p| p.contains(&w) && p.contains(&u)))
            };
            let o0 = opposite(ws[0])?;
            let a1 = ws.iter().copied().find(|&u| u != ws[0] && u != o0)?;
            let lines = [[ws[0], o0], [a1, opposite(a1)?]];
            let normal = unit(normal);
            let xv = DVec3::from_array(mesh.coords[v]);
            let mut size = 0.0f64;
            let mut height = 0.0f64;
            for &f in faces {
                for &w in topo.facet_vertices(f as usize) {
                    let d = DVec3::from_array(mesh.coords[w as usize]) - xv;
                    size = size.max(d.length());
                    height = height.max(d.dot(normal).abs());
                }
            }
            Some(Fan {
                normal,
                lines,
                planar: height <= PLANAR_TOLERANCE * size,
            })
        })
        .collect()
}

/// Normal of boundary facet `f` (length ≈ twice its area), pointing out of its element.
fn facet_normal(mesh: &LinearMesh, topo: &Topology, f: usize) -> DVec3 {
    let q = topo.facet_vertices(f);
    let x = |i: usize| DVec3::from_array(mesh.coords[q[i] as usize]);
    let n = (x(2) - x(0)).cross(x(3) - x(1));
    let e = topo.facet_elements[f][0];
    if e == NONE {
        return n;
    }
    let centre = mesh.element(e as usize).iter().fold(DVec3::ZERO, |s, &v| {
        s + DVec3::from_array(mesh.coords[v as usize])
    });
    let k = mesh.element(e as usize).len() as f64;
    let face_centre = (0..4).fold(DVec3::ZERO, |s, i| s + x(i));
    let out = face_centre / 4.0 - centre / k;
    if n.dot(out) < 0.0 { -n } else { n }
}

fn tangential(d: DVec3, n: DVec3) -> DVec3 {
    let s = d.dot(n);
    d - s * n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::generate::{grid_3d, uniform};
    use crate::spline::{ElementClass, Q2Reason};

    /// A one-layer hex grid on `xs` × [0, 1] (8 cells) × [0, 0.2], its lines along x sheared
    /// by `bend_deg` from x = 0.5 on (y += tan(bend)·max(0, x − 0.5)), then, with `bent`,
    /// rolled onto cylinders about the y axis (x → angle, z → radius 1 + z); the shear is a
    /// single kink of the x-lines in the flat domain, and rolling keeps it within the surface.
    fn sheared(xs: &[f64], bend_deg: f64, bent: bool, layers: usize) -> LinearMesh {
        let zs: Vec<f64> = (0..=layers)
            .map(|k| 0.2 * k as f64 / layers as f64)
            .collect();
        let mut mesh = grid_3d(xs, &uniform(8, 0.125), &zs);
        let t = bend_deg.to_radians().tan();
        for p in &mut mesh.coords {
            let [x, y, z] = *p;
            let y = y + t * (x - 0.5).max(0.0);
            *p = if bent {
                [(1.0 + z) * x.cos(), y, (1.0 + z) * x.sin()]
            } else {
                [x, y, z]
            };
        }
        mesh
    }

    fn kinks_of(mesh: &LinearMesh) -> Kinks {
        let topo = Topology::build(mesh);
        detect(mesh, &topo, 10.0, &feature_vertices(mesh, &topo, 30.0))
    }

    /// Vertices of the `sheared` grid at x index `i` inside the top and bottom faces.
    fn column(nx: usize, i: usize) -> Vec<usize> {
        let mut out = Vec::new();
        for k in [0, 1] {
            for j in 1..8 {
                out.push((k * 9 + j) * nx + i);
            }
        }
        out
    }

    fn marked(mask: &[bool]) -> Vec<usize> {
        (0..mask.len()).filter(|&i| mask[i]).collect()
    }

    #[test]
    fn flat_and_bent_grids_have_no_kinks() {
        let flat = grid_3d(&uniform(4, 0.25), &uniform(5, 0.2), &uniform(3, 0.3));
        assert_eq!(kinks_of(&flat).n_vertices, 0);
        // Graded spacing (factor 1.3 per cell) on cylinders, three layers.
        let mut xs = vec![0.0];
        for i in 0..8 {
            xs.push(xs[i] + 0.05 * 1.3f64.powi(i as i32));
        }
        let bent = sheared(&xs, 0.0, true, 3);
        let k = kinks_of(&bent);
        assert_eq!(k.n_vertices, 0, "{:?}", marked(&k.vertices));
        assert_eq!(k.n_elements, 0);
    }

    #[test]
    fn a_bend_is_found_on_its_line_on_curved_faces_only() {
        let xs = uniform(10, 0.1);
        let k = kinks_of(&sheared(&xs, 30.0, true, 1));
        assert_eq!(marked(&k.vertices), {
            let mut c = column(11, 5);
            c.sort_unstable();
            c
        });
        // The elements touching that column: x indices 4 and 5, all 8 rows.
        let want: Vec<usize> = (0..8).flat_map(|j| [j * 10 + 4, j * 10 + 5]).collect();
        assert_eq!(marked(&k.elements), want);
        assert_eq!(k.n_elements, 16);
        // On planes the same bend is no kink (planar patches stay exact).
        assert_eq!(kinks_of(&sheared(&xs, 30.0, false, 1)).n_vertices, 0);
        // A 5° bend is below the threshold at this spacing (normal turning 0.1 rad ≈ 5.7°),
        // and above it at half the spacing (≈ 2.9°): the threshold scales with the mesh.
        assert_eq!(kinks_of(&sheared(&xs, 5.0, true, 1)).n_vertices, 0);
        assert_eq!(
            marked(&kinks_of(&sheared(&uniform(20, 0.05), 5.0, true, 1)).vertices),
            {
                let mut c = column(21, 10);
                c.sort_unstable();
                c
            }
        );
        // A 0.5° bend stays below the smallest threshold.
        let fine = uniform(100, 0.01);
        assert_eq!(kinks_of(&sheared(&fine, 0.5, true, 1)).n_vertices, 0);
        // 180° turns detection off.
        let mesh = sheared(&xs, 30.0, true, 1);
        let topo = Topology::build(&mesh);
        assert_eq!(detect(&mesh, &topo, 180.0, &[]).n_vertices, 0);
    }

    /// The interior kinks of `mesh` at `angle_deg`.
    fn interior_of(mesh: &LinearMesh, angle_deg: f64) -> Vec<usize> {
        marked(&interior_kink_elements(
            mesh,
            &Topology::build(mesh),
            angle_deg,
        ))
    }

    /// The shear of `sheared` turns the x-lines by exactly the bend at x = 0.5 (direction
    /// (1, 0) → (1, tan b)): with three layers the grid has interior vertices there, and the
    /// elements at them (x cells 4 and 5, every row and layer) are interior kinks where the
    /// bend is above the angle, and no others; lines of a cylinder turning by 5.7° per vertex,
    /// a bend of one layer (no interior vertex) and the same bend in 2D above the angle are not.
    #[test]
    fn interior_lines_kink_where_they_turn_by_more_than_the_angle() {
        let xs = uniform(10, 0.1);
        let mut column_sorted: Vec<usize> = (0..3)
            .flat_map(|k| (0..8).flat_map(move |j| [(k * 8 + j) * 10 + 4, (k * 8 + j) * 10 + 5]))
            .collect();
        column_sorted.sort_unstable();
        assert_eq!(
            interior_of(&sheared(&xs, 40.0, false, 3), 35.0),
            column_sorted
        );
        assert_eq!(
            interior_of(&sheared(&xs, 40.0, true, 3), 35.0),
            column_sorted
        );
        assert!(interior_of(&sheared(&xs, 30.0, false, 3), 35.0).is_empty());
        assert_eq!(
            interior_of(&sheared(&xs, 30.0, false, 3), 25.0),
            column_sorted
        );
        // Rolled onto cylinders the x-lines turn by 0.1 rad (5.7°) at every vertex.
        assert!(interior_of(&sheared(&xs, 0.0, true, 3), 10.0).is_empty());
        assert!(interior_of(&sheared(&xs, 60.0, true, 1), 35.0).is_empty());
        assert!(interior_of(&sheared(&xs, 60.0, false, 3), 180.0).is_empty());
        // 2D: the same shear of a 10 × 8 grid, its x-lines turning at x = 0.5.
        let mut flat = crate::mesh::generate::grid_2d(&xs, &uniform(8, 0.125));
        let t = 40f64.to_radians().tan();
        for p in &mut flat.coords {
            p[1] += t * (p[0] - 0.5).max(0.0);
        }
        let want: Vec<usize> = (0..8).flat_map(|j| [j * 10 + 4, j * 10 + 5]).collect();
        assert_eq!(interior_of(&flat, 35.0), want);
        assert!(interior_of(&flat, 45.0).is_empty());
    }

    /// A cube grid of n³ cells on [−1, 1]³ pushed out onto the unit sphere (x → x·|x|∞/|x|):
    /// its boundary is a cubed sphere with eight corners of three boundary faces.
    fn cubed_ball(n: usize) -> LinearMesh {
        let s = uniform(n, 2.0 / n as f64)
            .iter()
            .map(|x| x - 1.0)
            .collect::<Vec<_>>();
        let mut mesh = grid_3d(&s, &s, &s);
        for p in &mut mesh.coords {
            let inf = p.iter().fold(0.0f64, |m, c| m.max(c.abs()));
            let l = DVec3::from_array(*p).length();
            if l > 0.0 {
                *p = p.map(|c| c * inf / l);
            }
        }
        mesh
    }

    #[test]
    fn neighbours_of_irregular_boundary_vertices_are_kinks() {
        let n = 6;
        let mesh = cubed_ball(n);
        let k = kinks_of(&mesh);
        let id = |i: usize, j: usize, l: usize| (l * (n + 1) + j) * (n + 1) + i;
        for c in 0..8 {
            let at = |b: usize, near: usize| if c >> b & 1 == 0 { near } else { n - near };
            let corner = id(at(0, 0), at(1, 0), at(2, 0));
            // The corner itself is irregular (no grid lines to kink), the diagonal vertex of
            // each of its three boundary faces is smooth but marked, and so are the block arcs.
            assert!(!k.vertices[corner]);
            for diagonal in [
                id(at(0, 1), at(1, 1), at(2, 0)),
                id(at(0, 1), at(1, 0), at(2, 1)),
                id(at(0, 0), at(1, 1), at(2, 1)),
            ] {
                assert!(k.vertices[diagonal], "corner {c}: vertex {diagonal}");
            }
        }
        // Face-interior vertices two cells from every arc are smooth and not marked.
        assert!(!k.vertices[id(2, 2, 0)] && !k.vertices[id(3, 3, 0)]);
        // 180° turns the detection off, next to irregular vertices too.
        let topo = Topology::build(&mesh);
        assert_eq!(detect(&mesh, &topo, 180.0, &[]).n_vertices, 0);
    }

    #[test]
    fn spacing_jumps_are_kinks_on_curved_faces() {
        // Spacing 0.1 up to x = 0.5, then 0.3: a ratio of 3 at x = 0.5 only.
        let xs = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.8, 1.1, 1.4];
        let k = kinks_of(&sheared(&xs, 0.0, true, 1));
        let mut want = column(9, 5);
        want.sort_unstable();
        assert_eq!(marked(&k.vertices), want);
        assert_eq!(kinks_of(&sheared(&xs, 0.0, false, 1)).n_vertices, 0);
    }

    #[test]
    fn excluded_vertices_are_no_kinks_and_reasons_follow_the_masks() {
        let mesh = sheared(&uniform(10, 0.1), 30.0, true, 1);
        let topo = Topology::build(&mesh);
        let mut exclude = feature_vertices(&mesh, &topo, 30.0);
        for v in column(11, 5) {
            exclude[v] = true;
        }
        assert_eq!(detect(&mesh, &topo, 10.0, &exclude).n_vertices, 0);
        let k = detect(&mesh, &topo, 10.0, &feature_vertices(&mesh, &topo, 30.0));
        let mut demote = vec![false; mesh.n_elements()];
        demote[0] = true;
        demote[4] = true;
        assert!(k.elements[4] && !k.elements[0]);
        // The pipeline's order of reasons: a kink element stays a kink element when demoted.
        let s = crate::spline::SplineSpace::build_with_q2(
            &mesh,
            &topo,
            &[
                (&k.elements, Q2Reason::BoundaryKink),
                (&demote, Q2Reason::InvalidSplineMap),
            ],
        );
        assert_eq!(s.classes[0], ElementClass::Q2(Q2Reason::InvalidSplineMap));
        assert_eq!(s.classes[4], ElementClass::Q2(Q2Reason::BoundaryKink));
        assert!(s.classes[1].is_spline() || k.elements[1]);
    }
}
