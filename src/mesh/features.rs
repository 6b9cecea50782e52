//! Sharp features of the boundary: feature edges, feature corners and smooth patches.
//!
//! Input: a [`LinearMesh`], its [`Topology`], [`FeatureParams`] and optional user edits
//! ([`parse_edits`]). Output: [`Features`].
//!
//! * **3D.** A boundary edge is a *feature edge* when the normals of its two boundary faces
//!   differ by more than `angle_deg` (dihedral angle), when the two faces carry different
//!   boundary tags (with `tags`), or when it does not lie on exactly two boundary faces
//!   (non-manifold). User edits then add or remove edges (`add i j` / `remove i j`, vertex ids).
//!   A *feature corner* is a vertex where a number of feature edges other than 2 meet.
//!   *Patches* are the connected sets of boundary faces joined across non-feature edges.
//! * **2D.** Features are the corners of the boundary polygon: boundary vertices where the
//!   boundary turns by more than `angle_deg`, where the tags of the two boundary edges differ,
//!   or that do not lie on exactly two boundary edges; edits `add i` / `remove i` name vertices.
//!   Patches are the boundary chains between corners (a closed loop without corners is one).
//! * **Coarse smooth boundaries.** A turning above `angle_deg` makes a feature only where it is
//!   concentrated: more than [`CONCENTRATION`] × the same-way turning of the flatter of its two
//!   neighbours (3D: the edges opposite it in its two faces; 2D: the neighbouring vertices;
//!   unknown or opposite turning counts as 0), see `concentrated`. A coarse torus or ellipse turns by 45° at every edge or vertex, smoothly;
//!   a cylinder's rim, a box edge or a trailing edge turns with flat facets beside it. A shape
//!   whose every edge turns alike (a one-hex cube) is taken for smooth.
//! * **Planes and lines.** A patch is planar (3D) or a chain straight (2D) when its vertices lie
//!   within 1e-6 × the bounding-box diagonal of its least-squares plane or line; the fit keeps
//!   such patches planar and chains straight to rounding.
//!
//! Invariants: feature edges are boundary edges; [`Features::vertex_mask`] is true exactly at
//! the vertices of feature edges (3D) or at corners (2D); every boundary facet has one patch.

mod angles;
mod planes;

use crate::math::linalg::{DVec3, unit};
use crate::mesh::topology::NONE;
use crate::mesh::{LinearMesh, Topology};
use crate::params::{ParamError, in_range};
use angles::{corners_2d, creases_3d};
use planes::{planar_patches, straight_chains};
use std::path::{Path, PathBuf};

/// What counts as a sharp feature.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FeatureParams {
    /// Facet normals (3D) or boundary edge directions (2D) turning by more than this many
    /// degrees make a feature; 180 finds none by angle.
    pub angle_deg: f64,
    /// Boundaries between differently tagged boundary regions are features.
    pub tags: bool,
}

impl Default for FeatureParams {
    fn default() -> Self {
        FeatureParams {
            angle_deg: 35.0,
            tags: true,
        }
    }
}

impl FeatureParams {
    /// No feature is found (angle 180, tags ignored).
    pub fn off() -> Self {
        FeatureParams {
            angle_deg: 180.0,
            tags: false,
        }
    }
}

impl FeatureParams {
    /// `--feature-angle`: degrees in [0, 180].
    pub fn check(&self) -> Result<(), ParamError> {
        in_range("--feature-angle", self.angle_deg, 0.0, 180.0)
    }
}

/// What the features became in a curved mesh (the `features` object of `curve --report`).
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FeatureReport {
    /// What was found (its fields sit beside the two below in the JSON).
    #[serde(flatten)]
    pub found: FeatureSummary,
    /// Largest distance of an output node at a feature vertex from the input vertex, relative
    /// to the bounding-box diagonal.
    pub feature_vertex_deviation_max: f64,
    /// Largest distance of an output boundary node of a planar patch (2D: straight chain) from
    /// the patch's plane (line), relative to the bounding-box diagonal (0 without any).
    pub planarity_max: f64,
}

/// One line of a feature edits file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FeatureEdit {
    /// `add` (true) or `remove`.
    pub add: bool,
    /// One vertex (2D corners) or two (3D edges), 0-based in the order the file's vertices are
    /// read.
    pub vertices: Vec<u32>,
    /// 1-based line of the file, for messages.
    pub line: usize,
}

