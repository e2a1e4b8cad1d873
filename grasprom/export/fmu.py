"""FMU export of the impedance controller: FMI 2.0 / 3.0 co-simulation, native C, no Python.

One C core (``fmu/src/grasp_core.c``, shared with the Arduino export) runs the controller
step; ``fmu_model.c`` holds one instance (parameters, state, variables; no globals) and the
FMI state machine; ``fmi2_wrapper.c`` / ``fmi3_wrapper.c`` are the FMI glue.  Everything that
describes the model is generated (:mod:`grasprom.export.codegen`) from the Python objects and
one variable table (:func:`grasprom.export.variables.variables`):

* ``grasp_tables.h`` -- surrogate curves and chain constants
  (:func:`~grasprom.export.codegen.tables_source`),
* ``grasp_fmu_config.h`` -- value references, start/min/max, unit factors, SI <-> core
  conversions, instantiation token,
* ``modelDescription.xml`` (FMI 2 or 3), ``sources/buildDescription.xml`` (FMI 3),
* ``documentation/index.html`` -- variable table, equations, status policy.

This module writes the sources, compiles the binary and packs the FMU.

The binary for this platform is compiled with ``gcc`` at export time
(``binaries/linux64`` for FMI 2, ``binaries/x86_64-linux`` for FMI 3), and the win64 DLL with
MinGW-w64 when it is installed (``binaries/win64``, ``binaries/x86_64-windows``); ``sources/`` holds
everything needed to rebuild elsewhere (``fmpy compile``).

Timing: the controller runs at its sample time ``sample_time`` (s).  ``doStep(t, h)`` requires
``h`` to be a multiple of it and runs ``h / sample_time`` controller steps at the input ``theta``
set before the call; the outputs after the call are those of the last step (a sampled
controller: the outputs respond to the input of the previous communication point, no direct
feedthrough).  Before the first step the outputs hold their start values.

Variable units are SI (m, N, N m, rad, s, Pa) with display units (mm, deg, N/mm, kPa, ms).
"""

from __future__ import annotations

import hashlib
import math
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path

from grasprom import __version__
from grasprom.control import ControllerParams
from grasprom.export.codegen import (
    CORE_SOURCES,
    FMI_VERSIONS,
    MODEL_IDENTIFIER,
    MODEL_SOURCES,
    WRAPPER,
    build_description,
    config_header,
    documentation_html,
    fmu_c_files,
    model_description,
    tables_source,
)
from grasprom.export.variables import Variable, variables
from grasprom.paths import c_file
from grasprom.surrogate import Surrogate

BINARY_DIR = {2: "linux64", 3: "x86_64-linux"}
"""Platform folder of the binary under ``binaries/`` per FMI version (Linux x86-64)."""
WINDOWS_BINARY_DIR = {2: "win64", 3: "x86_64-windows"}
"""FMU platform folders of the Windows DLL (FMI 2, FMI 3)."""
MINGW_CC = "x86_64-w64-mingw32-gcc"
"""The MinGW-w64 cross compiler of the Windows DLL (Debian: gcc-mingw-w64-x86-64)."""
OLDEST_GLIBC = (2, 14)
"""Newest glibc symbol version the Linux binary needs (``exp`` is bound to its 2.2.5 version):
it loads on glibc 2.14 and later (CentOS 7, RHEL 8; tested with objdump)."""


def platform_notes(fmi_version: int, windows: bool) -> list[tuple[str, str]]:
    """The binary folders of an FMU and what each needs to load (for its documentation).

    Parameters
    ----------
    fmi_version : int
    windows : bool
        Whether the win64 DLL is included.

    Returns
    -------
    list of (str, str)
    """
    glibc = ".".join(map(str, OLDEST_GLIBC))
    out = [(BINARY_DIR[fmi_version], f"x86_64 Linux, glibc >= {glibc} (gcc build)")]
    if windows:
        note = ("x86_64 Windows (MinGW-w64 build, GCC runtime linked statically: needs only "
                "KERNEL32.dll and msvcrt.dll)")  # fmt: skip
        out.append((WINDOWS_BINARY_DIR[fmi_version], note))
    return out


FMI_HEADERS = {
    2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
    3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"),
}
DRIVER_SOURCE = "fmu_driver.c"
"""C driver (dlopen, no Python) used by the tests and the benchmark."""

CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-fPIC", "-fvisibility=hidden")

DESCRIPTION = (
    "Open-loop impedance controller of a laparoscopic grasper: handle angle in, motor "
    "torque out, tissue forces from an FE surrogate (grasprom)"
)
"""``description`` of the modelDescription."""


