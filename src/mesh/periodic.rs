//! Periodic boundary pairs (`--periodic A:B`): two boundary groups of a mesh that are images of
//! each other under a rigid transform, a translation or a rotation about an axis.
//!
//! Input: the linear mesh, its topology and the pairs as the user names them
//! ([`PeriodicSpec`]: boundary names or tags). Output: one [`PeriodicPair`] per spec (the tags,
//! the transform found from the vertex positions, the vertex map), or a one-line
//! [`PeriodicError`]. After sampling, [`node_pairs`] pairs the order-P nodes of the two sides
//! and [`make_images`] moves them so that the nodes of B are exactly the transform of A's.
//! The distributed job (`distributed::periodic`) finds its pairs on the gathered sides with
//! [`pair_facets`] and moves its gathered seam nodes with [`place_images`], the same code.
//!
//! Invariants of an accepted pair: A and B are different non-empty boundary groups with as many
//! vertices each; every vertex of A, mapped by the transform, lies within [`PERIODIC_REL_TOL`]
//! times its shortest boundary edge of a vertex of B, and the map is one-to-one.
//!
//! The transform is found without knowing the correspondence: the translation between the
//! centroids, else rotations built from frames that a rigid map carries from A to B (the
//! area-weighted normal of the group and the principal axes of its vertex cloud, with either
//! sign) that carry A's outward normal onto B's inward one, each verified, the best kept.

use crate::math::linalg::DVec3;
use crate::mesh::high_order::HighOrderMesh;
use crate::mesh::raw::DeclaredPeriodic;
use crate::mesh::{LinearMesh, Topology};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};

/// Largest distance, relative to the vertex's shortest boundary edge, between a vertex of A
/// mapped by the transform and its vertex of B.
pub const PERIODIC_REL_TOL: f64 = 1e-6;

/// How many groups an error message lists.
const MAX_LISTED: usize = 8;

/// One `--periodic A:B`: boundary A (the master) is mapped onto boundary B (its image).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PeriodicSpec {
    /// Boundary name or tag of the master side.
    pub master: String,
    /// Boundary name or tag of the image side.
    pub slave: String,
    /// Declared by the input file (Gmsh's `$Periodic`) rather than given with `--periodic`.
    pub from_file: bool,
}

impl PeriodicSpec {
    /// How messages name the pair: `--periodic A:B`, or `$Periodic pair A:B` for a pair of the
    /// input file.
    pub fn label(&self) -> String {
        match self.from_file {
            false => format!("--periodic {self}"),
            true => format!("$Periodic pair {self}"),
        }
    }
}

impl std::str::FromStr for PeriodicSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.split_once(':') {
            Some((a, b)) if !a.is_empty() && !b.is_empty() && !b.contains(':') => {
                Ok(PeriodicSpec {
                    master: a.to_string(),
                    slave: b.to_string(),
                    from_file: false,
                })
            }
            _ => Err(format!(
                "expected A:B (two boundary names or tags), got {s:?}"
            )),
        }
    }
}

impl std::fmt::Display for PeriodicSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.master, self.slave)
    }
}

/// Why a periodic pair cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("{spec}: {what}")]
pub struct PeriodicError {
    /// The pair as given ([`PeriodicSpec::label`]).
    pub spec: String,
    /// What is wrong, in one line.
    pub what: String,
}

/// A rigid map x ↦ R x + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    /// The rotation R (rows).
    pub rotation: [[f64; 3]; 3],
    /// The translation t.
    pub translation: [f64; 3],
}

impl Rigid {
    /// The translation by `t`.
    pub fn translation(t: [f64; 3]) -> Rigid {
        Rigid {
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation: t,
        }
    }

    /// The map CGNS's `Periodic_t` states (the inverse of
    /// [`Rigid::center_angles_translation`]): x' = R (x − c) + c + T, R = R_z(γ) R_y(β) R_x(α).
    pub fn from_center_angles_translation(c: [f64; 3], angles: [f64; 3], t: [f64; 3]) -> Rigid {
        let (sa, ca) = angles[0].sin_cos();
        let (sb, cb) = angles[1].sin_cos();
        let (sg, cg) = angles[2].sin_cos();
        let rotation = [
            [cg * cb, cg * sb * sa - sg * ca, cg * sb * ca + sg * sa],
            [sg * cb, sg * sb * sa + cg * ca, sg * sb * ca - cg * sa],
            [-sb, cb * sa, cb * ca],
        ];
        let mut r = Rigid {
            rotation,
            translation: [0.0; 3],
        };
        let rc = r.apply(c);
        r.translation = std::array::from_fn(|i| c[i] + t[i] - rc[i]);
        r
    }

    /// The map of a 4×4 affine matrix by rows (its last row ignored).
    pub fn from_affine(a: &[f64; 16]) -> Rigid {
        Rigid {
            rotation: [[a[0], a[1], a[2]], [a[4], a[5], a[6]], [a[8], a[9], a[10]]],
            translation: [a[3], a[7], a[11]],
        }
    }

    /// R x + t.
    pub fn apply(&self, x: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        let t = &self.translation;
        std::array::from_fn(|i| r[i][0] * x[0] + r[i][1] * x[1] + r[i][2] * x[2] + t[i])
    }

    /// R v: the map's turn of a direction (a normal, a tangent).
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        std::array::from_fn(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    }

