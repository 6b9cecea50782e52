"""polyspline: curved high-order quad/hex meshes from linear ones, without CAD.

The Python face of the polyspline library (docs/python.md). The heavy work runs in Rust with
the GIL released; Ctrl-C stops a job between its stages.

* :func:`curve` curves a mesh in memory: a path, a ``meshio.Mesh`` or numpy arrays; it
  returns a :class:`Curved` mesh (arrays in Gmsh's node order, ``.to_meshio()``,
  ``.write()``, ``.report``).
* :func:`curve_file` is ``polyspline curve MESH -o OUTPUT`` and returns the report.
* :func:`read` reads any mesh file polyspline reads into a ``meshio.Mesh``.
* :func:`check` is ``polyspline check --json``: the sampled det J validity of a high-order
  mesh (a path, a :class:`Curved` or :class:`Mesh`, or a ``meshio.Mesh``).
* :func:`generate` is ``polyspline generate``: a synthetic linear :class:`Mesh`.
* :func:`options` lists the option keywords and their defaults.

The option keywords are the command line's ``curve`` options with ``_`` for ``-``
(``kink_angle=20`` is ``--kink-angle 20``), with the same defaults, parsing and checks; a
flag takes ``True``/``False``. An unknown keyword raises ``TypeError``; a bad value raises
:class:`ParameterError` (a ``ValueError``) with the command line's message. Failures raise
the classes of :mod:`polyspline.errors`.
"""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Dict, Optional, Tuple

import numpy as np

# Mesa's Vulkan drivers print an error line while adapters are probed when the process has no
# runtime directory (the command line does the same).
if not os.environ.get("XDG_RUNTIME_DIR"):
    import tempfile

    os.environ["XDG_RUNTIME_DIR"] = tempfile.gettempdir()

from . import _polyspline  # noqa: E402
from .errors import (
    DeviceError,
    Error,
    InputError,
    NotCurvableError,
    OutputError,
    ParameterError,
    PolysplineError,
    SolveError,
    ValidityError,
)

__version__ = _polyspline.__version__

#: A progress callback receives one dict per event: ``{"event": "started" | "finished",
#: "stage": name}`` around every stage (the names of the report's ``timings``), and
#: ``{"event": "cg", "stage": "fit_cg", "iteration": i, "rel_residual": r}`` on every CG
#: iteration of the fit. An exception it raises stops the job and is re-raised.
ProgressCallback = Callable[[Dict[str, Any]], None]


def options(kind: str = "curve") -> Dict[str, Any]:
    """The option keywords and their defaults as the command line spells them (``None``: no
    default, ``False``: a flag). ``kind``: ``"curve"`` (:func:`curve`), ``"write"``
    (:meth:`Curved.write`), ``"curve_file"`` (:func:`curve_file`) or ``"generate"``
    (:func:`generate`)."""
    group = {"curve": "job", "write": "output", "curve_file": "file",
             "generate": "generate"}.get(kind)
    if group is None:
        raise ValueError(f"kind {kind!r}: expected 'curve', 'write', 'curve_file' or 'generate'")
    out = dict(_polyspline.option_defaults(group))
    if group == "file":
        out.update(_polyspline.option_defaults("job"))
        out.update(_polyspline.option_defaults("output"))
        out.pop("output", None)
    return out


def curve_file(
    mesh: "os.PathLike[str] | str",
    output: "os.PathLike[str] | str",
    *,
    progress: Optional[ProgressCallback] = None,
    **options: Any,
) -> Dict[str, Any]:
    """Curve the mesh file ``mesh`` into ``output``, exactly as ``polyspline curve MESH -o
    OUTPUT --OPTION VALUE...`` does (the same file, byte for byte), and return the report
    (the keys of ``--report``; ``report="r.json"`` also writes it). Every option of the
    command line's ``curve`` is a keyword, output options (``msh_version``, ``binary``,
    ``vtu_encoding``, ``volume_name``, ``vtu_boundary``) included."""
    text = _polyspline.curve_file(os.fspath(mesh), os.fspath(output), options, progress)
    return json.loads(text)