def instantiation_token(tables: str, config_values: str, fmi_version: int) -> str:
    """Deterministic GUID / instantiation token of an export (same inputs, same token).

    A name-based RFC 4122 UUID (version 5 layout: version and variant bits set) of the SHA-256
    of everything the binary depends on, in braces.
    """
    h = hashlib.sha256(f"{__version__}|{fmi_version}|{config_values}|{tables}".encode())
    return "{" + str(uuid.UUID(bytes=h.digest()[:16], version=5)) + "}"


# ---------------------------------------------------------------------------------- build
def fmi_headers_dir() -> Path:
    """Directory of the FMI 2/3 C headers shipped with fmpy."""
    try:
        import fmpy
    except ImportError as exc:  # pragma: no cover - fmpy is a dependency
        raise RuntimeError("fmpy is needed for the FMI headers (pip install fmpy)") from exc
    d = Path(fmpy.__file__).resolve().parent / "c-code"
    if not (d / "fmi2Functions.h").is_file():
        raise RuntimeError(f"FMI headers not found in {d}")
    return d


def _run(cmd: list[str], what: str) -> None:
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"{what} failed:\n{' '.join(cmd)}\n{res.stdout}{res.stderr}")


def write_sources(
    directory,
    params: ControllerParams,
    surrogate: Surrogate,
    fmi_version: int,
    vars_: list[Variable] | None = None,
) -> tuple[list[Variable], str]:
    """Write the complete C sources of the FMU into ``directory``.

    Returns
    -------
    (variables, token)
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    vars_ = vars_ if vars_ is not None else variables(params, surrogate)
    tables = tables_source(surrogate, params.chain_params)
    values = repr([(v.name, v.type, v.start, v.min, v.max) for v in vars_])
    token = instantiation_token(tables, values, fmi_version)
    (d / "grasp_tables.h").write_text(tables)
    (d / "grasp_fmu_config.h").write_text(config_header(vars_, token))
    for f in (*CORE_SOURCES, *MODEL_SOURCES, WRAPPER[fmi_version]):
        shutil.copy(c_file(f), d / f)
    hdr = fmi_headers_dir()
    for f in FMI_HEADERS[fmi_version]:
        shutil.copy(hdr / f, d / f)
    if fmi_version == 3:
        (d / "buildDescription.xml").write_text(build_description())
    return vars_, token


def compile_binary(
    sources_dir, out_path, fmi_version: int, cc: str = "gcc", windows: bool = False
) -> Path:
    """Compile the FMU binary (shared library) from ``sources_dir`` with ``cc``.

    ``windows``: a win64 DLL with the MinGW-w64 cross compiler ``cc``, the GCC runtime linked
    statically (it needs only the Windows system DLLs).
    """
    if shutil.which(cc) is None:
        hint = "gcc-mingw-w64-x86-64" if windows else "gcc"
        raise RuntimeError(f"C compiler {cc!r} not found (install {hint})")
    s = Path(sources_dir)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    files = [str(s / f) for f in fmu_c_files(fmi_version)]
    flags = (
        [f for f in CFLAGS if f not in ("-fPIC", "-fvisibility=hidden")]
        if windows
        else [*CFLAGS, "-DGC_OLD_GLIBC_EXP"]  # exp@GLIBC_2.2.5: loads on glibc < 2.29
    )
    extra = ["-static-libgcc"] if windows else []
    cmd = [cc, *flags, "-shared", f"-I{s}", "-o", str(out), *files, *extra, "-lm"]
    _run(cmd, "FMU binary build" + (" (win64)" if windows else ""))
    return out


def windows_compiler() -> str | None:
    """The MinGW-w64 cross compiler if installed (:data:`MINGW_CC`), else None."""
    return MINGW_CC if shutil.which(MINGW_CC) else None


def export_fmu(
    out,
    params: ControllerParams | None = None,
    surrogate: Surrogate | None = None,
    fmi_version: int = 2,
    cc: str = "gcc",
    windows: bool | None = None,
) -> Path:
    """Export the controller as a co-simulation FMU.

    Parameters
    ----------
    out : path
        FMU file to write (``.fmu``; written atomically).
    params : ControllerParams, optional
        Start values of the parameters (default :class:`ControllerParams`).
    surrogate : Surrogate
        Tissue force tables (required).
    fmi_version : int
        2 (binary in ``binaries/linux64``) or 3 (``binaries/x86_64-linux``).
    cc : str
        C compiler.
    windows : bool, optional
        Also build the win64 DLL (``binaries/win64`` / ``binaries/x86_64-windows``) with the
        MinGW-w64 cross compiler; None (default): if it is installed.

    Returns
    -------
    pathlib.Path
        The FMU written.

    Raises
    ------
    ValueError
        Bad FMI version, or a parameter outside the FMU's declared range.
    RuntimeError
        Compiler or FMI headers missing, or the build failed.
    """
    if fmi_version not in FMI_VERSIONS:
        raise ValueError(f"--fmi must be 2 or 3, got {fmi_version!r}")
    if surrogate is None:
        raise ValueError("export_fmu needs a surrogate")
    params = params or ControllerParams()
    vars_ = variables(params, surrogate)
    check_parameter_ranges(vars_)
    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="grasprom_fmu_") as tmp:
        root = Path(tmp) / "fmu"
        _, token = write_sources(root / "sources", params, surrogate, fmi_version, vars_)
        binary = root / "binaries" / BINARY_DIR[fmi_version] / f"{MODEL_IDENTIFIER}.so"
        compile_binary(root / "sources", binary, fmi_version, cc)
        mingw = windows_compiler()
        if windows and mingw is None:
            raise RuntimeError(f"the win64 DLL needs {MINGW_CC} (Debian: gcc-mingw-w64-x86-64)")
        with_dll = mingw is not None and windows is not False
        if with_dll:
            dll = root / "binaries" / WINDOWS_BINARY_DIR[fmi_version] / f"{MODEL_IDENTIFIER}.dll"
            compile_binary(root / "sources", dll, fmi_version, mingw, windows=True)
        (root / "modelDescription.xml").write_text(
            model_description(vars_, fmi_version, token, params, DESCRIPTION)
        )
        (root / "resources").mkdir()
        (root / "resources" / DEMO_INPUT_NAME).write_text(demo_input_csv(params, surrogate))
        (root / "documentation").mkdir()
        (root / "documentation" / "index.html").write_text(
            documentation_html(
                vars_, fmi_version, token, params, platform_notes(fmi_version, with_dll)
            )  # fmt: skip
        )
        tmp_fmu = Path(tmp) / "out.fmu"
        zip_tree(root, tmp_fmu)
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(tmp_fmu), out)
        except OSError as exc:
            raise OSError(f"cannot write the FMU {out}: {exc.strerror or exc}") from None
    return out


DEMO_INPUT_NAME = "grasp_input.csv"
"""Name of the default input in the FMU's ``resources/`` (and of ``examples/fmu_grasp_input.csv``
when written for the default parameters)."""

DEMO_PHASES = (("rest open", 1), ("close", 4), ("hold", 6), ("release", 4), ("rest open", 1))
"""Grasp-hold-release of the default input: phases and their shares of the duration (16ths)."""

DEMO_HOLD_FORCE_N = 10.0
"""Tissue (jaw) force held by the default input, N: a firm atraumatic grasp (grasping forces of
laparoscopic graspers are of the order of 5-20 N at the jaw)."""


def demo_hold_gap_mm(params: ControllerParams, surrogate: Surrogate | None = None) -> float:
    """Jaw gap (mm) held by the default input: where the surrogate's tissue force is
    :data:`DEMO_HOLD_FORCE_N` (material and thickness of ``params``); without a surrogate, the
    gap at which the inner walls meet (``2 t``). Limited to the chain's gap range."""
    from scipy.optimize import brentq

    chain = params.chain_params
    lo, hi = chain.gap_closed_mm, chain.gap_open_mm
    if surrogate is None:
        return min(max(2.0 * params.thickness_mm, lo), hi)

    def excess(g: float) -> float:
        f = surrogate.force_scalar(g, params.thickness_mm, params.material)
        return f - DEMO_HOLD_FORCE_N

    if excess(lo) <= 0.0:
        return lo
    return brentq(excess, lo, hi, xtol=1e-9) if excess(hi) < 0.0 else hi


