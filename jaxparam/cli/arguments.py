"""Command-line options that mirror the API: named choices in either spelling, and defaults
read from the API functions' signatures (:func:`jaxparam.options.default_of`).

A named option (``--weights``, ``--boundary``, ``--solver``, ...) accepts
``shape-preserving`` and ``shape_preserving`` alike; the parsed value is the hyphenated
command-line spelling, which reports print, and handlers call the library with
:func:`jaxparam.options.canonical` of it.
"""
from __future__ import annotations

import argparse
import sys
from importlib import metadata
from typing import Any, Callable, Iterable

from .. import boundary as bmap
from .. import weights as wts
from ..linear import convex_map
from ..options import canonical, choose, default_of, hyphenated

from .pipeline import FLATTEN_OPTIONS, flatten_mesh

__all__ = ["Named", "add_named", "add_mirrored", "positive_int", "add_flatten_options", "flatten_options",
           "EXAMPLES", "HelpFormatter", "version", "subparser"]

#: One example a subcommand, shown at the end of its ``--help``.
EXAMPLES = {
    "info": "jaxparam info camelhead.off --json",
    "flatten": "jaxparam flatten camelhead.off -o flat.ply --weights mean-value --boundary circle\n"
               "  jaxparam flatten camelhead.off -o flat.glb --energy symmetric-dirichlet "
               "--free-boundary --checker-texture --report r.json --plot uv.png",
    "meshless": "jaxparam meshless points.xyz -o surface.obj --k 10 --plot uv.png",
    "fit": "jaxparam fit flat.obj -o spline.obj --surface spline --resolution 64",
    "remesh": "jaxparam remesh camelhead.off -o semi.obj --levels 4 --base-faces 6 "
              "--plot remesh.png",
    "compress": "jaxparam compress semi.obj -o small.obj --keep 0.02 --wavelet lifted",
    "manifold": "jaxparam manifold bunny.off -o bunny_semi.obj --base-faces 100 --levels 3",
    "atlas": "jaxparam atlas bunny.off -o bunny_atlas.glb --texture-size 1024 --plot atlas.png",
    "batch": "jaxparam batch meshes/ -o flat/ --weights mean-value --workers 2\n"
             "  jaxparam batch meshes/ -o flat/ --engine ray      (pip install 'jaxparam[ray]')",
}


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Help that keeps the examples' line breaks and shows every option's default (options
    without one, and flags, show none).  A :class:`Named` option shows its choices as
    ``{a,b,c}``, read only when help or a usage message is printed."""

    _printing = False       # add_argument formats an option's metavar too: resolve none then

    def format_help(self) -> str:
        self._printing = True
        return super().format_help()

    def _metavar_formatter(self, action, default_metavar):
        if action.metavar is None and isinstance(action.type, Named) and (
                self._printing or action.type.resolved):
            return super()._metavar_formatter(
                argparse.Action(action.option_strings, action.dest, metavar=action.type.metavar),
                default_metavar)
        return super()._metavar_formatter(action, default_metavar)

    def _get_help_string(self, action):
        text = action.help or ""
        if ("%(default)" not in text and action.option_strings and not action.required
                and action.default not in (None, False, argparse.SUPPRESS)
                and action.nargs != 0):
            text += " (default: %(default)s)"
        return text


def version() -> str:
    """The installed version of jaxparam (the package's own when it is not installed)."""
    try:
        return metadata.version("jaxparam")
    except metadata.PackageNotFoundError:
        return getattr(sys.modules.get("jaxparam"), "__version__", "unknown")


def subparser(sub, name: str, help: str, **kwargs) -> argparse.ArgumentParser:
    """``sub.add_parser(name)`` with its example as epilog and ``--quiet``."""
    p = sub.add_parser(name, help=help, description=kwargs.pop("description", help[:1].upper()
                                                                     + help[1:] + "."),
                       epilog="example:\n  " + EXAMPLES[name] if name in EXAMPLES else None,
                       formatter_class=HelpFormatter, **kwargs)
    p.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="no progress bars (also JAXPARAM_PROGRESS=0 or TQDM_DISABLE=1)")
    return p


class Named:
    """An argparse ``type=`` that accepts one of ``choices`` in either spelling.

    **Arguments:** ``choices`` the valid names (canonical or hyphenated), or a function
    returning them, called on first use (so that ``--energy``'s names load the energies
    only when the option is given or help is shown); ``what`` the option's name in the error
    message (``"weights"``).

    Calling it with a string returns the hyphenated spelling, or raises
    :class:`argparse.ArgumentTypeError` (a usage error, exit 2) listing the choices.
    """

    def __init__(self, choices: Iterable[str] | Callable[[], Iterable[str]], what: str, *,
                 default: str | None = None):
        self._choices = choices if callable(choices) else tuple(hyphenated(c) for c in choices)
        self.what = what
        self.default = None if default is None else hyphenated(default)
        self.__name__ = what            # argparse names the type in some messages

    @property
    def resolved(self) -> bool:
        """Whether the choices are known (not a function still to call)."""
        return not callable(self._choices)

    @property
    def choices(self) -> tuple[str, ...]:
        """The valid names, hyphenated."""
        if callable(self._choices):
            self._choices = tuple(hyphenated(c) for c in self._choices())
        return self._choices

    def __call__(self, text: str) -> str:
        if text == self.default:        # argparse converts a string default too: no lookup
            return text
        return hyphenated(choose(text, self.choices, what=self.what, where="",
                                 error=argparse.ArgumentTypeError))

    @property
    def metavar(self) -> str:
        """``{a,b,c}``, as argparse shows ``choices=``."""
        return "{" + ",".join(self.choices) + "}"


