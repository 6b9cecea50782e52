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
//! Steps. (1) Each rank measures the facets it owns (those whose first element, the lowest
//! global index, is its own) and lists the ties of its own spline elements with the serial
//! functions (`spline::intervals::survey_parts`), each facet oriented and its
//! vertices summed as the whole mesh's topology does (its first element's side), so the
//! values are the serial survey's bit for bit. A facet is named by its first element's global
//! index and side. (2) Rank 0 numbers the facets in the serial topology's order, by their
//! sorted node tags (the ranks send the keys of the facets they own: 40 B each in 3D), then
//! gathers the measured ratios (24 B per interior facet) and, one rank at a time, the ties
//! (32 B each on the wire, 16 B held; about 24 per hex), and runs the serial survey and, for
//! graded knots, the serial splitting and weighted means
//! (`spline::intervals::surface_ratios`) on them; (3) every rank asks rank 0 for the
//! ratios of its sub-mesh's facets and takes the split elements, then computes its elements'
//! weights with the serial formula.
//!
//! Invariant: the ratios every rank uses are the serial run's, bit for bit where the file's
//! node tags increase with the nodes' order (the sums run over the facets in the serial
//! order); elsewhere up to the order of the sums. The weights of ghosts at the fringe of the
//! ghost layer, whose neighbours are cut off, are uniform there (their classes are too); the
//! own elements' and their neighbours' are the serial ones. Memory: rank 0 holds the whole
//! mesh's ties and measured ratios for the survey (about 0.7 KB per hex), before the fit.

use super::comm::Comm;
use super::read::LocalMesh;
use crate::mesh::Topology;
use crate::mesh::topology::NONE;
use crate::spline::intervals::{self, KnotSurvey, Tie};
use crate::spline::{KnotParams, KnotSurfaceInfo, Knots};

/// Ties sent to rank 0 in one message (32 B each).
const TIE_CHUNK: usize = 1 << 16;

/// A facet's key: its node tags sorted (2D: the last two 0).
type FacetKey = [u64; 4];

/// The whole mesh's knot survey (see the module docs).
pub struct SharedSurvey {
    /// Rank 0: the survey of the whole mesh in the serial numbering, and every facet's name
    /// with its number (sorted by name); `None` elsewhere.
    survey: Option<(KnotSurvey, Vec<(u64, u32)>)>,
    /// Per facet of the rank's topology with both its elements here: its name (global index of
    /// its first element × 8 + side); `u64::MAX` elsewhere.
    names: Vec<u64>,
    /// Per facet of the rank's topology: its first element here is not the whole mesh's
    /// first, so its ratio is the global one negated.
    flipped: Vec<bool>,
    /// [`KnotSurvey::graded_share`] of the whole mesh.
    pub graded_share: f64,
    /// [`KnotSurvey::max_abs_log_ratio`] of the whole mesh.
    pub max_abs_log_ratio: f64,
}

impl crate::pipeline::passes::KnotFigures for SharedSurvey {
    fn graded_share(&self) -> f64 {
        self.graded_share
    }
    fn max_abs_log_ratio(&self) -> f64 {
        self.max_abs_log_ratio
    }
}

/// Facet `f`'s first element over the whole mesh (the lower global index of its elements
/// here) and its side there.
fn first(local: &LocalMesh, topo: &Topology, f: usize) -> (u32, u8) {
    let ([e, _], [side, _]) = intervals::elements_in_global_order(topo, f, &local.global_element);
    (e, side)
}