    /// The map `self` ∘ `b`: x ↦ R (R_b x + t_b) + t.
    pub fn after(&self, b: &Rigid) -> Rigid {
        let (ra, rb) = (&self.rotation, &b.rotation);
        Rigid {
            rotation: std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..3).map(|k| ra[i][k] * rb[k][j]).sum())
            }),
            translation: self.apply(b.translation),
        }
    }

    /// Rᵀ (x − t).
    pub fn apply_inverse(&self, x: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        let y = [
            x[0] - self.translation[0],
            x[1] - self.translation[1],
            x[2] - self.translation[2],
        ];
        std::array::from_fn(|i| r[0][i] * y[0] + r[1][i] * y[1] + r[2][i] * y[2])
    }

    /// The inverse map x ↦ Rᵀ x − Rᵀ t.
    pub fn inverse(&self) -> Rigid {
        let r = &self.rotation;
        let rotation = std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]));
        let back = self.apply_inverse([0.0; 3]);
        Rigid {
            rotation,
            translation: back,
        }
    }

    /// The map as CGNS's `Periodic_t` states it: x' = R (x − c) + c + T with R the rotation
    /// about x by α, then about y by β, then about z by γ (R = R_z R_y R_x, counter-clockwise,
    /// radians). Returns (c, [α, β, γ], T): for a rotation c is [`Rigid::axis_angle`]'s point
    /// on the axis, so T is the screw part along the axis (0 for a pure rotation); for a
    /// translation c = 0 and T = t.
    pub fn center_angles_translation(&self) -> ([f64; 3], [f64; 3], [f64; 3]) {
        let Some((_, c, _)) = self.axis_angle() else {
            return ([0.0; 3], [0.0; 3], self.translation);
        };
        let r = &self.rotation;
        // R_z(γ) R_y(β) R_x(α): r[2][0] = −sin β, r[2][1] = cos β sin α, r[2][2] = cos β cos α,
        // r[1][0] = sin γ cos β, r[0][0] = cos γ cos β.
        let beta = (-r[2][0]).clamp(-1.0, 1.0).asin();
        let (alpha, gamma) = if beta.cos() > 1e-12 {
            (r[2][1].atan2(r[2][2]), r[1][0].atan2(r[0][0]))
        } else {
            // Gimbal lock: only α ∓ γ is defined; put it all in γ.
            (0.0, (-r[0][1]).atan2(r[1][1]))
        };
        // T = t − (I − R) c = (R c + t) − c.
        let image = self.apply(c);
        (
            c,
            [alpha, beta, gamma],
            std::array::from_fn(|i| image[i] - c[i]),
        )
    }

    /// R is the identity.
    pub fn is_translation(&self) -> bool {
        let r = &self.rotation;
        (0..3).all(|i| (0..3).all(|j| r[i][j] == if i == j { 1.0 } else { 0.0 }))
    }

    /// The 4×4 affine matrix by rows (Gmsh's `$Periodic` transform, master to image).
    pub fn affine(&self) -> [f64; 16] {
        let r = &self.rotation;
        let t = &self.translation;
        [
            r[0][0], r[0][1], r[0][2], t[0], r[1][0], r[1][1], r[1][2], t[1], r[2][0], r[2][1],
            r[2][2], t[2], 0.0, 0.0, 0.0, 1.0,
        ]
    }

    /// A rotation's unit axis, a point on the axis (the one nearest the origin) and its angle
    /// in degrees (right-handed about the axis); `None` for a translation. The translation
    /// along the axis (a screw) is `translation · axis`.
    pub fn axis_angle(&self) -> Option<([f64; 3], [f64; 3], f64)> {
        if self.is_translation() {
            return None;
        }
        let r = &self.rotation;
        let w = DVec3::new(r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]);
        let trace = r[0][0] + r[1][1] + r[2][2];
        let angle = w.length().atan2(trace - 1.0);
        let axis = if w.length() > 1e-12 {
            w / w.length()
        } else {
            // A half turn: the axis is the column of R + I of largest norm.
            let cols: Vec<DVec3> = (0..3)
                .map(|j| DVec3::new(r[0][j], r[1][j], r[2][j]) + DVec3::from_array(unit_col(j)))
                .collect();
            let best = cols
                .iter()
                .copied()
                .max_by(|a, b| a.length().total_cmp(&b.length()))
                .unwrap_or(DVec3::Z);
            best / best.length()
        };
        // The point p on the axis with p·axis = 0 and (I − R) p = t − (t·axis) axis.
        let t = DVec3::from_array(self.translation);
        let t_perp = t - axis * t.dot(axis);
        // (I − R) is invertible on the plane ⟂ axis: solve with the axis row added.
        let m = crate::math::linalg::DMat3::from_cols(
            DVec3::new(1.0 - r[0][0], -r[1][0], -r[2][0]) + axis * axis.x,
            DVec3::new(-r[0][1], 1.0 - r[1][1], -r[2][1]) + axis * axis.y,
            DVec3::new(-r[0][2], -r[1][2], 1.0 - r[2][2]) + axis * axis.z,
        );
        let p = m.inverse() * t_perp;
        Some((axis.to_array(), p.to_array(), angle.to_degrees()))
    }
}

fn unit_col(j: usize) -> [f64; 3] {
    let mut e = [0.0; 3];
    e[j] = 1.0;
    e
}

/// A verified periodic pair of boundary groups.
#[derive(Clone, Debug)]
pub struct PeriodicPair {
    /// The pair as given.
    pub spec: PeriodicSpec,
    /// Boundary tag of the master side A.
    pub master_tag: i32,
    /// Boundary tag of the image side B.
    pub slave_tag: i32,
    /// Maps A onto B.
    pub transform: Rigid,
    /// (vertex of B, vertex of A) for every vertex of B.
    pub vertex_map: Vec<[u32; 2]>,
    /// Largest |T(x_A) − x_B| over the vertex pairs of the input.
    pub input_mismatch: f64,
}

/// The node pairs of one periodic pair of a [`HighOrderMesh`]: what the MSH `$Periodic`
/// section writes.
#[derive(Clone, Debug, PartialEq)]
pub struct PeriodicLink {
    /// Boundary tag of the master side.
    pub master_tag: i32,
    /// Boundary tag of the image side.
    pub slave_tag: i32,
    /// Maps the master side onto the image side.
    pub transform: Rigid,
    /// (node of the image side, node of the master side), 0-based.
    pub node_pairs: Vec<[u32; 2]>,
}

/// One pair as the report and `info` show it.
#[deny(missing_docs)]
#[derive(Clone, Debug, Serialize)]
pub struct PeriodicSummary {
    /// The master side A as given (name or tag).
    pub master: String,
    /// The image side B as given.
    pub slave: String,
    /// Boundary tag of A.
    pub master_tag: i32,
    /// Boundary tag of B.
    pub slave_tag: i32,
    /// `translation` or `rotation`.
    pub kind: &'static str,
    /// t of the map x_B = R x_A + t.
    pub translation: [f64; 3],
    /// A rotation's unit axis (right-handed with `angle_degrees`).
    pub axis: Option<[f64; 3]>,
    /// A rotation's point on the axis nearest the origin.
    pub axis_point: Option<[f64; 3]>,
    /// A rotation's angle in degrees.
    pub angle_degrees: Option<f64>,
    /// Vertices of the input on each side.
    pub vertex_pairs: usize,
    /// Largest |T(x_A) − x_B| over the input's vertex pairs, relative to the bounding-box
    /// diagonal.
    pub input_mismatch: f64,
    /// Declared by the input file (Gmsh's `$Periodic`) rather than by `--periodic`.
    pub from_file: bool,
}

impl PeriodicPair {
    /// The pair as the report and `info` show it; `diagonal` scales the mismatch.
    pub fn summary(&self, diagonal: f64) -> PeriodicSummary {
        let rot = self.transform.axis_angle();
        PeriodicSummary {
            master: self.spec.master.clone(),
            slave: self.spec.slave.clone(),
            master_tag: self.master_tag,
            slave_tag: self.slave_tag,
            kind: if rot.is_some() {
                "rotation"
            } else {
                "translation"
            },
            translation: self.transform.translation,
            axis: rot.map(|r| r.0),
            axis_point: rot.map(|r| r.1),
            angle_degrees: rot.map(|r| r.2),
            vertex_pairs: self.vertex_map.len(),
            input_mismatch: self.input_mismatch / diagonal,
            from_file: self.spec.from_file,
        }
    }
}

