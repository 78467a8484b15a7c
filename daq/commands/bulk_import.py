"""``ramdaq import`` of several files at once: which files a list of files, folders and globs
names, and where each one's recording goes.

A folder gives its CSV, TSV/TXT, UFF/UNV and TDMS files (its sub-folders too), in name order;
a glob the files it matches; a file itself. Each file becomes ``STEM.mcap`` beside it, or in
``out`` when that folder is given; two files that would write the same recording (``a.csv`` and
``a.uff`` in one folder) are refused before anything is written, naming both.
"""

from __future__ import annotations

import glob
from collections.abc import Sequence
from pathlib import Path

__all__ = ["IMPORT_SUFFIXES", "import_sources", "bulk_outputs"]

IMPORT_SUFFIXES = (".csv", ".tsv", ".txt", ".uff", ".unv", ".tdms")
"""The suffixes a folder's files are imported by (``ramdaq import`` reads each by its suffix)."""


def import_sources(patterns: Sequence[str]) -> list[Path]:
    """The files ``patterns`` (files, folders, globs) name, each once, in the order given.

    Raises
    ------
    FileNotFoundError
        A pattern that names nothing, or a folder without a file to import; one line naming it.
    """
    out: list[Path] = []
    for pat in patterns:
        p = Path(pat)
        if p.is_dir():
            found = sorted(f for f in p.rglob("*") if f.is_file()
                           and f.suffix.lower() in IMPORT_SUFFIXES)
            if not found:
                raise FileNotFoundError(f"{pat}: no {', '.join(IMPORT_SUFFIXES)} file in it")
        elif p.is_file():
            found = [p]
        else:
            found = sorted(Path(f) for f in glob.glob(pat, recursive=True) if Path(f).is_file())
            if not found:
                raise FileNotFoundError(f"{pat}: no such file, folder or matching file")
        out += [f for f in found if f.resolve() not in {g.resolve() for g in out}]
    return out


def bulk_outputs(files: Sequence[Path], out: Path | None) -> list[Path]:
    """Each file's recording: ``STEM.mcap`` beside it, or in the folder ``out``.

    Raises
    ------
    ValueError
        Two files that would write one recording, naming both.
    """
    outs = [(out / f.stem if out else f.with_suffix("")).with_suffix(".mcap") for f in files]
    seen: dict[Path, Path] = {}
    for f, o in zip(files, outs, strict=True):
        if o.resolve() in seen:
            raise ValueError(f"{seen[o.resolve()]} and {f} would both be imported into {o}; "
                             f"import one of them on its own with --out")
        seen[o.resolve()] = f
    return outs
