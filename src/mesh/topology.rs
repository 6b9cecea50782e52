//! Mesh topology: unique edges and faces, adjacency, boundary, components, valences.
//!
//! Input: a [`LinearMesh`]. Output: a [`Topology`] built from sorted entity keys, with these
//! conventions. The keys are sorted without a global sort: a key starts with the entity's
//! lowest vertex, so the slots are gathered per lowest vertex through the vertex → element
//! lists (a counting sort) and each vertex's few keys are sorted alone (`keys_by_lowest_vertex`;
//! linear time and memory, in parallel over blocks of vertices).
//!
//! * **Local sides and edges** are those of the reference element
//!   ([`crate::math::reference`]): side `2k + s` is the side where coordinate k equals s, hex
//!   edge `4k + i` runs along direction k. A quad's edges are its sides.
//! * **Facets** are the (d−1)-entities: edges in 2D, faces in 3D. `facet_elements[f]` holds
//!   the one or two elements on it (`NONE` for the outside) and `facet_sides` their local sides.
//! * The boundary is computed from the topology alone: facets with one element. Boundary tags
//!   of the file are attached to the boundary facets with the same vertex set.
//! * Non-manifold configurations (a facet shared by more than two elements, a boundary edge
//!   on other than two boundary faces, a vertex whose elements do not form one fan) are
//!   recorded in [`NonManifold`], not repaired.

use super::LinearMesh;
use crate::math::reference::{HEX_EDGES, HEX_SIDES, QUAD_SIDES};
use rayon::prelude::*;
use std::collections::HashMap;

/// Marks "no element" / "no entity".
pub const NONE: u32 = u32::MAX;

/// Configurations the curving cannot treat as a manifold mesh.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct NonManifold {
    /// Facets shared by more than two elements.
    pub facets: Vec<u32>,
    /// 3D: boundary edges that do not have exactly two boundary faces.
    pub edges: Vec<u32>,
    /// Vertices whose incident elements do not form one fan (connected through facets at
    /// the vertex), or 2D boundary vertices without exactly two boundary edges.
    pub vertices: Vec<u32>,
}

impl NonManifold {
    pub fn is_empty(&self) -> bool {
        self.facets.is_empty() && self.edges.is_empty() && self.vertices.is_empty()
    }
}

/// The topology of a [`LinearMesh`].
#[derive(Clone, Debug, Default)]
pub struct Topology {
    pub dim: usize,
    pub n_elements: usize,
    pub n_vertices: usize,
    /// Unique edges as (lower vertex id, higher vertex id).
    pub edges: Vec<[u32; 2]>,
    /// Edge id of each local edge: 4 per quad (by side), 12 per hex (see [`HEX_EDGES`]).
    pub element_edges: Vec<u32>,
    /// 3D: unique faces, vertices in the local order of the first element that has the face
    /// (outward for that element). Empty in 2D.
    pub faces: Vec<[u32; 4]>,
    /// 3D: face id of each local side (6 per hex). Empty in 2D.
    pub element_faces: Vec<u32>,
    /// Elements on each facet (edges in 2D, faces in 3D); the second is `NONE` on the boundary.
    pub facet_elements: Vec<[u32; 2]>,
    /// Local side of the facet in each of `facet_elements` (unused entries are `u8::MAX`).
    pub facet_sides: Vec<[u8; 2]>,
    /// Neighbour across each local side (`2·dim` per element), `NONE` on the boundary.
    pub element_neighbors: Vec<u32>,
    /// Facets with one element, in facet order.
    pub boundary_facets: Vec<u32>,
    /// Tag of each boundary facet (parallel to `boundary_facets`; 0 = untagged).
    pub boundary_facet_tags: Vec<i32>,
    /// Vertices on a boundary facet.
    pub vertex_on_boundary: Vec<bool>,
    /// Edges on a boundary facet.
    pub edge_on_boundary: Vec<bool>,
    /// Elements around each vertex, CSR: `vertex_elements[vertex_offsets[v]..vertex_offsets[v+1]]`.
    pub vertex_offsets: Vec<u32>,
    pub vertex_elements: Vec<u32>,
    /// Number of elements around each edge (3D edge valence; in 2D 1 or 2).
    pub edge_valence: Vec<u32>,
    /// Connected component of each element (through shared facets), numbered from 0.
    pub element_component: Vec<u32>,
    pub n_components: usize,
    pub non_manifold: NonManifold,
    /// File-tagged facets that are interior facets of the mesh (tags kept nowhere).
    pub interior_tagged_facets: usize,
    /// File-tagged facets that are no facet of any element.
    pub unmatched_tagged_facets: usize,
}