impl std::fmt::Display for PeriodicSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = |a: [f64; 3]| format!("({:.6}, {:.6}, {:.6})", a[0], a[1], a[2]);
        write!(
            f,
            "{} -> {} (tags {} -> {}): ",
            self.master, self.slave, self.master_tag, self.slave_tag
        )?;
        match (self.axis, self.axis_point, self.angle_degrees) {
            (Some(a), Some(p), Some(deg)) => {
                write!(f, "rotation {deg:.6}° about axis {} through {}", v(a), v(p))?
            }
            _ => write!(f, "translation {}", v(self.translation))?,
        }
        write!(
            f,
            ", {} vertex pairs, mismatch {:.1e}{}",
            self.vertex_pairs,
            self.input_mismatch,
            if self.from_file {
                " (declared by the file)"
            } else {
                ""
            }
        )
    }
}

/// One side of a pair: its boundary facets' vertices with their shortest boundary edge, the
/// vertex centroid and the area-weighted outward normal.
struct Side {
    tag: i32,
    vertices: Vec<u32>,
    edge: Vec<f64>,
    centroid: DVec3,
    normal: DVec3,
}

fn point(x: [f64; 3]) -> DVec3 {
    DVec3::from_array(x)
}

/// One boundary facet of a side as `Side::from_facets` takes it: its vertices (indices into
/// the coordinates, in the facet's cyclic order) and the centroid of its element (the facet's
/// normal is turned away from it).
pub struct SideFacet {
    pub vertices: Vec<u32>,
    pub inside: [f64; 3],
}

impl Side {
    fn new(mesh: &LinearMesh, topo: &Topology, tag: i32) -> Side {
        let facets = topo
            .boundary_facets
            .iter()
            .zip(&topo.boundary_facet_tags)
            .filter(|&(_, &t)| t == tag)
            .map(|(&f, _)| {
                let f = f as usize;
                let ex = mesh.element(topo.facet_elements[f][0] as usize);
                let inside = ex
                    .iter()
                    .map(|&v| point(mesh.coords[v as usize]))
                    .sum::<DVec3>()
                    / ex.len() as f64;
                SideFacet {
                    vertices: topo.facet_vertices(f).to_vec(),
                    inside: inside.to_array(),
                }
            });
        Side::from_facets(&mesh.coords, mesh.dim, tag, facets)
    }

    /// The side made of `facets` over `coords` (a mesh's, or the gathered boundary of a
    /// distributed one).
    fn from_facets(
        coords: &[[f64; 3]],
        dim: usize,
        tag: i32,
        facets: impl Iterator<Item = SideFacet>,
    ) -> Side {
        let mut edge: HashMap<u32, f64> = HashMap::new();
        let mut normal = DVec3::ZERO;
        for f in facets {
            let vs = &f.vertices;
            let n = vs.len();
            for i in 0..n {
                let (a, b) = (vs[i], vs[(i + 1) % n]);
                let len = (point(coords[a as usize]) - point(coords[b as usize])).length();
                for v in [a, b] {
                    let e = edge.entry(v).or_insert(f64::INFINITY);
                    *e = e.min(len);
                }
            }
            let x: Vec<DVec3> = vs.iter().map(|&v| point(coords[v as usize])).collect();
            let centre = x.iter().copied().sum::<DVec3>() / n as f64;
            let mut nf = if dim == 2 {
                let d = x[1] - x[0];
                DVec3::new(d.y, -d.x, 0.0)
            } else {
                0.5 * (x[2] - x[0]).cross(x[3] - x[1])
            };
            // Outward: away from the centroid of the facet's element.
            if nf.dot(centre - point(f.inside)) < 0.0 {
                nf = -nf;
            }
            normal += nf;
        }
        let mut vertices: Vec<u32> = edge.keys().copied().collect();
        vertices.sort_unstable();
        let edge = vertices.iter().map(|v| edge[v]).collect();
        let centroid = vertices
            .iter()
            .map(|&v| point(coords[v as usize]))
            .sum::<DVec3>()
            / vertices.len().max(1) as f64;
        Side {
            tag,
            vertices,
            edge,
            centroid,
            normal,
        }
    }

    /// Principal axes of the vertex cloud (unit eigenvectors of its covariance).
    fn axes(&self, coords: &[[f64; 3]]) -> [DVec3; 3] {
        let mut c = [[0.0; 3]; 3];
        for &v in &self.vertices {
            let d = point(coords[v as usize]) - self.centroid;
            let d = d.to_array();
            for i in 0..3 {
                for j in 0..3 {
                    c[i][j] += d[i] * d[j];
                }
            }
        }
        symmetric_eigenvectors(c)
    }
}

/// Unit eigenvectors of a symmetric 3×3 matrix (cyclic Jacobi rotations).
fn symmetric_eigenvectors(mut a: [[f64; 3]; 3]) -> [DVec3; 3] {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A ← Jᵀ A J, V ← V J.
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    order.map(|j| DVec3::new(v[0][j], v[1][j], v[2][j]))
}

/// An orthonormal frame from two directions (None when they are nearly parallel).
fn frame(u: DVec3, w: DVec3) -> Option<[DVec3; 3]> {
    let lu = u.length();
    if lu == 0.0 || !lu.is_finite() {
        return None;
    }
    let e1 = u / lu;
    let w2 = w - e1 * w.dot(e1);
    if w2.length() <= 1e-6 * w.length() || w.length() == 0.0 {
        return None;
    }
    let e2 = w2 / w2.length();
    Some([e1, e2, e1.cross(e2)])
}

/// The rotation taking frame `a` onto frame `b` (R = B Aᵀ).
fn rotation_between(a: [DVec3; 3], b: [DVec3; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| b[k][i] * a[k][j]).sum::<f64>()))
}

/// Points in cells of side `h`, for nearest-point queries within `h`.
pub(crate) struct PointGrid<'a> {
    h: f64,
    points: &'a [[f64; 3]],
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl<'a> PointGrid<'a> {
    pub(crate) fn new(points: &'a [[f64; 3]], ids: &[u32], h: f64) -> PointGrid<'a> {
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for &i in ids {
            cells
                .entry(Self::key(points[i as usize], h))
                .or_default()
                .push(i);
        }
        PointGrid { h, points, cells }
    }
    fn key(x: [f64; 3], h: f64) -> [i64; 3] {
        x.map(|c| (c / h).floor() as i64)
    }
    /// The nearest point within about `h` of `q`, with its distance.
    pub(crate) fn nearest(&self, q: [f64; 3]) -> Option<(u32, f64)> {
        let k = Self::key(q, self.h);
        let mut best: Option<(u32, f64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(ids) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                        continue;
                    };
                    for &i in ids {
                        let d = (point(self.points[i as usize]) - point(q)).length();
                        if best.is_none_or(|b| d < b.1) {
                            best = Some((i, d));
                        }
                    }
                }
            }
        }
        best
    }
}

