"""Library-wide settings: ``jp.config`` (one object, read at call time, never cached).

``jp.config.progress``
    Progress bars on (``True``) or off (``False``) for the whole library.  The default is on,
    unless the environment variable ``JAXPARAM_PROGRESS`` is ``0``/``false``/``off`` or tqdm's own
    ``TQDM_DISABLE`` is set to a true value.  A call's ``verbose=`` argument, where a function has
    one, overrides the setting for that call.

``jp.config.compile_cache``
    The folder of JAX's persistent compilation cache, which ``import jaxparam`` turns on so that a
    second process reuses the kernels the first compiled: ``$JAXPARAM_CACHE`` when set, else
    ``$XDG_CACHE_HOME/jaxparam/jax`` (``~/.cache/jaxparam/jax``).  ``JAXPARAM_CACHE=off`` (or
    ``0``/``false``/``none``), or ``jp.config.compile_cache = None``, turns it off.  Compilations
    shorter than 0.2 s are not stored (JAX's own ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS``
    changes that); delete the folder to empty it.

``jp.config.buckets``
    Shape buckets for the minimizers' kernels (on by default; ``JAXPARAM_BUCKETS=0`` turns them
    off): the vertex, face and Hessian sizes are padded to a few bucket sizes, so that meshes of
    similar size, and the atlas's split rounds, reuse compiled code
    (:mod:`jaxparam.optimize.padding`).  Off, every new size compiles again; results agree
    either way to rounding.

``jp.config.keep_freed_mb``
    How much freed memory the process keeps for reuse, in MiB (default 512; ``JAXPARAM_KEEP_FREED_MB``
    sets the default, ``0`` leaves glibc's own limits).  With glibc, blocks of up to that size come
    from the heap and up to that much freed memory stays in the process: XLA's buffer for a
    compiled call's temporaries is then not page-faulted in again on every call (the meshless
    map's gradient on 126k fan entries: 40 % faster; :mod:`jaxparam.memory`).  Applied when JAX
    loads and whenever it is set; elsewhere than glibc it does nothing.

``jp.config.threads``
    How many threads the NumPy stages of the points stack use for their blocks of rows (tangent
    frames, fans, gaps; :mod:`jaxparam.blocks`).  Default: the cores this process may run on;
    ``JAXPARAM_THREADS`` sets the default.  ``1`` runs every block in the calling thread.  The
    results are bitwise the same for any value.

``import jaxparam`` does not import JAX (issue 17): :func:`configure_jax` (float64 and the
compilation cache) runs the moment JAX loads, whoever imports it, through
:func:`jaxparam.lazy_jax.when_jax_loads`.


This module imports only :mod:`jaxparam.lazy_jax` (no JAX), so every layer may read it.
"""
from __future__ import annotations

import operator
import os
import warnings
from pathlib import Path

from .lazy_jax import jax_loaded

__all__ = ["Settings", "config", "env_flag", "default_compile_cache", "default_keep_freed_mb",
           "default_threads", "configure_jax"]

_FALSE = {"0", "false", "no", "off", ""}


def env_flag(name: str, default: bool) -> bool:
    """The boolean value of environment variable ``name`` (``default`` when it is unset):
    ``0``, ``false``, ``no``, ``off`` and the empty string are false, anything else true."""
    value = os.environ.get(name)
    if value is None:
        return default
    return value.strip().lower() not in _FALSE


