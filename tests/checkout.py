"""Copy the checkout for tests that run commands in a scratch tree (README, wheel, docs)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def copy_checkout(dest: Path) -> None:
    """Copy the tracked and untracked-but-not-ignored files of the checkout to ``dest``."""
    files = None
    if shutil.which("git"):
        git = ["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others",
               "--exclude-standard"]  # fmt: skip
        res = subprocess.run(git, capture_output=True, timeout=60)
        if res.returncode == 0:
            files = [f for f in res.stdout.decode().split("\0") if f]
    if files is None:
        shutil.copytree(ROOT, dest, dirs_exist_ok=True, ignore=shutil.ignore_patterns(
            ".git", "build", "*.egg-info", "__pycache__", ".pytest_cache", "report"))  # fmt: skip
        return
    for f in files:
        src = ROOT / f
        if src.is_file():
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / f)