/// A bad feature edits file.
#[derive(Debug, thiserror::Error)]
pub enum FeatureError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}:{line}: {what}", path.display())]
    Line {
        path: PathBuf,
        line: usize,
        what: String,
    },
    #[error(transparent)]
    Params(#[from] crate::params::ParamError),
}

/// The edits of a feature edits file's `text` (read from `path`, which the errors name): one
/// edit per line, `add i j` / `remove i j` (3D) or `add i` / `remove i` (2D); `#` starts a
/// comment, blank lines are skipped. The ids are checked against the mesh by
/// [`Features::detect`].
pub fn parse_edits(text: &str, path: &Path) -> Result<Vec<FeatureEdit>, FeatureError> {
    let mut edits = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let content = raw.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let bad = |what: String| FeatureError::Line {
            path: path.to_owned(),
            line,
            what,
        };
        let mut words = content.split_whitespace();
        let add = match words.next() {
            Some("add") => true,
            Some("remove") => false,
            Some(w) => {
                return Err(bad(format!(
                    "unknown edit `{w}`; expected `add` or `remove` followed by vertex ids"
                )));
            }
            None => unreachable!("non-empty line"),
        };
        let vertices = words
            .map(|w| {
                w.parse::<u32>()
                    .map_err(|_| bad(format!("`{w}` is not a vertex id (0-based integer)")))
            })
            .collect::<Result<Vec<u32>, _>>()?;
        if vertices.is_empty() || vertices.len() > 2 {
            return Err(bad(format!(
                "expected one vertex id (2D corner) or two (3D edge), found {}",
                vertices.len()
            )));
        }
        edits.push(FeatureEdit {
            add,
            vertices,
            line,
        });
    }
    Ok(edits)
}

/// The sharp features of a mesh boundary (see module docs).
#[derive(Clone, Debug, Default)]
pub struct Features {
    pub dim: usize,
    /// 3D: feature edges as topology edge ids, sorted. Empty in 2D.
    pub edges: Vec<u32>,
    /// Feature corners (vertex ids, sorted): 3D vertices with ≠ 2 feature edges, 2D corners.
    pub corners: Vec<u32>,
    /// Patch of each boundary facet (parallel to `topo.boundary_facets`).
    pub facet_patch: Vec<u32>,
    pub n_patches: usize,
    /// Per patch: `Some((unit normal, offset))` when all its vertices lie on the plane
    /// `n·x = offset` within 1e-6 × the mesh's bounding-box diagonal; in 2D the line of a
    /// straight chain (normal with zero z).
    pub planes: Vec<Option<([f64; 3], f64)>>,
    /// Per vertex: on a feature edge (3D) or a corner (2D).
    pub vertex_mask: Vec<bool>,
    /// Per topology edge: a feature edge (3D; all false in 2D).
    pub edge_mask: Vec<bool>,
    /// Per vertex: a feature vertex on a thin rim, as the fit's feature models classify it
    /// with the curve continued across periodic seams (`fit::features::FeatureModels`);
    /// empty (none) until the smooth targets set it.
    pub thin_rim: Vec<bool>,
}

/// What [`Features`] found, for `info` and reports.
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FeatureSummary {
    /// Angle (degrees) above which a boundary edge or vertex is a feature (`--feature-angle`).
    pub feature_angle_deg: f64,
    /// Whether boundary tags of the input also delimit features.
    pub tags: bool,
    /// Boundary edges marked as feature curves (3D; 0 in 2D).
    pub feature_edges: usize,
    /// Feature corners: 2D corners, or 3D vertices where feature curves meet or end.
    pub feature_corners: usize,
    /// Boundary vertices on a feature.
    pub feature_vertices: usize,
    /// Smooth boundary patches the features cut the boundary into.
    pub patches: usize,
    /// Planar patches (3D) or straight chains (2D).
    pub planar_patches: usize,
    /// Elements a crease runs between ([`Features::crease_elements`]).
    pub crease_elements: usize,
}

