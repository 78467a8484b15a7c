"""Check .ci/lower-bounds.txt against pyproject.toml, and (``--installed``) against the venv.

    python3 .ci/check_floors.py REPO [--installed]

Every requirement of pyproject.toml -- ``[project] dependencies``, the ``test`` extra (with the
project's own extras it names, e.g. ``ramdaq[notebook]``) and ``[build-system] requires`` -- has a
``>=`` floor, and lower-bounds.txt pins it to exactly that
version (``==``); lower-bounds.txt pins nothing else. With ``--installed`` (run by the venv's
python), every pinned distribution is installed at its pin: a constraint only limits what pip
installs, so a floor pinned there but not installed would go untested without a word.

Standard library only. Exits 1 with one line per problem.
"""

from __future__ import annotations

import re
import sys
import tomllib
from importlib import metadata
from pathlib import Path

_REQ = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[[^\]]*\])?\s*(.*?)\s*(?:;.*)?$")
_SPEC = re.compile(r"^\s*(>=|<=|==|!=|~=|>|<)\s*(\S+)\s*$")
_PIN = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*==\s*([0-9][0-9.]*)\s*(?:#.*)?$")


def canonical(name: str) -> str:
    """PEP 503 name: lower case, runs of ``-_.`` as one ``-``."""
    return re.sub(r"[-_.]+", "-", name).lower()


def release(version: str) -> tuple[int, ...]:
    """A plain release number as a tuple without trailing zeros (``2.0`` equals ``2.0.0``)."""
    parts = [int(p) for p in version.split(".")]
    while len(parts) > 1 and parts[-1] == 0:
        parts.pop()
    return tuple(parts)


def floors(repo: Path) -> tuple[dict[str, str], list[str]]:
    """``{name: floor}`` of pyproject.toml's requirements, and the ones that have no ``>=``."""
    doc = tomllib.loads((repo / "pyproject.toml").read_text(encoding="utf-8"))
    extras = doc["project"]["optional-dependencies"]
    reqs = (doc["project"]["dependencies"] + _expand(extras["test"], doc["project"]["name"], extras)
            + doc["build-system"]["requires"])
    out: dict[str, str] = {}
    bad: list[str] = []
    for req in reqs:
        m = _REQ.match(req)
        specs = [_SPEC.match(s) for s in m.group(2).split(",")] if m else []
        spec = {s.group(1): s.group(2) for s in specs if s}
        if not m or ">=" not in spec:
            bad.append(f"pyproject.toml: {req!r} has no '>=' floor")
            continue
        out[canonical(m.group(1))] = spec[">="]
    return out, bad


def _expand(reqs: list[str], project: str, extras: dict[str, list[str]]) -> list[str]:
    """``reqs`` with each of the project's own extras (``ramdaq[notebook]``) replaced by that
    extra's requirements."""
    out: list[str] = []
    for req in reqs:
        m = re.match(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*\[([^\]]*)\]\s*$", req)
        if m and canonical(m.group(1)) == canonical(project):
            for extra in m.group(2).split(","):
                out += _expand(extras[extra.strip()], project, extras)
        else:
            out.append(req)
    return out


def pins(path: Path) -> tuple[dict[str, str], list[str]]:
    """``{name: version}`` of the ``name==version`` lines, and the lines that are neither that,
    a comment nor blank."""
    out: dict[str, str] = {}
    bad: list[str] = []
    for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        m = _PIN.match(line)
        if m:
            out[canonical(m.group(1))] = m.group(2)
        else:
            bad.append(f"{path}:{i}: not 'name==version': {line.strip()!r}")
    return out, bad


def problems(repo: Path, installed: bool) -> list[str]:
    want, out = floors(repo)
    pinned, bad = pins(repo / ".ci" / "lower-bounds.txt")
    out += bad
    for name, floor in sorted(want.items()):
        if name not in pinned:
            out.append(f"lower-bounds.txt: {name} is not pinned (pyproject.toml: >={floor})")
        elif release(pinned[name]) != release(floor):
            out.append(f"lower-bounds.txt: {name}=={pinned[name]}, but pyproject.toml's floor "
                       f"is {floor}")
    out += [f"lower-bounds.txt: {name} is pinned but pyproject.toml does not require it"
            for name in sorted(set(pinned) - set(want))]
    if installed:
        for name, version in sorted(pinned.items()):
            try:
                have = metadata.version(name)
            except metadata.PackageNotFoundError:
                out.append(f"venv: {name} is not installed (pinned {version})")
                continue
            if have != version:
                out.append(f"venv: {name} {have} is installed, not the pinned {version}")
    return out


def main(argv: list[str]) -> int:
    repo = Path(argv[1])
    installed = "--installed" in argv[2:]
    found = problems(repo, installed)
    for line in found:
        print(line, file=sys.stderr)
    if not found:
        n = len(pins(repo / ".ci" / "lower-bounds.txt")[0])
        print(f"lower-bounds.txt pins all {n} floors of pyproject.toml"
              + (", each installed at its pin" if installed else ""))
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