def demo_input(params: ControllerParams, surrogate: Surrogate | None = None,
               duration_s: float = 4.0, step_s: float | None = None):  # fmt: skip
    """Grasp-hold-release handle angle: rest open, close, hold, release, rest open.

    The handle closes with a minimum-jerk profile from the open end stop to the angle of
    :func:`demo_hold_gap_mm` (10 N of tissue force with a surrogate), holds, and reopens;
    shares of the duration :data:`DEMO_PHASES`.

    Parameters
    ----------
    params : ControllerParams
        Chain (end stops, deg), thickness (mm), material and sample time (s).
    surrogate : Surrogate, optional
        Tissue force for the hold gap.
    duration_s : float
        Length, s (> 0).
    step_s : float, optional
        Time step of the samples, s (default: the sample time; importers such as fmpy
        interpolate linearly between samples).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        Time (s) and handle angle ``theta`` (rad).
    """
    import numpy as np

    from grasprom.chain import kinematics as kin
    from grasprom.control.trajectory import minimum_jerk

    step = params.sample_time_s if step_s is None else step_s
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be positive and finite, got {duration_s!r}")
    if not (math.isfinite(step) and 0 < step <= duration_s):
        raise ValueError(f"step_s must be in (0, duration_s], got {step!r}")
    chain = params.chain_params
    theta_hold = math.radians(kin.theta_from_gap_deg(demo_hold_gap_mm(params, surrogate), chain))
    theta_open = math.radians(kin.theta_range_deg(chain)[1])
    t = np.round(np.arange(round(duration_s / step) + 1) * step, 12)  # 0.35, not 0.350...03
    edges = np.cumsum([0] + [w for _, w in DEMO_PHASES]) / 16.0 * duration_s
    closing = minimum_jerk((t - edges[1]) / (edges[2] - edges[1]))[0]
    opening = minimum_jerk((t - edges[3]) / (edges[4] - edges[3]))[0]
    closed_share = np.where(t < edges[3], closing, 1.0 - opening)
    theta = theta_open + (theta_hold - theta_open) * closed_share
    return t, theta