impl Features {
    /// Detect the features of `mesh` (topology `topo`) with `params`, then apply `edits`
    /// (from `edits_path`, named in errors).
    pub fn detect(
        mesh: &LinearMesh,
        topo: &Topology,
        params: &FeatureParams,
        edits: &[FeatureEdit],
        edits_path: &Path,
    ) -> Result<Features, FeatureError> {
        let bad = |line: usize, what: String| FeatureError::Line {
            path: edits_path.to_owned(),
            line,
            what,
        };
        let (vertex_mask, edge_mask) = if topo.dim == 2 {
            (
                corner_mask_2d(mesh, topo, params, edits, &bad)?,
                vec![false; topo.edges.len()],
            )
        } else {
            edge_masks_3d(mesh, topo, params, edits, &bad)?
        };
        let (facet_patch, n_patches) = patches(topo, &vertex_mask, &edge_mask);
        let nv = mesh.n_vertices();
        let (lo, hi) = mesh.bounding_box();
        let tol = 1e-6 * (DVec3::from(hi) - DVec3::from(lo)).length();
        let planes = if topo.dim == 3 {
            planar_patches(mesh, topo, &facet_patch, n_patches, tol)
        } else {
            straight_chains(mesh, topo, &facet_patch, n_patches, tol)
        };
        let edges: Vec<u32> = (0..edge_mask.len() as u32)
            .filter(|&e| edge_mask[e as usize])
            .collect();
        let corners = if topo.dim == 2 {
            (0..nv as u32)
                .filter(|&v| vertex_mask[v as usize])
                .collect()
        } else {
            let mut count = vec![0u32; nv];
            for &e in &edges {
                for v in topo.edges[e as usize] {
                    count[v as usize] += 1;
                }
            }
            (0..nv as u32)
                .filter(|&v| count[v as usize] != 0 && count[v as usize] != 2)
                .collect()
        };
        Ok(Features {
            dim: topo.dim,
            edges,
            corners,
            facet_patch,
            n_patches,
            planes,
            vertex_mask,
            edge_mask,
            thin_rim: Vec::new(),
        })
    }

    /// Features by angle and tags alone (no edits).
    pub fn detect_without_edits(
        mesh: &LinearMesh,
        topo: &Topology,
        params: &FeatureParams,
    ) -> Features {
        Self::detect(mesh, topo, params, &[], Path::new("")).expect("no edits, so no edit errors")
    }

    /// Whether vertex `v` lies on a thin rim ([`Features::thin_rim`]).
    pub fn on_thin_rim(&self, v: u32) -> bool {
        self.thin_rim.get(v as usize).copied().unwrap_or(false)
    }

    /// True when nothing was found.
    pub fn is_empty(&self) -> bool {
        !self.vertex_mask.iter().any(|&m| m)
    }

    /// Counts for reports.
    pub fn summary(&self, params: &FeatureParams, topo: &Topology) -> FeatureSummary {
        FeatureSummary {
            feature_angle_deg: params.angle_deg,
            tags: params.tags,
            feature_edges: self.edges.len(),
            feature_corners: self.corners.len(),
            feature_vertices: self.vertex_mask.iter().filter(|&&m| m).count(),
            patches: self.n_patches,
            planar_patches: self.planes.iter().filter(|p| p.is_some()).count(),
            crease_elements: self.crease_elements(topo).iter().filter(|&&c| c).count(),
        }
    }

    /// (feature vertex deviation, planarity) of the sampled mesh `ho` of `mesh`, relative to
    /// the bounding-box diagonal (see [`FeatureReport`]).
    /// `rows[i]`, when given, is the row of `ho.boundary` of the features' boundary facet i
    /// (features found on a topology with fewer boundary facets than `ho`'s, as a periodic
    /// mesh's with its seams interior); else row i.
    pub fn deviations(
        &self,
        mesh: &LinearMesh,
        ho: &crate::mesh::HighOrderMesh,
        rows: Option<&[u32]>,
    ) -> (f64, f64) {
        let (lo, hi) = mesh.bounding_box();
        let diag = (DVec3::from(hi) - DVec3::from(lo))
            .length()
            .max(f64::MIN_POSITIVE);
        let vertex = (0..mesh.n_vertices())
            .filter(|&v| self.vertex_mask[v])
            .map(|v| (DVec3::from(ho.nodes[v]) - DVec3::from(mesh.coords[v])).length())
            .fold(0.0, f64::max);
        let npf = ho.nodes_per_facet();
        let mut planarity = 0.0f64;
        for (i, &p) in self.facet_patch.iter().enumerate() {
            if let Some(Some((n, d))) = self.planes.get(p as usize) {
                let r = rows.map_or(i, |r| r[i] as usize);
                for &k in &ho.boundary[r * npf..(r + 1) * npf] {
                    let x = DVec3::from(ho.nodes[k as usize]);
                    planarity = planarity.max((DVec3::from(*n).dot(x) - d).abs());
                }
            }
        }
        (vertex / diag, planarity / diag)
    }