class Settings:
    """The mutable settings of the library (``jp.config``).

    Attributes are declared here and nowhere else; setting an unknown name raises
    ``AttributeError`` naming the known ones, so a typo is not silently ignored.
    """

    __slots__ = ("_progress", "_compile_cache", "_buckets", "_keep_freed_mb", "_threads")

    def __init__(self) -> None:
        self._progress: bool | None = None
        self._buckets: bool | None = None
        self._compile_cache: str | None = default_compile_cache()
        self._keep_freed_mb: int = default_keep_freed_mb()
        self._threads: int | None = None

    @property
    def progress(self) -> bool:
        """Whether progress bars show (``JAXPARAM_PROGRESS`` and ``TQDM_DISABLE`` set the default)."""
        if self._progress is not None:
            return self._progress
        return env_flag("JAXPARAM_PROGRESS", True) and not env_flag("TQDM_DISABLE", False)

    @progress.setter
    def progress(self, value: bool | None) -> None:
        self._progress = None if value is None else bool(value)

    @property
    def buckets(self) -> bool:
        """Whether the minimizers pad their kernels' sizes to buckets (``JAXPARAM_BUCKETS``
        sets the default, on)."""
        if self._buckets is not None:
            return self._buckets
        return env_flag("JAXPARAM_BUCKETS", True)

    @buckets.setter
    def buckets(self, value: bool | None) -> None:
        self._buckets = None if value is None else bool(value)

    @property
    def compile_cache(self) -> str | None:
        """The persistent compilation cache's folder, or None when it is off."""
        return self._compile_cache

    @compile_cache.setter
    def compile_cache(self, folder) -> None:
        self._compile_cache = None if folder is None else str(Path(folder).expanduser())
        self.apply_compile_cache()

    def apply_compile_cache(self) -> None:
        """Hand :attr:`compile_cache` to JAX (on, in that folder; or off); before JAX has
        loaded, nothing (:func:`configure_jax` applies it at the load)."""
        if not jax_loaded():
            return
        import jax

        try:
            if self._compile_cache is None:
                jax.config.update("jax_enable_compilation_cache", False)
                return
            jax.config.update("jax_enable_compilation_cache", True)
            jax.config.update("jax_compilation_cache_dir", self._compile_cache)
            if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
                jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
        except (AttributeError, KeyError):  # an old JAX without these options: run uncached
            pass

    @property
    def threads(self) -> int:
        """Threads for the points stack's row blocks (``JAXPARAM_THREADS`` sets the default:
        else the cores this process may run on)."""
        if self._threads is not None:
            return self._threads
        return default_threads()

    @threads.setter
    def threads(self, value: int | None) -> None:
        if value is None:
            self._threads = None
            return
        try:
            n = operator.index(value)           # ints, NumPy integers; not floats or strings
        except TypeError:
            n = 0
        if isinstance(value, bool) or n < 1:
            raise ValueError(f"jp.config.threads must be a whole number >= 1 (or None for the "
                             f"default), got {value!r}.")
        self._threads = int(n)

    @property
    def keep_freed_mb(self) -> int:
        """MiB of freed memory kept in the process for reuse (glibc; see the module docstring)."""
        return self._keep_freed_mb

    @keep_freed_mb.setter
    def keep_freed_mb(self, mb: int) -> None:
        self._keep_freed_mb = _keep_mb(mb, "jp.config.keep_freed_mb")
        if jax_loaded():
            from . import memory

            memory.keep_freed(self._keep_freed_mb)

    def __setattr__(self, name, value):
        if name not in Settings.__slots__ and not isinstance(getattr(Settings, name, None), property):
            known = [n for n, v in vars(Settings).items() if isinstance(v, property)]
            raise AttributeError(f"jp.config has no setting {name!r}; the settings are {known}")
        object.__setattr__(self, name, value)

    def __repr__(self) -> str:
        return (f"jp.config(progress={self.progress}, buckets={self.buckets}, "
                f"compile_cache={self.compile_cache!r}, keep_freed_mb={self.keep_freed_mb})")


def default_compile_cache() -> str | None:
    """The cache folder named by the environment (see the module docstring), or None (off)."""
    value = os.environ.get("JAXPARAM_CACHE")
    if value is not None:
        if value.strip().lower() in _FALSE | {"none"}:
            return None
        return str(Path(value).expanduser())
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return str(Path(base) / "jaxparam" / "jax")


#: The most MiB :attr:`Settings.keep_freed_mb` takes (glibc's mallopt takes a C int; the same
#: as ``jaxparam.memory.MAX_KEEP_MB``, which this module does not import).
MAX_KEEP_MB = 2047


def _keep_mb(value, what: str) -> int:
    """``value`` as a whole number of MiB in ``[0, MAX_KEEP_MB]``, else ``ValueError`` naming
    ``what``."""
    try:
        if isinstance(value, bool):
            raise TypeError
        mb = operator.index(value)
    except TypeError:
        raise ValueError(f"{what} must be a whole number of MiB, got {value!r}.") from None
    if not 0 <= mb <= MAX_KEEP_MB:
        raise ValueError(f"{what} must be in [0, {MAX_KEEP_MB}] MiB, got {mb}.")
    return mb


def default_keep_freed_mb() -> int:
    """``$JAXPARAM_KEEP_FREED_MB`` (a whole number of MiB, 0 to :data:`MAX_KEEP_MB`) or 512;
    another value is ignored with a warning that names the variable (a setting must not stop
    the import)."""
    value = os.environ.get("JAXPARAM_KEEP_FREED_MB")
    if value is None or not value.strip():
        return 512
    try:
        mb = int(value.strip())
    except ValueError:
        mb = value
    try:
        return _keep_mb(mb, "JAXPARAM_KEEP_FREED_MB")
    except ValueError as exc:
        warnings.warn(f"{exc} (0 leaves glibc's own limits); using 512.", stacklevel=2)
    return 512


def default_threads() -> int:
    """``$JAXPARAM_THREADS`` (a whole number >= 1), else the cores this process may run on
    (its CPU affinity, so ``taskset`` is honoured); a bad value is ignored with a warning."""
    value = os.environ.get("JAXPARAM_THREADS")
    if value is not None and value.strip():
        try:
            n = int(value.strip())
            if n >= 1:
                return n
        except ValueError:
            pass
        warnings.warn(f"JAXPARAM_THREADS={value!r} is not a whole number >= 1; using the cores.",
                      stacklevel=2)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):          # not Linux
        return max(1, os.cpu_count() or 1)


#: The one settings object of the library, exported as ``jp.config``.
config = Settings()


def configure_jax(jax) -> None:
    """What ``import jaxparam`` sets in JAX: float64 (``jax_enable_x64``) and the persistent
    compilation cache (:attr:`Settings.compile_cache`); and, for XLA's buffers, the freed
    memory kept for reuse (:attr:`Settings.keep_freed_mb`)."""
    from . import memory

    jax.config.update("jax_enable_x64", True)
    config.apply_compile_cache()
    memory.keep_freed(config.keep_freed_mb)
