"""``jaxparam batch``: flatten every mesh file of a folder, one bad file never stops the rest.

::

    jaxparam batch FOLDER -o OUTFOLDER [flatten options] [--workers N] [--engine local|ray]

Every ``.obj``, ``.off``, ``.ply`` and ``.stl`` file directly inside FOLDER
(not in sub-folders; hidden files skipped; names in sorted order) goes
through the same pipeline as ``jaxparam flatten`` and is written as
``OUTFOLDER/<stem>.obj``; an input whose ``<stem>.obj`` another input's
output would also take keeps its full name (``a.off`` and ``a.obj`` give
``a.off.obj`` and ``a.obj.obj``; with ``a.obj.off`` too, ``a.obj.off.obj``),
so no two inputs ever write the same file (:func:`output_paths`).
``OUTFOLDER/summary.jsonl`` gets one JSON object per input file, in input
order, with at least ``file``, ``status`` (``"ok"`` or ``"error"``),
``error`` (the message, or null), ``error_type``, ``output``, the report's
metrics (``vertices``, ``faces``, ``flips``, ``sym_dirichlet``, ...,
``holes_filled``), ``seconds`` (the file's wall time) and ``stage_seconds``.

Every file is written to a temporary name and renamed, so an interrupted
batch leaves only complete outputs; the summary is written last.

Exit codes: 0 every file flattened; 3 at least one input was bad (a
``MeshError``/``MeshFileError``: the summary says which and why); 4 no bad
input but a solver failed on at least one file; 1 an unexpected error
(a bug: the summary keeps its type and message); 2 usage (OUTFOLDER equals
FOLDER, ``--engine ray`` without ray installed).  A missing FOLDER, or one
without mesh files, exits 3 without writing anything.

Engines: ``local`` runs the files in this process (``--workers 1``, the
default) or in a pool of ``N`` processes started with the ``spawn`` method
(``concurrent.futures``); a worker that dies (a crash, the out-of-memory
killer) is replaced and the files it may have held are retried one at a
time, so the one that kills a worker is named in the summary.  ``ray`` runs
one task per file on a Ray cluster (``ray.init()`` decides which).

Each file goes through :func:`jaxparam.cli.pipeline.flatten_mesh`, the
pipeline of ``jaxparam flatten``, so the two commands cannot drift apart; the
exit codes are the pipeline's table.
"""
from __future__ import annotations

import concurrent.futures as cf
import json
import multiprocessing
import sys
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Callable

from ..errors import MeshFileError
from ..io import atomic_write, load, save
from ..progress import progress, write
from .arguments import add_flatten_options, flatten_options, positive_int, subparser
from .pipeline import (EXIT_INPUT, EXIT_INTERNAL, EXIT_OK, EXIT_SOLVER, EXIT_USAGE, clean,
                       enable_compile_cache, failure, flatten_mesh, flip_warning)

__all__ = ["MESH_EXTENSIONS", "SUMMARY", "find_mesh_files", "output_paths", "flatten_file",
           "run_batch", "exit_code", "cmd_batch", "add_parser"]

#: File extensions the batch picks up (case-insensitive).
MESH_EXTENSIONS = (".obj", ".off", ".ply", ".stl")

#: The summary's file name inside OUTFOLDER: one JSON object a line, in input order.
SUMMARY = "summary.jsonl"


def find_mesh_files(folder) -> list[Path]:
    """The mesh files directly inside ``folder``, sorted by name.

    Raises :class:`MeshFileError` when ``folder`` is missing, is not a folder
    or holds no ``.obj``/``.off``/``.ply``/``.stl`` file.
    """
    d = Path(folder)
    if not d.exists():
        raise MeshFileError(f"batch: {folder}: no such folder.")
    if not d.is_dir():
        raise MeshFileError(f"batch: {folder} is a file, not a folder; for one mesh use "
                            "jaxparam flatten MESH -o OUT.obj.")
    files = sorted(p for p in d.iterdir()
                   if p.suffix.lower() in MESH_EXTENSIONS and not p.name.startswith(".")
                   and not p.is_dir())
    if not files:
        raise MeshFileError(f"batch: {folder} holds no mesh files ({', '.join(MESH_EXTENSIONS)}); "
                            "check the folder.")
    return files