/// How well `t` maps side `a` onto the side in `grid`: the vertex map and the worst vertex of A by distance/tolerance with its distance (infinite where no vertex of B
/// is near).
struct Verdict {
    map: Vec<[u32; 2]>,
    worst: Option<(u32, f64, f64)>,
}

fn verify(coords: &[[f64; 3]], a: &Side, grid: &PointGrid, t: &Rigid) -> Verdict {
    let mut map = Vec::with_capacity(a.vertices.len());
    let mut used = HashMap::new();
    let mut worst: Option<(u32, f64, f64)> = None;
    for (k, &v) in a.vertices.iter().enumerate() {
        let q = t.apply(coords[v as usize]);
        let tol = PERIODIC_REL_TOL * a.edge[k];
        let (hit, d) = match grid.nearest(q) {
            Some((w, d)) => (Some(w), d),
            None => (None, f64::INFINITY),
        };
        let ratio = d / tol;
        // A vertex of B taken twice: the map is not one-to-one.
        let dup = hit.is_some_and(|w| used.insert(w, v).is_some());
        let ratio = if dup { f64::INFINITY } else { ratio };
        if ratio > 1.0 && worst.is_none_or(|w| ratio > w.1) {
            worst = Some((v, ratio, d));
        }
        if let Some(w) = hit {
            map.push([w, v]);
        }
    }
    Verdict { map, worst }
}

/// The boundary tag a name or tag string denotes.
fn resolve_tag(
    names: &BTreeMap<i32, String>,
    tags: &[i32],
    spec: &PeriodicSpec,
    s: &str,
) -> Result<i32, PeriodicError> {
    let by_name = names
        .iter()
        .filter(|(t, n)| n.as_str() == s && tags.contains(t))
        .map(|(t, _)| *t)
        .next();
    if let Some(t) = by_name {
        return Ok(t);
    }
    if let Ok(t) = s.parse::<i32>()
        && t != 0
        && tags.contains(&t)
    {
        return Ok(t);
    }
    let listed: Vec<String> = tags
        .iter()
        .filter(|&&t| t != 0)
        .take(MAX_LISTED)
        .map(|t| match names.get(t) {
            Some(n) => format!("{t} {n:?}"),
            None => t.to_string(),
        })
        .collect();
    let more = if tags.len() > MAX_LISTED { ", ..." } else { "" };
    Err(PeriodicError {
        spec: spec.label(),
        what: format!(
            "no boundary group named or tagged {s:?} (boundary groups: {}{more})",
            if listed.is_empty() {
                "none".to_string()
            } else {
                listed.join(", ")
            }
        ),
    })
}

/// Each tag in one pair at most, the two sides different.
fn distinct(
    seen: &mut Vec<i32>,
    spec: &PeriodicSpec,
    ta: i32,
    tb: i32,
) -> Result<(), PeriodicError> {
    let err = |what: String| PeriodicError {
        spec: spec.label(),
        what,
    };
    if ta == tb {
        return Err(err(format!("both sides are boundary tag {ta}")));
    }
    for t in [ta, tb] {
        if seen.contains(&t) {
            return Err(err(format!(
                "boundary tag {t} is already in another periodic pair"
            )));
        }
    }
    seen.extend([ta, tb]);
    Ok(())
}

/// The boundary tags (A, B) of every pair of `specs` among the boundary groups `tags` (sorted)
/// named by `names`: each names two different groups, and no group is in two pairs.
pub fn spec_tags(
    names: &BTreeMap<i32, String>,
    tags: &[i32],
    specs: &[PeriodicSpec],
) -> Result<Vec<(PeriodicSpec, i32, i32)>, PeriodicError> {
    let mut seen = Vec::new();
    specs
        .iter()
        .map(|spec| {
            let ta = resolve_tag(names, tags, spec, &spec.master)?;
            let tb = resolve_tag(names, tags, spec, &spec.slave)?;
            distinct(&mut seen, spec, ta, tb)?;
            Ok((spec.clone(), ta, tb))
        })
        .collect()
}

/// The sides of a mesh's boundary groups, each built once.
struct Sides<'m> {
    mesh: &'m LinearMesh,
    topo: &'m Topology,
    built: HashMap<i32, Side>,
}

impl Sides<'_> {
    fn get(&mut self, tag: i32) -> &Side {
        let (mesh, topo) = (self.mesh, self.topo);
        self.built
            .entry(tag)
            .or_insert_with(|| Side::new(mesh, topo, tag))
    }
}

/// Resolve and verify every pair of `specs` on the mesh, then the pairs the input declares
/// ([`LinearMesh::declared_periodic`], Gmsh's `$Periodic`) whose groups no pair of `specs`
/// names: a pair given on the command line wins over the file's for its groups. A declared
/// pair whose affine map disagrees with the transform found from the positions is an error.
pub fn resolve(
    mesh: &LinearMesh,
    topo: &Topology,
    specs: &[PeriodicSpec],
) -> Result<Vec<PeriodicPair>, PeriodicError> {
    let mut tags: Vec<i32> = topo.boundary_facet_tags.clone();
    tags.sort_unstable();
    tags.dedup();
    let mut resolved: Vec<Declared<'_>> = spec_tags(&mesh.tag_names, &tags, specs)?
        .into_iter()
        .map(|(spec, ta, tb)| (spec, ta, tb, Vec::new()))
        .collect();
    let mut seen: Vec<i32> = resolved.iter().flat_map(|r| [r.1, r.2]).collect();
    let given = seen.clone();
    let mut sides = Sides {
        mesh,
        topo,
        built: HashMap::new(),
    };
    let n_given = resolved.len();
    let images = |d: &DeclaredPeriodic| {
        // A claim naming no sides (CGNS): the groups its map carries onto each other.
        let groups: Vec<i32> = tags.iter().copied().filter(|&t| t != 0).collect();
        for &t in &groups {
            sides.get(t);
        }
        let all: Vec<&Side> = groups.iter().map(|t| &sides.built[t]).collect();
        images_under(mesh, &all, d)
    };
    resolved.extend(declared(
        &mesh.tag_names,
        &mesh.declared_periodic,
        &tags,
        &given,
        images,
    )?);
    let mut out = Vec::new();
    for (i, (spec, ta, tb, claims)) in resolved.iter().enumerate() {
        let err = |what: String| PeriodicError {
            spec: spec.label(),
            what,
        };
        let (ta, tb) = (*ta, *tb);
        if i >= n_given {
            distinct(&mut seen, spec, ta, tb)?;
        }
        sides.get(ta);
        sides.get(tb);
        let (a, b) = (&sides.built[&ta], &sides.built[&tb]);
        let found = pair(&mesh.coords, mesh.dim, spec, a, b).map_err(err)?;
        for claim in claims {
            check_declared(&mesh.coords, mesh.dim, a, &found, claim).map_err(err)?;
        }
        out.push(found);
    }
    Ok(out)
}