    /// Elements on either side of a crease that runs *between* elements: in 3D a feature edge
    /// whose boundary faces belong to two different elements, in 2D a corner whose two boundary
    /// edges do. They become constrained Q2 elements, so the map is only C⁰ there; a crease
    /// along one element's own edge is C⁰ inside that element already.
    pub fn crease_elements(&self, topo: &Topology) -> Vec<bool> {
        let mut mark = vec![false; topo.n_elements];
        // Element of each boundary facet at each feature vertex / edge.
        let mut owners: std::collections::HashMap<u32, Vec<u32>> = Default::default();
        for &f in &topo.boundary_facets {
            let e = topo.facet_elements[f as usize][0];
            if self.dim == 2 {
                for &v in topo.facet_vertices(f as usize) {
                    if self.vertex_mask[v as usize] {
                        owners.entry(v).or_default().push(e);
                    }
                }
            } else {
                let side = topo.facet_sides[f as usize][0] as usize;
                for ed in face_edges(topo, e as usize, side) {
                    if self.edge_mask[ed as usize] {
                        owners.entry(ed).or_default().push(e);
                    }
                }
            }
        }
        for es in owners.values() {
            if es.iter().any(|&e| e != es[0]) {
                for &e in es {
                    mark[e as usize] = true;
                }
            }
        }
        mark
    }

    /// Each feature vertex's neighbours along the feature edges (two where a feature curve
    /// passes through, more or one at corners and ends).
    pub fn curve_neighbours(&self, topo: &Topology) -> std::collections::HashMap<u32, Vec<u32>> {
        let mut along: std::collections::HashMap<u32, Vec<u32>> = Default::default();
        for &ed in &self.edges {
            let [a, b] = topo.edges[ed as usize];
            along.entry(a).or_default().push(b);
            along.entry(b).or_default().push(a);
        }
        along
    }

    /// 3D: the elements with a boundary face on a curved feature curve (a feature edge at whose
    /// ends the curve turns by more than [`CURVED_FEATURE_DEG`]), such as the cells along a
    /// cylinder's rims, unless they are thin ([`RIM_Q2_MIN_ASPECT`]). They become constrained
    /// Q2 elements: a C¹ spline along a curved rim, held at its vertices, leaves about four
    /// times the error of a quadratic interpolating the rim's targets (the smooth targets are
    /// accurate there), and its cross-rim neighbour is the other side of the crease, so the
    /// rim is only C⁰ anyway. Empty in 2D.
    pub fn curved_feature_elements(&self, mesh: &LinearMesh, topo: &Topology) -> Vec<bool> {
        let mut mark = vec![false; topo.n_elements];
        if self.dim != 3 || self.edges.is_empty() {
            return mark;
        }
        let x = |v: u32| DVec3::from(mesh.coords[v as usize]);
        let along = self.curve_neighbours(topo);
        let cos_straight = CURVED_FEATURE_DEG.to_radians().cos();
        let turns = |v: u32| -> bool {
            let Some(&[a, b]) = along.get(&v).map(|l| &l[..]) else {
                return false;
            };
            let (da, db) = (
                (x(v) - x(a)).normalize_or_zero(),
                (x(b) - x(v)).normalize_or_zero(),
            );
            da.dot(db) < cos_straight
        };
        for &f in &topo.boundary_facets {
            let e = topo.facet_elements[f as usize][0];
            let side = topo.facet_sides[f as usize][0] as usize;
            if !mark[e as usize]
                && face_edges(topo, e as usize, side).into_iter().any(|ed| {
                    self.edge_mask[ed as usize] && topo.edges[ed as usize].into_iter().any(turns)
                })
                && edge_aspect(mesh, topo, e as usize) >= RIM_Q2_MIN_ASPECT
            {
                mark[e as usize] = true;
            }
        }
        mark
    }
}

/// A feature curve turning by more than this angle (degrees) at a vertex is curved there
/// ([`Features::curved_feature_elements`]).
pub const CURVED_FEATURE_DEG: f64 = 1.0;

/// Cells along a curved feature curve with a shortest-to-longest edge ratio below this keep
/// their spline elements ([`Features::curved_feature_elements`]): a boundary-layer cell a
/// thousand times thinner than long, with Q2 targets on its wall side and the spline on its
/// inner side, folds (an extruded O-grid's wall went back to straight), while the spline
/// moves the layer as a whole.
pub const RIM_Q2_MIN_ASPECT: f64 = 0.1;