def curve(
    mesh: Any,
    *,
    progress: Optional[ProgressCallback] = None,
    **options: Any,
) -> "Curved":
    """Curve a linear quad or hex mesh in memory.

    ``mesh`` is one of

    * a path (any format polyspline reads);
    * a ``meshio.Mesh`` (its ``quad``/``hexahedron`` cells are the elements, ``line``/``quad``
      cells the tagged boundary; tags from the cell data ``gmsh:physical``, ``medit:ref`` or
      ``cell_tags``, names from ``field_data``);
    * a tuple ``(points, cells)`` or ``(points, cells, facets, facet_tags)`` or
      ``(points, cells, facets, facet_tags, tag_names)`` of arrays: points ``(n, 2)`` or
      ``(n, 3)``, cells ``(m, 4)`` quads or ``(m, 8)`` hexes in VTK/Gmsh node order,
      facets ``(k, 2)`` lines or ``(k, 4)`` quads with one integer tag each, and
      ``{tag: name}``.

    The keywords are the job's options (:func:`options`); output options belong to
    :meth:`Curved.write`. Returns the :class:`Curved` mesh with its report.
    """
    if isinstance(mesh, (str, os.PathLike)):
        source: Any = os.fspath(mesh)
    else:
        source = _raw_of(mesh)
    return Curved(_polyspline.curve_mesh(source, options, progress))


def check(mesh: Any, *, strict: bool = False) -> Dict[str, Any]:
    """The validity and quality of a high-order mesh, as ``polyspline check MESH --json``:
    det J sampled on every element (the same report, key for key).

    ``mesh`` is a path (``.msh``, ``.vtu``... any file polyspline reads; the command line's
    messages), a :class:`Curved` or :class:`Mesh`, or a ``meshio.Mesh`` (checked through a
    temporary Gmsh file written by meshio, in meshio's node conventions). Returns a dict:
    ``dimension``, ``elements``, ``order``, ``nodes``, ``boundary_facets``, ``invalid``
    (elements with a sampled det J ≤ 0), ``min_scaled_jacobian``, ``min_det_jacobian``,
    ``worst_element`` (0-based), ``method``. With ``strict=True`` an invalid element raises
    :class:`ValidityError` instead (the command line's exit status 3).
    """
    if isinstance(mesh, Mesh):
        report = json.loads(mesh._inner.check())
        where = repr(mesh)
    elif isinstance(mesh, (str, os.PathLike)):
        report = json.loads(_polyspline.check(os.fspath(mesh)))
        where = os.fspath(mesh)
    elif hasattr(mesh, "cells") and hasattr(mesh, "points"):
        import tempfile

        import meshio

        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "mesh.msh")
            meshio.write(path, mesh, file_format="gmsh")
            report = json.loads(_polyspline.check(path))
        where = "<meshio mesh>"
    else:
        raise TypeError("mesh: expected a path, a polyspline.Mesh or Curved, or a meshio.Mesh")
    if strict and report["invalid"] > 0:
        raise ValidityError(
            f"{where}: {report['invalid']} element(s) with a sampled det J <= 0 "
            f"(min det J {report['min_det_jacobian']:.6e}; worst element {report['worst_element']})"
        )
    return report


def generate(kind: str, *, output: "Optional[os.PathLike[str] | str]" = None,
             binary: bool = False, **options: Any) -> "Mesh":
    """A synthetic linear mesh, as ``polyspline generate KIND``: ``"disc"`` (2D),
    ``"cylinder"``, ``"torus"`` (``elements=N`` required), ``"ogrid"`` or ``"cgrid"``
    (boundary-layer grids: ``wall``, ``thickness``, ``around``, ``across``, ``first_height``,
    ``growth``, ``farfield``, ``layers``, ``span``, ``wake``). The keywords are the command
    line's options (:func:`options` ``("generate")``), parsed and checked by the same code.

    Returns the :class:`Mesh` (order 1; ``.info`` has its ``elements``, ``vertices``,
    ``boundary_facets`` and, for O- and C-grids, the wall-normal ``spacing`` line); pass it
    to :func:`curve` directly, or ``.to_meshio()``. With ``output``, it is also written as the
    command line writes it (the same bytes; ``binary`` for binary MSH).
    """
    mesh = Mesh(_polyspline.generate(str(kind), options))
    if output is not None:
        mesh.write(output, binary=binary)
    elif binary:
        raise ValueError("binary: only with output")
    return mesh


