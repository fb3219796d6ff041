"""Named options: one vocabulary for the API and the command line.

Options that take a name (weights, boundary, spacing, energy, solver, wavelet, surface
kind, ...) have canonical names with underscores (``shape_preserving``).  Both the API and
the ``jaxparam`` command accept the hyphenated spelling too (``shape-preserving``);
:func:`choose` maps either to the canonical name and words the error for anything else.

Where a command-line option mirrors a keyword of the API, :func:`default_of` reads its
default from the function's signature, so the two never disagree.

This module imports nothing from jaxparam but :mod:`jaxparam.errors`, so every layer may
use it.
"""
from __future__ import annotations

import inspect
from typing import Any, Callable, Iterable

import numpy as np

from .errors import MeshError

__all__ = ["canonical", "hyphenated", "choose", "default_of", "is_integer", "is_number", "is_flag"]

_NONE = object()


def canonical(name: str) -> str:
    """The canonical spelling of an option name: hyphens become underscores
    (``"shape-preserving"`` -> ``"shape_preserving"``)."""
    return name.replace("-", "_")


def hyphenated(name: str) -> str:
    """The command-line spelling of an option name: underscores become hyphens
    (``"shape_preserving"`` -> ``"shape-preserving"``)."""
    return name.replace("_", "-")


def choose(value: str, choices: Iterable[str], *, what: str, where: str,
           error: type[Exception] = MeshError) -> str:
    """The canonical name of ``value`` among ``choices``; either spelling is accepted.

    **Arguments:** ``value`` the name given (``"shape-preserving"`` or
    ``"shape_preserving"``); ``choices`` the valid names (either spelling; compared in
    canonical form); ``what`` the option's name for the message (``"weights"``);
    ``where`` the function or command that received it (``"convex_map"``; empty for a
    caller that adds its own prefix, as argparse does); ``error`` the exception class
    raised (default :class:`~jaxparam.errors.MeshError`).

    **Returns:** the canonical (underscore) name, e.g. ``"shape_preserving"``.

    **Raises:** ``error`` with the message ``"{where}: unknown {what} {value!r}; use one of
    a, b, c."`` (the choices spelled as given) when ``value`` is not a string or names none
    of the choices.
    """
    choices = tuple(choices)
    if isinstance(value, str) and canonical(value) in {canonical(c) for c in choices}:
        return canonical(value)
    prefix = f"{where}: " if where else ""
    raise error(f"{prefix}unknown {what} {value!r}; use one of {', '.join(choices)}.")


def default_of(func: Callable, name: str, fallback: Any = _NONE) -> Any:
    """The default value of parameter ``name`` in ``func``'s signature.

    **Arguments:** ``func`` a function (or class, method); ``name`` one of its parameters;
    ``fallback`` returned when ``func`` has no such parameter with a default (for example
    when it takes the option through ``**options``).

    **Raises:** :class:`TypeError` when there is no such default and no ``fallback``.
    """
    param = inspect.signature(func).parameters.get(name)
    if param is not None and param.default is not inspect.Parameter.empty:
        return param.default
    if fallback is not _NONE:
        return fallback
    raise TypeError(f"default_of: {getattr(func, '__qualname__', func)} has no parameter "
                    f"{name!r} with a default.")


def is_integer(x) -> bool:
    """Whether ``x`` is an integer option value (Python or NumPy; ``True`` is not one)."""
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


def is_number(x) -> bool:
    """Whether ``x`` is a real number option value (int or float, Python or NumPy; not a
    bool, a string or an array)."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def is_flag(x) -> bool:
    """Whether ``x`` is a bool option value (Python or NumPy)."""
    return isinstance(x, (bool, np.bool_))