/// The knot survey of the whole mesh (collective; see the module docs). `local` and `topo`:
/// this rank's sub-mesh and its topology.
pub fn survey(comm: &dyn Comm, local: &LocalMesh, topo: &Topology) -> SharedSurvey {
    // With glued seams the knot surfaces run on across them (the serial `seam::knot_weights`):
    // the survey is the glued share's, each element measured on its own vertices.
    let glued = local.glued.as_deref();
    let (mesh, topo) = glued.map_or((&local.mesh, topo), |s| (&s.mesh, &s.topo));
    let g = &local.global_element;
    let own = |e: u32| (e as usize) < local.n_owned;
    // Own elements that are spline elements by topology (their two rings are on this rank).
    let spline: Vec<bool> = crate::spline::classify::classify(mesh, topo)
        .iter()
        .enumerate()
        .map(|(e, c)| own(e as u32) && c.is_spline())
        .collect();
    let (measured, ties) = match glued {
        Some(_) => intervals::survey_parts_glued(&local.mesh, mesh, topo, &spline, g),
        None => intervals::survey_parts(mesh, topo, &spline, g),
    };
    drop(spline);
    let name = |f: usize| {
        let (e, side) = first(local, topo, f);
        g[e as usize] * 8 + side as u64
    };
    let owned = |f: usize| own(first(local, topo, f).0);
    // The facets this rank owns, named, with their keys (for rank 0's numbering).
    let width = if topo.dim == 3 { 4 } else { 2 };
    let keys: Vec<f64> = (0..topo.n_facets())
        .filter(|&f| owned(f))
        .flat_map(|f| {
            let mut k = [0u64; 4];
            let vs = topo.facet_vertices(f);
            for (x, &v) in k.iter_mut().zip(vs) {
                *x = local.global_vertex[v as usize];
            }
            k[..vs.len()].sort_unstable();
            let mut r = k[..width].to_vec();
            r.push(name(f));
            r
        })
        .map(|x| x as f64)
        .collect();
    let numbers = comm.gather_f64(0, &keys).map(|all| numbering(&all, width));
    drop(keys);
    let measured: Vec<f64> = measured
        .iter()
        .enumerate()
        .filter(|&(f, _)| owned(f))
        .filter_map(|(f, m)| m.map(|(m, w)| [name(f) as f64, m, w]))
        .flatten()
        .collect();
    let by_facet = comm.gather_f64(0, &measured).map(|all| {
        let names = numbers.as_ref().expect("rank 0 numbers the facets");
        let mut by_facet = vec![None; names.len()];
        for r in all.chunks_exact(3) {
            by_facet[number(names, r[0]) as usize] = Some((r[1], r[2]));
        }
        by_facet
    });
    drop(measured);
    // The ties, one rank and at most `TIE_CHUNK` of them at a time: rank 0 holds one chunk's
    // records besides the ties, a rank one chunk's beside its own ties.
    let counts: Vec<usize> = comm
        .all_gather_f64(&[ties.len() as f64])
        .iter()
        .map(|c| c[0] as usize)
        .collect();
    let mut whole: Vec<Tie> = Vec::with_capacity(if comm.rank() == 0 {
        counts.iter().sum()
    } else {
        0
    });
    for (q, &n) in counts.iter().enumerate() {
        for start in (0..n).step_by(TIE_CHUNK) {
            let send: Vec<f64> = if q == comm.rank() {
                ties[start..n.min(start + TIE_CHUNK)]
                    .iter()
                    .flat_map(|t| {
                        // The second facet's sign is the tie's.
                        let f2 = name(t.f2() as usize) as f64 + 1.0;
                        [
                            g[t.element as usize] as f64,
                            g[t.neighbour as usize] as f64,
                            name(t.f as usize) as f64,
                            if t.opposite() { -f2 } else { f2 },
                        ]
                    })
                    .collect()
            } else {
                Vec::new()
            };
            if let Some(all) = comm.gather_f64(0, &send) {
                let names = numbers.as_ref().expect("rank 0 numbers the facets");
                whole.extend(all.chunks_exact(4).map(|r| {
                    Tie::new(
                        r[0] as u32,
                        r[1] as u32,
                        number(names, r[2]),
                        number(names, r[3].abs() - 1.0),
                        r[3] < 0.0,
                    )
                }));
            }
        }
    }
    drop(ties);
    let survey = by_facet
        .zip(numbers)
        .map(|(by_facet, names)| (KnotSurvey::from_parts(by_facet, whole), names));
    // Rank 0's figures on every rank (the others add zeros).
    let mut figures = survey
        .as_ref()
        .map_or([0.0; 2], |(s, _)| [s.graded_share, s.max_abs_log_ratio]);
    comm.sum_f64(&mut figures);
    // This rank's facets: names where both elements are here, orientation.
    let names = (0..topo.n_facets())
        .map(|f| {
            if topo.facet_elements[f][1] == NONE {
                u64::MAX
            } else {
                name(f)
            }
        })
        .collect();
    let flipped = (0..topo.n_facets())
        .map(|f| first(local, topo, f).0 != topo.facet_elements[f][0])
        .collect();
    SharedSurvey {
        survey,
        names,
        flipped,
        graded_share: figures[0],
        max_abs_log_ratio: figures[1],
    }
}

/// The number of the facet named `x` in rank 0's `names` ([`numbering`]).
fn number(names: &[(u64, u32)], x: f64) -> u32 {
    let i = names
        .binary_search_by_key(&(x as u64), |&(n, _)| n)
        .expect("every facet is numbered");
    names[i].1
}

/// Rank 0: every facet's name with its number in the serial topology's order (by sorted node
/// tags), sorted by name, from the ranks' records `[key (width), name]`.
fn numbering(records: &[f64], width: usize) -> Vec<(u64, u32)> {
    let mut keyed: Vec<(FacetKey, u64)> = records
        .chunks_exact(width + 1)
        .map(|r| {
            let key = std::array::from_fn(|i| if i < width { r[i] as u64 } else { 0 });
            (key, r[width] as u64)
        })
        .collect();
    keyed.sort_unstable();
    let mut names: Vec<(u64, u32)> = keyed
        .iter()
        .enumerate()
        .map(|(i, &(_, n))| (n, i as u32))
        .collect();
    drop(keyed);
    names.sort_unstable();
    names
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
        names,
        flipped,
        ..
    } = shared;
    // The survey's topology: the glued share's with glued seams.
    let topo = local.glued.as_deref().map_or(topo, |s| &s.topo);
    let n_global = local.n_global as usize;
    let ratios = survey.map(|(s, names)| (intervals::surface_ratios(s, n_global, params), names));
    // The ratios of this rank's facets with both elements here, asked of rank 0 by name.
    let asking: Vec<usize> = (0..names.len()).filter(|&f| names[f] != u64::MAX).collect();
    let mut ask = vec![Vec::new(); comm.size()];
    ask[0] = asking.iter().map(|&f| names[f] as f64).collect();
    drop(names);
    let asked = comm.exchange_f64(&ask);
    drop(ask);
    let answer: Vec<Vec<f64>> = match &ratios {
        Some((r, names)) => asked
            .iter()
            .map(|list| {
                list.iter()
                    .map(|&x| r.rho[number(names, x) as usize])
                    .collect()
            })
            .collect(),
        None => vec![Vec::new(); comm.size()],
    };
    drop(asked);
    let answered = comm.exchange_f64(&answer).swap_remove(0);
    drop(answer);
    let mut rho = vec![0.0f64; flipped.len()];
    for (&f, &x) in asking.iter().zip(&answered) {
        rho[f] = x;
    }
    drop((asking, answered));
    let ratios = ratios.map(|(r, _)| r);
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