/// One pair found and verified on boundary facets given apart from a mesh (the gathered
/// boundary of a distributed mesh): `coords` holds the sides' vertices, `a` and `b` the
/// facets of sides `ta` and `tb`, and every file link in `claims` (a pair of
/// [`declared_pairs`]) must agree with the transform found, as [`resolve`] checks it. The
/// pair's vertex map is in indices of `coords`.
pub fn pair_facets(
    coords: &[[f64; 3]],
    dim: usize,
    spec: &PeriodicSpec,
    (ta, a): (i32, Vec<SideFacet>),
    (tb, b): (i32, Vec<SideFacet>),
    claims: &[&DeclaredPeriodic],
) -> Result<PeriodicPair, PeriodicError> {
    let a = Side::from_facets(coords, dim, ta, a.into_iter());
    let b = Side::from_facets(coords, dim, tb, b.into_iter());
    let err = |what| PeriodicError {
        spec: spec.label(),
        what,
    };
    let found = pair(coords, dim, spec, &a, &b).map_err(err)?;
    for claim in claims {
        check_declared(coords, dim, &a, &found, claim).map_err(err)?;
    }
    Ok(found)
}

/// A file's pair with the links it gathers.
pub type Declared<'m> = (PeriodicSpec, i32, i32, Vec<&'m DeclaredPeriodic>);

/// The pairs the file declares (`declared`, Gmsh's `$Periodic` links naming their sides)
/// among the boundary groups `tags` (sorted) named by `names`, after the pairs `given` (the
/// command line's, whose groups they may not name; `seen`: their groups), each checked as
/// [`resolve`] checks them: what the ranks of a distributed job run on the gathered groups.
/// A claim naming no sides (CGNS, which the ranks do not read) is refused.
pub fn declared_pairs<'m>(
    names: &BTreeMap<i32, String>,
    declared: &'m [DeclaredPeriodic],
    tags: &[i32],
    seen: &mut Vec<i32>,
) -> Result<Vec<Declared<'m>>, PeriodicError> {
    let given = seen.clone();
    let out = self::declared(names, declared, tags, &given, |_| Vec::new())?;
    for (spec, ta, tb, _) in &out {
        distinct(seen, spec, *ta, *tb)?;
    }
    Ok(out)
}

/// The pairs of boundary groups the file declares, each with the file's links it gathers
/// (several entity pairs of one physical pair). A claim that gives its map only (CGNS) pairs
/// every two boundary groups the map carries onto each other ([`images_under`]). Left out: the
/// reverse of a pair already kept, and pairs naming a group of `given` (the command line's
/// pairs). A link whose sides are not two separate boundary groups (an entity without a
/// physical group, both in the same group, a group without boundary facets, or a map that
/// carries no group onto another) is an error: used as is, the written sides would no longer
/// be images of each other and the output would silently lose the periodicity the file
/// declares.
fn declared<'m>(
    names: &BTreeMap<i32, String>,
    declared: &'m [DeclaredPeriodic],
    tags: &[i32],
    given: &[i32],
    mut images: impl FnMut(&DeclaredPeriodic) -> Vec<(i32, i32)>,
) -> Result<Vec<Declared<'m>>, PeriodicError> {
    let mut out: Vec<Declared<'m>> = Vec::new();
    let name = |t: i32| names.get(&t).cloned().unwrap_or(t.to_string());
    for d in declared {
        let refuse = |why: String| PeriodicError {
            spec: claim_place(d),
            what: format!("{why}, or remove the link"),
        };
        let pairs = match d.sides {
            Some([ta, tb]) => {
                let why = if ta == 0 || tb == 0 {
                    Some("an entity has no physical group, so its facets are no boundary group to pair; give both entities a physical group (Gmsh: Physical Curve/Surface)".to_string())
                } else if ta == tb {
                    Some(format!(
                        "both entities are in physical group {}; put the two sides in separate physical groups",
                        name(ta)
                    ))
                } else if let Some(&t) = [ta, tb].iter().find(|t| !tags.contains(t)) {
                    Some(format!(
                        "physical group {} has no boundary facets in the mesh",
                        name(t)
                    ))
                } else {
                    None
                };
                if let Some(why) = why {
                    return Err(refuse(why));
                }
                vec![(ta, tb)]
            }
            None => {
                let found = images(d);
                if found.is_empty() {
                    return Err(refuse(
                        "its map carries no boundary group onto another; put each side in a boundary condition of its own, or pair them with --periodic A:B".into(),
                    ));
                }
                found
            }
        };
        for (ta, tb) in pairs {
            if given.contains(&ta) || given.contains(&tb) {
                continue;
            }
            if let Some(o) = out.iter_mut().find(|o| o.1 == ta && o.2 == tb) {
                o.3.push(d);
                continue;
            }
            if out.iter().any(|o| o.1 == tb && o.2 == ta) {
                continue;
            }
            let spec = PeriodicSpec {
                master: name(ta),
                slave: name(tb),
                from_file: true,
            };
            out.push((spec, ta, tb, vec![d]));
        }
    }
    Ok(out)
}

/// A claim and where the file makes it (a tree file's source already names its node).
fn claim_place(d: &DeclaredPeriodic) -> String {
    match d.location {
        crate::mesh::raw::Location::Tree => d.source.clone(),
        l => format!("{} ({l})", d.source),
    }
}

/// The pairs (A, B) of boundary groups (`sides`) that the claim's map carries onto each other:
/// as many vertices, and the image of A's vertex bounding box and centroid on B's within a
/// thousandth of A's shortest edge (a screen; [`pair`] then verifies every vertex).
fn images_under(mesh: &LinearMesh, sides: &[&Side], claim: &DeclaredPeriodic) -> Vec<(i32, i32)> {
    let Some(a) = claim.affine else {
        return Vec::new();
    };
    let map = Rigid::from_affine(&a);
    let flat = |mut x: [f64; 3]| {
        if mesh.dim == 2 {
            x[2] = 0.0;
        }
        point(x)
    };
    let bbox = |xs: &mut dyn Iterator<Item = DVec3>| {
        xs.fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        })
    };
    let mut out = Vec::new();
    for sa in sides {
        let Some(shortest) = sa.edge.iter().copied().reduce(f64::min) else {
            continue;
        };
        let image = |v: &u32| flat(map.apply(mesh.coords[*v as usize]));
        let (lo, hi) = bbox(&mut sa.vertices.iter().map(image));
        let centroid = flat(map.apply(sa.centroid.to_array()));
        let tol = 1e-3 * shortest
            + 4.0
                * claim.precision
                * (hi.abs().max(lo.abs()).length() + point(map.translation).length());
        for sb in sides {
            if sb.tag == sa.tag || sb.vertices.len() != sa.vertices.len() {
                continue;
            }
            let (blo, bhi) = bbox(&mut sb.vertices.iter().map(|v| flat(mesh.coords[*v as usize])));
            let near = |p: DVec3, q: DVec3| (p - q).abs().max_element() <= tol;
            if near(lo, blo) && near(hi, bhi) && near(centroid, flat(sb.centroid.to_array())) {
                out.push((sa.tag, sb.tag));
            }
        }
    }
    out
}

