//! `polyspline._polyspline`: the extension module under the `polyspline` Python package.
//!
//! Input: option keywords (mapped onto the command line's option groups of `curve` and
//! `generate`, [`cli`]), mesh paths,
//! and meshes as raw little-endian buffers (points `f64 × 3`, cells `i64`, tags `i32`) that the
//! Python layer (`python/polyspline/__init__.py`) makes from numpy arrays and meshio meshes.
//! Output: the report as JSON text (and `check`'s report, as `polyspline check --json`), and
//! the curved or generated mesh as a [`Curved`] object whose arrays are buffers in Gmsh's,
//! VTK's or polyspline's lattice node order.
//!
//! Invariants: the GIL is released while a job runs; at every progress event (every stage and
//! every CG iteration) the job checks Python's signals (Ctrl-C) and calls the optional
//! callback, and stops when either raised (within one CG iteration during the fit's solve,
//! else at the next stage), re-raising that exception; every library error becomes an exception of the
//! `polyspline` hierarchy (`python/polyspline/errors.py`) with the command line's one-line
//! message; unknown option keywords raise `TypeError`.

mod cli;
mod convert;
mod options;

use cli::curve::{FileArgs, JobArgs, OutputArgs, curve_files, prepare_files};
use polyspline::mesh::HighOrderMesh;
use polyspline::pipeline::{CurveError, CurveReport};
use polyspline::progress::{Progress, Stage};
use polyspline::quality::CheckReport;
use pyo3::exceptions::{PyKeyboardInterrupt, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// Longest error message (characters), as the command line's.
const MAX_ERROR_CHARS: usize = 2000;

/// The receiver of a job's progress: checks Python's signals and calls the callback at every
/// event; the first exception either raises is kept and stops the job.
struct PyProgress {
    callback: Option<Py<PyAny>>,
    error: Mutex<Option<PyErr>>,
    stop: AtomicBool,
}

impl PyProgress {
    fn new(callback: Option<Py<PyAny>>) -> Self {
        PyProgress {
            callback: callback.filter(|c| Python::attach(|py| !c.is_none(py))),
            error: Mutex::new(None),
            stop: AtomicBool::new(false),
        }
    }

    fn event(&self, args: impl for<'py> FnOnce(Python<'py>) -> PyResult<Bound<'py, PyAny>>) {
        if self.stop.load(Ordering::Relaxed) {
            return;
        }
        Python::attach(|py| {
            // Signals are delivered to the main thread only; elsewhere this is a no-op.
            let result = py.check_signals().and_then(|()| match &self.callback {
                Some(cb) => cb.call1(py, (args(py)?,)).map(drop),
                None => Ok(()),
            });
            if let Err(e) = result {
                self.error
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .get_or_insert(e);
                self.stop.store(true, Ordering::Relaxed);
            }
        });
    }

    fn stage_event(&self, event: &'static str, stage: Stage) {
        self.event(|py| {
            let d = PyDict::new(py);
            d.set_item("event", event)?;
            d.set_item("stage", stage.key())?;
            Ok(d.into_any())
        });
    }

    /// The exception that stopped the job, if any.
    fn take_error(&self) -> Option<PyErr> {
        self.error.lock().unwrap_or_else(|p| p.into_inner()).take()
    }
}

