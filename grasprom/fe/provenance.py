"""Provenance recorded with every FE case: package versions, the git revision of the source
checkout, and UTC time stamps.
"""

from __future__ import annotations

import datetime as _dt
import platform
import subprocess
from pathlib import Path
from typing import Any

from grasprom import __version__


def package_versions() -> dict[str, str | None]:
    """Versions of grasprom, numpy, scipy, scikit-fem, pandas and Python.

    Returns
    -------
    dict
        ``{"grasprom": ..., "numpy": ..., "scipy": ..., "skfem": ..., "pandas": ...,
        "python": ...}``; None for a package that cannot be imported.
    """
    import importlib

    out: dict[str, str | None] = {"grasprom": __version__}
    for name in ("numpy", "scipy", "skfem", "pandas"):
        try:
            out[name] = str(importlib.import_module(name).__version__)
        except Exception:  # noqa: BLE001 - best effort provenance
            out[name] = None
    out["python"] = platform.python_version()
    return out


def git_revision() -> dict[str, Any]:
    """Git revision of the repository holding the grasprom package (best effort).

    Only reported when the package directory is inside a git work tree whose top level
    holds a ``pyproject.toml`` (i.e. a source checkout, not a site-packages install).

    Returns
    -------
    dict
        ``{"git_revision": str | None, "git_dirty": bool | None}``.
    """
    pkg_dir = Path(__file__).resolve().parent
    none: dict[str, Any] = {"git_revision": None, "git_dirty": None}

    def _git(*args: str) -> str | None:
        try:
            p = subprocess.run(
                ["git", "-C", str(pkg_dir), *args],
                capture_output=True,
                text=True,
                timeout=10,
                check=False,
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return p.stdout.strip() if p.returncode == 0 else None

    top = _git("rev-parse", "--show-toplevel")
    if not top or not (Path(top) / "pyproject.toml").is_file():
        return none
    rev = _git("rev-parse", "HEAD")
    if rev is None:
        return none
    status = _git("status", "--porcelain", "--untracked-files=no")
    return {"git_revision": rev, "git_dirty": None if status is None else bool(status)}


def provenance() -> dict[str, Any]:
    """Versions and git revision, computed once per sweep and stored in every sidecar."""
    return {"versions": package_versions(), **git_revision()}


def now_iso() -> str:
    """The current UTC time, ISO 8601 to the second (the time stamps of case files)."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
