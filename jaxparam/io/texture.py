"""Texture images for UV checks: a checkerboard to embed in a GLB or draw through the UVs."""
from __future__ import annotations

import numpy as np

__all__ = ["checker_texture"]


def checker_texture(size: int = 512, squares: int = 16, *,
                    colors=((235, 235, 235), (40, 90, 170))) -> np.ndarray:
    """A checkerboard image: ``(size, size, 3) uint8``, ``squares`` squares a side, in two
    ``colors`` (RGB 0-255).  Over UVs in ``[0, 1]`` each square spans ``1 / squares``.

    Example::

        jp.save("flat.glb", mesh, uv, texture=jp.io.checker_texture())
    """
    size, squares = int(size), int(squares)
    if size < 1 or squares < 1:
        raise ValueError(f"checker_texture: size and squares must be positive, got {size} and {squares}.")
    cell = (np.arange(size) * squares) // size
    odd = (cell[:, None] + cell[None, :]) % 2
    return np.asarray(colors, np.uint8)[odd]
