"""Where the shipped data and the C sources are: the one resolver of the package.

Two layouts are served by the same functions:

- a source checkout (``pip install -e .`` or ``PYTHONPATH``): the C tree is the top-level
  ``fmu/`` folder and the shipped FE data ``fe_data/``, both beside the ``grasprom`` package;
- an installed wheel (``pip install .``): the build copies both into the package as
  ``grasprom/_shipped/fmu`` and ``grasprom/_shipped/fe_data`` (see ``setup.py``), so nothing
  is downloaded and nothing depends on the current directory.

The C tree (``fmu/``) has four folders: ``include/`` (headers), ``src/`` (the controller core
and the FMU model with its FMI 2 / FMI 3 wrappers), ``harness/`` (drivers and test mains: the
FMU's C driver, the ctypes shim, the fixed-point test main and the simavr harnesses of the
Arduino budget measurement and of the firmware tests) and ``arduino/`` (the firmware sketch).
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
"""The installed ``grasprom`` package."""

C_SUBDIRS = ("include", "src", "harness", "arduino")
"""Folders of the C tree, searched in this order by :func:`c_file`."""

DEFAULT_SWEEP_DIR = "fe_data/default"
"""The shipped FE sweep the surrogate is built from by default (relative name)."""

DEFAULT_HOLDOUT_DIR = "fe_data/holdout"
"""The shipped off-grid FE cases of the held-out surrogate error (relative name)."""


def shipped_root() -> Path:
    """The folder holding ``fmu/`` and ``fe_data/``.

    Returns
    -------
    Path
        ``grasprom/_shipped`` in an installed wheel, else the checkout holding this package.
    """
    packaged = PACKAGE_DIR / "_shipped"
    if (packaged / "fmu").is_dir():
        return packaged
    return PACKAGE_DIR.parent


def c_dir() -> Path:
    """The C tree (``fmu/`` with ``include/``, ``src/``, ``harness/``).

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        If neither the checkout nor the installed package holds it.
    """
    path = shipped_root() / "fmu"
    if not (path / "src").is_dir():
        raise FileNotFoundError(
            f"the C sources of grasprom are missing (looked for {path}/src); "
            "reinstall the package (pip install .) or run from a source checkout"
        )
    return path


def c_file(name: str) -> Path:
    """Path of one C source or header of the C tree, by file name.

    Parameters
    ----------
    name : str
        File name, e.g. ``"grasp_core.c"`` or ``"fmu_driver.c"``.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        If no folder of the tree has it.
    """
    root = c_dir()
    for sub in C_SUBDIRS:
        path = root / sub / name
        if path.is_file():
            return path
    raise FileNotFoundError(f"no C file {name!r} in {root} ({', '.join(C_SUBDIRS)})")


def c_include_dirs() -> list[Path]:
    """Folders of the C tree to pass as ``-I`` when compiling from it in place.

    Returns
    -------
    list of Path
    """
    root = c_dir()
    return [root / sub for sub in C_SUBDIRS]


def resolve_data_dir(directory: str | Path) -> Path:
    """``directory``, or the shipped copy of a relative ``fe_data/...`` path.

    A relative path whose first part is ``fe_data`` and which does not exist from the current
    directory is looked up among the shipped data (checkout or installed wheel), so the default
    ``fe_data/default`` works from any directory.

    Parameters
    ----------
    directory : str or Path
        The directory the user named.

    Returns
    -------
    Path
        The directory to read (it may still not exist; the reader reports that).
    """
    path = Path(directory)
    if not path.is_dir() and not path.is_absolute() and path.parts[:1] == ("fe_data",):
        shipped = shipped_root() / path
        if shipped.is_dir():
            return shipped
    return path