def output_paths(files, outfolder) -> list[Path]:
    """``OUTFOLDER/<name>.obj`` for each input, every name different (ignoring case, as
    macOS and Windows do).

    An input gets ``<stem>.obj`` unless another input's output would have that name; then
    its full file name: ``<stem><ext>.obj``.  Repeated until no two names clash (``x.off``,
    ``x.obj`` and ``x.obj.off`` become ``x.off.obj``, ``x.obj.obj`` and ``x.obj.off.obj``).
    Full names that differ only in case (``A.obj``, ``a.obj``) get a numbered suffix,
    ``a.obj-2.obj``, in input order.
    """
    files = [Path(p) for p in files]
    full = [False] * len(files)
    while True:
        names = [f"{p.name if whole else p.stem}.obj" for p, whole in zip(files, full)]
        keys = [n.casefold() for n in names]
        clash = [not whole and keys.count(k) > 1 for k, whole in zip(keys, full)]
        if not any(clash):
            break
        full = [whole or c for whole, c in zip(full, clash)]
    taken, seen = set(keys), set()
    for i, n in enumerate(names):
        if keys[i] in seen:                 # full names that differ only in case
            k = 2
            while f"{n[:-4]}-{k}.obj".casefold() in taken:
                k += 1
            names[i] = f"{n[:-4]}-{k}.obj"
            keys[i] = names[i].casefold()
            taken.add(keys[i])
        seen.add(keys[i])
    out = Path(outfolder)
    return [out / n for n in names]


def flatten_file(path, out_path, options: dict) -> dict:
    """Load, flatten and save one file; never raises for a bad file.

    **Arguments:** ``path`` the input mesh file; ``out_path`` the OBJ to write;
    ``options`` the keyword options of :func:`~jaxparam.cli.pipeline.flatten_mesh`
    (``weights``, ``boundary``, ``spacing``, ``energy``, ``free_boundary``, ``solver``,
    ``max_iters``, as ``jaxparam flatten`` parses them).

    **Returns:** the summary record (see the module docstring), JSON-safe, with
    ``exit_code`` 0, 3, 4 or 1 for this file.
    """
    t0 = time.perf_counter()
    rec = {"file": str(path), "status": "error", "error": None, "error_type": None, "output": None}
    try:
        mesh = load(path)
        notes: list = []
        uv, rep = flatten_mesh(mesh, **options, say=notes.append, verbose=False)  # the batch bar only
        save(out_path, mesh, uv)
        rep = dict(rep)
        rec["stage_seconds"] = rep.pop("seconds", {})
        rec.update(rep)
        rec.update(status="ok", output=str(out_path), notes=notes, exit_code=EXIT_OK)
    except Exception as exc:  # a bug must not stop the batch either; the summary keeps it visible
        code, message = failure(exc)
        rec.update(error=message, error_type=type(exc).__name__, exit_code=code)
    rec["seconds"] = time.perf_counter() - t0
    return clean(rec)


def _crash_record(path, message: str) -> dict:
    """The summary record of a file whose worker process died."""
    return {"file": str(path), "status": "error", "error": message, "error_type": "WorkerDied",
            "output": None, "exit_code": EXIT_INTERNAL, "seconds": None}


def _run_pool(jobs, workers: int, report, work: Callable) -> None:
    """Run ``work(*args)`` for ``jobs`` (``(index, args)``) in a spawn-started process pool.

    A dead worker breaks the whole pool, and with several workers it is not
    known which file killed it: the files left unfinished are then retried in
    a one-worker pool, one at a time, and a file that kills that worker too
    gets a ``WorkerDied`` record.
    """
    ctx = multiprocessing.get_context("spawn")
    suspects = []
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=enable_compile_cache) as pool:
        futures = {pool.submit(work, *args): (i, args) for i, args in jobs}
        for fut in cf.as_completed(futures):
            i, args = futures[fut]
            try:
                report(i, fut.result())
            except BrokenProcessPool:
                suspects.append((i, args))
    pool = None
    try:
        for i, args in sorted(suspects, key=lambda j: j[0]):
            if pool is None:
                pool = cf.ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=enable_compile_cache)
            try:
                report(i, pool.submit(work, *args).result())
            except BrokenProcessPool:
                pool.shutdown(wait=False)
                pool = None
                report(i, _crash_record(args[0], "the worker process died while flattening this "
                                                 "file (a crash, or killed for memory); try it "
                                                 "alone with jaxparam flatten"))
    finally:
        if pool is not None:
            pool.shutdown()


def _run_ray(jobs, report, work: Callable) -> None:
    """One Ray task per file; ``ray.init()`` connects to a running cluster or starts a local one."""
    import ray

    ray.init(ignore_reinit_error=True)
    task = ray.remote(work)
    refs = {task.remote(*args): i for i, args in jobs}
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        for ref in done:
            report(refs[ref], ray.get(ref))