impl Topology {
    /// Number of local sides per element (4 or 6).
    pub fn sides(&self) -> usize {
        2 * self.dim
    }

    pub fn n_facets(&self) -> usize {
        self.facet_elements.len()
    }

    /// Elements around vertex `v`.
    pub fn elements_at_vertex(&self, v: usize) -> &[u32] {
        &self.vertex_elements[self.vertex_offsets[v] as usize..self.vertex_offsets[v + 1] as usize]
    }

    /// Number of elements around vertex `v` (2D valence; 3D n(v)).
    pub fn vertex_valence(&self, v: usize) -> usize {
        (self.vertex_offsets[v + 1] - self.vertex_offsets[v]) as usize
    }

    /// Neighbour of element `e` across local side `side`, or `NONE`.
    pub fn neighbor(&self, e: usize, side: usize) -> u32 {
        self.element_neighbors[e * self.sides() + side]
    }

    /// This topology with the boundary facets of `glued` made interior, as on a periodic mesh
    /// glued across its seams: each `(f, e, s)` names a boundary facet f and the element e
    /// (its side s) across it. The facet keeps its own vertices (those of its element, not of
    /// e's side); the element across becomes the facet's second element and the first
    /// element's neighbour. The boundary facets, their tags and the boundary marks of vertices
    /// and edges follow; vertex, edge and face ids are unchanged.
    pub fn with_interior_facets(&self, mesh: &LinearMesh, glued: &[(u32, u32, u8)]) -> Topology {
        let mut t = self.clone();
        let sides = self.sides();
        for &(f, e, s) in glued {
            let f = f as usize;
            let [e0, _] = self.facet_elements[f];
            t.facet_elements[f][1] = e;
            t.facet_sides[f][1] = s;
            t.element_neighbors[e0 as usize * sides + self.facet_sides[f][0] as usize] = e;
        }
        let tagged = self.boundary_facet_tags.len() == self.boundary_facets.len();
        let (mut facets, mut tags) = (Vec::new(), Vec::new());
        for (i, &f) in self.boundary_facets.iter().enumerate() {
            if t.facet_elements[f as usize][1] == NONE {
                facets.push(f);
                if tagged {
                    tags.push(self.boundary_facet_tags[i]);
                }
            }
        }
        (t.vertex_on_boundary, t.edge_on_boundary) = boundary_marks(
            self.dim,
            &mesh.elements,
            self.n_vertices,
            self.edges.len(),
            &facets,
            &t.facet_elements,
            &t.facet_sides,
            &t.element_edges,
        );
        t.boundary_facets = facets;
        t.boundary_facet_tags = tags;
        t
    }

    /// Facet id of local side `side` of element `e`.
    pub fn element_facet(&self, e: usize, side: usize) -> u32 {
        if self.dim == 2 {
            self.element_edges[e * 4 + side]
        } else {
            self.element_faces[e * 6 + side]
        }
    }

    /// The boundary facets at each vertex (empty for interior vertices).
    pub fn boundary_facets_at_vertices(&self) -> Vec<Vec<u32>> {
        let mut out: Vec<Vec<u32>> = vec![Vec::new(); self.n_vertices];
        for &f in &self.boundary_facets {
            for &v in self.facet_vertices(f as usize) {
                out[v as usize].push(f);
            }
        }
        out
    }

    /// Per vertex: it is one of [`NonManifold::vertices`].
    pub fn non_manifold_vertex_mask(&self) -> Vec<bool> {
        let mut out = vec![false; self.n_vertices];
        for &v in &self.non_manifold.vertices {
            out[v as usize] = true;
        }
        out
    }

    /// Vertices of facet `f` (2 or 4 entries).
    pub fn facet_vertices(&self, f: usize) -> &[u32] {
        if self.dim == 2 {
            &self.edges[f][..]
        } else {
            &self.faces[f][..]
        }
    }

    /// 2D: interior vertices whose valence is not 4. 3D: edges not having both end points on
    /// the boundary whose valence is not 4 (the "irregular" measure of `meshes/real/SOURCES.md`).
    pub fn irregular_count(&self) -> usize {
        if self.dim == 2 {
            (0..self.n_vertices)
                .filter(|&v| !self.vertex_on_boundary[v] && self.vertex_valence(v) != 4)
                .count()
        } else {
            self.edges
                .iter()
                .zip(&self.edge_valence)
                .filter(|&(e, &val)| {
                    !(self.vertex_on_boundary[e[0] as usize]
                        && self.vertex_on_boundary[e[1] as usize])
                        && val != 4
                })
                .count()
        }
    }

