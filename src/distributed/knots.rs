//! Graded knot intervals across ranks: the serial knot survey and surface ratios
//! ([`crate::spline::intervals`]) of the whole mesh, with every rank's share measured where
//! it lies and the knot surfaces, which cross the shares, joined on rank 0.
//!
//! Input: a rank's [`LocalMesh`] (own elements and ghosts) and its topology. Output:
//! [`SharedSurvey`] (the whole mesh's graded share and largest |ln ratio| on every rank, what
//! `--knot-intervals auto` decides on) and [`knots`] (this sub-mesh's [`Knots`]: the
//! extraction weights of its elements, its elements split where a knot surface is, and the
//! whole mesh's [`crate::spline::KnotSurfaceInfo`]).
//!
//! Steps. (1) Each rank renumbers its sub-mesh as the whole mesh numbers it (elements by
//! global index, vertices by node tag) and builds its topology: a facet's first element is
//! then its lowest global element and its vertices are in that element's order, as in the
//! serial topology, so [`crate::spline::intervals::survey_parts`] measures the facets it owns
//! (those whose first element is its own) and the ties of its own spline elements exactly as
//! the serial survey does. (2) The facets are numbered by their sorted node tags over the
//! ranks (all-gathered, 32 B per facet in 3D): the serial topology's order for a file listing
//! its nodes in tag order. (3) Rank 0 gathers the measured ratios (24 B per interior facet)
//! and the ties (32 B each, about 24 per hex) and runs the serial survey and, for graded
//! knots, the serial splitting and weighted means ([`crate::spline::intervals::surface_ratios`])
//! on them; (4) every rank asks rank 0 for the ratios of its sub-mesh's facets and takes the
//! split elements, then computes its elements' weights with the serial formula.
//!
//! Invariant: the ratios every rank uses are the serial run's, bit for bit where the file's
//! node tags increase with the nodes' order (the sums run over the facets in the serial
//! order); elsewhere up to the order of the sums. The weights of ghosts at the fringe of the
//! ghost layer, whose neighbours are cut off, are uniform there (their classes are too); the
//! own elements' and their neighbours' are the serial ones.

use super::comm::Comm;
use super::read::LocalMesh;
use crate::mesh::topology::NONE;
use crate::mesh::{LinearMesh, Topology};
use crate::spline::intervals::{self, KnotSurvey, Tie};
use crate::spline::{KnotParams, KnotSurfaceInfo, Knots};

/// A facet's key: its node tags sorted (2D: the last two 0).
type FacetKey = [u64; 4];

/// The whole mesh's knot survey (see the module docs).
pub struct SharedSurvey {
    /// Rank 0: the survey of the whole mesh in the serial numbering; `None` elsewhere.
    survey: Option<KnotSurvey>,
    /// Per facet of the rank's topology: its global number.
    global_facet: Vec<u32>,
    /// Per facet of the rank's topology: its first element is not the whole mesh's first
    /// (the lowest global element), so its ratio is the global one negated.
    flipped: Vec<bool>,
    /// [`KnotSurvey::graded_share`] of the whole mesh.
    pub graded_share: f64,
    /// [`KnotSurvey::max_abs_log_ratio`] of the whole mesh.
    pub max_abs_log_ratio: f64,
}

/// The sub-mesh renumbered as the whole mesh numbers it: elements by global index, vertices
/// by node tag. Returns the mesh, each of its elements' local index and its vertices' tags.
fn in_global_order(local: &LocalMesh) -> (LinearMesh, Vec<usize>, Vec<u64>) {
    let mesh = &local.mesh;
    let npe = mesh.nodes_per_element();
    let mut elements: Vec<usize> = (0..mesh.n_elements()).collect();
    elements.sort_unstable_by_key(|&e| local.global_element[e]);
    let mut vertices: Vec<u32> = (0..mesh.n_vertices() as u32).collect();
    vertices.sort_unstable_by_key(|&v| local.global_vertex[v as usize]);
    let mut new_of = vec![0u32; vertices.len()];
    for (i, &v) in vertices.iter().enumerate() {
        new_of[v as usize] = i as u32;
    }
    let sorted = LinearMesh {
        dim: mesh.dim,
        coords: vertices.iter().map(|&v| mesh.coords[v as usize]).collect(),
        elements: elements
            .iter()
            .flat_map(|&e| mesh.element(e).iter().map(|&v| new_of[v as usize]))
            .collect(),
        ..Default::default()
    };
    let tags = vertices
        .iter()
        .map(|&v| local.global_vertex[v as usize])
        .collect();
    debug_assert_eq!(sorted.elements.len(), npe * elements.len());
    (sorted, elements, tags)
}

