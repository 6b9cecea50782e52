//! The `curve` job end to end: read → topology → element maps → sample → write, with timings.
//!
//! Input: a mesh path and [`CurveOptions`]. Output: the written high-order mesh file and a
//! [`CurveReport`]. The output file is written atomically and never onto the input.

use crate::io::gmsh_write::{MshVersion, write_msh};
use crate::io::output::{WriteError, write_atomically};
use crate::io::vtu_write::{VtuEncoding, write_vtu};
use crate::io::{ReadError, read_mesh};
use crate::mesh::{MeshOptions, Topology};
use crate::sample::{BezierElements, HighOrderMesh, MAX_ORDER, sample};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What geometry to sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Geometry {
    /// The input's straight-sided (bilinear/trilinear) elements at the requested order.
    Straight,
}

/// Output file options.
#[derive(Clone, Debug)]
pub struct OutputOptions {
    pub msh_version: MshVersion,
    pub binary: bool,
    pub vtu_encoding: VtuEncoding,
}

impl Default for OutputOptions {
    fn default() -> Self {
        OutputOptions {
            msh_version: MshVersion::V41,
            binary: false,
            vtu_encoding: VtuEncoding::Base64,
        }
    }
}

/// Options of the `curve` job.
#[derive(Clone, Debug)]
pub struct CurveOptions {
    pub order: usize,
    /// Order 1 output split into `subdivide`^d elements per input element.
    pub subdivide: Option<usize>,
    pub geometry: Geometry,
    pub mesh: MeshOptions,
    pub output: OutputOptions,
}

/// Everything that can stop the `curve` job.
#[derive(Debug, thiserror::Error)]
pub enum CurveError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error(transparent)]
    Write(#[from] WriteError),
    #[error("{0}")]
    Options(String),
}

/// What `curve` did, for `--report` and the terminal.
#[derive(Clone, Debug, Serialize)]
pub struct CurveReport {
    pub input: PathBuf,
    pub output: PathBuf,
    pub dimension: usize,
    pub elements: usize,
    pub order: usize,
    pub subdivide: Option<usize>,
    pub geometry: Geometry,
    pub output_nodes: usize,
    pub output_elements: usize,
    pub boundary_facets: usize,
    pub control_points: usize,
    pub spline_elements: usize,
    pub q2_elements: usize,
    /// Seconds per stage, and `total`.
    pub timings: BTreeMap<String, f64>,
}

/// Output format from the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputFormat {
    Msh,
    Vtu,
}

impl OutputFormat {
    pub fn from_path(path: &Path) -> Option<OutputFormat> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "msh" => Some(OutputFormat::Msh),
            "vtu" => Some(OutputFormat::Vtu),
            _ => None,
        }
    }
}

/// Write a high-order mesh to `path` in the format its extension names.
pub fn write_high_order(
    mesh: &HighOrderMesh,
    path: &Path,
    options: &OutputOptions,
    inputs: &[&Path],
) -> Result<(), WriteError> {
    let format = OutputFormat::from_path(path).ok_or_else(|| WriteError::Unsupported {
        path: path.to_owned(),
        what: "unknown output format; use .msh (Gmsh) or .vtu (VTK)".into(),
    })?;
    if format == OutputFormat::Msh && mesh.dim == 3 && mesh.order > 9 {
        return Err(WriteError::Unsupported {
            path: path.to_owned(),
            what: format!(
                "Gmsh has no hexahedron of order {}; the highest is 9 (use .vtu for order 10)",
                mesh.order
            ),
        });
    }
    write_atomically(path, inputs, |w| match format {
        OutputFormat::Msh => write_msh(mesh, options.msh_version, options.binary, w),
        OutputFormat::Vtu => write_vtu(mesh, options.vtu_encoding, w),
    })
}

/// Run the `curve` job.
pub fn curve(
    input: &Path,
    output: &Path,
    options: &CurveOptions,
) -> Result<CurveReport, CurveError> {
    let order = options.subdivide.unwrap_or(options.order);
    if options.subdivide.is_some() && options.order != 1 {
        return Err(CurveError::Options(
            "--subdivide gives order-1 output; use it with --order 1".into(),
        ));
    }
    if !(1..=MAX_ORDER).contains(&order) {
        return Err(CurveError::Options(format!(
            "order {order} is out of range 1..={MAX_ORDER}"
        )));
    }
    if OutputFormat::from_path(output).is_none() {
        return Err(WriteError::Unsupported {
            path: output.to_owned(),
            what: "unknown output format; use .msh (Gmsh) or .vtu (VTK)".into(),
        }
        .into());
    }
    let start = Instant::now();
    let mut timings = BTreeMap::new();
    let mut lap = {
        let mut t = Instant::now();
        move |name: &str, timings: &mut BTreeMap<String, f64>| {
            timings.insert(name.to_string(), t.elapsed().as_secs_f64());
            t = Instant::now();
        }
    };
    let mesh = read_mesh(input, &options.mesh)?;
    lap("read", &mut timings);
    let topo = Topology::build(&mesh);
    lap("topology", &mut timings);
    let source: &dyn BezierElements = match options.geometry {
        Geometry::Straight => &mesh,
    };
    let mut ho = sample(source, &mesh, &topo, order);
    if options.subdivide.is_some() {
        ho = ho.subdivided();
    }
    lap("sample", &mut timings);
    write_high_order(&ho, output, &options.output, &[input])?;
    lap("write", &mut timings);
    timings.insert("total".into(), start.elapsed().as_secs_f64());
    Ok(CurveReport {
        input: input.to_owned(),
        output: output.to_owned(),
        dimension: mesh.dim,
        elements: mesh.n_elements(),
        order: ho.order,
        subdivide: options.subdivide,
        geometry: options.geometry,
        output_nodes: ho.nodes.len(),
        output_elements: ho.n_elements(),
        boundary_facets: ho.n_boundary(),
        control_points: 0,
        spline_elements: 0,
        q2_elements: 0,
        timings,
    })
}
