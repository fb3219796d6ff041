"""JAX, loaded on first use (issue 17: ``import jax`` alone costs over a second, more than a
whole NumPy flatten).

JAX is configured the moment it loads, whoever imports it:
:func:`when_jax_loads` runs its callbacks right after ``jax/__init__.py`` has executed (an
import hook), or at once when JAX is already loaded; the package registers
:func:`jaxparam.settings.configure_jax` there, which turns on ``jax_enable_x64`` and the compilation cache.  So
"importing jaxparam turns on float64" holds for a user's own ``import jax``, before or after.

Modules on the NumPy paths import ``jax``/``jnp`` from here (``from .lazy_jax import jax,
jnp``): :data:`jax` and :data:`jnp` are stand-ins that import JAX on first real use.  Until
then ``jax.jit`` (and ``functools.partial(jax.jit, ...)``) gives a function that jits on its
first call, ``jax.tree_util.register_*`` is deferred to the load, and ``jax.core.Tracer`` /
``jax.Array`` are a class nothing is an instance of (no tracer can exist before JAX loads).
Anything else (``jnp.asarray``, ``jax.lax``, ...) imports JAX and is the real thing.

This module imports nothing from jaxparam and no JAX, so every layer may use it.
"""
from __future__ import annotations

import functools
import importlib
import sys
from typing import Callable

__all__ = ["jax", "jnp", "jax_loaded", "when_jax_loads", "lazy_jit", "LazyJit"]

_loaded = False                         # jax/__init__.py has run to its end
_callbacks: list[Callable] = []         # run once, in order, with the jax module


def jax_loaded() -> bool:
    """Whether JAX has been imported (completely) in this process."""
    global _loaded
    if not _loaded:
        mod = sys.modules.get("jax")
        spec = getattr(mod, "__spec__", None)
        _loaded = mod is not None and not getattr(spec, "_initializing", False) \
            and hasattr(mod, "jit")
    return _loaded


def when_jax_loads(fn: Callable) -> None:
    """Call ``fn(jax)`` now if JAX is loaded, else right after it loads (before the import
    statement that loads it returns)."""
    if jax_loaded():
        fn(sys.modules["jax"])
        return
    _callbacks.append(fn)
    if not any(isinstance(f, _JaxFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _JaxFinder())


def _jax_has_loaded(module) -> None:
    global _loaded
    _loaded = True
    for f in [f for f in sys.meta_path if isinstance(f, _JaxFinder)]:
        sys.meta_path.remove(f)
    while _callbacks:
        _callbacks.pop(0)(module)


class _JaxFinder:
    """A meta-path finder that finds nothing itself: for ``jax`` it takes the spec the other
    finders give and makes its loader call :func:`_jax_has_loaded` after executing the module."""

    def find_spec(self, name, path=None, target=None):
        if name != "jax":
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                break
        else:
            return None
        loader = spec.loader
        run = getattr(loader, "exec_module", None)
        if run is None:
            return spec

        def exec_module(module):
            run(module)
            _jax_has_loaded(module)

        loader.exec_module = exec_module           # this loader instance serves jax only
        return spec

    def invalidate_caches(self) -> None:
        pass


class LazyJit:
    """``jax.jit(fun, **options)``, built on the first call (or attribute read), so that
    defining a jitted function imports no JAX.  Calls, ``.lower`` and the rest go to the
    real jitted function; as a method it binds like a function."""

    def __init__(self, fun: Callable, options: dict):
        self._jitted = None
        self._fun, self._options = fun, options
        functools.update_wrapper(self, fun)

    def jitted(self):
        """The real ``jax.jit`` function (imports JAX)."""
        if self._jitted is None:
            self._jitted = importlib.import_module("jax").jit(self._fun, **self._options)
        return self._jitted

    def __call__(self, *args, **kwargs):
        return (self._jitted or self.jitted())(*args, **kwargs)

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_jitted", "_fun", "_options"):
            raise AttributeError(name)
        return getattr(self.jitted(), name)

    def __get__(self, obj, objtype=None):
        return self if obj is None else functools.partial(self, obj)


def lazy_jit(fun: Callable | None = None, **options):
    """``jax.jit`` that imports JAX on the first call (see :class:`LazyJit`); also as
    ``functools.partial(lazy_jit, static_argnames=...)``."""
    if fun is None:
        return lambda f: LazyJit(f, options)
    return LazyJit(fun, options)


class _NotLoaded:
    """Stands for ``jax.core.Tracer`` and ``jax.Array`` before JAX loads: nothing is one."""


class _Namespace:
    def __init__(self, module: str, **known):
        self._module, self._known = module, known

    def __getattr__(self, name):
        if not jax_loaded():
            if name in self._known:
                return self._known[name]
            if self._module == "jax.tree_util" and name.startswith("register_"):
                return _deferred(name)
        return getattr(importlib.import_module(self._module), name)


def _deferred(name: str):
    """``jax.tree_util.<name>(cls, ...)`` when JAX loads; returns ``cls`` now."""
    def register(cls, *args, **kwargs):
        when_jax_loads(lambda jax: getattr(jax.tree_util, name)(cls, *args, **kwargs))
        return cls
    return register


#: Stand-ins for ``import jax`` and ``import jax.numpy as jnp`` (see the module docstring).
jax = _Namespace("jax", jit=lazy_jit, Array=_NotLoaded, core=_Namespace("jax.core", Tracer=_NotLoaded),
                 tree_util=_Namespace("jax.tree_util"))
jnp = _Namespace("jax.numpy")
