//! Small synthetic meshes for tests, examples and benchmarks.
//!
//! Every generator returns an oriented [`LinearMesh`] (counter-clockwise quads, right-handed
//! hexes) with boundary tags: in 2D tag `2k + s + 1` on the grid side where coordinate k is at
//! its minimum (s = 0) or maximum (s = 1), likewise in 3D; curved or star-shaped generators tag
//! their whole outer boundary 1.

use super::{LinearMesh, MeshOptions};
use crate::params::ParamError;

pub mod boundary_layer;
pub use boundary_layer::{
    BoundaryLayer, BoundaryLayerMesh, CHANNEL_PAIR, GenerateError, SECTOR_PAIR, Wall,
    WallNormalSpacing, cgrid, channel, ogrid, sector,
};

/// Structured quad grid on the tensor product of the coordinate lists `xs` × `ys`.
pub fn grid_2d(xs: &[f64], ys: &[f64]) -> LinearMesh {
    let (nx, ny) = (xs.len(), ys.len());
    assert!(nx >= 2 && ny >= 2, "a grid needs two coordinates per axis");
    let id = |i: usize, j: usize| (j * nx + i) as u32;
    let coords = (0..ny)
        .flat_map(|j| (0..nx).map(move |i| [xs[i], ys[j], 0.0]))
        .collect();
    let mut elements = Vec::with_capacity(4 * (nx - 1) * (ny - 1));
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            elements.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let mut tagged_facets = Vec::new();
    let mut facet_tags = Vec::new();
    for i in 0..nx - 1 {
        tagged_facets.extend([id(i, 0), id(i + 1, 0), id(i, ny - 1), id(i + 1, ny - 1)]);
        facet_tags.extend([3, 4]);
    }
    for j in 0..ny - 1 {
        tagged_facets.extend([id(0, j), id(0, j + 1), id(nx - 1, j), id(nx - 1, j + 1)]);
        facet_tags.extend([1, 2]);
    }
    finish(2, coords, elements, tagged_facets, facet_tags)
}

/// Structured hex grid on `xs` × `ys` × `zs`.
pub fn grid_3d(xs: &[f64], ys: &[f64], zs: &[f64]) -> LinearMesh {
    let (nx, ny, nz) = (xs.len(), ys.len(), zs.len());
    assert!(
        nx >= 2 && ny >= 2 && nz >= 2,
        "a grid needs two coordinates per axis"
    );
    let id = |i: usize, j: usize, k: usize| ((k * ny + j) * nx + i) as u32;
    let mut coords = Vec::with_capacity(nx * ny * nz);
    for &z in zs {
        for &y in ys {
            for &x in xs {
                coords.push([x, y, z]);
            }
        }
    }
    let mut elements = Vec::with_capacity(8 * (nx - 1) * (ny - 1) * (nz - 1));
    for k in 0..nz - 1 {
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                elements.extend([
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i + 1, j + 1, k),
                    id(i, j + 1, k),
                    id(i, j, k + 1),
                    id(i + 1, j, k + 1),
                    id(i + 1, j + 1, k + 1),
                    id(i, j + 1, k + 1),
                ]);
            }
        }
    }
    let mut tagged_facets = Vec::new();
    let mut facet_tags = Vec::new();
    // Faces normal to axis `a` at index 0 and at the last index.
    let n = [nx, ny, nz];
    for a in 0..3 {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        for (s, at) in [0, n[a] - 1].into_iter().enumerate() {
            for u in 0..n[b] - 1 {
                for v in 0..n[c] - 1 {
                    let p = |du: usize, dv: usize| {
                        let mut ijk = [0; 3];
                        ijk[a] = at;
                        ijk[b] = u + du;
                        ijk[c] = v + dv;
                        id(ijk[0], ijk[1], ijk[2])
                    };
                    tagged_facets.extend([p(0, 0), p(1, 0), p(1, 1), p(0, 1)]);
                    facet_tags.push((2 * a + s + 1) as i32);
                }
            }
        }
    }
    finish(3, coords, elements, tagged_facets, facet_tags)
}

/// Evenly spaced coordinates `0, h, 2h, …, n·h`.
pub fn uniform(n: usize, h: f64) -> Vec<f64> {
    (0..=n).map(|i| i as f64 * h).collect()
}