def read(path: "os.PathLike[str] | str", *, arrays: bool = False):
    """Read a mesh file with polyspline's readers (every input format: Gmsh MSH, VTU/VTK,
    Medit, MFEM, Exodus, SU2, CGNS/HDF5, Abaqus; and the high-order files it writes).

    Returns a ``meshio.Mesh`` (meshio's node order; tags in ``gmsh:physical``, names in
    ``field_data``), or with ``arrays=True`` a dict of numpy arrays without meshio:
    ``points`` (n × 3), ``cells`` and ``cell_tags`` ({meshio cell type: array}, Gmsh's node
    order for high-order cells) and ``tag_names`` ({tag: name}).
    """
    kind, data = _polyspline.read(os.fspath(path))
    if kind == "high_order":
        mesh = _Arrays(data)
        if not arrays:
            return mesh.to_meshio()
        cells, tags = {}, {}
        for dim, conn, t in ((mesh.dim, mesh.cells, mesh.cell_tags),
                             (mesh.dim - 1, mesh.facets, mesh.facet_tags)):
            if len(conn):
                name = _meshio_type(dim, conn.shape[1])
                cells[name] = conn
                tags[name] = t if len(t) else np.zeros(len(conn), dtype=np.int32)
        return {"points": mesh.points, "cells": cells, "cell_tags": tags,
                "tag_names": mesh.tag_names}
    points, blocks, tag_names = data
    points = np.frombuffer(points, dtype=np.float64).reshape(-1, 3)
    cells, tags = [], []
    for name, n, nodes, block_tags in blocks:
        data_ = np.frombuffer(nodes, dtype=np.int64).reshape(-1, n)
        t = np.frombuffer(block_tags, dtype=np.int32)
        cells.append((name, data_))
        tags.append(t if len(t) else np.zeros(len(data_), dtype=np.int32))
    if arrays:
        out_cells: Dict[str, np.ndarray] = {}
        out_tags: Dict[str, np.ndarray] = {}
        for (name, c), t in zip(cells, tags):
            out_cells[name] = np.concatenate([out_cells[name], c]) if name in out_cells else c
            out_tags[name] = np.concatenate([out_tags[name], t]) if name in out_tags else t
        return {"points": points, "cells": out_cells, "cell_tags": out_tags,
                "tag_names": dict(tag_names)}
    import meshio

    dims = {"vertex": 0, "line": 1, "triangle": 2, "quad": 2}
    field_data = {}
    for tag, name in tag_names.items():
        dim = next((dims.get(c[0], 3) for c, t in zip(cells, tags) if tag in t), 0)
        field_data[name] = np.array([tag, dim])
    return meshio.Mesh(points, [meshio.CellBlock(n, c) for n, c in cells],
                       cell_data={"gmsh:physical": tags}, field_data=field_data)


# --- input -----------------------------------------------------------------------------------

_LINEAR = {
    (1, 2): "line",
    (2, 4): "quad",
    (3, 8): "hexahedron",
}
_TAG_KEYS = ("gmsh:physical", "medit:ref", "cell_tags")


def _points(points: Any) -> bytes:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points: expected an (n, 2) or (n, 3) array, got shape {p.shape}")
    if p.shape[1] == 2:
        p = np.hstack([p, np.zeros((len(p), 1))])
    return np.ascontiguousarray(p).tobytes()


def _block(name: str, cells: Any, tags: Any = None) -> Tuple[str, int, bytes, bytes]:
    c = np.asarray(cells)
    if c.ndim != 2 or not np.issubdtype(c.dtype, np.integer):
        raise ValueError(f"cells of type {name}: expected a 2D integer array, got {c.dtype} {c.shape}")
    t = np.zeros(0, dtype=np.int32) if tags is None else np.asarray(tags, dtype=np.int32).ravel()
    return (name, c.shape[1], np.ascontiguousarray(c, dtype=np.int64).tobytes(), t.tobytes())