/// The file's affine map of a declared pair must carry every vertex of A onto its vertex of B
/// as the transform found does (to the same tolerance).
fn check_declared(
    coords: &[[f64; 3]],
    dim: usize,
    side: &Side,
    found: &PeriodicPair,
    claim: &DeclaredPeriodic,
) -> Result<(), String> {
    let Some(a) = claim.affine else {
        return Ok(());
    };
    let map = Rigid::from_affine(&a);
    let mut worst: Option<(u32, f64, f64)> = None;
    for &[w, v] in &found.vertex_map {
        let Ok(k) = side.vertices.binary_search(&v) else {
            continue;
        };
        let mut x = map.apply(coords[v as usize]);
        if dim == 2 {
            x[2] = 0.0;
        }
        let d = (point(x) - point(coords[w as usize])).length();
        // A map stored in single precision is only as exact as its digits.
        let stored = 4.0 * claim.precision * (point(x).length() + point(map.translation).length());
        let tol = (PERIODIC_REL_TOL * side.edge[k])
            .max(2.0 * found.input_mismatch)
            .max(stored);
        let ratio = if d.is_finite() {
            d / tol
        } else {
            f64::INFINITY
        };
        if ratio > 1.0 && worst.is_none_or(|b| ratio > b.1) {
            worst = Some((v, ratio, d));
        }
    }
    match worst {
        None => Ok(()),
        Some((v, _, d)) => Err(format!(
            "the file's map ({}) disagrees with the transform found from the vertex positions: it puts vertex {v} {d:.3e} from its image (tolerance {PERIODIC_REL_TOL:e} of its edge)",
            claim_place(claim)
        )),
    }
}

/// Find and verify the transform mapping side `a` onto side `b` (vertices in `coords`).
fn pair(
    coords: &[[f64; 3]],
    dim: usize,
    spec: &PeriodicSpec,
    a: &Side,
    b: &Side,
) -> Result<PeriodicPair, String> {
    if a.vertices.len() != b.vertices.len() {
        return Err(format!(
            "{} has {} boundary vertices and {} has {}: they cannot be images of each other",
            spec.master,
            a.vertices.len(),
            spec.slave,
            b.vertices.len()
        ));
    }
    let shared: Vec<u32> = a
        .vertices
        .iter()
        .copied()
        .filter(|v| b.vertices.binary_search(v).is_ok())
        .collect();
    if !shared.is_empty() {
        return Err(format!(
            "{} and {} share {} vertices (first: {}); periodic sides must be apart",
            spec.master,
            spec.slave,
            shared.len(),
            shared[0]
        ));
    }
    let h = a
        .edge
        .iter()
        .chain(&b.edge)
        .copied()
        .fold(f64::INFINITY, f64::min);
    if !(h > 0.0 && h.is_finite()) {
        return Err(format!(
            "{} or {} has a zero-length edge",
            spec.master, spec.slave
        ));
    }
    let grid = PointGrid::new(coords, &b.vertices, h);
    let mut candidates = vec![Rigid::translation((b.centroid - a.centroid).to_array())];
    // Direction pairs a rigid map carries from A to B (up to sign).
    let (xa, xb) = (a.axes(coords), b.axes(coords));
    let mut dirs: Vec<(DVec3, DVec3)> = vec![(a.normal, b.normal)];
    if dim == 3 {
        // The smallest rotation between the normals (planar sides of a sector).
        dirs.push((a.normal.cross(-b.normal), a.normal.cross(-b.normal)));
        dirs.extend((0..3).map(|i| (xa[i], xb[i])));
    } else {
        dirs.extend(
            (0..3)
                .map(|i| (xa[i], xb[i]))
                .filter(|(u, _)| u.z.abs() < 0.5),
        );
        dirs.push((DVec3::Z, DVec3::Z));
    }
    for i in 0..dirs.len() {
        for j in 0..dirs.len() {
            if i == j {
                continue;
            }
            for si in [1.0, -1.0] {
                for sj in [1.0, -1.0] {
                    let (Some(fa), Some(fb)) = (
                        frame(dirs[i].0, dirs[j].0),
                        frame(dirs[i].1 * si, dirs[j].1 * sj),
                    ) else {
                        continue;
                    };
                    let r = rotation_between(fa, fb);
                    // A periodic map carries the outward normal of A onto the inward normal
                    // of B; a half turn that maps A onto B mirrored (and, in the plane, a
                    // flip of z) carries it onto the outward one and is no periodicity.
                    let rn = point(
                        Rigid {
                            rotation: r,
                            translation: [0.0; 3],
                        }
                        .apply(a.normal.to_array()),
                    );
                    if rn.dot(b.normal) > 0.0 || (dim == 2 && r[2][2] < 0.0) {
                        continue;
                    }
                    let t = b.centroid
                        - point(
                            Rigid {
                                rotation: r,
                                translation: [0.0; 3],
                            }
                            .apply(a.centroid.to_array()),
                        );
                    candidates.push(Rigid {
                        rotation: r,
                        translation: t.to_array(),
                    });
                }
            }
        }
    }
    let mut best: Option<(Rigid, Verdict)> = None;
    for t in candidates {
        let v = verify(coords, a, &grid, &t);
        let score = |v: &Verdict| v.worst.map_or(0.0, |w| w.1);
        let better = match &best {
            None => true,
            Some((_, bv)) => score(&v) < score(bv),
        };
        if better {
            best = Some((t, v));
        }
        if best.as_ref().is_some_and(|b| b.1.worst.is_none()) {
            break;
        }
    }
    let (mut transform, verdict) = best.expect("the translation is a candidate");
    if let Some((v, _, d)) = verdict.worst {
        let d = if d.is_finite() {
            d
        } else {
            // The distance to the nearest vertex of B, for the message.
            let q = transform.apply(coords[v as usize]);
            b.vertices
                .iter()
                .map(|&w| (point(coords[w as usize]) - point(q)).length())
                .fold(f64::INFINITY, f64::min)
        };
        let x = coords[v as usize];
        return Err(format!(
            "no translation or rotation maps {} onto {}: vertex {v} at ({:.6}, {:.6}, {:.6}) lands {d:.3e} from the nearest vertex of {} (tolerance {PERIODIC_REL_TOL:e} of its edge)",
            spec.master, spec.slave, x[0], x[1], x[2], spec.slave
        ));
    }
    // Least-squares translation over the matched vertices (the centroids' is the same for a
    // translation; for a rotation it removes the centroid rounding).
    let n = verdict.map.len() as f64;
    let rot_only = Rigid {
        rotation: transform.rotation,
        translation: [0.0; 3],
    };
    let mean = verdict
        .map
        .iter()
        .map(|&[w, v]| point(coords[w as usize]) - point(rot_only.apply(coords[v as usize])))
        .sum::<DVec3>()
        / n;
    transform.translation = mean.to_array();
    if dim == 2 {
        transform.translation[2] = 0.0;
    }
    let input_mismatch = verdict
        .map
        .iter()
        .map(|&[w, v]| {
            (point(coords[w as usize]) - point(transform.apply(coords[v as usize]))).length()
        })
        .fold(0.0, f64::max);
    let mut vertex_map = verdict.map;
    vertex_map.sort_unstable();
    Ok(PeriodicPair {
        spec: spec.clone(),
        master_tag: a.tag,
        slave_tag: b.tag,
        transform,
        vertex_map,
        input_mismatch,
    })
}

