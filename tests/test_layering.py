"""The package's layering, read from the table in docs/design.md ("Layers").

Each module (a top-level file or a subpackage) may import only modules listed before it in
the table, or the files of its own subpackage; no module may import or use another module's
private (underscore) names, whether through ``from x import _name`` or ``x._name``.
"""
import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "jaxparam"
DESIGN = ROOT / "docs" / "design.md"


def layer_table() -> list[list[str]]:
    """The rows of the layer table: ``| n | layer | module, module, ... |``, in order."""
    text = DESIGN.read_text()
    section = text.split("\n## Layers\n", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        m = re.match(r"^\|\s*(\d+)\s*\|[^|]*\|([^|]*)\|", line)
        if m:
            rows.append([re.sub(r"[`/ ]", "", x) for x in m.group(2).split(",") if x.strip()])
    return rows


ORDER = [name for row in layer_table() for name in row]


def unit_of(module: str) -> str:
    """``jaxparam.points.graph`` -> ``points``; ``jaxparam`` -> ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def module_name(path: Path, root: Path = ROOT) -> str:
    rel = path.relative_to(root).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def is_module(dotted: str, root: Path = ROOT) -> bool:
    p = root.joinpath(*dotted.split("."))
    return p.with_suffix(".py").exists() or (p / "__init__.py").exists()


def private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def imports(path: Path, root: Path = ROOT):
    """Yield ``(target module, imported names, line)`` for every import of jaxparam code,
    and the aliases bound to jaxparam modules."""
    me = module_name(path, root)
    package = me if path.name == "__init__.py" else me.rsplit(".", 1)[0]
    tree = ast.parse(path.read_text())
    aliases = {}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif node.module and node.module.split(".")[0] == "jaxparam":
                target = node.module
            else:
                continue
            names = [a.name for a in node.names]
            found.append((target, names, node.lineno))
            for a in node.names:
                if is_module(f"{target}.{a.name}", root):
                    aliases[a.asname or a.name] = f"{target}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "jaxparam":
                    found.append((a.name, [], node.lineno))
                    aliases[a.asname or a.name.split(".")[0]] = a.name if a.asname else "jaxparam"
    return me, found, aliases, tree


FILES = sorted(PKG.rglob("*.py"))


def test_the_table_lists_every_module_once():
    units = {unit_of(module_name(p)) for p in FILES}
    assert len(ORDER) == len(set(ORDER)), [n for n in ORDER if ORDER.count(n) > 1]
    assert units == set(ORDER), (units - set(ORDER), set(ORDER) - units)


def test_imports_go_downwards_only():
    bad = []
    for p in FILES:
        me, found, _, _ = imports(p)
        mine = unit_of(me)
        if mine == "__init__":
            continue
        for target, names, line in found:
            deps = {unit_of(target)} if target != "jaxparam" else {unit_of(f"jaxparam.{n}") for n in names}
            for dep in deps:
                if dep != mine and ORDER.index(dep) > ORDER.index(mine):
                    bad.append(f"{p.relative_to(ROOT)}:{line}: {mine} imports {dep} (listed later)")
    assert not bad, bad


def test_no_module_uses_another_modules_private_names():
    bad = []
    for p in FILES:
        me, found, aliases, tree = imports(p)
        for target, names, line in found:
            if target != me:
                bad += [f"{p.relative_to(ROOT)}:{line}: imports {target}.{n}" for n in names if private(n)]
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and aliases[node.value.id] != me and private(node.attr)):
                bad.append(f"{p.relative_to(ROOT)}:{node.lineno}: uses {aliases[node.value.id]}.{node.attr}")
    assert not bad, bad


def test_the_checks_see_both_spellings_of_a_private_use(tmp_path):
    """Guard against a vacuous check: a planted private import and a planted ``x._name``."""
    pkg = tmp_path / "jaxparam"
    (pkg / "points").mkdir(parents=True)
    for f in ("__init__.py", "sparse.py", "linear.py", "points/__init__.py"):
        (pkg / f).write_text("")
    bad = pkg / "points" / "graph.py"
    bad.write_text("from ..linear import _private\nfrom .. import sparse as S\nS._hidden\n")
    me, found, aliases, tree = imports(bad, tmp_path)
    assert me == "jaxparam.points.graph"
    assert ("jaxparam.linear", ["_private"], 1) in found
    assert aliases["S"] == "jaxparam.sparse"
    assert any(isinstance(n, ast.Attribute) and n.attr == "_hidden" for n in ast.walk(tree))


#: ``jp.__all__`` before the redesign (commit 301fd65): every name must still be there.
PUBLIC_BEFORE = [
    "DegenerateFaceError", "DistortionReport", "ENERGIES", "Energy", "JaxparamError", "MeshError",
    "MeshFileError", "MinimizeResult", "NonManifoldError", "PointCloudError", "SolverError",
    "TopologyError", "TriMesh", "boundary", "convex_map", "distortion", "energies", "energy",
    "errors", "fit_surface", "fitting", "geometry", "least_squares_map", "linear", "load",
    "load_points", "manifold", "manifold_map", "meshless_map", "metrics", "minimize", "optimize",
    "plot", "points", "reconstruct_surface", "remesh", "save", "shapes", "sparse", "tol",
    "topology", "wavelets", "weights",
]


def test_the_public_names_are_all_still_there():
    import jaxparam as jp

    assert set(PUBLIC_BEFORE) <= set(jp.__all__), set(PUBLIC_BEFORE) - set(jp.__all__)
    missing = [n for n in jp.__all__ if not hasattr(jp, n)]
    assert not missing, missing


def test_no_file_exceeds_600_non_blank_lines():
    long = {str(p.relative_to(ROOT)): n for p in FILES
            if (n := sum(1 for line in p.read_text().splitlines() if line.strip())) > 600}
    assert not long, long
