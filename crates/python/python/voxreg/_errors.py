"""The exceptions voxreg raises (the Rust core raises these classes)."""


class VoxregError(Exception):
    """Base class of every error voxreg raises (a failure of the computation itself, such
    as a factorization that failed or an internal error, is a plain ``VoxregError``)."""


class InputError(VoxregError, ValueError):
    """The input cannot be regularized: wrong dtype or shape, a negative label, no surface,
    grey levels without a threshold."""


class ParameterError(VoxregError, ValueError):
    """A parameter is out of range, unknown, or combined with one it excludes."""


class IoError(VoxregError, OSError):
    """A file cannot be read or written (missing, malformed, unknown extension)."""