def write_demo_input(path, params: ControllerParams, surrogate: Surrogate | None = None,
                     duration_s: float = 4.0) -> Path:  # fmt: skip
    """Write :func:`demo_input` for ``fmpy simulate --input-file`` (CSV: ``time`` s, ``theta``
    rad, ``theta_dot`` rad/s).

    Without an input the FMU holds ``theta`` at its start (the open handle) and every output
    stays constant.  ``theta_dot`` is 0: the FMU differentiates ``theta`` itself unless
    ``use_theta_dot``; the column keeps fmpy from warning about an unset input.

    Parameters
    ----------
    path : path
        CSV to write.
    params : ControllerParams
    surrogate : Surrogate, optional
        For the hold gap (:func:`demo_hold_gap_mm`).
    duration_s : float
        Length of the input, s.

    Returns
    -------
    pathlib.Path
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(demo_input_csv(params, surrogate, duration_s))
    return out


def demo_input_csv(params: ControllerParams, surrogate: Surrogate | None = None,
                   duration_s: float = 4.0, step_s: float | None = None) -> str:  # fmt: skip
    """Text of the CSV of :func:`write_demo_input` (arguments of :func:`demo_input`)."""
    t, theta = demo_input(params, surrogate, duration_s, step_s)
    lines = ["time,theta,theta_dot"]
    lines += [f"{a!r},{b!r},0.0" for a, b in zip(t.tolist(), theta.tolist())]
    return "\n".join(lines) + "\n"


def check_parameter_ranges(vars_: list[Variable]) -> None:
    """Raise if a parameter's start value is outside its declared [min, max].

    Parameters
    ----------
    vars_ : list of Variable

    Raises
    ------
    ValueError
        On the first parameter out of range (SI units in the message).
    """
    for v in vars_:
        if v.causality == "parameter" and v.min is not None:
            if not v.min <= v.start <= v.max:
                raise ValueError(
                    f"parameter {v.name} = {v.start:g} outside the FMU's range "
                    f"[{v.min:g}, {v.max:g}] (SI units)"
                )


def zip_tree(root: Path, path: Path) -> None:
    """Zip the files under ``root`` into ``path`` reproducibly (sorted, fixed time stamps).

    Parameters
    ----------
    root : Path
        Folder whose content becomes the archive's root.
    path : Path
        Archive to write.
    """
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted(root.rglob("*")):
            if f.is_file():
                info = zipfile.ZipInfo(f.relative_to(root).as_posix(), (1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, f.read_bytes())


def build_driver(directory, cc: str = "gcc", windows: bool = False) -> Path:
    """Compile the C driver (``fmu_driver``: dlopen, no Python) into ``directory``.

    ``windows``: ``fmu_driver.exe`` with the MinGW-w64 cross compiler ``cc`` (LoadLibrary; run
    it with wine on Linux).
    """
    if shutil.which(cc) is None:
        raise RuntimeError(f"C compiler {cc!r} not found (install gcc)")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    exe = d / ("fmu_driver.exe" if windows else "fmu_driver")
    libs = ["-static-libgcc", "-lm"] if windows else ["-ldl", "-lm"]
    cmd = [cc, "-std=c99", "-O2", "-g", "-Wall", "-Wextra", "-Werror", f"-I{fmi_headers_dir()}",
           "-o", str(exe), str(c_file(DRIVER_SOURCE)), *libs]  # fmt: skip
    _run(cmd, "C driver build")
    return exe
