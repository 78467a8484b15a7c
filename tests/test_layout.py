"""The package's layout holds: every subpackage is installed under ``ramdaq``, the layers import
downwards only (analysis <- drivers <- daq), nothing imports in a circle, the gap diagnosis never
sees its benchmark's truth simulator, and no private name crosses a module boundary."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
PACKAGE_DIR: dict[str, str] = PYPROJECT["tool"]["setuptools"]["package-dir"]


def _folder_of(package: str) -> Path:
    """The repository folder a ``ramdaq.*`` package is installed from (longest package-dir prefix)."""
    head = max((k for k in PACKAGE_DIR if package == k or package.startswith(k + ".")), key=len)
    return ROOT / PACKAGE_DIR[head] / Path(*package[len(head):].split(".")[1:])


def _modules() -> dict[str, Path]:
    """Every module of the installed package: dotted name -> file."""
    out = {}
    for pkg in PYPROJECT["tool"]["setuptools"]["packages"]:
        for f in _folder_of(pkg).glob("*.py"):
            out[pkg if f.stem == "__init__" else f"{pkg}.{f.stem}"] = f
    return out


MODULES = _modules()


PACKAGE_OF = {path: (mod if path.stem == "__init__" else mod.rpartition(".")[0])
              for mod, path in MODULES.items()}


def _absolute(node: ast.ImportFrom, path: Path) -> str | None:
    """The absolute module a ``from`` import names (relative ones resolved against ``path``'s package)."""
    if node.level == 0:
        return node.module
    base = PACKAGE_OF[path].split(".")[: len(PACKAGE_OF[path].split(".")) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(path: Path) -> list[tuple[str, list[str], int]]:
    """(module, names, line) of every ramdaq import in ``path``, relative or absolute, at any depth
    (under TYPE_CHECKING too: a circle of type hints is still a circle for the reader)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        target = _absolute(node, path) if isinstance(node, ast.ImportFrom) else None
        if target and target.startswith("ramdaq"):
            out.append((target, [a.name for a in node.names], node.lineno))
        elif isinstance(node, ast.Import):
            out += [(a.name, [], node.lineno) for a in node.names if a.name.startswith("ramdaq")]
    return out


def _edges() -> dict[str, set[str]]:
    """Module -> the ramdaq modules it imports (``from pkg import mod`` counts as mod)."""
    edges: dict[str, set[str]] = {m: set() for m in MODULES}
    for mod, path in MODULES.items():
        for target, names, _ in _imports(path):
            subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES]
            edges[mod].update(subs or ([target] if target in MODULES else []))
    return edges


def test_the_import_graph_is_read() -> None:
    """The checks below mean something only if the imports are found: relative ones included."""
    edges = _edges()
    assert "ramdaq.analysis.model.rig" in edges["ramdaq.analysis.impact"]
    assert "ramdaq.drivers.block" in edges["ramdaq.daq.recorder"]
    assert sum(map(len, edges.values())) > 200


def test_every_folder_with_an_init_is_installed() -> None:
    listed = {_folder_of(p).resolve() for p in PYPROJECT["tool"]["setuptools"]["packages"]}
    folders = {init.parent.resolve() for top in set(PACKAGE_DIR.values())
               for init in (ROOT / top).rglob("__init__.py")}
    assert folders - listed == set(), "folders with an __init__.py missing from pyproject's packages"


@pytest.mark.parametrize(("lower", "upper"), [("ramdaq.analysis", "ramdaq.drivers"),
                                              ("ramdaq.analysis", "ramdaq.daq"),
                                              ("ramdaq.drivers", "ramdaq.daq"),
                                              ("ramdaq.analysis.gap", "ramdaq.analysis.truth")])
def test_layers_import_downwards_only(lower: str, upper: str) -> None:
    wrong = [f"{m} -> {t}" for m, ts in _edges().items() if m.startswith(lower + ".") or m == lower
             for t in ts if t.startswith(upper + ".") or t == upper]
    assert wrong == []


def test_no_import_circle() -> None:
    edges = _edges()
    state: dict[str, int] = {}
    circles: list[list[str]] = []

    def visit(m: str, stack: list[str]) -> None:
        state[m] = 1
        for t in sorted(edges[m]):
            if state.get(t) == 1:
                circles.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t, stack + [t])
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m, [m])
    assert circles == []


def test_no_private_name_crosses_a_module() -> None:
    crossing = []
    for path in MODULES.values():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        aliases = {}
        for target, names, line in _imports(path):
            crossing += [f"{path.relative_to(ROOT)}:{line}: {target}.{n}" for n in names
                         if n.startswith("_") and not n.startswith("__")]
        for node in ast.walk(tree):
            target = _absolute(node, path) if isinstance(node, ast.ImportFrom) else None
            if target and target.startswith("ramdaq"):
                aliases.update({a.asname or a.name: a.name for a in node.names
                                if f"{target}.{a.name}" in MODULES})
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                crossing.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value.id}.{node.attr}")
    assert crossing == []


def test_shipped_rigs_are_found_by_name() -> None:
    from ramdaq.analysis.model.rig import load_rig, rig_path, shipped_rigs

    assert {"albacore", "sampson"} <= set(shipped_rigs())
    assert load_rig("albacore").name == load_rig(ROOT / "recordings" / "rigs" / "albacore.toml").name
    assert rig_path("recordings/rigs/albacore.toml") == Path("recordings/rigs/albacore.toml")


def test_an_unknown_rig_name_says_which_are_shipped() -> None:
    from ramdaq.analysis.model.rig import RigError, load_rig

    with pytest.raises(RigError,
                       match=r"nautilus: no such rig file, nor a shipped rig \(shipped: .*albacore"):
        load_rig("nautilus")