/// Shortest over longest edge of hex `e`.
fn edge_aspect(mesh: &LinearMesh, topo: &Topology, e: usize) -> f64 {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for &ed in &topo.element_edges[e * 12..(e + 1) * 12] {
        let [a, b] = topo.edges[ed as usize];
        let l =
            (DVec3::from(mesh.coords[a as usize]) - DVec3::from(mesh.coords[b as usize])).length();
        (lo, hi) = (lo.min(l), hi.max(l));
    }
    if hi > 0.0 { lo / hi } else { 0.0 }
}

/// A bad edit at a 1-based line of the edits file.
type BadEdit<'a> = dyn Fn(usize, String) -> FeatureError + 'a;

/// 2D: the corners (per vertex) by angle, tags and non-manifold fans, then `edits`.
fn corner_mask_2d(
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FeatureParams,
    edits: &[FeatureEdit],
    bad: &BadEdit,
) -> Result<Vec<bool>, FeatureError> {
    let nv = mesh.n_vertices();
    let tag = |i: usize| topo.boundary_facet_tags.get(i).copied().unwrap_or(0);
    let mut vertex_mask = vec![false; nv];
    let by_angle = corners_2d(mesh, topo, params.angle_deg);
    let mut at: Vec<Vec<usize>> = vec![Vec::new(); nv];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        for &v in topo.facet_vertices(f as usize) {
            at[v as usize].push(i);
        }
    }
    for v in 0..nv {
        match at[v][..] {
            [] => {}
            [i, j] => {
                vertex_mask[v] = by_angle[v] || (params.tags && tag(i) != tag(j));
            }
            // One boundary edge: the boundary goes on across a glued periodic seam (a closed
            // boundary has none such).
            [_] => {}
            _ => vertex_mask[v] = true,
        }
    }
    for ed in edits {
        let &[v] = &ed.vertices[..] else {
            return Err(bad(
                ed.line,
                "a 2D mesh's features are corners: give one vertex id".into(),
            ));
        };
        if v as usize >= nv || !topo.vertex_on_boundary[v as usize] {
            return Err(bad(
                ed.line,
                format!("vertex {v} is not a boundary vertex of the mesh ({nv} vertices)"),
            ));
        }
        vertex_mask[v as usize] = ed.add;
    }
    Ok(vertex_mask)
}

/// 3D: the feature edges (per topology edge) by angle, tags and non-manifold edges, then
/// `edits`; and the vertices on them.
fn edge_masks_3d(
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FeatureParams,
    edits: &[FeatureEdit],
    bad: &BadEdit,
) -> Result<(Vec<bool>, Vec<bool>), FeatureError> {
    let nv = mesh.n_vertices();
    let nb = topo.boundary_facets.len();
    let tag = |i: usize| topo.boundary_facet_tags.get(i).copied().unwrap_or(0);
    let mut vertex_mask = vec![false; nv];
    let mut edge_mask = vec![false; topo.edges.len()];
    let mut normal = vec![DVec3::ZERO; nb];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let q = topo.faces[f as usize];
        let x = |k: usize| DVec3::from(mesh.coords[q[k] as usize]);
        normal[i] = unit((x(2) - x(0)).cross(x(3) - x(1)));
    }
    let mut edge_facets: Vec<Vec<usize>> = vec![Vec::new(); topo.edges.len()];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let fe = topo.facet_elements[f as usize][0] as usize;
        let side = topo.facet_sides[f as usize][0] as usize;
        for ed in face_edges(topo, fe, side) {
            edge_facets[ed as usize].push(i);
        }
    }
    let by_angle = creases_3d(mesh, topo, &normal, &edge_facets, params.angle_deg);
    for (ed, fs) in edge_facets.iter().enumerate() {
        edge_mask[ed] = match fs[..] {
            [] => false,
            [i, j] => by_angle[ed] || (params.tags && tag(i) != tag(j)),
            // One boundary face: the boundary goes on across a glued periodic seam.
            [_] => false,
            _ => true,
        };
    }
    for ed in edits {
        let &[a, b] = &ed.vertices[..] else {
            return Err(bad(
                ed.line,
                "a 3D mesh's features are edges: give two vertex ids".into(),
            ));
        };
        let key = [a.min(b), a.max(b)];
        let id = topo
            .edges
            .binary_search(&key)
            .ok()
            .filter(|&id| topo.edge_on_boundary[id]);
        let Some(id) = id else {
            return Err(bad(
                ed.line,
                format!("vertices {a} and {b} are not the ends of a boundary edge of the mesh"),
            ));
        };
        edge_mask[id] = ed.add;
    }
    for (ed, &m) in edge_mask.iter().enumerate() {
        if m {
            for v in topo.edges[ed] {
                vertex_mask[v as usize] = true;
            }
        }
    }
    Ok((vertex_mask, edge_mask))
}

