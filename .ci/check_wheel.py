"""Check a built ramdaq wheel against pyproject.toml: one top-level name, every module and data file.

    python3 .ci/check_wheel.py REPO WHEEL

* RECORD lists nothing at the top level but ``ramdaq/`` and the ``.dist-info`` folder, and
  ``top_level.txt`` (where the backend writes one) names ``ramdaq`` alone;
* every ``*.py`` of every package in ``[tool.setuptools] packages`` (found through
  ``package-dir``) and every file matched by ``[tool.setuptools.package-data]`` is in the wheel.

Standard library only (runs on the CI machine's python3, outside any venv). Exits 1 with one line
per problem.
"""

from __future__ import annotations

import sys
import tomllib
import zipfile
from pathlib import Path


def _folder(repo: Path, package: str, package_dir: dict[str, str]) -> Path:
    """The repository folder of ``package``: its longest mapped prefix in ``package-dir``."""
    parts = package.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in package_dir:
            return repo.joinpath(package_dir[prefix], *parts[n:])
    return repo.joinpath(*parts)


def expected_files(repo: Path) -> set[str]:
    """Paths in the wheel that pyproject.toml promises: the packages' modules and their data."""
    tool = tomllib.loads((repo / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    package_dir = tool.get("package-dir", {})
    out: set[str] = set()
    for package in tool["packages"]:
        folder = _folder(repo, package, package_dir)
        inside = package.replace(".", "/")
        out |= {f"{inside}/{p.name}" for p in folder.glob("*.py")}
        for pattern in tool.get("package-data", {}).get(package, []):
            out |= {f"{inside}/{p.relative_to(folder).as_posix()}" for p in folder.glob(pattern)}
    return out


def problems(repo: Path, wheel: Path) -> list[str]:
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        (dist_info,) = {n.split("/")[0] for n in names if n.split("/")[0].endswith(".dist-info")}
        record = [line.split(",")[0] for line in z.read(f"{dist_info}/RECORD").decode().splitlines()
                  if line]
        top_level = (z.read(f"{dist_info}/top_level.txt").decode().split()
                     if f"{dist_info}/top_level.txt" in names else ["ramdaq"])
    out = [f"{wheel.name}: RECORD installs {top!r} at the top level"
           for top in sorted({p.split("/")[0] for p in record} - {"ramdaq", dist_info})]
    if top_level != ["ramdaq"]:
        out.append(f"{wheel.name}: top_level.txt names {top_level}, not ['ramdaq']")
    out += [f"{wheel.name}: {p} is missing (pyproject.toml packages / package-data)"
            for p in sorted(expected_files(repo) - names)]
    return out


def main(argv: list[str]) -> int:
    repo, wheel = Path(argv[1]), Path(argv[2])
    found = problems(repo, wheel)
    for line in found:
        print(line, file=sys.stderr)
    if not found:
        print(f"{wheel.name}: only ramdaq at the top level; all {len(expected_files(repo))} "
              f"modules and data files of pyproject.toml's packages are in it")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