/// Nodes of the facets of `ho` tagged `tag`, sorted.
fn tagged_nodes(ho: &HighOrderMesh, tag: i32) -> Vec<u32> {
    let npf = ho.nodes_per_facet();
    let mut nodes: Vec<u32> = ho
        .boundary
        .chunks(npf)
        .zip(&ho.boundary_tags)
        .filter(|(_, t)| **t == tag)
        .flat_map(|(f, _)| f.iter().copied())
        .collect();
    nodes.sort_unstable();
    nodes.dedup();
    nodes
}

/// The order-P node pairs of each pair on `straight`, the straight-sided sampling of the input
/// at the output's order (before any subdivision; the curved and subdivided meshes number
/// their nodes alike). The straight nodes of the two sides are exact images, so they pair by
/// position; `pairs[i]` gives link `i`.
pub fn node_pairs(
    straight: &HighOrderMesh,
    pairs: &[PeriodicPair],
) -> Result<Vec<PeriodicLink>, PeriodicError> {
    let p = straight.order.max(1) as f64;
    pairs
        .iter()
        .map(|pair| {
            let a = tagged_nodes(straight, pair.master_tag);
            let b = tagged_nodes(straight, pair.slave_tag);
            let shortest = pair_spacing(straight, pair.slave_tag) / p;
            let grid = PointGrid::new(&straight.nodes, &b, shortest);
            let tol = (PERIODIC_REL_TOL * shortest).max(2.0 * pair.input_mismatch);
            let mut node_pairs = Vec::with_capacity(a.len());
            for &n in &a {
                let q = pair.transform.apply(straight.nodes[n as usize]);
                match grid.nearest(q) {
                    Some((m, d)) if d <= tol => node_pairs.push([m, n]),
                    _ => {
                        return Err(PeriodicError {
                            spec: pair.spec.label(),
                            what: format!(
                                "node {n} of the order-{} mesh has no image",
                                straight.order
                            ),
                        });
                    }
                }
            }
            node_pairs.sort_unstable();
            if node_pairs.len() != b.len() || node_pairs.windows(2).any(|w| w[0][0] == w[1][0]) {
                return Err(PeriodicError {
                    spec: pair.spec.label(),
                    what: format!(
                        "the order-{} nodes of the two sides do not pair one-to-one",
                        straight.order
                    ),
                });
            }
            Ok(PeriodicLink {
                master_tag: pair.master_tag,
                slave_tag: pair.slave_tag,
                transform: pair.transform,
                node_pairs,
            })
        })
        .collect()
}

/// Shortest facet edge (between facet corner nodes) of the facets tagged `tag`.
fn pair_spacing(ho: &HighOrderMesh, tag: i32) -> f64 {
    let npf = ho.nodes_per_facet();
    let p = ho.order;
    let corners: Vec<usize> = if ho.dim == 2 {
        vec![0, p]
    } else {
        vec![0, p, (p + 1) * (p + 1) - 1, (p + 1) * p]
    };
    let mut h = f64::INFINITY;
    for (f, _) in ho
        .boundary
        .chunks(npf)
        .zip(&ho.boundary_tags)
        .filter(|(_, t)| **t == tag)
    {
        for i in 0..corners.len() {
            let a = ho.nodes[f[corners[i]] as usize];
            let b = ho.nodes[f[corners[(i + 1) % corners.len()]] as usize];
            h = h.min((point(a) - point(b)).length());
        }
    }
    h
}

/// What [`make_images`] did.
#[derive(Clone, Copy, Debug, Default)]
pub struct ImageInfo {
    /// Largest move of a seam node.
    pub max_shift: f64,
    /// Largest |T(x_A) − x_B| over the node pairs after the move.
    pub max_mismatch: f64,
    /// Elements re-certified because a node of theirs moved.
    pub recertified: usize,
    /// Smallest certified lower bound of det J over the re-certified elements (∞ for none).
    pub min_det_bound: f64,
}

/// Weights of the master node in its new position, tried in turn for the pairs around
/// elements that lose their certificate: the midpoint, then each side kept.
pub const IMAGE_WEIGHTS: [f64; 3] = [0.5, 1.0, 0.0];

/// Place the seam nodes of `links` (indices into `nodes`) from their `original` positions:
/// the master of pair k of link l at `w·x_A + (1−w)·T⁻¹(x_B)`, w = `IMAGE_WEIGHTS[weight[l][k]]`,
/// then every image at T of its master, in link order, repeated so that a node that is an
/// image in one pair and a master in another (corners of doubly periodic meshes) settles.
pub fn place_images(
    nodes: &mut [[f64; 3]],
    original: &[[f64; 3]],
    links: &[PeriodicLink],
    weight: &[Vec<usize>],
) {
    for (l, w) in links.iter().zip(weight) {
        for (k, &[s, m]) in l.node_pairs.iter().enumerate() {
            let wa = IMAGE_WEIGHTS[w[k]];
            let xa = point(original[m as usize]);
            let xb = point(l.transform.apply_inverse(original[s as usize]));
            nodes[m as usize] = (xa * wa + xb * (1.0 - wa)).to_array();
        }
    }
    for _ in 0..links.len() {
        for l in links {
            for &[s, m] in &l.node_pairs {
                nodes[s as usize] = l.transform.apply(nodes[m as usize]);
            }
        }
    }
}