/// The key of facet `f` of `topo`, whose vertices have the tags `tags`.
fn key(topo: &Topology, f: usize, tags: impl Fn(u32) -> u64) -> FacetKey {
    let mut k = [0u64; 4];
    let vs = topo.facet_vertices(f);
    for (x, &v) in k.iter_mut().zip(vs) {
        *x = tags(v);
    }
    k[..vs.len()].sort_unstable();
    k
}

/// The knot survey of the whole mesh (collective; see the module docs). `local` and `topo`:
/// this rank's sub-mesh and its topology.
pub fn survey(comm: &dyn Comm, local: &LocalMesh, topo: &Topology) -> SharedSurvey {
    let (sorted, local_of, tags) = in_global_order(local);
    let st = Topology::build(&sorted);
    let own = |e: usize| local_of[e] < local.n_owned;
    // Own elements that are spline elements by topology (their one-ring is on this rank).
    let spline: Vec<bool> = crate::spline::classify::classify(&sorted, &st)
        .iter()
        .enumerate()
        .map(|(e, c)| own(e) && c.is_spline())
        .collect();
    let (measured, ties) = intervals::survey_parts(&sorted, &st, &spline);
    drop(spline);
    // The facets this rank owns, in the order of their keys (the topology sorts them so).
    let owned = |f: usize| own(st.facet_elements[f][0] as usize);
    let width = if st.dim == 3 { 4 } else { 2 };
    let mine: Vec<f64> = (0..st.n_facets())
        .filter(|&f| owned(f))
        .flat_map(|f| key(&st, f, |v| tags[v as usize])[..width].to_vec())
        .map(|t| t as f64)
        .collect();
    let mut all: Vec<FacetKey> = comm
        .all_gather_f64(&mine)
        .concat()
        .chunks_exact(width)
        .map(|c| std::array::from_fn(|i| c.get(i).map_or(0, |&t| t as u64)))
        .collect();
    drop(mine);
    all.sort_unstable();
    let number = |k: &FacetKey| {
        all.binary_search(k)
            .expect("every facet is owned by one rank") as u32
    };
    let sorted_facet: Vec<u32> = (0..st.n_facets())
        .map(|f| number(&key(&st, f, |v| tags[v as usize])))
        .collect();
    let ge = |e: u32| local.global_element[local_of[e as usize]];
    let measured: Vec<f64> = measured
        .iter()
        .enumerate()
        .filter(|&(f, _)| owned(f))
        .filter_map(|(f, m)| m.map(|(m, w)| [sorted_facet[f] as f64, m, w]))
        .flatten()
        .collect();
    // A tie's sign is the sign of its second facet's number plus one.
    let ties: Vec<f64> = ties
        .iter()
        .flat_map(|t| {
            let f2 = sorted_facet[t.f2 as usize] as f64 + 1.0;
            [
                ge(t.element) as f64,
                ge(t.neighbour) as f64,
                sorted_facet[t.f as usize] as f64,
                if t.opposite { -f2 } else { f2 },
            ]
        })
        .collect();
    drop((st, sorted, sorted_facet));
    // This rank's topology: each facet's number and orientation.
    let global_vertex = &local.global_vertex;
    let global_facet: Vec<u32> = (0..topo.n_facets())
        .map(|f| number(&key(topo, f, |v| global_vertex[v as usize])))
        .collect();
    let flipped = topo
        .facet_elements
        .iter()
        .map(|&[a, b]| {
            b != NONE && local.global_element[a as usize] > local.global_element[b as usize]
        })
        .collect();
    let nf = all.len();
    drop(all);
    let measured = comm.gather_f64(0, &measured);
    let ties = comm.gather_f64(0, &ties);
    let survey = measured
        .zip(ties)
        .map(|(measured, ties)| whole_survey(nf, &measured, &ties));
    // Rank 0's figures on every rank (the others add zeros).
    let mut figures = survey
        .as_ref()
        .map_or([0.0; 2], |s| [s.graded_share, s.max_abs_log_ratio]);
    comm.sum_f64(&mut figures);
    SharedSurvey {
        survey,
        global_facet,
        flipped,
        graded_share: figures[0],
        max_abs_log_ratio: figures[1],
    }
}

