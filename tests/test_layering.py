"""Modules import only modules above them in the design's list (docs/design.md)."""
import ast
from pathlib import Path

ORDER = ["errors", "tol", "memory", "topology", "triangles", "mesh", "disk", "geometry", "boundary", "weights", "sparse", "combination", "linear",
         "metrics", "energies", "optimize", "points", "fitting", "remesh", "wavelets", "manifold",
         "shapes", "plot", "batch", "cli", "demo", "__init__"]
PKG = Path(__file__).resolve().parents[1] / "jaxparam"


def imported_modules(path: Path) -> set:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                out.add(node.module.split(".")[0])
            else:
                out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("jaxparam."):
            out.add(node.module.split(".")[1])
    return out


def test_every_module_is_in_the_list():
    names = {p.stem for p in PKG.glob("*.py")}
    assert names <= set(ORDER), names - set(ORDER)


def test_imports_go_upwards_only():
    bad = []
    for p in PKG.glob("*.py"):
        me = ORDER.index(p.stem)
        for dep in imported_modules(p):
            if dep in ORDER and ORDER.index(dep) >= me and p.stem != "__init__":
                bad.append(f"{p.stem} imports {dep}")
    assert not bad, bad