/// Move the seam nodes of `ho` so that every image node is exactly the transform of its
/// master: the master goes to `w·x_A + (1−w)·T⁻¹(x_B)` and the image to T of that, `w` = ½
/// first; elements containing a moved node are certified (`certify` gives a certified lower
/// bound of det J, positive when valid), and around those that fail the other weights are
/// tried. Returns the elements still uncertified (empty on success) and the figures.
pub fn make_images(
    ho: &mut HighOrderMesh,
    links: &[PeriodicLink],
    certify: impl Fn(&HighOrderMesh, usize) -> f64 + Sync,
) -> (Vec<usize>, ImageInfo) {
    use rayon::prelude::*;
    let original = ho.nodes.clone();
    let mut weight: Vec<Vec<usize>> = links.iter().map(|l| vec![0; l.node_pairs.len()]).collect();
    place_images(&mut ho.nodes, &original, links, &weight);
    let moved: Vec<bool> = (0..ho.nodes.len())
        .map(|n| ho.nodes[n] != original[n])
        .collect();
    let npe = ho.nodes_per_element();
    let touched: Vec<usize> = (0..ho.n_elements())
        .filter(|&e| {
            ho.elements[e * npe..(e + 1) * npe]
                .iter()
                .any(|&n| moved[n as usize])
        })
        .collect();
    let mut check: Vec<usize> = touched.clone();
    let mut bad: Vec<usize> = Vec::new();
    let mut min_det_bound = f64::INFINITY;
    for round in 0..IMAGE_WEIGHTS.len() {
        let bounds: Vec<(usize, f64)> = check.par_iter().map(|&e| (e, certify(ho, e))).collect();
        min_det_bound = bounds.iter().map(|b| b.1).fold(f64::INFINITY, f64::min);
        bad = bounds
            .iter()
            .filter(|b| !(b.1 > 0.0))
            .map(|b| b.0)
            .collect();
        if bad.is_empty() || round + 1 == IMAGE_WEIGHTS.len() {
            break;
        }
        let mut in_bad = vec![false; ho.nodes.len()];
        for &e in &bad {
            for &n in &ho.elements[e * npe..(e + 1) * npe] {
                in_bad[n as usize] = true;
            }
        }
        for (l, w) in links.iter().zip(weight.iter_mut()) {
            for (k, &[s, m]) in l.node_pairs.iter().enumerate() {
                if in_bad[s as usize] || in_bad[m as usize] {
                    w[k] = round + 1;
                }
            }
        }
        place_images(&mut ho.nodes, &original, links, &weight);
        check = touched.clone();
    }
    let mut info = ImageInfo {
        recertified: touched.len(),
        min_det_bound,
        ..Default::default()
    };
    for n in 0..ho.nodes.len() {
        info.max_shift = info
            .max_shift
            .max((point(ho.nodes[n]) - point(original[n])).length());
    }
    info.max_mismatch = max_mismatch(&ho.nodes, links);
    (bad, info)
}

/// Largest |T(x_master) − x_image| over the node pairs of `links` (indices into `nodes`).
pub fn max_mismatch(nodes: &[[f64; 3]], links: &[PeriodicLink]) -> f64 {
    links
        .iter()
        .flat_map(|l| {
            l.node_pairs.iter().map(|&[s, m]| {
                (point(l.transform.apply(nodes[m as usize])) - point(nodes[s as usize])).length()
            })
        })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_parses_two_names() {
        let s: PeriodicSpec = "left:right".parse().unwrap();
        assert_eq!((s.master.as_str(), s.slave.as_str()), ("left", "right"));
        assert!("left".parse::<PeriodicSpec>().is_err());
        assert!(":b".parse::<PeriodicSpec>().is_err());
        assert!("a:b:c".parse::<PeriodicSpec>().is_err());
    }

    #[test]
    fn rotation_axis_angle_and_inverse() {
        // 30° about z through (1, 2, 0).
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let r = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
        let p = [1.0, 2.0, 0.0];
        let rp = Rigid {
            rotation: r,
            translation: [0.0; 3],
        }
        .apply(p);
        let t = Rigid {
            rotation: r,
            translation: [p[0] - rp[0], p[1] - rp[1], 0.0],
        };
        let (axis, point_on, deg) = t.axis_angle().unwrap();
        assert!((deg - 30.0).abs() < 1e-12);
        assert!((axis[2] - 1.0).abs() < 1e-12);
        assert!((point_on[0] - 1.0).abs() < 1e-12 && (point_on[1] - 2.0).abs() < 1e-12);
        let x = [3.0, -1.0, 0.5];
        let back = t.apply_inverse(t.apply(x));
        assert!((0..3).all(|i| (back[i] - x[i]).abs() < 1e-14));
        let inv = t.inverse().apply(t.apply(x));
        assert!((0..3).all(|i| (inv[i] - x[i]).abs() < 1e-14));
    }

    /// R_x(α), then R_y(β), then R_z(γ) about c, then T: the CGNS `Periodic_t` map.
    fn cgns_map(c: [f64; 3], a: [f64; 3], t: [f64; 3], x: [f64; 3]) -> [f64; 3] {
        let mut y = [x[0] - c[0], x[1] - c[1], x[2] - c[2]];
        for (axis, &angle) in a.iter().enumerate() {
            let (i, j) = ((axis + 1) % 3, (axis + 2) % 3);
            let (cs, sn) = (angle.cos(), angle.sin());
            let (yi, yj) = (y[i], y[j]);
            y[i] = cs * yi - sn * yj;
            y[j] = sn * yi + cs * yj;
        }
        std::array::from_fn(|k| y[k] + c[k] + t[k])
    }

    #[test]
    fn cgns_parameters_rebuild_the_map() {
        let x = [0.3, -1.2, 2.5];
        // A rotation about a skew axis through a point off the origin, with a screw part.
        let (axis, theta) = (DVec3::new(1.0, 2.0, 2.0) / 3.0, 0.7f64);
        let k = |v: DVec3| -> [f64; 3] { v.to_array() };
        let rot: [[f64; 3]; 3] = std::array::from_fn(|i| {
            let e = DVec3::from_array(unit_col(i));
            // Rows of R: R e_i by Rodrigues, transposed below.
            k(e * theta.cos()
                + axis.cross(e) * theta.sin()
                + axis * axis.dot(e) * (1.0 - theta.cos()))
        });
        let rot = std::array::from_fn(|i| std::array::from_fn(|j| rot[j][i]));
        for map in [
            Rigid::translation([0.0, -0.0575, 0.0]),
            Rigid {
                rotation: rot,
                translation: [0.4, -0.1, 0.9],
            },
        ] {
            for m in [map, map.inverse()] {
                let (c, a, t) = m.center_angles_translation();
                let (want, got) = (m.apply(x), cgns_map(c, a, t, x));
                assert!(
                    (0..3).all(|i| (want[i] - got[i]).abs() < 1e-12),
                    "{want:?} {got:?}"
                );
            }
        }
    }
}