/// Rank 0: the serial survey of `nf` facets from the ranks' records ([`survey`]).
fn whole_survey(nf: usize, measured: &[f64], ties: &[f64]) -> KnotSurvey {
    let mut by_facet = vec![None; nf];
    for r in measured.chunks_exact(3) {
        by_facet[r[0] as usize] = Some((r[1], r[2]));
    }
    let ties = ties
        .chunks_exact(4)
        .map(|r| Tie {
            element: r[0] as u32,
            neighbour: r[1] as u32,
            f: r[2] as u32,
            f2: (r[3].abs() - 1.0) as u32,
            opposite: r[3] < 0.0,
        })
        .collect();
    KnotSurvey::from_parts(by_facet, ties)
}

/// This sub-mesh's graded knots from the whole mesh's survey (collective; see the module
/// docs): the serial ratios of the knot surfaces, the extraction weights of every element of
/// `topo` (the rank's topology the survey was made with), its split elements and the whole
/// mesh's figures of the knot surfaces.
pub fn knots(
    comm: &dyn Comm,
    shared: SharedSurvey,
    local: &LocalMesh,
    topo: &Topology,
    params: &KnotParams,
) -> Knots {
    let SharedSurvey {
        survey,
        global_facet,
        flipped,
        ..
    } = shared;
    let n_global = local.n_global as usize;
    let ratios = survey.map(|s| intervals::surface_ratios(s, n_global, params));
    // The ratios of this rank's facets, asked of rank 0.
    let mut ask = vec![Vec::new(); comm.size()];
    ask[0] = global_facet.iter().map(|&g| g as f64).collect();
    drop(global_facet);
    let asked = comm.exchange_f64(&ask);
    drop(ask);
    let answer: Vec<Vec<f64>> = match &ratios {
        Some(r) => asked
            .iter()
            .map(|list| list.iter().map(|&g| r.rho[g as usize]).collect())
            .collect(),
        None => vec![Vec::new(); comm.size()],
    };
    drop(asked);
    let rho: Vec<f64> = comm.exchange_f64(&answer).swap_remove(0);
    drop(answer);
    // The split elements and the figures, from rank 0.
    let split_ids: Vec<f64> = ratios.as_ref().map_or_else(Vec::new, |r| {
        (0..n_global)
            .filter(|&e| r.split[e])
            .map(|e| e as f64)
            .collect()
    });
    let mut split_ids: Vec<u64> = comm
        .all_gather_f64(&split_ids)
        .concat()
        .into_iter()
        .map(|g| g as u64)
        .collect();
    split_ids.sort_unstable();
    let info = shared_info(comm, ratios.as_ref().map(|r| &r.info));
    drop(ratios);
    let weights = intervals::weights_from_ratios(topo, |f| {
        let r = rho[f as usize];
        if flipped[f as usize] { -r } else { r }
    });
    let split = if info.split_elements > 0 {
        local
            .global_element
            .iter()
            .map(|g| split_ids.binary_search(g).is_ok())
            .collect()
    } else {
        Vec::new()
    };
    Knots {
        weights: Some(weights),
        split,
        info,
    }
}

/// Rank 0's `info` on every rank.
fn shared_info(comm: &dyn Comm, info: Option<&KnotSurfaceInfo>) -> KnotSurfaceInfo {
    let mut v = info.map_or([0.0; 8], |i| {
        [
            i.surfaces as f64,
            i.graded as f64,
            i.non_orientable as f64,
            i.clamped as f64,
            i.max_abs_log_ratio,
            i.split_elements as f64,
            i.max_spread,
            i.graded_share,
        ]
    });
    comm.sum_f64(&mut v);
    KnotSurfaceInfo {
        surfaces: v[0] as usize,
        graded: v[1] as usize,
        non_orientable: v[2] as usize,
        clamped: v[3] as usize,
        max_abs_log_ratio: v[4],
        split_elements: v[5] as usize,
        max_spread: v[6],
        graded_share: v[7],
    }
}