def run_batch(files, outputs, options: dict, *, workers: int = 1, engine: str = "local",
              say=print, work: Callable = flatten_file) -> list[dict]:
    """Flatten ``files`` into ``outputs`` (same length); returns the records in input order.

    **Arguments:** ``options`` as for :func:`flatten_file`; ``workers`` processes (1: this
    one); ``engine`` ``"local"`` or ``"ray"``; ``say`` receives one progress line per
    finished file; ``work(path, out_path, options) -> record`` the job run for each file
    (default :func:`flatten_file`; a module-level function, so a spawned worker finds it
    by reference; tests pass one that kills its worker).

    JAX's persistent compilation cache is enabled in each local process that flattens.
    """
    jobs = [(i, (str(f), str(o), options)) for i, (f, o) in enumerate(zip(files, outputs))]
    records: list = [None] * len(jobs)
    done = [0]

    bar = progress(total=len(jobs), desc="batch", unit="file")

    def report(i, rec):
        records[i] = rec
        done[0] += 1
        bar.update(1)
        state = "ok" if rec["status"] == "ok" else f"error: {rec['error']}"
        if rec["status"] == "ok" and rec.get("converged") is False:
            state += (f" (warning: the minimization stopped after {rec.get('iterations')} "
                      "iterations without converging)")
        if rec["status"] == "ok" and rec.get("flips"):
            state += f" (warning: {flip_warning(rec)})"
        say(f"[{done[0]}/{len(jobs)}] {Path(rec['file']).name}: {state}")

    with bar:
        if engine == "ray":
            _run_ray(jobs, report, work)
        elif workers <= 1:
            enable_compile_cache()
            for i, args in jobs:
                report(i, work(*args))
        else:
            _run_pool(jobs, workers, report, work)
    return records


def exit_code(records) -> int:
    """0 if every file is ok; otherwise 3 if any input was bad, else 4 for a solver failure, else 1."""
    codes = {r.get("exit_code", EXIT_INTERNAL) for r in records}
    for code in (EXIT_INPUT, EXIT_SOLVER, EXIT_INTERNAL):
        if code in codes:
            return code
    return EXIT_OK


def cmd_batch(args) -> int:
    """``jaxparam batch FOLDER -o OUTFOLDER``: see the module docstring."""
    def err(msg):
        print(f"jaxparam batch: {msg}", file=sys.stderr)

    if args.engine == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            err("--engine ray needs the 'ray' package, which is not installed (pip install ray); "
                "use --engine local --workers N for a process pool on this machine.")
            return EXIT_USAGE
    files = find_mesh_files(args.folder)
    out = Path(args.output)
    if out.resolve() == Path(args.folder).resolve():
        err(f"the output folder {args.output} is the input folder; the results would overwrite "
            "the inputs: give another -o folder.")
        return EXIT_USAGE
    if out.exists() and not out.is_dir():
        raise MeshFileError(f"batch: {args.output} is a file, not a folder; give a folder to -o.")
    outputs = output_paths(files, out)
    t = time.perf_counter()
    quiet = getattr(args, "quiet", False)
    records = run_batch(files, outputs, flatten_options(args), workers=args.workers,
                        engine=args.engine,
                        say=(lambda m: None if "warning" not in m else write(m)) if quiet else write)
    atomic_write(out / SUMMARY, lambda f: f.writelines(json.dumps(r) + "\n" for r in records))
    ok = sum(r["status"] == "ok" for r in records)
    unconverged = sum(r["status"] == "ok" and r.get("converged") is False for r in records)
    folded = [Path(r["file"]).name for r in records if r["status"] == "ok" and r.get("flips")]
    if folded:
        err(f"warning: {len(folded)} map(s) have flipped or degenerate UV triangles "
            f"({', '.join(folded[:5])}{', ...' if len(folded) > 5 else ''}); their records count "
            "them under \"flips\" and the lines above say why")
    if unconverged:
        err(f"warning: {unconverged} minimization(s) stopped without converging; their records "
            "say \"converged\": false (raise --max-iters or try another --solver)")
    print(f"{out / SUMMARY}: {ok} of {len(records)} files flattened "
          f"({time.perf_counter() - t:.1f} s)")
    return exit_code(records)


def add_parser(sub) -> None:
    """Add ``batch`` to the CLI's subparsers ``sub``, with the flatten options."""
    p = subparser(sub, "batch", "flatten every mesh file of a folder",
                       description="Flatten every .obj/.off/.ply/.stl file of FOLDER into "
                                   "OUTFOLDER/<stem>.obj; one bad file never stops the rest, "
                                   "OUTFOLDER/summary.jsonl says which and why. Exit 0 all ok, "
                                   "3 some input bad, 4 a solver failed.")
    p.add_argument("folder")
    p.add_argument("-o", "--output", required=True, help="the output folder (created if needed)")
    add_flatten_options(p)
    p.add_argument("--workers", type=positive_int("--workers"), default=1,
                   help="processes working in parallel (1: this process)")
    p.add_argument("--engine", choices=["local", "ray"], default="local",
                   help="local: this machine (--workers processes); ray: one Ray task per "
                        "file on the cluster ray.init() finds, or a local one "
                        "(pip install 'jaxparam[ray]')")
    p.set_defaults(func=cmd_batch)