def add_named(p: argparse.ArgumentParser, flag: str, choices, default,
              help: str | None = None, *, what: str | None = None) -> None:
    """Add the named option ``flag`` to ``p``: either spelling accepted, the choices (names, or
    a function returning them, see :class:`Named`) listed in the help, ``default`` (a name,
    or None) shown hyphenated."""
    default = None if default is None else hyphenated(default)
    kind = Named(choices, what or flag.lstrip("-").replace("-", " "), default=default)
    text = (help + " " if help else "") + ("(default: %(default)s)" if default else "")
    p.add_argument(flag, type=kind, default=default, help=text or None)


def add_mirrored(p: argparse.ArgumentParser, flag: str, func: Callable, name: str, help: str,
                 *, type: Callable = int, fallback: Any = None) -> None:
    """Add ``flag``, an option mirroring parameter ``name`` of ``func``: its default is
    :func:`~jaxparam.options.default_of` ``(func, name)`` (``fallback`` when ``func`` takes
    it through ``**options``), shown in the help."""
    default = default_of(func, name) if fallback is None else default_of(func, name, fallback)
    p.add_argument(flag, type=type, default=default, help=f"{help} (default: %(default)s)")


def positive_int(flag: str) -> Callable[[str], int]:
    """argparse ``type=`` for ``flag``: an integer of at least 1, else a usage error (exit 2)
    at parse time (``--max-iters -3`` was refused with exit 3 after 3 s of work; session 27)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = 0
        if value < 1:
            raise argparse.ArgumentTypeError(f"{flag} must be a positive integer, got {text!r}")
        return value
    return parse


def _energy_names() -> list[str]:
    from ..energies import ENERGIES

    return sorted(ENERGIES)


def _solver_names() -> list[str]:
    from ..optimize import SOLVERS

    return list(SOLVERS)


def add_flatten_options(p: argparse.ArgumentParser) -> None:
    """The options of ``jaxparam flatten`` (and ``batch``); defaults are
    :func:`jaxparam.convex_map`'s and :func:`jaxparam.minimize`'s (the latter as
    :func:`~.pipeline.flatten_mesh` repeats them, so that a linear flatten imports neither
    the energies nor the optimizers: ``tests/test_cli.py`` checks that they agree)."""
    add_named(p, "--weights", wts.KINDS, default_of(convex_map, "weights"))
    add_named(p, "--boundary", bmap.SHAPES, default_of(convex_map, "boundary"))
    add_named(p, "--spacing", bmap.SPACINGS, default_of(convex_map, "spacing"))
    add_named(p, "--energy", _energy_names, None,
              "minimize this energy after the convex map (e.g. symmetric-dirichlet, mips)")
    p.add_argument("--free-boundary", action="store_true",
                   help="let the boundary move while minimizing (needs --energy)")
    add_named(p, "--solver", _solver_names, default_of(flatten_mesh, "solver"))
    add_mirrored(p, "--max-iters", flatten_mesh, "max_iters", "iterations at most",
                 type=positive_int("--max-iters"))


def flatten_option_conflict(args: argparse.Namespace) -> str | None:
    """The message refusing the minimization's options without ``--energy`` (the convex
    map alone has no iterations, solver or moving boundary, and they would be ignored
    without a word), or ``None`` when the options agree."""
    if getattr(args, "energy", "") is not None or not hasattr(args, "free_boundary"):
        return None
    given = [name for name, on in (
        ("--free-boundary", args.free_boundary),
        ("--solver", canonical(args.solver) != canonical(default_of(flatten_mesh, "solver"))),
        ("--max-iters", args.max_iters != default_of(flatten_mesh, "max_iters"))) if on]
    if not given:
        return None
    return (f"{' and '.join(given)} set{'s' if len(given) == 1 else ''} how an energy is "
            "minimized, but no --energy is given: add one (e.g. --energy symmetric-dirichlet), "
            f"or leave out {' and '.join(given)} for the convex map alone.")


def flatten_options(args: argparse.Namespace) -> dict:
    """The keyword options of :func:`~.pipeline.flatten_mesh` from parsed arguments."""
    return {k: getattr(args, k) for k in FLATTEN_OPTIONS}