def _raw_of(mesh: Any):
    """The extension's input tuple of a :class:`Mesh`, a meshio mesh or a tuple of arrays."""
    if isinstance(mesh, Mesh):
        return mesh._raw()
    if hasattr(mesh, "cells") and hasattr(mesh, "points"):
        blocks = []
        for i, block in enumerate(mesh.cells):
            tags = None
            for key in _TAG_KEYS:
                if key in mesh.cell_data:
                    tags = mesh.cell_data[key][i]
                    break
            blocks.append(_block(block.type, block.data, tags))
        names = {int(v[0]): str(k) for k, v in getattr(mesh, "field_data", {}).items() if len(v)}
        return (_points(mesh.points), blocks, names)
    if not isinstance(mesh, (tuple, list)) or not 2 <= len(mesh) <= 5 or len(mesh) == 3:
        raise TypeError(
            "mesh: expected a path, a meshio.Mesh, or a tuple (points, cells[, facets, facet_tags[, tag_names]])"
        )
    points, cells = mesh[0], np.asarray(mesh[1])
    dim = {4: 2, 8: 3}.get(cells.shape[-1] if cells.ndim == 2 else 0)
    if dim is None:
        raise ValueError(f"cells: expected (m, 4) quads or (m, 8) hexes, got shape {cells.shape}")
    blocks = [_block(_LINEAR[(dim, cells.shape[1])], cells)]
    names: Dict[int, str] = {}
    if len(mesh) >= 4:
        facets = np.asarray(mesh[2])
        kind = _LINEAR.get((dim - 1, facets.shape[-1] if facets.ndim == 2 else 0))
        if kind is None:
            raise ValueError(f"facets: expected ({'k, 2' if dim == 2 else 'k, 4'}) node ids, got shape {facets.shape}")
        blocks.append(_block(kind, facets, mesh[3]))
    if len(mesh) == 5:
        names = {int(k): str(v) for k, v in dict(mesh[4]).items()}
    return (_points(points), blocks, names)


# --- output ----------------------------------------------------------------------------------

# meshio keeps Gmsh's node order except for a few cells, where it uses VTK's; the permutation
# is the one meshio's Gmsh reader applies (meshio/gmsh/common.py, `_gmsh_to_meshio_order`).
_GMSH_TO_MESHIO = {
    "hexahedron27": [0, 1, 2, 3, 4, 5, 6, 7, 8, 11, 13, 9, 16, 18, 19, 17, 10, 12, 14, 15,
                     22, 23, 21, 24, 20, 25, 26],
}


def _meshio_type(dim: int, n: int) -> str:
    base = {1: "line", 2: "quad", 3: "hexahedron"}[dim]
    return base if n == 2 ** dim else f"{base}{n}"


class _Arrays:
    """A high-order mesh as numpy arrays (cells in Gmsh's node order)."""

    def __init__(self, d: Dict[str, Any]):
        self.dim: int = d["dim"]
        self.order: int = d["order"]
        self.points = np.frombuffer(d["points"], dtype=np.float64).reshape(-1, 3)
        self.cells = np.frombuffer(d["cells"], dtype=np.int64).reshape(-1, d["nodes_per_cell"])
        self.cell_tags = np.frombuffer(d["cell_tags"], dtype=np.int32)
        self.facets = np.frombuffer(d["facets"], dtype=np.int64).reshape(-1, d["nodes_per_facet"])
        self.facet_tags = np.frombuffer(d["facet_tags"], dtype=np.int32)
        self.tag_names: Dict[int, str] = dict(d["tag_names"])

    def to_meshio(self):
        import meshio

        blocks, tags = [], []
        for dim, conn, t in ((self.dim, self.cells, self.cell_tags),
                             (self.dim - 1, self.facets, self.facet_tags)):
            if not len(conn):
                continue
            name = _meshio_type(dim, conn.shape[1])
            if name in _GMSH_TO_MESHIO:
                conn = conn[:, _GMSH_TO_MESHIO[name]]
            blocks.append(meshio.CellBlock(name, np.ascontiguousarray(conn)))
            tags.append(t.astype(np.int32) if len(t) else np.zeros(len(conn), dtype=np.int32))
        field_data = {}
        for tag, name in self.tag_names.items():
            dim = self.dim - 1 if np.any(self.facet_tags == tag) else self.dim
            field_data[name] = np.array([tag, dim])
        # Gmsh's entities, which meshio's MSH 4.1 writer needs with several cell types and
        # declares from the nodes' `gmsh:dim_tags`: the volume is entity 1, each boundary tag
        # an entity of its own (untagged facets one more) holding its facets' interior nodes.
        geometrical = [np.ones(len(tags[0]), dtype=np.int32)]
        dim_tags = np.column_stack([np.full(len(self.points), self.dim),
                                    np.ones(len(self.points))]).astype(np.int32)
        if len(tags) > 1:
            facet_entity = tags[1].copy()
            facet_entity[facet_entity <= 0] = max(int(facet_entity.max()), 0) + 1
            geometrical.append(facet_entity)
            interior = self.facets[:, 2 ** (self.dim - 1):]
            dim_tags[interior.ravel(), 0] = self.dim - 1
            dim_tags[interior.ravel(), 1] = np.repeat(facet_entity, interior.shape[1])
        return meshio.Mesh(
            self.points.copy(),
            blocks,
            point_data={"gmsh:dim_tags": dim_tags},
            cell_data={"gmsh:physical": tags, "gmsh:geometrical": geometrical},
            field_data=field_data,
        )


