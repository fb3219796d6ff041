"""Progress bars for every long stage of the library, behind one switch (``jp.config.progress``).

``progress(iterable=None, *, total=None, desc, unit="it", verbose=None)`` returns a tqdm bar
(usable as an iterator wrapper, a context manager, or with ``.update(n)``).  It

- is disabled when ``verbose`` is false, or when ``verbose`` is None and ``jp.config.progress``
  is off (``JAXPARAM_PROGRESS=0`` or ``TQDM_DISABLE=1`` in the environment);
- uses the notebook widget only inside Jupyter *with* ipywidgets, and the text bar otherwise,
  so a kernel without ipywidgets never prints tqdm's "IProgress not found" warning;
- shows only for stages that last longer than ``delay`` seconds (default 1 s).
"""
from __future__ import annotations

import sys
from functools import lru_cache

from .settings import config

__all__ = ["progress", "enabled", "write"]


def enabled(verbose: bool | None = None) -> bool:
    """Whether a bar shows: ``verbose`` when given, else the library switch."""
    return config.progress if verbose is None else bool(verbose)


@lru_cache(maxsize=1)
def _bar_class():
    """tqdm's notebook bar in a Jupyter kernel that has ipywidgets, else the text bar."""
    from tqdm import tqdm as text_bar

    shell = sys.modules.get("IPython")
    try:
        kernel = shell is not None and type(shell.get_ipython()).__name__ == "ZMQInteractiveShell"
    except Exception:  # noqa: BLE001 - IPython present but not running a shell
        kernel = False
    if not kernel:
        return text_bar
    try:
        import ipywidgets  # noqa: F401
        from tqdm.notebook import tqdm as notebook_bar
    except ImportError:
        return text_bar
    return notebook_bar


def progress(iterable=None, *, total=None, desc: str, unit: str = "it", verbose: bool | None = None,
             delay: float = 1.0, leave: bool = False):
    """A progress bar over ``iterable`` (or of ``total`` steps) labelled ``desc``.

    Example::

        with progress(total=n_collapses, desc="decimation", unit="collapse") as bar:
            ...
            bar.update(k)
    """
    return _bar_class()(iterable, total=total, desc=desc, unit=unit, disable=not enabled(verbose),
                        delay=delay, leave=leave, file=sys.stderr)


def write(message: str) -> None:
    """Print ``message`` as one line on stderr without breaking a running text bar (tqdm
    clears the bar, prints, and redraws it)."""
    from tqdm import tqdm as text_bar

    text_bar.write(message, file=sys.stderr)


class StageBar:
    """A :class:`~jaxparam.clock.StageClock`'s stages shown as one bar of ``total`` stages.

    ``mark("name")`` closes the stage ``name`` on the clock (as ``clock("name")`` does, returning
    its seconds) and advances the bar, naming the stage just done; :meth:`close` ends the bar.

    Example::

        clock = StageClock()
        mark = StageBar(clock, total=3, desc="reconstruct_surface")
        ...; mark("neighbours")
        ...; mark("delaunay")
        mark.close()
    """

    def __init__(self, clock: StageClock, *, total: int, desc: str, verbose: bool | None = None):
        self._clock = clock
        self._bar = progress(total=total, desc=desc, unit="stage", verbose=verbose)

    def __call__(self, name: str) -> float:
        seconds = self._clock(name)
        self._bar.set_postfix_str(name, refresh=False)
        self._bar.update(1)
        return seconds

    def note(self, text: str) -> None:
        """Show ``text`` beside the bar while a stage runs (e.g. its round)."""
        self._bar.set_postfix_str(text)

    def close(self) -> None:
        self._bar.close()

