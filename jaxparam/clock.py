"""A wall-clock stage timer: the ``seconds`` dicts of reports and ``stage_seconds``.

One clock serves every pipeline that reports per-stage timings (the command line,
``reconstruct_surface``)::

    clock = StageClock()
    mesh = load(path)
    clock("load")                       # the stage that ran since the clock was made
    uv = convex_map(mesh)
    clock("convex_map")                 # ... since the previous call
    with clock.stage("report"):         # or time one block, whatever ran before it
        rep = report(mesh, uv)
    clock.seconds                       # {"load": 0.01, "convex_map": 0.2, "report": 0.05}

This module imports nothing from jaxparam, so every layer may use it.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Callable, Iterator

__all__ = ["StageClock"]


class StageClock(dict):
    """Wall-clock seconds per named stage, a ``dict`` of ``{stage name: seconds}``.

    ``clock("name")`` closes the stage that ran since the previous call (or since the clock
    was made, or since :meth:`restart`), records its duration in seconds under ``name`` and
    returns it.  Being a plain ``dict`` of floats, the clock itself goes into a report or a
    JSON file unchanged; :attr:`seconds` gives a detached copy.  Recording a name twice
    overwrites the first duration.

    **Arguments:** ``timer`` a function returning the current time in seconds (default
    :func:`time.perf_counter`; tests may pass a fake).
    """

    def __init__(self, timer: Callable[[], float] = time.perf_counter):
        super().__init__()
        self._timer = timer
        self._mark = timer()

    def __call__(self, name: str) -> float:
        """Close the stage ``name`` (time since the previous mark, in seconds), record it
        and start the next stage now."""
        now = self._timer()
        seconds = now - self._mark
        self[name] = seconds
        self._mark = now
        return seconds

    def restart(self) -> None:
        """Start the next stage now, without recording the time since the previous mark
        (work that belongs to no stage)."""
        self._mark = self._timer()

    @contextmanager
    def stage(self, name: str) -> Iterator["StageClock"]:
        """Time the ``with`` block alone as the stage ``name`` (recorded also when the block
        raises); what ran before the block is not counted."""
        self.restart()
        try:
            yield self
        finally:
            self(name)

    @property
    def seconds(self) -> dict[str, float]:
        """The stages recorded so far, ``{name: seconds}``, as a new plain dict."""
        return dict(self)

    @property
    def total(self) -> float:
        """The sum of the recorded stages, in seconds."""
        return float(sum(self.values()))