class Mesh(_Arrays):
    """A high-order (or, from :func:`generate`, linear) mesh held by polyspline.

    Attributes: ``points`` (n × 3 float64), ``cells`` (elements × (order+1)^dim, int64, Gmsh's
    node order), ``cell_tags`` (one region tag per element, or empty), ``facets`` (boundary
    facets × (order+1)^(dim-1), Gmsh's order, oriented outward), ``facet_tags`` (one tag per
    facet, 0 for none), ``tag_names`` ({tag: name}), ``dim``, ``order``.
    """

    def __init__(self, inner: Any):
        super().__init__(inner.arrays("gmsh"))
        self._inner = inner
        #: What made it (:func:`generate`'s counts); :class:`Curved` has ``report`` instead.
        self.info: Dict[str, Any] = json.loads(inner.report_json)

    def cells_vtk(self) -> Tuple[np.ndarray, np.ndarray]:
        """(cells, facets) in VTK's Lagrange node order (cell types 70 and 72, facets 68/70)."""
        d = self._inner.arrays("vtk")
        cells = np.frombuffer(d["cells"], dtype=np.int64).reshape(-1, d["nodes_per_cell"])
        facets = np.frombuffer(d["facets"], dtype=np.int64).reshape(-1, d["nodes_per_facet"])
        return cells, facets

    def to_meshio(self):
        """The mesh as a ``meshio.Mesh`` in meshio's conventions: ``quad9``, ``hexahedron27``
        (VTK's triquadratic order, as meshio keeps it), ``hexahedron64``... and the boundary
        facets as ``line*``/``quad*`` cells; tags in ``gmsh:physical``, names in
        ``field_data``."""
        return super().to_meshio()

    def write(self, path: "os.PathLike[str] | str", **options: Any) -> None:
        """Write the mesh as ``polyspline curve`` would (format from the extension: .msh, .vtu,
        .cgns, .inp), with the output options of :func:`options` ``("write")``."""
        self._inner.write(os.fspath(path), options)

    def check(self, *, strict: bool = False) -> Dict[str, Any]:
        """:func:`check` of this mesh."""
        return check(self, strict=strict)

    def _raw(self):
        """The input tuple of :func:`curve` (a linear mesh: order 1)."""
        if self.order != 1:
            raise ValueError(f"mesh: order {self.order}; curve takes a linear mesh (order 1)")
        return _raw_of((self.points, self.cells, self.facets, self.facet_tags, self.tag_names))

    def __repr__(self) -> str:
        return (f"<polyspline.{type(self).__name__} {len(self.cells)} order-{self.order} "
                f"{'quads' if self.dim == 2 else 'hexes'}, {len(self.points)} nodes>")


class Curved(Mesh):
    """A curved high-order mesh and its report: a :class:`Mesh` with ``report``, a dict with
    the keys of the command line's ``--report``."""

    def __init__(self, inner: Any):
        super().__init__(inner)
        self.report: Dict[str, Any] = self.info


__all__ = [
    "Curved",
    "Mesh",
    "DeviceError",
    "Error",
    "InputError",
    "NotCurvableError",
    "OutputError",
    "ParameterError",
    "PolysplineError",
    "ProgressCallback",
    "SolveError",
    "ValidityError",
    "check",
    "curve",
    "curve_file",
    "generate",
    "options",
    "read",
]