/// The patch of each boundary facet and the number of patches: boundary facets joined across
/// non-feature edges (3D) or vertices (2D), by union-find.
fn patches(topo: &Topology, vertex_mask: &[bool], edge_mask: &[bool]) -> (Vec<u32>, usize) {
    let nv = vertex_mask.len();
    let nb = topo.boundary_facets.len();
    // Patches: union boundary facets across non-feature edges (3D) / vertices (2D).
    let mut uf: Vec<u32> = (0..nb as u32).collect();
    fn find(uf: &mut [u32], mut i: u32) -> u32 {
        while uf[i as usize] != i {
            uf[i as usize] = uf[uf[i as usize] as usize];
            i = uf[i as usize];
        }
        i
    }
    let mut joined: Vec<u32> = vec![NONE; if topo.dim == 2 { nv } else { topo.edges.len() }];
    for (i, &f) in topo.boundary_facets.iter().enumerate() {
        let keys: Vec<u32> = if topo.dim == 2 {
            topo.facet_vertices(f as usize)
                .iter()
                .copied()
                .filter(|&v| !vertex_mask[v as usize])
                .collect()
        } else {
            let fe = topo.facet_elements[f as usize][0] as usize;
            let side = topo.facet_sides[f as usize][0] as usize;
            face_edges(topo, fe, side)
                .into_iter()
                .filter(|&ed| !edge_mask[ed as usize])
                .collect()
        };
        for k in keys {
            let j = joined[k as usize];
            if j == NONE {
                joined[k as usize] = i as u32;
            } else {
                let (a, b) = (find(&mut uf, i as u32), find(&mut uf, j));
                uf[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut facet_patch = vec![NONE; nb];
    let mut n_patches = 0;
    for i in 0..nb {
        let r = find(&mut uf, i as u32) as usize;
        if facet_patch[r] == NONE {
            facet_patch[r] = n_patches as u32;
            n_patches += 1;
        }
        facet_patch[i] = facet_patch[r];
    }
    (facet_patch, n_patches)
}

/// Topology edge ids of local side `side` of hex `e`.
pub fn face_edges(topo: &Topology, e: usize, side: usize) -> Vec<u32> {
    use crate::math::reference::HEX_EDGES;
    let k = side / 2;
    let s = (side % 2) as u8;
    (0..12)
        .filter(|&le| {
            let [a, b] = HEX_EDGES[le];
            crate::math::reference::HEX_VERTEX_PARAMS[a][k] == s
                && crate::math::reference::HEX_VERTEX_PARAMS[b][k] == s
        })
        .map(|le| topo.element_edges[e * 12 + le])
        .collect()
}

/// A turning above the feature angle is a crease only where it is more than this many times
/// the turning next to it.
pub const CONCENTRATION: f64 = 4.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::generate::{grid_2d, grid_3d, uniform};

    fn detect(mesh: &LinearMesh, params: FeatureParams) -> Features {
        Features::detect_without_edits(mesh, &Topology::build(mesh), &params)
    }

    fn untagged(mut mesh: LinearMesh) -> LinearMesh {
        mesh.tagged_facets.clear();
        mesh.facet_tags.clear();
        mesh
    }

    /// A cube of 4×4×4 hexes: 12 feature edges of 4 mesh edges, 8 corners, 6 planar patches. The tags alone find the same. A cube of one hex turns by
    /// 90° at every edge, as a coarse sphere would: its tags find its edges, the angle does not.
    #[test]
    fn cube_has_twelve_feature_edges_and_eight_corners() {
        let one = grid_3d(&[0.0, 1.0], &[0.0, 1.0], &[0.0, 1.0]);
        let f = detect(&one, FeatureParams::default());
        assert_eq!((f.edges.len(), f.corners.len(), f.n_patches), (12, 8, 6));
        assert!(f.planes.iter().all(|p| p.is_some()));
        assert!(detect(&untagged(one), FeatureParams::default()).is_empty());
        let u = uniform(4, 0.25);
        let grid = grid_3d(&u, &u, &u);
        let f = detect(&untagged(grid.clone()), FeatureParams::default());
        assert_eq!((f.edges.len(), f.corners.len(), f.n_patches), (48, 8, 6));
        // Vertices on the 12 cube edges: 8 corners + 12 × 3 inner ones.
        assert_eq!(f.vertex_mask.iter().filter(|&&m| m).count(), 44);
        let tags_only = FeatureParams {
            angle_deg: 180.0,
            tags: true,
        };
        let t = detect(&grid, tags_only);
        assert_eq!((t.edges, t.corners), (f.edges, f.corners));
        assert!(detect(&untagged(grid), tags_only).is_empty());
    }

    /// An extruded polygon: the rims are features at 35°, the 30° turns between wall facets
    /// are not; at 25° the wall's vertical edges are not either (every one turns alike: a
    /// smooth wall sampled coarsely), but a spike in the wall is.
    #[test]
    fn cylinder_rims_and_angle_threshold() {
        let k = 12; // 30° between neighbouring wall facets
        let ring = |r: f64| -> Vec<[f64; 3]> {
            (0..k)
                .map(|i| {
                    let t = std::f64::consts::TAU * i as f64 / k as f64;
                    [r * t.cos(), r * t.sin(), 0.0]
                })
                .collect()
        };
        // Annulus of k quads between radii 1 and 2, extruded in 2 layers.
        let mut coords = ring(1.0);
        coords.extend(ring(2.0));
        let mut elements = Vec::new();
        for i in 0..k as u32 {
            let j = (i + 1) % k as u32;
            elements.extend([i, k as u32 + i, k as u32 + j, j]);
        }
        let annulus = LinearMesh {
            dim: 2,
            coords,
            elements,
            ..Default::default()
        };
        let mesh = crate::mesh::generate::extrude(&annulus, &[0.0, 0.5, 1.0]);
        let mesh = untagged(mesh);
        let f = detect(&mesh, FeatureParams::default());
        // 4 rims of k edges (inner/outer × bottom/top), no corners, 4 patches.
        assert_eq!((f.edges.len(), f.corners.len(), f.n_patches), (4 * k, 0, 4));
        assert_eq!(f.planes.iter().filter(|p| p.is_some()).count(), 2);
        let fine = detect(
            &mesh,
            FeatureParams {
                angle_deg: 25.0,
                tags: false,
            },
        );
        assert_eq!(fine.edges, f.edges);
        assert!(detect(&mesh, FeatureParams::off()).is_empty());
        // Pull the outer wall out to a spike at (3, 0): the wall turns by 104° there and by
        // -7° (the other way) next to it, so the spike's edge is a crease.
        let mut bent = mesh.clone();
        for p in bent.coords.iter_mut() {
            if (p[0] - 2.0).abs() < 1e-12 && p[1].abs() < 1e-12 {
                p[0] = 3.0;
            }
        }
        let g = detect(&bent, FeatureParams::default());
        let vertical: Vec<[f64; 3]> = g
            .edges
            .iter()
            .map(|&e| Topology::build(&bent).edges[e as usize])
            .filter(|[p, q]| bent.coords[*p as usize][2] != bent.coords[*q as usize][2])
            .map(|[p, _]| bent.coords[p as usize])
            .collect();
        assert!(!vertical.is_empty(), "{:?}", g.edges.len());
        assert!(vertical.iter().all(|x| x[0] == 3.0 && x[1].abs() < 1e-12));
    }

    /// 2D: the corners of a square are features, the straight sides' vertices are not; a
    /// crease between two elements marks both.
    #[test]
    fn square_corners_in_2d_and_crease_elements() {
        let u = uniform(3, 1.0 / 3.0);
        let mesh = untagged(grid_2d(&u, &u));
        let topo = Topology::build(&mesh);
        let f = Features::detect_without_edits(&mesh, &topo, &FeatureParams::default());
        assert_eq!(f.corners, vec![0, 3, 12, 15]);
        assert_eq!(f.n_patches, 4);
        // The four sides are straight chains, on their lines to rounding.
        for (i, &e) in topo.boundary_facets.iter().enumerate() {
            let (n, d) = f.planes[f.facet_patch[i] as usize].expect("straight");
            for v in topo.edges[e as usize] {
                assert!((DVec3::from(n).dot(mesh.coords[v as usize].into()) - d).abs() < 1e-15);
            }
        }
        // Each corner is one quad's own corner: nothing to demote.
        assert!(f.crease_elements(&topo).iter().all(|&m| !m));
        // A corner added on the bottom side runs between quads 0 and 1.
        let edits = [FeatureEdit {
            add: true,
            vertices: vec![1],
            line: 1,
        }];
        let f = Features::detect(
            &mesh,
            &topo,
            &FeatureParams::default(),
            &edits,
            Path::new("e"),
        )
        .unwrap();
        let marked: Vec<usize> = (0..9).filter(|&e| f.crease_elements(&topo)[e]).collect();
        assert_eq!(marked, vec![0, 1]);
        assert_eq!(f.n_patches, 5);
    }

    /// Edits add and remove edges; bad lines are refused with the file and line named.
    #[test]
    fn edits_file_adds_removes_and_reports_bad_lines() {
        let u = uniform(3, 1.0 / 3.0);
        let mesh = untagged(grid_3d(&u, &u, &u));
        let topo = Topology::build(&mesh);
        let p = FeatureParams::default();
        // Vertices 0–1 lie on a cube edge; 1–2 too; 5–6 is an edge of the bottom face's inside.
        let path = Path::new("edits.txt");
        let text = "# edits\nremove 0 1\n\nadd 5 6  # a line on the bottom face\n";
        let edits = parse_edits(text, path).unwrap();
        let f = Features::detect(&mesh, &topo, &p, &edits, path).unwrap();
        let base = Features::detect_without_edits(&mesh, &topo, &p);
        assert_eq!(f.edges.len(), base.edges.len());
        let id = |a: u32, b: u32| topo.edges.binary_search(&[a, b]).unwrap();
        assert!(!f.edge_mask[id(0, 1)] && base.edge_mask[id(0, 1)]);
        assert!(f.edge_mask[id(5, 6)] && !base.edge_mask[id(5, 6)]);
        for (text, needle) in [
            ("add 0 1\nmove 1 2\n", ":2: unknown edit `move`"),
            ("add 0 x\n", ":1: `x` is not a vertex id"),
            ("add 0 1 2\n", ":1: expected one vertex id"),
            (
                "\nadd 0 63\n",
                ":2: vertices 0 and 63 are not the ends of a boundary edge",
            ),
            ("add 21 22\n", ":1: vertices 21 and 22"), // an interior edge
            ("remove 0\n", ":1: a 3D mesh's features are edges"),
            ("add 0 1000\n", ":1: vertices 0 and 1000"),
        ] {
            let err = parse_edits(text, path)
                .and_then(|e| Features::detect(&mesh, &topo, &p, &e, path))
                .unwrap_err()
                .to_string();
            assert!(
                err.starts_with(&path.display().to_string()) && err.contains(needle),
                "{text:?}: {err}"
            );
        }
    }
    /// On an O-grid cylinder the cells with a face on a rim are marked (their rim is a curved
    /// feature curve), and no others; a box's straight feature edges mark nothing.
    #[test]
    fn cells_along_curved_rims() {
        let disc = crate::mesh::generate::butterfly_disc(4, 2);
        let zs = uniform(3, 1.0 / 3.0);
        let mesh = crate::mesh::generate::extrude(&disc, &zs);
        let topo = Topology::build(&mesh);
        let f = detect(&mesh, FeatureParams::default());
        let marked = f.curved_feature_elements(&mesh, &topo);
        let on_wall = |v: u32| {
            let x = mesh.coords[v as usize];
            (x[0].hypot(x[1]) - 1.0).abs() < 1e-9
        };
        let on_cap = |v: u32| {
            let z = mesh.coords[v as usize][2];
            z.abs() < 1e-9 || (z - 1.0).abs() < 1e-9
        };
        let mut n = 0;
        for e in 0..mesh.n_elements() {
            let vs = mesh.element(e);
            let rim = vs.iter().filter(|&&v| on_wall(v) && on_cap(v)).count();
            assert_eq!(marked[e], rim >= 2, "element {e}");
            n += marked[e] as usize;
        }
        assert!(n > 0);
        let bx = grid_3d(&uniform(3, 1.0), &uniform(3, 1.0), &uniform(3, 1.0));
        let tb = Topology::build(&bx);
        let fb = detect(&bx, FeatureParams::default());
        assert!(!fb.edges.is_empty());
        assert!(fb.curved_feature_elements(&bx, &tb).iter().all(|&m| !m));
    }
}