/// L-shaped domain: the unit-spaced `2n × 2n` square without its top-right `n × n` quarter.
/// The re-entrant corner at (n, n) is a boundary vertex with 3 quads.
pub fn l_shape(n: usize) -> LinearMesh {
    let full = grid_2d(&uniform(2 * n, 1.0), &uniform(2 * n, 1.0));
    let keep: Vec<bool> = (0..full.n_elements())
        .map(|e| {
            let (i, j) = (e % (2 * n), e / (2 * n));
            !(i >= n && j >= n)
        })
        .collect();
    let elements: Vec<u32> = full
        .elements
        .chunks(4)
        .zip(&keep)
        .filter(|(_, k)| **k)
        .flat_map(|(c, _)| c.iter().copied())
        .collect();
    let used: std::collections::HashSet<u32> = elements.iter().copied().collect();
    // Boundary tags of the full square do not describe the L; tag nothing here and compact.
    let mut map = vec![u32::MAX; full.coords.len()];
    let mut coords = Vec::new();
    for (i, p) in full.coords.iter().enumerate() {
        if used.contains(&(i as u32)) {
            map[i] = coords.len() as u32;
            coords.push(*p);
        }
    }
    let elements = elements.iter().map(|&v| map[v as usize]).collect();
    finish(2, coords, elements, Vec::new(), Vec::new())
}

/// A disc-like quad mesh whose centre vertex has `k` quads around it (k = 3, 5, …): an inner
/// fan of k quads and an outer ring of 3k quads, so every other interior vertex has valence 4.
pub fn star_2d(k: usize) -> LinearMesh {
    assert!(k >= 3, "a star needs at least 3 sectors");
    use std::f64::consts::PI;
    let polar = |r: f64, t: f64| [r * t.cos(), r * t.sin(), 0.0];
    let w = 2.0 * PI / k as f64;
    let mut coords = vec![[0.0, 0.0, 0.0]];
    // Per sector i: a_i (spoke), b_i (corner), p_i, q_i, c_i, r_i (outer ring).
    for i in 0..k {
        let t = i as f64 * w;
        coords.push(polar(1.0, t)); // a
        coords.push(polar(1.4, t + w / 2.0)); // b
        coords.push(polar(2.5, t)); // p
        coords.push(polar(2.6, t + w / 4.0)); // q
        coords.push(polar(3.0, t + w / 2.0)); // c
        coords.push(polar(2.6, t + 3.0 * w / 4.0)); // r
    }
    let v = |i: usize, which: usize| (1 + 6 * (i % k) + which) as u32;
    let (a, b, p, q, c, r) = (0, 1, 2, 3, 4, 5);
    let mut elements = Vec::new();
    let mut tagged_facets = Vec::new();
    for i in 0..k {
        let j = i + 1;
        elements.extend([0, v(i, a), v(i, b), v(j, a)]);
        elements.extend([v(i, a), v(i, p), v(i, q), v(i, b)]);
        elements.extend([v(i, b), v(i, q), v(i, c), v(i, r)]);
        elements.extend([v(i, b), v(i, r), v(j, p), v(j, a)]);
        tagged_facets.extend([
            v(i, p),
            v(i, q),
            v(i, q),
            v(i, c),
            v(i, c),
            v(i, r),
            v(i, r),
            v(j, p),
        ]);
    }
    let facet_tags = vec![1; tagged_facets.len() / 2];
    finish(2, coords, elements, tagged_facets, facet_tags)
}

/// Extrude a quad mesh along z through the levels `zs`: hexes whose vertical edges through
/// interior 2D vertices of valence k have valence k.
pub fn extrude(mesh: &LinearMesh, zs: &[f64]) -> LinearMesh {
    assert_eq!(mesh.dim, 2, "extrude takes a quad mesh");
    assert!(zs.len() >= 2, "extrusion needs two levels");
    let nv = mesh.coords.len() as u32;
    let mut coords = Vec::with_capacity(mesh.coords.len() * zs.len());
    for &z in zs {
        coords.extend(mesh.coords.iter().map(|p| [p[0], p[1], z]));
    }
    let mut elements = Vec::new();
    for l in 0..zs.len() as u32 - 1 {
        for q in mesh.elements.chunks(4) {
            elements.extend(q.iter().map(|&v| v + l * nv));
            elements.extend(q.iter().map(|&v| v + (l + 1) * nv));
        }
    }
    // Side tags carry over (as quads); bottom and top get the next two tags.
    let top_tag = mesh.facet_tags.iter().copied().max().unwrap_or(0);
    let mut tagged_facets = Vec::new();
    let mut facet_tags = Vec::new();
    for l in 0..zs.len() as u32 - 1 {
        for (f, &t) in mesh.tagged_facets.chunks(2).zip(&mesh.facet_tags) {
            tagged_facets.extend([
                f[0] + l * nv,
                f[1] + l * nv,
                f[1] + (l + 1) * nv,
                f[0] + (l + 1) * nv,
            ]);
            facet_tags.push(t);
        }
    }
    let last = (zs.len() as u32 - 1) * nv;
    for q in mesh.elements.chunks(4) {
        tagged_facets.extend([q[0], q[3], q[2], q[1]]);
        facet_tags.push(top_tag + 1);
        tagged_facets.extend(q.iter().map(|&v| v + last));
        facet_tags.push(top_tag + 2);
    }
    finish(3, coords, elements, tagged_facets, facet_tags)
}

