"""Provenance of a build (``build.json`` / the report's last section): versions of the Python
packages and C tools, FE data hashes, git revision, command line, stage times, artefact hashes."""

from __future__ import annotations

import hashlib
import platform
import shutil
import sys
import warnings
from pathlib import Path
from typing import Any

from grasprom.pipeline.options import BuildOptions
from grasprom.pipeline.result import BuildResult


def sha256_path(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def provenance(res: BuildResult, opts: BuildOptions) -> dict[str, Any]:
    """Provenance block of a build: versions, hashes, git revision, command line, timings.

    Parameters
    ----------
    res : BuildResult
    opts : BuildOptions

    Returns
    -------
    dict
    """
    from grasprom.fe import git_revision

    return {
        "command_line": list(opts.command_line if opts.command_line is not None else sys.argv),
        "started": res.started,
        "options": _options(res, opts),
        "augmentation": res.augmentation,
        "fe_hash": getattr(res.surrogate, "fe_hash", None) or _dir_hash(res.fe_dir),
        "holdout_fe_hash": _dir_hash(res.holdout_dir),
        "versions": _versions(),
        "tools": _tools(),
        **git_revision(),
        "stage_times_s": dict(res.stage_times_s),
        "total_s": res.total_s,
        "failed_stage": res.failed_stage,
        "error": res.error,
        "artefact_sha256": _artefact_hashes(res),
    }


def _options(res: BuildResult, opts: BuildOptions) -> dict[str, Any]:
    """The build's options as run (FE directories resolved), JSON-ready."""
    return {
        "fe_dir": str(res.fe_dir),
        "holdout_dir": None if res.holdout_dir is None else str(res.holdout_dir),
        "thickness_mm": opts.thickness_mm,
        "material": opts.material,
        "out_dir": str(res.out_dir),
        "fast": opts.fast,
        "augmented": None if opts.augmented is None else str(opts.augmented),
    }


def _dir_hash(d: Path | None) -> str | None:
    """FE hash of a sweep directory; None when missing or unreadable."""
    from grasprom.surrogate import fe_dir_hash

    if d is None or not d.is_dir():
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fe_dir_hash(d)
    except Exception:  # noqa: BLE001 - provenance must not fail the report
        return None


def _artefact_hashes(res: BuildResult) -> dict[str, str]:
    """SHA-256 of every artefact file written so far (not the report nor build.json itself)."""
    artefacts = {}
    for key, p in res.files.items():
        if p.is_file() and key not in ("report", "build_json"):
            artefacts[p.name] = sha256_path(p)
    return artefacts


def _versions() -> dict[str, str | None]:
    """Versions of grasprom and the Python packages it uses, and the platform."""
    import importlib

    from grasprom.fe import package_versions

    out = dict(package_versions())
    for mod, name in (("matplotlib", "matplotlib"), ("control", "control"), ("fmpy", "fmpy")):
        try:
            out[name] = str(importlib.import_module(mod).__version__)
        except Exception:  # noqa: BLE001 - best effort provenance
            out[name] = None
    out["platform"] = platform.platform()
    return out


def _tools() -> dict[str, str | None]:
    """First ``--version`` line of gcc and avr-gcc, and the simavr path (None when missing)."""
    return {t: _tool_version(t) for t in ("gcc", "avr-gcc")} | {"simavr": shutil.which("simavr")}


def _tool_version(tool: str) -> str | None:
    """First line of ``tool --version``; None when the tool is missing or fails."""
    import subprocess

    if shutil.which(tool) is None:
        return None
    try:
        res = subprocess.run([tool, "--version"], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    first = (res.stdout or res.stderr).strip().splitlines()
    return first[0] if first else None