impl Progress for PyProgress {
    fn started(&self, stage: Stage) {
        self.stage_event("started", stage);
    }
    fn finished(&self, stage: Stage) {
        self.stage_event("finished", stage);
    }
    fn cg(&self, iteration: usize, rel_residual: f64) {
        self.event(|py| {
            let d = PyDict::new(py);
            d.set_item("event", "cg")?;
            d.set_item("stage", Stage::FitCg.key())?;
            d.set_item("iteration", iteration)?;
            d.set_item("rel_residual", rel_residual)?;
            Ok(d.into_any())
        });
    }
    fn cancelled(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// The exception of the `polyspline` hierarchy for `e` (`fallback` names the class of an
/// untyped error, by the phase it came from).
fn to_py_err(py: Python<'_>, e: &anyhow::Error, fallback: &str) -> PyErr {
    use polyspline::io::ReadError;
    use polyspline::io::output::WriteError;
    let class = if let Some(c) = e.downcast_ref::<CurveError>() {
        match c {
            CurveError::Read(_) | CurveError::Features(_) | CurveError::Periodic { .. } => {
                "InputError"
            }
            CurveError::NotCurvable { .. } => "NotCurvableError",
            CurveError::Write(_) => "OutputError",
            CurveError::Options(_) => "ParameterError",
            CurveError::Gpu { .. } => "DeviceError",
            CurveError::Solve { .. } | CurveError::Energy { .. } | CurveError::Elastic { .. } => {
                "SolveError"
            }
            CurveError::Blend { .. } | CurveError::Validity { .. } | CurveError::Invalid { .. } => {
                "ValidityError"
            }
            CurveError::Cancelled => return PyKeyboardInterrupt::new_err("interrupted"),
        }
    } else if e.is::<ReadError>() || e.is::<polyspline::mesh::features::FeatureError>() {
        "InputError"
    } else if e.is::<WriteError>() {
        "OutputError"
    } else if e.is::<polyspline::params::ParamError>() {
        "ParameterError"
    } else if e.is::<polyspline::exec::gpu::GpuError>() {
        "DeviceError"
    } else {
        fallback
    };
    let message = polyspline::mesh::raw::one_line(&e.to_string(), MAX_ERROR_CHARS);
    error(py, class, message)
}

/// An exception of class `class` of `polyspline.errors`.
fn error(py: Python<'_>, class: &str, message: String) -> PyErr {
    match py
        .import("polyspline.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1((message,)))
    {
        Ok(exc) => PyErr::from_value(exc),
        Err(e) => e,
    }
}

/// The outcome of a job run with the GIL released: the progress receiver's exception first
/// (Ctrl-C, or the callback's), then the job's error.
fn finish<T>(
    py: Python<'_>,
    progress: &PyProgress,
    result: anyhow::Result<T>,
    fallback: &str,
) -> PyResult<T> {
    if let Some(e) = progress.take_error() {
        return Err(e);
    }
    result.map_err(|e| to_py_err(py, &e, fallback))
}

fn report_json(py: Python<'_>, r: &CurveReport) -> PyResult<String> {
    serde_json::to_string(r).map_err(|e| error(py, "Error", e.to_string()))
}

/// Curve the mesh file `mesh` into `output` as `polyspline curve MESH -o OUTPUT` with the
/// options `options` would, and return the report as JSON.
#[pyfunction]
#[pyo3(signature = (mesh, output, options, progress=None))]
fn curve_file(
    py: Python<'_>,
    mesh: PathBuf,
    output: PathBuf,
    options: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let mut argv = vec![
        mesh.into_os_string(),
        "--output".into(),
        output.into_os_string(),
    ];
    argv.extend(
        options::argv::<FileArgs>(py, options, &["mesh", "output"])?
            .into_iter()
            .map(Into::into),
    );
    let (mut files, matches) = options::parse_matches::<FileArgs>(py, argv)?;
    files.record_given(&matches);
    let progress = PyProgress::new(progress);
    let result = py.detach(|| {
        let job = prepare_files(files).map_err(|e| (e, "OutputError"))?;
        curve_files(&job, &progress).map_err(|e| (e, "InputError"))
    });
    let (result, fallback) = match result {
        Ok(r) => (Ok(r), "Error"),
        Err((e, f)) => (Err(e), f),
    };
    let r = finish(py, &progress, result, fallback)?;
    report_json(py, &r)
}

/// Curve a mesh in memory: `mesh` is a path (read by polyspline's readers) or the tuple
/// [`convert::raw_from_py`] takes. Returns the curved mesh.
#[pyfunction]
#[pyo3(signature = (mesh, options, progress=None))]
fn curve_mesh(
    py: Python<'_>,
    mesh: &Bound<'_, PyAny>,
    options: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Curved> {
    let argv = options::argv::<JobArgs>(py, options, &[])?;
    let (mut job, matches) =
        options::parse_matches::<JobArgs>(py, argv.into_iter().map(Into::into).collect())?;
    job.record_given(&matches);
    let source = match mesh.extract::<PathBuf>() {
        Ok(path) => Source::Path(path),
        Err(_) => Source::Raw(convert::raw_from_py(mesh)?),
    };
    let progress = PyProgress::new(progress);
    let result = py.detach(|| -> anyhow::Result<_> {
        let options = job.resolve(polyspline::pipeline::OutputOptions::default())?;
        let curved = match source {
            Source::Path(path) => {
                polyspline::pipeline::curve_in_memory_with_progress(&path, &options, &progress)?
            }
            Source::Raw(raw) => polyspline::pipeline::curve_raw_in_memory_with_progress(
                raw,
                Path::new(MEMORY),
                &options,
                &progress,
            )?,
        };
        Ok(curved)
    });
    let curved = finish(py, &progress, result, "ParameterError")?;
    Ok(Curved {
        report: report_json(py, &curved.report)?,
        ho: curved.ho,
    })
}

/// The name messages give a mesh passed as arrays.
const MEMORY: &str = "<memory>";

enum Source {
    Path(PathBuf),
    Raw(polyspline::mesh::raw::RawMesh),
}

/// A curved high-order mesh held by Rust (the Python class `polyspline.Curved` wraps it).
#[pyclass(frozen, module = "polyspline._polyspline")]
struct Curved {
    ho: HighOrderMesh,
    report: String,
}

#[pymethods]
impl Curved {
    /// The report as JSON (the keys of the command line's `--report`).
    #[getter]
    fn report_json(&self) -> &str {
        &self.report
    }

    #[getter]
    fn dim(&self) -> usize {
        self.ho.dim
    }

    #[getter]
    fn order(&self) -> usize {
        self.ho.order
    }

    /// The mesh as buffers with cells in node order `ordering` (`gmsh`, `vtk` or `lattice`):
    /// a dict of `points` (f64, n × 3), `cells` (i64), `cell_tags` (i32, may be empty),
    /// `facets` (i64), `facet_tags` (i32) and `tag_names` ({tag: name}).
    fn arrays<'py>(&self, py: Python<'py>, ordering: &str) -> PyResult<Bound<'py, PyDict>> {
        convert::arrays(py, &self.ho, ordering)
    }

    /// `polyspline check --json` of this mesh, as JSON.
    fn check(&self, py: Python<'_>) -> PyResult<String> {
        let ho = &self.ho;
        let report = py.detach(|| CheckReport::new(ho));
        serde_json::to_string(&report).map_err(|e| error(py, "Error", e.to_string()))
    }

    /// Write the mesh to `path` (format from the extension) with the output options of
    /// `polyspline curve`; atomically, as the command line writes.
    fn write(&self, py: Python<'_>, path: PathBuf, options: &Bound<'_, PyDict>) -> PyResult<()> {
        let argv = options::argv::<OutputArgs>(py, options, &[])?;
        let (mut out, matches) =
            options::parse_matches::<OutputArgs>(py, argv.into_iter().map(Into::into).collect())?;
        out.record_given(&matches);
        let ho = &self.ho;
        let result = py.detach(|| -> anyhow::Result<()> {
            if let Some(format) = polyspline::pipeline::OutputFormat::from_path(&path) {
                out.refuse_inapplicable(format)?;
            }
            let options = out.options();
            options.check()?;
            polyspline::pipeline::write_high_order(ho, &path, &options, &[])?;
            Ok(())
        });
        result.map_err(|e| to_py_err(py, &e, "OutputError"))
    }
}

/// `polyspline check MESH --json`: the sampled det J report of a high-order mesh file, as JSON.
#[pyfunction]
fn check(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    let result = py.detach(|| -> anyhow::Result<String> {
        let raw = polyspline::io::read_raw(&path)?;
        // The command line's reading of a high-order mesh (`cli::read_high_order`).
        let ho = HighOrderMesh::from_raw(raw)
            .map_err(|e| anyhow::anyhow!("{}: {}: {}", path.display(), e.location, e.message))?;
        Ok(serde_json::to_string(&CheckReport::new(&ho))?)
    });
    result.map_err(|e| to_py_err(py, &e, "InputError"))
}

/// `polyspline generate KIND` with the options `options` (its keywords but `output` and
/// `binary`, which belong to writing): the order-1 mesh it writes, and its counts as JSON.
#[pyfunction]
fn generate(py: Python<'_>, kind: String, options: &Bound<'_, PyDict>) -> PyResult<Curved> {
    use cli::generate::{ShapeArgs, make};
    let mut argv = vec![kind];
    argv.extend(options::argv::<ShapeArgs>(py, options, &["kind"])?);
    let args: ShapeArgs = options::parse(py, argv.into_iter().map(Into::into).collect())?;
    let made = py
        .detach(|| make(&args, Path::new("<generate>")))
        .map_err(|e| to_py_err(py, &e, "ParameterError"))?;
    let info = serde_json::json!({
        "elements": made.elements,
        "vertices": made.vertices,
        "boundary_facets": made.boundary_facets,
        "spacing": made.spacing,
    });
    Ok(Curved {
        ho: made.mesh,
        report: info.to_string(),
    })
}

/// Read a mesh file with polyspline's readers: the tuple [`convert::raw_to_py`] makes.
#[pyfunction]
fn read<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let raw = py
        .detach(|| polyspline::io::read_raw(&path))
        .map_err(|e| to_py_err(py, &e.into(), "InputError"))?;
    convert::raw_to_py(py, &raw)
}

/// The option names `kind` (`job`, `output`, `file` or `generate`) takes, with their defaults as the
/// command line spells them (`None` for none), for the Python layer's signatures and docs.
#[pyfunction]
fn option_defaults<'py>(py: Python<'py>, kind: &str) -> PyResult<Bound<'py, PyDict>> {
    match kind {
        "job" => options::defaults::<JobArgs>(py),
        "output" => options::defaults::<OutputArgs>(py),
        "file" => options::defaults::<FileArgs>(py),
        "generate" => options::defaults::<cli::generate::ShapeArgs>(py),
        _ => Err(PyTypeError::new_err(format!(
            "unknown option group {kind:?}"
        ))),
    }
}

#[pymodule]
fn _polyspline(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(curve_file, m)?)?;
    m.add_function(wrap_pyfunction!(curve_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(generate, m)?)?;
    m.add_function(wrap_pyfunction!(option_defaults, m)?)?;
    m.add_class::<Curved>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