    /// Build the topology of `mesh`.
    pub fn build(mesh: &LinearMesh) -> Topology {
        let dim = mesh.dim;
        let ne = mesh.n_elements();
        let nv = mesh.n_vertices();
        let npe = mesh.nodes_per_element();
        let nsides = 2 * dim;
        let elems = &mesh.elements;

        let (vertex_offsets, vertex_elements) = vertex_elements(elems, nv, npe);
        let around = Around {
            corners: elems,
            npe,
            offsets: &vertex_offsets,
            elements: &vertex_elements,
        };
        let (edges, edge_valence, element_edges) = unique_edges(elems, dim, ne, npe, around);
        // Facets: edges in 2D (already unique), faces in 3D.
        let (faces, element_faces) = if dim == 3 {
            unique_faces(elems, ne, around)
        } else {
            (Vec::new(), Vec::new())
        };
        let (facet_of_slot, n_facets): (&[u32], usize) = if dim == 3 {
            (&element_faces, faces.len())
        } else {
            (&element_edges, edges.len())
        };
        let Adjacency {
            facet_elements,
            facet_sides,
            facet_count,
            element_neighbors,
            boundary_facets,
            non_manifold,
        } = Adjacency::new(facet_of_slot, n_facets, nsides, ne);
        let (vertex_on_boundary, edge_on_boundary) = boundary_marks(
            dim,
            elems,
            nv,
            edges.len(),
            &boundary_facets,
            &facet_elements,
            &facet_sides,
            &element_edges,
        );
        let (element_component, n_components) = components(ne, &facet_elements, &facet_count);

        let mut topo = Topology {
            dim,
            n_elements: ne,
            n_vertices: nv,
            edges,
            element_edges,
            faces,
            element_faces,
            facet_elements,
            facet_sides,
            element_neighbors,
            boundary_facets,
            boundary_facet_tags: Vec::new(),
            vertex_on_boundary,
            edge_on_boundary,
            vertex_offsets,
            vertex_elements,
            edge_valence,
            element_component,
            n_components,
            non_manifold,
            interior_tagged_facets: 0,
            unmatched_tagged_facets: 0,
        };
        topo.find_non_manifold_edges_and_vertices(mesh);
        topo.attach_tags(mesh);
        topo
    }

    fn find_non_manifold_edges_and_vertices(&mut self, mesh: &LinearMesh) {
        let npe = mesh.nodes_per_element();
        let nsides = self.sides();
        if self.dim == 3 {
            // Boundary faces per edge.
            let mut count = vec![0u8; self.edges.len()];
            for &f in &self.boundary_facets {
                let [e, _] = self.facet_elements[f as usize];
                let side = self.facet_sides[f as usize][0] as usize;
                for (l, le) in HEX_EDGES.iter().enumerate() {
                    if HEX_SIDES[side].contains(&le[0]) && HEX_SIDES[side].contains(&le[1]) {
                        let id = self.element_edges[e as usize * 12 + l] as usize;
                        count[id] = count[id].saturating_add(1);
                    }
                }
            }
            self.non_manifold.edges = (0..self.edges.len() as u32)
                .filter(|&i| self.edge_on_boundary[i as usize] && count[i as usize] != 2)
                .collect();
        } else {
            // 2D: a boundary vertex has exactly two boundary edges.
            let mut count = vec![0u8; self.n_vertices];
            for &f in &self.boundary_facets {
                for &v in &self.edges[f as usize] {
                    count[v as usize] = count[v as usize].saturating_add(1);
                }
            }
            self.non_manifold.vertices = (0..self.n_vertices as u32)
                .filter(|&v| self.vertex_on_boundary[v as usize] && count[v as usize] != 2)
                .collect();
        }
        // Vertex fans: the elements at v must be connected through the sides that contain v.
        let elems = &mesh.elements;
        let sides_of_corner: Vec<Vec<usize>> = (0..npe)
            .map(|c| {
                (0..nsides)
                    .filter(|&s| {
                        if self.dim == 2 {
                            QUAD_SIDES[s].contains(&c)
                        } else {
                            HEX_SIDES[s].contains(&c)
                        }
                    })
                    .collect()
            })
            .collect();
        let split: Vec<u32> = (0..self.n_vertices)
            .into_par_iter()
            .filter(|&v| {
                let around = self.elements_at_vertex(v);
                if around.len() <= 1 {
                    return false;
                }
                let mut reached = vec![false; around.len()];
                let mut stack = vec![0usize];
                reached[0] = true;
                let mut n_reached = 1;
                while let Some(i) = stack.pop() {
                    let e = around[i] as usize;
                    let corner = (0..npe)
                        .find(|&c| elems[e * npe + c] == v as u32)
                        .expect("vertex belongs to the element");
                    for &s in &sides_of_corner[corner] {
                        let n = self.element_neighbors[e * nsides + s];
                        if n == NONE {
                            continue;
                        }
                        if let Some(j) = around.iter().position(|&x| x == n)
                            && !reached[j]
                        {
                            reached[j] = true;
                            n_reached += 1;
                            stack.push(j);
                        }
                    }
                }
                n_reached != around.len()
            })
            .map(|v| v as u32)
            .collect();
        self.non_manifold.vertices.extend(split);
        self.non_manifold.vertices.sort_unstable();
        self.non_manifold.vertices.dedup();
    }

