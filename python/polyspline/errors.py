"""The exceptions of polyspline: one class per kind of failure of the library.

Every message is the one line the command line prints after ``polyspline: error:`` (file,
place and problem). The extension raises these classes by name.
"""


class Error(Exception):
    """Base class of every polyspline error."""


#: The name the issue tracker and older scripts use.
PolysplineError = Error


class InputError(Error):
    """The input mesh (or the feature edits file) cannot be read, or is not a mesh
    polyspline curves: unknown format, a parse error, tangled elements..."""


class NotCurvableError(InputError):
    """The mesh is read but cannot be curved: duplicated elements, non-manifold facets,
    edges or vertices, or no boundary."""


class ParameterError(Error, ValueError):
    """An option out of range or of the wrong kind, or options that cannot be combined
    (also a ``ValueError``)."""


class OutputError(Error):
    """The output cannot be written: unknown format, an order the format cannot hold, a
    path onto the input, a full disk..."""


class DeviceError(Error):
    """The GPU backend was asked for and cannot run (no adapter, a device error)."""


class SolveError(Error):
    """A linear solve or minimisation failed (the fit's CG, the energy, the elastic
    analogy)."""


class ValidityError(Error):
    """The curved mesh could not be certified valid on every element; nothing was
    written."""


__all__ = [
    "Error",
    "PolysplineError",
    "InputError",
    "NotCurvableError",
    "ParameterError",
    "OutputError",
    "DeviceError",
    "SolveError",
    "ValidityError",
]