fn finish(
    dim: usize,
    coords: Vec<[f64; 3]>,
    elements: Vec<u32>,
    tagged_facets: Vec<u32>,
    facet_tags: Vec<i32>,
) -> LinearMesh {
    let mut mesh = LinearMesh {
        dim,
        coords,
        elements,
        tagged_facets,
        facet_tags,
        ..Default::default()
    };
    mesh.normalise_orientation(&MeshOptions::default(), &[])
        .expect("generated meshes are valid");
    mesh
}

/// A disc of radius 1 meshed as a "butterfly" O-grid: an inner square block of `n × n` quads
/// and four outer blocks of `n × m` quads reaching the circle. The four corners of the inner
/// square are interior vertices of valence 3, so the elements around them are Q2 elements of
/// the spline space; everything else is regular. Boundary tag 1 ("wall").
pub fn butterfly_disc(n: usize, m: usize) -> LinearMesh {
    assert!(
        n >= 1 && m >= 1,
        "a disc needs at least one element per block side"
    );
    use std::collections::HashMap;
    let a = 0.45_f64; // half-width of the inner square
    let mut coords: Vec<[f64; 3]> = Vec::new();
    let mut index: HashMap<(i64, i64), u32> = HashMap::new();
    let mut id = |p: [f64; 2], coords: &mut Vec<[f64; 3]>| -> u32 {
        let key = ((p[0] * 1e9).round() as i64, (p[1] * 1e9).round() as i64);
        *index.entry(key).or_insert_with(|| {
            coords.push([p[0], p[1], 0.0]);
            (coords.len() - 1) as u32
        })
    };
    let mut elements = Vec::new();
    // Inner square.
    let sq = |i: usize, j: usize| {
        [
            -a + 2.0 * a * i as f64 / n as f64,
            -a + 2.0 * a * j as f64 / n as f64,
        ]
    };
    for j in 0..n {
        for i in 0..n {
            let q = [sq(i, j), sq(i + 1, j), sq(i + 1, j + 1), sq(i, j + 1)];
            for p in q {
                elements.push(id(p, &mut coords));
            }
        }
    }
    // Outer blocks: blend between a side of the square and the matching quarter arc.
    use std::f64::consts::PI;
    for side in 0..4 {
        let rot = side as f64 * PI / 2.0;
        let (c, s) = (rot.cos(), rot.sin());
        let turn = |p: [f64; 2]| [c * p[0] - s * p[1], s * p[0] + c * p[1]];
        // Side x = a, y from -a to a; arc angle from -π/4 to π/4.
        let point = |i: usize, k: usize| {
            let t = i as f64 / n as f64;
            let r = k as f64 / m as f64;
            let inner = [a, -a + 2.0 * a * t];
            let ang = -PI / 4.0 + t * PI / 2.0;
            let outer = [ang.cos(), ang.sin()];
            turn([
                inner[0] + r * (outer[0] - inner[0]),
                inner[1] + r * (outer[1] - inner[1]),
            ])
        };
        for k in 0..m {
            for i in 0..n {
                let q = [
                    point(i, k),
                    point(i, k + 1),
                    point(i + 1, k + 1),
                    point(i + 1, k),
                ];
                for p in q {
                    elements.push(id(p, &mut coords));
                }
            }
        }
    }
    let mut mesh = LinearMesh {
        dim: 2,
        coords,
        elements,
        ..Default::default()
    };
    mesh.normalise_orientation(&MeshOptions::default(), &[])
        .expect("generated meshes are valid");
    let topo = super::Topology::build(&mesh);
    for &f in &topo.boundary_facets {
        mesh.tagged_facets
            .extend_from_slice(&topo.edges[f as usize]);
        mesh.facet_tags.push(1);
    }
    mesh.tag_names.insert(1, "wall".into());
    mesh
}