    fn attach_tags(&mut self, mesh: &LinearMesh) {
        self.boundary_facet_tags = vec![0; self.boundary_facets.len()];
        if mesh.facet_tags.is_empty() {
            return;
        }
        let npf = mesh.nodes_per_facet();
        let key = |vs: &[u32]| -> [u32; 4] {
            let mut k = [u32::MAX; 4];
            k[..vs.len()].copy_from_slice(vs);
            k.sort_unstable();
            k
        };
        let mut tagged: HashMap<[u32; 4], i32> = HashMap::with_capacity(mesh.facet_tags.len());
        for (f, &t) in mesh.tagged_facets.chunks(npf).zip(&mesh.facet_tags) {
            tagged.entry(key(f)).or_insert(t);
        }
        let mut matched = 0;
        for (i, &f) in self.boundary_facets.iter().enumerate() {
            if let Some(&t) = tagged.get(&key(self.facet_vertices(f as usize))) {
                self.boundary_facet_tags[i] = t;
                matched += 1;
            }
        }
        // The rest are interior facets or no facet at all.
        let mut interior = 0;
        if matched < tagged.len() {
            for f in 0..self.n_facets() {
                if self.facet_elements[f][1] != NONE
                    && tagged.contains_key(&key(self.facet_vertices(f)))
                {
                    interior += 1;
                }
            }
        }
        self.interior_tagged_facets = interior;
        self.unmatched_tagged_facets = tagged.len() - matched - interior;
    }
}

/// Union-find with path halving and union by size.
struct UnionFind {
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> Self {
        UnionFind {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
        }
    }
    fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] as usize != x {
            let p = self.parent[x] as usize;
            self.parent[x] = self.parent[p];
            x = self.parent[x] as usize;
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (mut a, mut b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        if self.size[a] < self.size[b] {
            std::mem::swap(&mut a, &mut b);
        }
        self.parent[b] = a as u32;
        self.size[a] += self.size[b];
    }
}

/// The unique edges (sorted vertex pairs, in order of their key), each edge's valence
/// (elements around it) and the edge of each element's local edge slot.
fn unique_edges(
    elems: &[u32],
    dim: usize,
    ne: usize,
    npe: usize,
    around: Around,
) -> (Vec<[u32; 2]>, Vec<u32>, Vec<u32>) {
    // Sorted (key, slot) pairs; one slot per local edge.
    let local_edges: Vec<[usize; 2]> = if dim == 2 {
        QUAD_SIDES.to_vec()
    } else {
        HEX_EDGES.to_vec()
    };
    let nle = local_edges.len();
    let at_corner = around.at_corner(nle, |l| local_edges[l]);
    let keys: Vec<(u64, u32)> =
        keys_by_lowest_vertex(ne, nle, around, &at_corner, KEY_BLOCK, |slot| {
            let (e, l) = (slot / nle, slot % nle);
            let a = elems[e * npe + local_edges[l][0]];
            let b = elems[e * npe + local_edges[l][1]];
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            (lo, ((lo as u64) << 32) | hi as u64)
        });
    let first = run_starts(&keys, |a, b| a.0 == b.0);
    let edges = first
        .par_iter()
        .map(|&i| {
            let k = keys[i as usize].0;
            [(k >> 32) as u32, k as u32]
        })
        .collect();
    let edge_valence = first
        .par_iter()
        .enumerate()
        .map(|(id, &i)| first.get(id + 1).map_or(keys.len() as u32, |&j| j) - i)
        .collect();
    let element_edges = slot_ids(&keys, &first, ne * nle, |&(_, slot)| slot);
    (edges, edge_valence, element_edges)
}

