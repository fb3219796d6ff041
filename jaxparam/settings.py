"""Library-wide settings: ``jp.config`` (one object, read at call time, never cached).

``jp.config.progress``
    Progress bars on (``True``) or off (``False``) for the whole library.  The default is on,
    unless the environment variable ``JAXPARAM_PROGRESS`` is ``0``/``false``/``off`` or tqdm's own
    ``TQDM_DISABLE`` is set to a true value.  A call's ``verbose=`` argument, where a function has
    one, overrides the setting for that call.

This module imports nothing from jaxparam, so every layer may read it.
"""
from __future__ import annotations

import os

__all__ = ["Settings", "config", "env_flag"]

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

    __slots__ = ("_progress",)

    def __init__(self) -> None:
        self._progress: bool | None = None

    @property
    def progress(self) -> bool:
        """Whether progress bars show (``JAXPARAM_PROGRESS`` and ``TQDM_DISABLE`` set the default)."""
        if self._progress is not None:
            return self._progress
        return env_flag("JAXPARAM_PROGRESS", True) and not env_flag("TQDM_DISABLE", False)

    @progress.setter
    def progress(self, value: bool | None) -> None:
        self._progress = None if value is None else bool(value)

    def __setattr__(self, name, value):
        if name not in Settings.__slots__ and not isinstance(getattr(Settings, name, None), property):
            known = [n for n, v in vars(Settings).items() if isinstance(v, property)]
            raise AttributeError(f"jp.config has no setting {name!r}; the settings are {known}")
        object.__setattr__(self, name, value)

    def __repr__(self) -> str:
        return f"jp.config(progress={self.progress})"


#: The one settings object of the library, exported as ``jp.config``.
config = Settings()
