"""The exceptions voxreg raises (the Rust core raises these classes)."""

import operator


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


def label_argument(name: str, value):
    """``value`` as a label (an integer in ``0..=2**32 - 1``) or None, else a
    ``ParameterError`` naming ``name``."""
    if value is None:
        return None
    try:
        label = operator.index(value)  # ints and numpy integers, not floats or strings
    except TypeError:
        raise ParameterError(f"{name} must be an integer label or None, got {value!r}") from None
    if isinstance(value, bool) or not 0 <= label <= 2**32 - 1:
        raise ParameterError(f"{name} must be a label from 0 to 4294967295 or None, got {value!r}")
    return label