/// The elements' corners (`npe` vertices each) and the vertex → element lists of
/// [`vertex_elements`] (an element once per corner at the vertex, elements in order).
#[derive(Clone, Copy)]
struct Around<'a> {
    corners: &'a [u32],
    npe: usize,
    offsets: &'a [u32],
    elements: &'a [u32],
}

impl Around<'_> {
    /// For each corner of an element, the local entities (of `per_element`, each with the
    /// corners `local(l)`) that contain it.
    fn at_corner<const N: usize>(
        &self,
        per_element: usize,
        local: impl Fn(usize) -> [usize; N],
    ) -> Vec<Vec<usize>> {
        (0..self.npe)
            .map(|c| {
                (0..per_element)
                    .filter(|&l| local(l).contains(&c))
                    .collect()
            })
            .collect()
    }
}

/// Vertices per task of [`keys_by_lowest_vertex`].
const KEY_BLOCK: usize = 4096;

/// The pairs (key, slot) of all `ne · per_element` slots (slot = element · per_element +
/// local), sorted, where `key_at(slot)` is (the lowest vertex of the slot's entity, its key)
/// and every key starts with that vertex: equal to sorting all pairs (the slot breaks ties),
/// without a global sort. A counting pass sizes each block of `block` vertices; then
/// per block, in parallel, each vertex's slots are gathered from the elements around it (the
/// local entities `at_corner` of the vertex's corner, all of them where the element has the
/// vertex at more than one corner) and sorted.
fn keys_by_lowest_vertex<K: Ord + Copy + Send + Sync>(
    ne: usize,
    per_element: usize,
    around: Around,
    at_corner: &[Vec<usize>],
    block: usize,
    key_at: impl Fn(usize) -> (u32, K) + Sync,
) -> Vec<(K, u32)> {
    let nv = around.offsets.len() - 1;
    let n_blocks = nv.div_ceil(block);
    let counts = (0..ne * per_element)
        .into_par_iter()
        .fold(
            || vec![0usize; n_blocks],
            |mut c, slot| {
                c[key_at(slot).0 as usize / block] += 1;
                c
            },
        )
        .reduce(
            || vec![0usize; n_blocks],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    let mut start = vec![0usize; n_blocks + 1];
    for b in 0..n_blocks {
        start[b + 1] = start[b] + counts[b];
    }
    let mut keys: Vec<(K, u32)> = Vec::with_capacity(ne * per_element);
    // The first slot's pair fills the vector; every entry is written below.
    if ne * per_element > 0 {
        keys.resize(ne * per_element, (key_at(0).1, 0));
    }
    let mut parts = Vec::with_capacity(n_blocks);
    let mut rest = keys.as_mut_slice();
    for b in 0..n_blocks {
        let (part, tail) = rest.split_at_mut(start[b + 1] - start[b]);
        parts.push(part);
        rest = tail;
    }
    parts.into_par_iter().enumerate().for_each(|(b, part)| {
        let mut n = 0;
        for v in b * block..((b + 1) * block).min(nv) {
            let first = n;
            let elements =
                &around.elements[around.offsets[v] as usize..around.offsets[v + 1] as usize];
            for (i, &e) in elements.iter().enumerate() {
                if i > 0 && elements[i - 1] == e {
                    continue; // the element again, at another of its corners
                }
                let (e, npe) = (e as usize, around.npe);
                let corners = &around.corners[e * npe..(e + 1) * npe];
                let all: Vec<usize>;
                let locals = if elements.get(i + 1) == Some(&(e as u32)) {
                    all = (0..per_element).collect();
                    &all
                } else {
                    let c = corners.iter().position(|&x| x as usize == v);
                    &at_corner[c.expect("the vertex is a corner of the element")]
                };
                for &l in locals {
                    let slot = e * per_element + l;
                    let (lo, key) = key_at(slot);
                    if lo as usize == v {
                        part[n] = (key, slot as u32);
                        n += 1;
                    }
                }
            }
            part[first..n].sort_unstable();
        }
        debug_assert_eq!(n, part.len());
    });
    keys
}

/// The start of every run of equal entries (`same`) of the sorted `keys`, in order: the
/// unique entries' first places.
fn run_starts<K: Sync>(keys: &[K], same: impl Fn(&K, &K) -> bool + Sync) -> Vec<u32> {
    (0..keys.len())
        .into_par_iter()
        .filter(|&i| i == 0 || !same(&keys[i - 1], &keys[i]))
        .map(|i| i as u32)
        .collect()
}

/// Per slot (`n` of them, each `slot(key)` of exactly one of the sorted `keys`), the number of
/// its key's run (`first`: [`run_starts`]).
fn slot_ids<K: Sync>(
    keys: &[K],
    first: &[u32],
    n: usize,
    slot: impl Fn(&K) -> u32 + Sync,
) -> Vec<u32> {
    use std::sync::atomic::{AtomicU32, Ordering};
    // Every slot is written once, by its run's task: relaxed stores, read after the join.
    let ids: Vec<AtomicU32> = (0..n)
        .into_par_iter()
        .map(|_| AtomicU32::new(NONE))
        .collect();
    first.par_iter().enumerate().for_each(|(id, &i)| {
        let end = first.get(id + 1).map_or(keys.len(), |&j| j as usize);
        for k in &keys[i as usize..end] {
            ids[slot(k) as usize].store(id as u32, Ordering::Relaxed);
        }
    });
    ids.into_par_iter().map(AtomicU32::into_inner).collect()
}

/// The unique faces of a hex mesh (in order of their sorted vertex keys, each with the
/// vertices of its first element side) and the face of each element side slot.
fn unique_faces(elems: &[u32], ne: usize, around: Around) -> (Vec<[u32; 4]>, Vec<u32>) {
    let at_corner = around.at_corner(6, |l| HEX_SIDES[l]);
    let keys: Vec<([u32; 4], u32)> =
        keys_by_lowest_vertex(ne, 6, around, &at_corner, KEY_BLOCK, |slot| {
            let (e, l) = (slot / 6, slot % 6);
            let mut k = HEX_SIDES[l].map(|c| elems[e * 8 + c]);
            k.sort_unstable();
            (k[0], k)
        });
    let first = run_starts(&keys, |a, b| a.0 == b.0);
    let faces = first
        .par_iter()
        .map(|&i| {
            let slot = keys[i as usize].1 as usize;
            let (e, l) = (slot / 6, slot % 6);
            HEX_SIDES[l].map(|c| elems[e * 8 + c])
        })
        .collect();
    let element_faces = slot_ids(&keys, &first, ne * 6, |&(_, slot)| slot);
    (faces, element_faces)
}

/// Facet ↔ element adjacency.
struct Adjacency {
    facet_elements: Vec<[u32; 2]>,
    facet_sides: Vec<[u8; 2]>,
    /// Elements around each facet (more than 2: non-manifold).
    facet_count: Vec<u32>,
    element_neighbors: Vec<u32>,
    boundary_facets: Vec<u32>,
    non_manifold: NonManifold,
}

impl Adjacency {
    /// Facet → elements and element → neighbours from the facet of each element side slot.
    fn new(facet_of_slot: &[u32], n_facets: usize, nsides: usize, ne: usize) -> Adjacency {
        let mut facet_elements = vec![[NONE, NONE]; n_facets];
        let mut facet_sides = vec![[u8::MAX, u8::MAX]; n_facets];
        let mut facet_count = vec![0u32; n_facets];
        for (slot, &f) in facet_of_slot.iter().enumerate() {
            let f = f as usize;
            let c = facet_count[f] as usize;
            if c < 2 {
                facet_elements[f][c] = (slot / nsides) as u32;
                facet_sides[f][c] = (slot % nsides) as u8;
            }
            facet_count[f] += 1;
        }
        let mut non_manifold = NonManifold::default();
        let mut element_neighbors = vec![NONE; ne * nsides];
        for f in 0..n_facets {
            if facet_count[f] > 2 {
                non_manifold.facets.push(f as u32);
                continue;
            }
            let [a, b] = facet_elements[f];
            if b != NONE {
                let [sa, sb] = facet_sides[f];
                element_neighbors[a as usize * nsides + sa as usize] = b;
                element_neighbors[b as usize * nsides + sb as usize] = a;
            }
        }
        let boundary_facets: Vec<u32> = (0..n_facets as u32)
            .filter(|&f| facet_count[f as usize] == 1)
            .collect();

        Adjacency {
            facet_elements,
            facet_sides,
            facet_count,
            element_neighbors,
            boundary_facets,
            non_manifold,
        }
    }
}

/// Which vertices and edges lie on the boundary facets.
#[allow(clippy::too_many_arguments)]
fn boundary_marks(
    dim: usize,
    elems: &[u32],
    nv: usize,
    n_edges: usize,
    boundary_facets: &[u32],
    facet_elements: &[[u32; 2]],
    facet_sides: &[[u8; 2]],
    element_edges: &[u32],
) -> (Vec<bool>, Vec<bool>) {
    let mut vertex_on_boundary = vec![false; nv];
    let mut edge_on_boundary = vec![false; n_edges];
    for &f in boundary_facets {
        let [e, _] = facet_elements[f as usize];
        let side = facet_sides[f as usize][0] as usize;
        let e = e as usize;
        if dim == 2 {
            edge_on_boundary[f as usize] = true;
            for &c in &QUAD_SIDES[side] {
                vertex_on_boundary[elems[e * 4 + c] as usize] = true;
            }
        } else {
            for &c in &HEX_SIDES[side] {
                vertex_on_boundary[elems[e * 8 + c] as usize] = true;
            }
            for (l, le) in HEX_EDGES.iter().enumerate() {
                if HEX_SIDES[side].contains(&le[0]) && HEX_SIDES[side].contains(&le[1]) {
                    edge_on_boundary[element_edges[e * 12 + l] as usize] = true;
                }
            }
        }
    }

    (vertex_on_boundary, edge_on_boundary)
}

/// Vertex → elements as offsets and a flat list (counting sort, elements in order).
fn vertex_elements(elems: &[u32], nv: usize, npe: usize) -> (Vec<u32>, Vec<u32>) {
    let mut vertex_offsets = vec![0u32; nv + 1];
    for &v in elems {
        vertex_offsets[v as usize + 1] += 1;
    }
    for v in 0..nv {
        vertex_offsets[v + 1] += vertex_offsets[v];
    }
    let mut fill = vertex_offsets.clone();
    let mut vertex_elements = vec![0u32; elems.len()];
    for (i, &v) in elems.iter().enumerate() {
        vertex_elements[fill[v as usize] as usize] = (i / npe) as u32;
        fill[v as usize] += 1;
    }
    drop(fill);

    (vertex_offsets, vertex_elements)
}

/// Connected components: union-find over interior (two-element) facets; components are
/// numbered in order of their first element.
fn components(ne: usize, facet_elements: &[[u32; 2]], facet_count: &[u32]) -> (Vec<u32>, usize) {
    let mut uf = UnionFind::new(ne);
    for (f, fe) in facet_elements.iter().enumerate() {
        if fe[1] != NONE && facet_count[f] == 2 {
            uf.union(fe[0] as usize, fe[1] as usize);
        }
    }
    let mut comp_id = vec![NONE; ne];
    let mut element_component = vec![0u32; ne];
    let mut n_components = 0;
    for (e, c) in element_component.iter_mut().enumerate() {
        let r = uf.find(e);
        if comp_id[r] == NONE {
            comp_id[r] = n_components as u32;
            n_components += 1;
        }
        *c = comp_id[r];
    }

    (element_component, n_components)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// A structured n³ hex grid with its vertices numbered in a scrambled order, so that the
    /// sorted keys' runs do not follow the elements.
    fn scrambled_grid(n: usize) -> Vec<u32> {
        let nv = (n + 1).pow(3);
        let label = |v: usize| ((v * 7919) % nv) as u32;
        let xs: Vec<f64> = (0..=n).map(|i| i as f64).collect();
        let grid = crate::mesh::generate::grid_3d(&xs, &xs, &xs);
        grid.elements.iter().map(|&v| label(v as usize)).collect()
    }

    /// `f` of the vertex → element lists of the elements `corners` (`npe` each).
    fn with_around<R>(corners: &[u32], nv: usize, npe: usize, f: impl FnOnce(Around) -> R) -> R {
        let (offsets, elements) = vertex_elements(corners, nv, npe);
        f(Around {
            corners,
            npe,
            offsets: &offsets,
            elements: &elements,
        })
    }

    /// The keys gathered per lowest vertex, in blocks of any size, equal all (key, slot)
    /// pairs sorted, for the hex edges and faces of a scrambled grid and the sides of a quad
    /// grid.
    #[test]
    fn keys_by_lowest_vertex_equal_a_full_sort() {
        fn check<K: Ord + Copy + Send + Sync + std::fmt::Debug, const N: usize>(
            ne: usize,
            around: Around,
            local: impl Fn(usize) -> [usize; N],
            per: usize,
            key_at: impl Fn(usize) -> (u32, K) + Sync,
        ) {
            let at_corner = around.at_corner(per, local);
            let mut all: Vec<(K, u32)> = (0..ne * per)
                .map(|slot| (key_at(slot).1, slot as u32))
                .collect();
            all.sort();
            for block in [1, 7, 100, 1 << 20] {
                assert_eq!(
                    keys_by_lowest_vertex(ne, per, around, &at_corner, block, &key_at),
                    all,
                    "block {block}"
                );
            }
        }
        let n: usize = 6;
        let (ne, nv) = (n * n * n, (n + 1).pow(3));
        let elems = scrambled_grid(n);
        let (offsets, elements) = vertex_elements(&elems, nv, 8);
        let around = Around {
            corners: &elems,
            npe: 8,
            offsets: &offsets,
            elements: &elements,
        };
        check(
            ne,
            around,
            |l| HEX_EDGES[l],
            12,
            |slot| {
                let [a, b] = HEX_EDGES[slot % 12].map(|c| elems[slot / 12 * 8 + c]);
                (a.min(b), [a.min(b), a.max(b)])
            },
        );
        check(
            ne,
            around,
            |l| HEX_SIDES[l],
            6,
            |slot| {
                let mut k = HEX_SIDES[slot % 6].map(|c| elems[slot / 6 * 8 + c]);
                k.sort_unstable();
                (k[0], k)
            },
        );
        let xs: Vec<f64> = (0..=9).map(|i| i as f64).collect();
        let quads = crate::mesh::generate::grid_2d(&xs, &xs[..5]);
        // As generated, and with one element's corner 2 moved onto its corner 1 (that element
        // listed twice at the vertex).
        let mut collapsed = quads.elements.clone();
        collapsed[2] = collapsed[1];
        for corners in [&quads.elements, &collapsed] {
            let (offsets, elements) = vertex_elements(corners, quads.n_vertices(), 4);
            let around = Around {
                corners,
                npe: 4,
                offsets: &offsets,
                elements: &elements,
            };
            check(
                quads.n_elements(),
                around,
                |l| QUAD_SIDES[l],
                4,
                |slot| {
                    let [a, b] = QUAD_SIDES[slot % 4].map(|c| corners[slot / 4 * 4 + c]);
                    (a.min(b), (a.min(b), a.max(b)))
                },
            );
        }
    }

    /// The unique edges and faces, their numbering, valences and first sides equal those of
    /// an ordered map from each key to the slots that have it.
    #[test]
    fn unique_edges_and_faces_match_an_ordered_map() {
        let n = 12;
        let elems = scrambled_grid(n);
        let ne = n * n * n;
        let nv = (n + 1).pow(3);
        let (edges, valence, element_edges) = with_around(&elems, nv, 8, |around| {
            unique_edges(&elems, 3, ne, 8, around)
        });
        let mut by_edge: BTreeMap<[u32; 2], Vec<usize>> = BTreeMap::new();
        for slot in 0..ne * 12 {
            let [a, b] = HEX_EDGES[slot % 12].map(|c| elems[slot / 12 * 8 + c]);
            by_edge.entry([a.min(b), a.max(b)]).or_default().push(slot);
        }
        assert_eq!(edges.len(), 3 * n * (n + 1) * (n + 1));
        assert_eq!(edges, by_edge.keys().copied().collect::<Vec<_>>());
        for (id, slots) in by_edge.values().enumerate() {
            assert_eq!(valence[id] as usize, slots.len());
            assert!(slots.iter().all(|&s| element_edges[s] == id as u32));
        }

        let (faces, element_faces) =
            with_around(&elems, nv, 8, |around| unique_faces(&elems, ne, around));
        let mut by_face: BTreeMap<[u32; 4], Vec<usize>> = BTreeMap::new();
        for slot in 0..ne * 6 {
            let mut k = HEX_SIDES[slot % 6].map(|c| elems[slot / 6 * 8 + c]);
            k.sort_unstable();
            by_face.entry(k).or_default().push(slot);
        }
        assert_eq!(faces.len(), 3 * n * n * (n + 1));
        assert_eq!(faces.len(), by_face.len());
        for (id, slots) in by_face.values().enumerate() {
            let s = slots[0];
            assert_eq!(faces[id], HEX_SIDES[s % 6].map(|c| elems[s / 6 * 8 + c]));
            assert!(slots.iter().all(|&s| element_faces[s] == id as u32));
        }
    }
}
