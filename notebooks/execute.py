"""Execute notebooks in place and store them with their figures, small enough to review.

    python notebooks/execute.py [NOTEBOOK.ipynb ...]     (default: every notebooks/*.ipynb)

Each notebook runs in a fresh kernel (nbclient, the ``python3`` kernel of this interpreter)
with its folder as the working directory and ``JAXPARAM_PROGRESS=0`` (no progress bars).
Then it is stripped (:func:`strip`): stderr streams, progress bars (widgets and text with
carriage returns), and per-cell execution timings go; figures, printed results and
execution counts stay.  A cell that raises stops the run with the notebook's name and the
error, and the notebook on disk is left as it was.

Needs the ``notebooks`` extra (``pip install -e ".[notebooks]"``): nbclient, nbformat and
ipykernel.  ``make notebooks`` runs it, then the notebooks' checks (tests/test_notebooks.py).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: Output MIME types that are progress widgets (ipywidgets), dropped when stripping.
WIDGET_TYPES = ("application/vnd.jupyter.widget-view+json",)


def is_progress(output: dict) -> bool:
    """Whether a cell output is a progress bar or stderr noise: a stderr stream, a widget,
    or a text stream redrawn with carriage returns (a text bar)."""
    if output.get("output_type") == "stream":
        text = "".join(output.get("text", ""))
        return output.get("name") == "stderr" or "\r" in text
    data = output.get("data", {})
    return any(t in data for t in WIDGET_TYPES)


def strip(nb) -> int:
    """Drop progress and stderr outputs and execution timings from ``nb`` (an nbformat
    notebook, changed in place); returns how many outputs were dropped."""
    dropped = 0
    for cell in nb.cells:
        if cell.get("cell_type") != "code":
            continue
        keep = [o for o in cell.get("outputs", []) if not is_progress(o)]
        dropped += len(cell.get("outputs", [])) - len(keep)
        cell["outputs"] = keep
        cell.get("metadata", {}).pop("execution", None)
    nb.metadata.pop("widgets", None)
    return dropped


def execute(path: Path, timeout: int = 900) -> tuple[float, int]:
    """Execute ``path`` in place; returns ``(seconds, outputs dropped by strip)``."""
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    os.environ["JAXPARAM_PROGRESS"] = "0"       # the kernel inherits it: no bars at all
    client = NotebookClient(nb, timeout=timeout, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    t = time.perf_counter()
    client.execute()
    seconds = time.perf_counter() - t
    dropped = strip(nb)
    nbformat.validate(nb)
    tmp = path.with_suffix(".ipynb.tmp")
    nbformat.write(nb, tmp)
    tmp.replace(path)
    return seconds, dropped


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("notebooks", nargs="*", type=Path)
    ap.add_argument("--timeout", type=int, default=900, help="seconds per cell (default 900)")
    args = ap.parse_args(argv)
    paths = args.notebooks or sorted(HERE.glob("*.ipynb"))
    for p in paths:
        try:
            seconds, dropped = execute(p, args.timeout)
        except Exception as exc:  # noqa: BLE001 - report which notebook failed, then stop
            print(f"{p}: failed: {type(exc).__name__}: {str(exc)[:2000]}", file=sys.stderr)
            return 1
        size = p.stat().st_size / 1024
        print(f"{p}: executed in {seconds:.0f} s, {dropped} progress/stderr outputs stripped, "
              f"{size:.0f} KiB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