/// Revolve a quad mesh (x > −`major`) into a ring-shaped solid:
/// solid: the cross-section is moved to x + `major` and turned through `segments` equal steps
/// of a full turn about the z axis (the section's y becomes z), closing the ring.
pub fn revolve(section: &LinearMesh, major: f64, segments: usize) -> LinearMesh {
    assert_eq!(section.dim, 2, "revolve takes a quad mesh");
    assert!(segments >= 3, "a ring needs at least 3 segments");
    let nv = section.coords.len() as u32;
    let mut coords = Vec::with_capacity(section.coords.len() * segments);
    for k in 0..segments {
        let phi = 2.0 * std::f64::consts::PI * k as f64 / segments as f64;
        coords.extend(section.coords.iter().map(|p| {
            let r = major + p[0];
            [r * phi.cos(), r * phi.sin(), p[1]]
        }));
    }
    let mut elements = Vec::new();
    for k in 0..segments as u32 {
        let next = (k + 1) % segments as u32;
        // The section's (x, y) axes become (radial, z); radial × z points against the turning
        // direction, so the next section is the hex's bottom face for a right-handed hex.
        for q in section.elements.chunks(4) {
            elements.extend(q.iter().map(|&v| v + next * nv));
            elements.extend(q.iter().map(|&v| v + k * nv));
        }
    }
    let mut tagged_facets = Vec::new();
    let mut facet_tags = Vec::new();
    for k in 0..segments as u32 {
        let next = (k + 1) % segments as u32;
        for (f, &t) in section.tagged_facets.chunks(2).zip(&section.facet_tags) {
            tagged_facets.extend([
                f[0] + k * nv,
                f[1] + k * nv,
                f[1] + next * nv,
                f[0] + next * nv,
            ]);
            facet_tags.push(t);
        }
    }
    let mut mesh = finish(3, coords, elements, tagged_facets, facet_tags);
    mesh.tag_names = section.tag_names.clone();
    mesh
}

/// Kinds of [`generate`]d benchmark meshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// 2D butterfly disc (valence-3 vertices).
    Disc,
    /// The disc extruded along z: a solid cylinder of height 2 (valence-3 edges).
    Cylinder,
    /// The disc revolved into a torus (major radius 3, tube radius 1).
    Torus,
}

/// What the `generate` command makes: a benchmark mesh of a [`Kind`] or a boundary-layer grid
/// ([`boundary_layer::ogrid`], [`boundary_layer::cgrid`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    Benchmark(Kind),
    Ogrid,
    Cgrid,
    /// The periodic channel over a bump (`boundary_layer::channel`).
    Channel,
    /// The periodic annular sector (`boundary_layer::sector`).
    Sector,
}

/// Most elements the `generate` command makes (memory grows linearly, see docs/reliability.md).
pub const MAX_GENERATED_ELEMENTS: usize = 10_000_000;

impl Shape {
    /// `generate SHAPE [--elements N]`: the element count belongs to the benchmark shapes (the
    /// boundary-layer grids take `--around` and `--across`, checked by their generators).
    pub fn check(self, elements: Option<usize>) -> Result<(), ParamError> {
        match (self, elements) {
            (Shape::Benchmark(_), Some(n)) => check_generated_elements(n),
            (_, Some(n)) => Err(ParamError::new(
                "--elements",
                n,
                "applies to disc, cylinder and torus; ogrid, cgrid, channel and sector take --around and --across",
            )),
            (_, None) => Ok(()),
        }
    }
}

/// `generate --elements N`: at least 1, at most [`MAX_GENERATED_ELEMENTS`].
pub fn check_generated_elements(n: usize) -> Result<(), ParamError> {
    if n == 0 || n > MAX_GENERATED_ELEMENTS {
        return Err(ParamError::new(
            "--elements",
            n,
            format!("must be in 1..={MAX_GENERATED_ELEMENTS}"),
        ));
    }
    Ok(())
}

/// A mesh of `kind` with about `elements` elements (at least a few dozen).
pub fn generate(kind: Kind, elements: usize) -> LinearMesh {
    // Disc: 3n² quads with m = n/2 ... n² + 4·n·m = 3n² for m = n/2.
    match kind {
        Kind::Disc => {
            let n = ((elements as f64 / 3.0).sqrt().round() as usize).max(2);
            butterfly_disc(n, (n / 2).max(1))
        }
        Kind::Cylinder => {
            let n = ((elements as f64 / 3.0).cbrt().round() as usize).max(2);
            let disc = butterfly_disc(n, (n / 2).max(1));
            let mut m = extrude(&disc, &uniform(n, 2.0 / n as f64));
            m.tag_names.insert(1, "wall".into());
            m.tag_names.insert(2, "bottom".into());
            m.tag_names.insert(3, "top".into());
            m
        }
        Kind::Torus => {
            // 3n² per section, 3n sections.
            let n = ((elements as f64 / 9.0).cbrt().round() as usize).max(2);
            revolve(&butterfly_disc(n, (n / 2).max(1)), 3.0, 3 * n)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn element_counts_are_checked_per_shape() {
        assert!(check_generated_elements(0).is_err());
        assert!(check_generated_elements(MAX_GENERATED_ELEMENTS + 1).is_err());
        assert!(Shape::Benchmark(Kind::Disc).check(Some(100)).is_ok());
        assert!(Shape::Ogrid.check(Some(100)).is_err());
        assert!(Shape::Ogrid.check(None).is_ok());
    }
}
