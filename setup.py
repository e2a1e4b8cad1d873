"""Setuptools hook: the wheel carries the C tree (``fmu/``) and the shipped FE data
(``fe_data/``) as ``grasprom/_shipped/...``, so an installed package needs no checkout.

:mod:`grasprom.paths` finds them there in a wheel and beside the package in a checkout.
Everything else is declared in ``pyproject.toml``.
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
SHIPPED = ("fmu", "fe_data")


class BuildPyWithShipped(build_py):
    """``build_py`` that also copies :data:`SHIPPED` into ``grasprom/_shipped``."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:  # editable installs read the checkout itself
            return
        target = Path(self.build_lib) / "grasprom" / "_shipped"
        for name in SHIPPED:
            dst = target / name
            if dst.exists():
                shutil.rmtree(dst)
            shutil.copytree(ROOT / name, dst, ignore=shutil.ignore_patterns("__pycache__"))


setup(cmdclass={"build_py": BuildPyWithShipped})
