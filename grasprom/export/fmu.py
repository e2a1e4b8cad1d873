"""FMU export of the impedance controller: FMI 2.0 / 3.0 co-simulation, native C, no Python.

One C core (``fmu/src/grasp_core.c``, shared with the Arduino export) runs the controller
step; ``fmu_model.c`` holds one instance (parameters, state, variables; no globals) and the
FMI state machine; ``fmi2_wrapper.c`` / ``fmi3_wrapper.c`` are the FMI glue.  Everything that
describes the model is generated here from the Python objects, from one variable table
(:func:`variables`):

* ``grasp_tables.h`` -- surrogate curves and chain constants
  (:func:`~grasprom.export.ccore.tables_source`),
* ``grasp_fmu_config.h`` -- value references, start/min/max, instantiation token,
* ``modelDescription.xml`` (FMI 2 or 3), ``sources/buildDescription.xml`` (FMI 3),
* ``documentation/index.html`` -- variable table, equations, status policy.

The binary for this platform is compiled with ``gcc`` at export time
(``binaries/linux64`` for FMI 2, ``binaries/x86_64-linux`` for FMI 3); ``sources/`` holds
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
import html
import math
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from grasprom import __version__
from grasprom.chain import kinematics as kin
from grasprom.control import ControllerParams
from grasprom.export.ccore import CORE_SOURCES, tables_source
from grasprom.fe import MATERIAL_NAMES
from grasprom.paths import c_file
from grasprom.surrogate import Surrogate

MODEL_IDENTIFIER = "GraspController"
"""Model identifier: name of the binary and of the FMI model."""

FMI_VERSIONS = (2, 3)

BINARY_DIR = {2: "linux64", 3: "x86_64-linux"}
"""Platform folder of the binary under ``binaries/`` per FMI version (Linux x86-64)."""

MODEL_SOURCES = ("fmu_model.c", "fmu_model.h")
WRAPPER = {2: "fmi2_wrapper.c", 3: "fmi3_wrapper.c"}
FMI_HEADERS = {
    2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
    3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"),
}
DRIVER_SOURCE = "fmu_driver.c"
"""C driver (dlopen, no Python) used by the tests and the benchmark."""

CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-fPIC", "-fvisibility=hidden")

# units: name -> (SI base-unit exponents, [(display unit, factor)]); display = factor * value
UNITS: dict[str, tuple[dict[str, int], list[tuple[str, float]]]] = {
    "s": ({"s": 1}, [("ms", 1e3)]),
    "rad": ({"rad": 1}, [("deg", 180.0 / math.pi)]),
    "rad/s": ({"rad": 1, "s": -1}, [("deg/s", 180.0 / math.pi)]),
    "m": ({"m": 1}, [("mm", 1e3)]),
    "N": ({"kg": 1, "m": 1, "s": -2}, []),
    "N.m": ({"kg": 1, "m": 2, "s": -2}, []),
    "N/m": ({"kg": 1, "s": -2}, [("N/mm", 1e-3)]),
    "N.m.s/rad": ({"kg": 1, "m": 2, "s": -1, "rad": -1}, []),
    "Hz": ({"s": -1}, []),
    "Pa": ({"kg": 1, "m": -1, "s": -2}, [("kPa", 1e-3), ("MPa", 1e-6)]),
    "m/N": ({"kg": -1, "s": 2}, [("mm/N", 1e3)]),
    "N.s/m": ({"kg": 1, "s": -1}, [("N.s/mm", 1e-3)]),
    "m/s": ({"m": 1, "s": -1}, [("mm/s", 1e3)]),
}

THETA_DOT_MAX = 1e3
"""Bound of the ``theta_dot`` input (rad/s); larger values are clamped."""

# parameters exposed by the FMU: name, ControllerParams field, factor to SI, unit, display
# unit, min, max (SI), description.  thickness bounds come from the surrogate.
_PARAMETERS = (
    (
        "spring_k",
        "spring_k_N_per_mm",
        1e3,
        "N/m",
        "N/mm",
        0.0,
        1e6,
        "return-spring rate of the instrument",
    ),
    (
        "damping",
        "damping_Nms_per_rad",
        1.0,
        "N.m.s/rad",
        None,
        0.0,
        10.0,
        "virtual damping at the handle pivot, on the handle velocity",
    ),
    (
        "velocity_cutoff",
        "velocity_cutoff_Hz",
        1.0,
        "Hz",
        None,
        0.01,
        1e5,
        "cutoff of the first-order low-pass filter of the velocity estimate "
        "(must be below the Nyquist frequency 0.5/sample_time)",
    ),
    (
        "pulley_radius",
        "pulley_radius_mm",
        1e-3,
        "m",
        "mm",
        1e-3,
        0.5,
        "motor pulley radius: torque = cable tension x radius",
    ),
    (
        "torque_limit",
        "torque_limit_Nm",
        1.0,
        "N.m",
        None,
        1e-6,
        100.0,
        "motor torque saturation (symmetric)",
    ),
    (
        "sample_time",
        "sample_time_s",
        1.0,
        "s",
        "ms",
        1e-5,
        1.0,
        "controller period; the communication step must be a multiple of it",
    ),
    (
        "coupling_stiffness",
        "coupling_stiffness_N_per_mm",
        1e3,
        "N/m",
        "N/mm",
        1.0,
        1e8,
        "virtual coupling stiffness at the jaw (bound on the rendered jaw stiffness)",
    ),
    (
        "force_warning",
        "force_warning_N",
        1.0,
        "N",
        None,
        1e-3,
        1e5,
        "tissue-safety threshold on the tissue jaw force",
    ),
    (
        "pressure_warning",
        "pressure_warning_MPa",
        1e6,
        "Pa",
        "kPa",
        1.0,
        1e9,
        "tissue-safety threshold on the mean contact pressure",
    ),
    (
        "jaw_length",
        "jaw_length_mm",
        1e-3,
        "m",
        "mm",
        1e-4,
        1.0,
        "length of tube under the jaws (contact area for the mean pressure)",
    ),
    (
        "diameter",
        "diameter_mm",
        1e-3,
        "m",
        "mm",
        1e-3,
        1.0,
        "tube outer diameter (contact width of the flattened tube); must exceed 2 x thickness",
    ),
    # rendering of diagnosed effects (grasprom diagnose -> --augmented); neutral defaults
    (
        "tissue_scale",
        "tissue_scale",
        1.0,
        None,
        None,
        1e-3,
        1e3,
        "factor on the tissue force and stiffness (tissue_stiffness_scale)",
    ),
    (
        "jaw_compliance",
        "jaw_compliance_mm_per_N",
        1e-3,
        "m/N",
        "mm/N",
        0.0,
        1.0,
        "series compliance of jaw + mechanism: coupling 1/(1/k_c + C) (jaw_compliance)",
    ),
    (
        "backlash",
        "backlash_deg",
        math.pi / 180.0,
        "rad",
        "deg",
        0.0,
        0.5,
        "play between the encoder and the linkage, total width (backlash)",
    ),
    (
        "friction_coulomb",
        "friction_coulomb_N",
        1.0,
        "N",
        None,
        0.0,
        1e3,
        "Coulomb friction at the finger, in the direction of the last motion (mechanism_friction)",
    ),
    (
        "friction_load_coefficient",
        "friction_load_coefficient",
        1.0,
        None,
        None,
        0.0,
        10.0,
        "load-proportional Coulomb friction, x |tissue handle force|",
    ),
    (
        "friction_viscous",
        "friction_viscous_N_s_per_mm",
        1e3,
        "N.s/m",
        "N.s/mm",
        0.0,
        1e6,
        "viscous friction at the finger, on the finger speed",
    ),
    (
        "friction_velocity_threshold",
        "friction_velocity_threshold_mm_per_s",
        1e-3,
        "m/s",
        "mm/s",
        1e-6,
        10.0,
        "finger speed above which the friction direction follows the motion",
    ),
    *(
        (
            f"prony_g_{i + 1}",
            f"prony_g[{i}]",
            1.0,
            None,
            None,
            0.0,
            100.0,
            f"Prony coefficient {i + 1} of the viscoelastic jaw-force rendering "
            "(tissue_viscoelasticity; 0 = term off)",
        )
        for i in range(4)
    ),
    *(
        (
            f"prony_tau_{i + 1}",
            f"prony_tau_s[{i}]",
            1.0,
            "s",
            None,
            1e-6,
            1e6,
            f"relaxation time of Prony term {i + 1}",
        )
        for i in range(4)
    ),
)


def _param_value(params: ControllerParams, field_: str) -> float:
    """A ControllerParams value by field name; ``prony_g[i]`` / ``prony_tau_s[i]`` are padded
    to the C core's four terms (g = 0 terms add exactly 0)."""
    if field_.endswith("]"):
        from grasprom.export.ccore import prony_padded

        name, idx = field_[:-1].split("[")
        g, tau = prony_padded(params)
        return float((g if name == "prony_g" else tau)[int(idx)])
    return float(getattr(params, field_))


ENCODER_COUNTS_MAX = 2**30


@dataclass(frozen=True)
class Variable:
    """One FMU variable (SI values).

    Parameters
    ----------
    name : str
        FMI variable name.
    vr : int
        Value reference (unique over all types, also in FMI 2).
    type : str
        ``Real``, ``Integer`` or ``Boolean`` (FMI 3: Float64, Int32, Boolean).
    causality : str
        ``independent``, ``input``, ``parameter`` or ``output``.
    variability : str
        ``continuous``, ``discrete`` or ``fixed``.
    description : str
    unit, display_unit : str or None
        Unit (a key of :data:`UNITS`) and display unit (Real only).
    start, min, max : float or None
        SI values (Boolean: start 0/1, no min/max; independent: none).
    """

    name: str
    vr: int
    type: str
    causality: str
    variability: str
    description: str
    unit: str | None = None
    display_unit: str | None = None
    start: float | None = None
    min: float | None = None
    max: float | None = None

    @property
    def initial(self) -> str | None:
        """``exact`` for outputs (start values hold until the first step), else default."""
        return "exact" if self.causality == "output" else None


def _nice_ceil(x: float) -> float:
    """Round up to two significant digits."""
    if x <= 0:
        return 0.0
    e = 10.0 ** (math.floor(math.log10(x)) - 1)
    return math.ceil(x / e - 1e-9) * e


def force_bound_N(surrogate: Surrogate, chain: kin.ChainParams) -> float:
    """Declared maximum of the force outputs (N): twice the largest tabulated force at the
    closed gap (the force falls with the gap), rounded up to two significant digits."""
    g_lo = min(kin.gap_mm(x, chain) for x in kin.theta_range_deg(chain))
    fmax = 0.0
    for m in MATERIAL_NAMES:
        lo, hi = surrogate.thickness_range(m)
        for i in range(241):
            t = lo + (hi - lo) * i / 240
            fmax = max(fmax, surrogate.evaluate_scalar(g_lo, t, m)[0])
        for t in surrogate.thicknesses(m):
            fmax = max(fmax, surrogate.evaluate_scalar(g_lo, t, m)[0])
    return _nice_ceil(2.0 * fmax)


def variables(params: ControllerParams, surrogate: Surrogate) -> list[Variable]:
    """The FMU's variables, in value-reference order (the single source of the C config
    header, the modelDescription and the documentation).

    Parameters
    ----------
    params : ControllerParams
        Start values of the parameters.
    surrogate : Surrogate
        Thickness range and force bound.

    Returns
    -------
    list of Variable
    """
    chain = params.chain_params
    th_lo_deg, th_hi_deg = kin.theta_range_deg(chain)
    th_lo, th_hi = math.radians(th_lo_deg), math.radians(th_hi_deg)
    gaps = [kin.gap_mm(th_lo_deg + (th_hi_deg - th_lo_deg) * i / 400, chain) for i in range(401)]
    g_min, g_max = min(gaps) * 1e-3 - 1e-6, max(gaps) * 1e-3 + 1e-6
    t_lo = min(surrogate.thickness_range(m)[0] for m in MATERIAL_NAMES) * 1e-3
    t_hi = max(surrogate.thickness_range(m)[1] for m in MATERIAL_NAMES) * 1e-3
    f_max = force_bound_N(surrogate, chain)
    tl_max = next(p[6] for p in _PARAMETERS if p[0] == "torque_limit")
    r_min = next(p[5] for p in _PARAMETERS if p[0] == "pulley_radius")
    t_min = next(p[5] for p in _PARAMETERS if p[0] == "sample_time")
    v_max = _nice_ceil(max((th_hi - th_lo) / t_min, THETA_DOT_MAX))

    out: list[Variable] = []

    def add(name, type_, causality, variability, description, **kw):
        out.append(Variable(name, len(out), type_, causality, variability, description, **kw))

    add("time", "Real", "independent", "continuous", "simulation time", unit="s")
    add(
        "theta",
        "Real",
        "input",
        "continuous",
        "handle angle (decreases when closing; 0 = closed end stop, as in grasprom simulate); "
        "clamped into [min, max], NaN holds the last valid angle",
        unit="rad",
        display_unit="deg",
        start=th_hi,
        min=th_lo,
        max=th_hi,
    )
    add(
        "theta_dot",
        "Real",
        "input",
        "continuous",
        "handle angular velocity, used for the damping when use_theta_dot is true "
        "(else ignored: the velocity is estimated from theta)",
        unit="rad/s",
        display_unit="deg/s",
        start=0.0,
        min=-THETA_DOT_MAX,
        max=THETA_DOT_MAX,
    )
    add(
        "thickness",
        "Real",
        "parameter",
        "fixed",
        "colon wall thickness (clamped into the tabulated range of the material)",
        unit="m",
        display_unit="mm",
        start=params.thickness_mm * 1e-3,
        min=t_lo,
        max=t_hi,
    )
    add(
        "material",
        "Integer",
        "parameter",
        "fixed",
        "tissue material model: " + ", ".join(f"{i} {m}" for i, m in enumerate(MATERIAL_NAMES)),
        start=MATERIAL_NAMES.index(params.material),
        min=0,
        max=len(MATERIAL_NAMES) - 1,
    )
    for name, field_, factor, unit, disp, lo, hi, desc in _PARAMETERS:
        add(
            name,
            "Real",
            "parameter",
            "fixed",
            desc,
            unit=unit,
            display_unit=disp,
            start=_param_value(params, field_) * factor,
            min=lo,
            max=hi,
        )
    add(
        "encoder_counts",
        "Integer",
        "parameter",
        "fixed",
        "motor encoder resolution in counts per revolution (0: no quantisation of theta)",
        start=int(params.encoder_counts_per_rev),
        min=0,
        max=ENCODER_COUNTS_MAX,
    )
    add(
        "render_spring",
        "Boolean",
        "parameter",
        "fixed",
        "include the instrument's return spring in the rendered handle force",
        start=int(bool(params.render_spring)),
    )
    add(
        "use_theta_dot",
        "Boolean",
        "parameter",
        "fixed",
        "damp the theta_dot input instead of the filtered backward-difference estimate",
        start=0,
    )
    add(
        "torque",
        "Real",
        "output",
        "discrete",
        "motor torque command, after saturation",
        unit="N.m",
        start=0.0,
        min=-tl_max,
        max=tl_max,
    )
    add(
        "force_handle",
        "Real",
        "output",
        "discrete",
        "rendered handle force (positive resists closing) = torque / pulley_radius",
        unit="N",
        start=0.0,
        min=-tl_max / r_min,
        max=tl_max / r_min,
    )
    add(
        "force_jaw",
        "Real",
        "output",
        "discrete",
        "rendered jaw force through the virtual coupling",
        unit="N",
        start=0.0,
        min=0.0,
        max=f_max,
    )
    add(
        "force_tissue",
        "Real",
        "output",
        "discrete",
        "tissue force of the surrogate at the kinematic gap",
        unit="N",
        start=0.0,
        min=0.0,
        max=f_max,
    )
    add(
        "gap",
        "Real",
        "output",
        "discrete",
        "jaw gap from the kinematic chain",
        unit="m",
        display_unit="mm",
        start=kin.gap_mm(th_hi_deg, chain) * 1e-3,
        min=g_min,
        max=g_max,
    )
    add(
        "velocity",
        "Real",
        "output",
        "discrete",
        "handle velocity used for the damping (filtered estimate or theta_dot)",
        unit="rad/s",
        display_unit="deg/s",
        start=0.0,
        min=-v_max,
        max=v_max,
    )
    for name, desc in (
        ("contact", "the jaws touch the tissue (surrogate force > 0)"),
        ("tissue_warning", "tissue force or mean contact pressure reached its threshold"),
        ("coupling_active", "tissue stiffer than the virtual coupling (rendering is bounded)"),
        ("saturated", "the torque hit torque_limit"),
        ("theta_clamped", "theta was outside its range, infinite or NaN"),
    ):
        add(name, "Boolean", "output", "discrete", desc, start=0)
    return out


def start_values(params: ControllerParams) -> dict[str, float | int | bool]:
    """FMU parameter values (SI, by variable name) equivalent to ``params``.

    For ``simulate_fmu(..., start_values=...)`` or any importer; the chain geometry and the
    surrogate are compiled into the FMU and cannot be changed this way.
    """
    d: dict[str, float | int | bool] = {
        "thickness": params.thickness_mm * 1e-3,
        "material": MATERIAL_NAMES.index(params.material),
    }
    for name, field_, factor, *_ in _PARAMETERS:
        d[name] = _param_value(params, field_) * factor
    d["encoder_counts"] = int(params.encoder_counts_per_rev)
    d["render_spring"] = bool(params.render_spring)
    return d


OUTPUT_COLUMNS = {
    "torque": ("torque_Nm", 1.0),
    "force_handle": ("force_handle_N", 1.0),
    "force_jaw": ("force_jaw_N", 1.0),
    "force_tissue": ("force_tissue_N", 1.0),
    "gap": ("gap_mm", 1e-3),
    "velocity": ("velocity_rad_per_s", 1.0),
    "contact": ("contact", None),
    "tissue_warning": ("tissue_warning", None),
    "coupling_active": ("coupling_active", None),
    "saturated": ("saturated", None),
    "theta_clamped": ("theta_clamped", None),
}
"""FMU output -> (column of :func:`~grasprom.control.controller.simulate`, factor to SI;
None: Boolean)."""


def instantiation_token(tables: str, config_values: str, fmi_version: int) -> str:
    """Deterministic GUID / instantiation token of an export (same inputs, same token)."""
    h = hashlib.sha256(f"{__version__}|{fmi_version}|{config_values}|{tables}".encode())
    return "{" + str(uuid.UUID(h.hexdigest()[:32])) + "}"


# ---------------------------------------------------------------------------------- C header
def _c_double(x: float) -> str:
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return float(x).hex()


def config_header(vars_: list[Variable], token: str) -> str:
    """C source of ``grasp_fmu_config.h`` (value references and the variable table)."""
    types = {"Real": "GF_REAL", "Integer": "GF_INTEGER", "Boolean": "GF_BOOLEAN"}
    caus = {
        "independent": "GF_INDEPENDENT",
        "parameter": "GF_PARAMETER",
        "input": "GF_INPUT",
        "output": "GF_OUTPUT",
    }
    lines = [
        "/* Generated by grasprom.export.fmu.config_header -- do not edit.  Values SI. */",
        "#ifndef GRASP_FMU_CONFIG_H",
        "#define GRASP_FMU_CONFIG_H",
        "#include <math.h>",
        '#include "fmu_model.h"',
        "",
        f'#define GF_MODEL_IDENTIFIER "{MODEL_IDENTIFIER}"',
        f'#define GF_TOKEN "{token}"',
        f"#define GF_N_VARS {len(vars_)}",
    ]
    lines += [f"#define GF_VR_{v.name} {v.vr}" for v in vars_]
    lines.append("")
    lines.append("#ifdef GF_DEFINE_VARS")
    lines.append("static const gf_var_t GF_VARS[GF_N_VARS] = {")
    rows = []
    for v in vars_:
        start = 0.0 if v.start is None else float(v.start)
        lo = -math.inf if v.min is None else float(v.min)
        hi = math.inf if v.max is None else float(v.max)
        rows.append(
            f'    {{"{v.name}", {types[v.type]}, {caus[v.causality]}, {_c_double(start)}, '
            f"{_c_double(lo)}, {_c_double(hi)}}}"
        )
    lines.append(",\n".join(rows))
    lines += ["};", "#endif", "", "#endif", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- XML
def _num(x: float | int, type_: str) -> str:
    if type_ == "Boolean":
        return "true" if x else "false"
    if type_ == "Integer":
        return str(int(x))
    return repr(float(x))


def _units_xml(fmi_version: int, indent: str = "  ") -> list[str]:
    lines = [f"{indent}<UnitDefinitions>"]
    for name, (base, displays) in UNITS.items():
        attrs = " ".join(f'{k}="{e}"' for k, e in base.items())
        lines.append(f'{indent}  <Unit name="{name}">')
        lines.append(f"{indent}    <BaseUnit {attrs}/>")
        for d, f in displays:
            lines.append(f'{indent}    <DisplayUnit name="{d}" factor="{f!r}"/>')
        lines.append(f"{indent}  </Unit>")
    lines.append(f"{indent}</UnitDefinitions>")
    return lines


_FMI3_TYPE = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}

LOG_CATEGORIES = (
    ("logEvents", "informational messages (with debug logging on)"),
    ("logStatusWarning", "clamped values"),
    ("logStatusError", "rejected calls and values, wrong-state calls"),
)


def _type_attrs(v: Variable) -> str:
    attrs = []
    if v.unit:
        attrs.append(f'unit="{v.unit}"')
    if v.display_unit:
        attrs.append(f'displayUnit="{v.display_unit}"')
    if v.start is not None:
        attrs.append(f'start="{_num(v.start, v.type)}"')
    if v.type != "Boolean":
        if v.min is not None:
            attrs.append(f'min="{_num(v.min, v.type)}"')
        if v.max is not None:
            attrs.append(f'max="{_num(v.max, v.type)}"')
    return " ".join(attrs)


def model_description(
    vars_: list[Variable],
    fmi_version: int,
    token: str,
    params: ControllerParams,
    description: str,
) -> str:
    """``modelDescription.xml`` for FMI 2.0 or 3.0 co-simulation."""
    if fmi_version not in FMI_VERSIONS:
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    stop = 4.0
    step = params.sample_time_s
    head = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<fmiModelDescription",
        f'  fmiVersion="{fmi_version}.0"',
        f'  modelName="{MODEL_IDENTIFIER}"',
        (f'  guid="{token}"' if fmi_version == 2 else f'  instantiationToken="{token}"'),
        f"  description={quoteattr(description)}",
        f'  generationTool="grasprom {__version__}"',
        '  variableNamingConvention="flat"',
    ]
    if fmi_version == 2:
        head.append('  numberOfEventIndicators="0">')
        sources = "".join(
            f'\n      <File name="{f}"/>' for f in ("grasp_core.c", "fmu_model.c", WRAPPER[2])
        )
        head += [
            f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}"',
            '    canHandleVariableCommunicationStepSize="true"',
            '    canInterpolateInputs="false" maxOutputDerivativeOrder="0"',
            '    canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="false"',
            '    canNotUseMemoryManagementFunctions="false" canGetAndSetFMUstate="false"',
            '    canSerializeFMUstate="false" providesDirectionalDerivative="false">',
            f"    <SourceFiles>{sources}\n    </SourceFiles>",
            "  </CoSimulation>",
        ]
    else:
        head[-1] += ">"
        head += [
            f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}"',
            '    canHandleVariableCommunicationStepSize="true" hasEventMode="false"',
            '    canBeInstantiatedOnlyOncePerProcess="false" canGetAndSetFMUState="false"',
            '    canSerializeFMUState="false" providesDirectionalDerivatives="false"',
            '    providesAdjointDerivatives="false" canReturnEarlyAfterIntermediateUpdate="false"',
            '    providesIntermediateUpdate="false" maxOutputDerivativeOrder="0"/>',
        ]
    lines = head + _units_xml(fmi_version)
    lines.append("  <LogCategories>")
    lines += [f'    <Category name="{n}" description="{d}"/>' for n, d in LOG_CATEGORIES]
    lines.append("  </LogCategories>")
    lines.append(f'  <DefaultExperiment startTime="0.0" stopTime="{stop!r}" stepSize="{step!r}"/>')
    lines.append("  <ModelVariables>")
    for v in vars_:
        common = (
            f'name="{v.name}" valueReference="{v.vr}" description={quoteattr(v.description)} '
            f'causality="{v.causality}" variability="{v.variability}"'
        )
        if v.initial:
            common += f' initial="{v.initial}"'
        ta = _type_attrs(v)
        if fmi_version == 2:
            lines.append(f"    <ScalarVariable {common}>")
            lines.append(f"      <{v.type} {ta}/>" if ta else f"      <{v.type}/>")
            lines.append("    </ScalarVariable>")
        else:
            t3 = _FMI3_TYPE[v.type]
            lines.append(f"    <{t3} {common}{' ' + ta if ta else ''}/>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    outputs = [v for v in vars_ if v.causality == "output"]
    if fmi_version == 2:
        lines.append("    <Outputs>")
        # index: 1-based position in ModelVariables (= vr + 1); no direct feedthrough
        lines += [f'      <Unknown index="{v.vr + 1}" dependencies=""/>' for v in outputs]
        lines.append("    </Outputs>")
    else:
        lines += [f'    <Output valueReference="{v.vr}" dependencies=""/>' for v in outputs]
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def build_description() -> str:
    """``sources/buildDescription.xml`` (FMI 3)."""
    files = "\n".join(
        f'      <SourceFile name="{f}"/>' for f in ("grasp_core.c", "fmu_model.c", WRAPPER[3])
    )
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<fmiBuildDescription fmiVersion="3.0">\n'
        f'  <BuildConfiguration modelIdentifier="{MODEL_IDENTIFIER}">\n'
        '    <SourceFileSet language="C99">\n'
        f"{files}\n"
        "    </SourceFileSet>\n"
        '    <Library name="m"/>\n'
        "  </BuildConfiguration>\n"
        "</fmiBuildDescription>\n"
    )


# ---------------------------------------------------------------------------------- docs
def documentation_html(
    vars_: list[Variable], fmi_version: int, token: str, params: ControllerParams
) -> str:
    """``documentation/index.html``: variables, equations, timing and status policy."""

    def cell(x) -> str:
        return "" if x is None else html.escape(str(x))

    def fmt(x, type_: str) -> str:
        return "" if x is None else _num(x, type_)

    rows = []
    for v in vars_:
        t = v.type if fmi_version == 2 else _FMI3_TYPE[v.type]
        fields = (
            v.name,
            v.vr,
            t,
            v.causality,
            v.variability,
            v.unit,
            v.display_unit,
            fmt(v.start, v.type),
            fmt(v.min, v.type),
            fmt(v.max, v.type),
            v.description,
        )
        rows.append("<tr>" + "".join(f"<td>{cell(x)}</td>" for x in fields) + "</tr>")
    mats = ", ".join(f"{i} = {m}" for i, m in enumerate(MATERIAL_NAMES))
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{MODEL_IDENTIFIER}</title>
<style>body{{font-family:sans-serif;max-width:70em;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #999;padding:2px 6px;font-size:90%}}code{{background:#eee}}</style>
</head><body>
<h1>{MODEL_IDENTIFIER} &mdash; open-loop impedance controller of a laparoscopic grasper</h1>
<p>FMI {fmi_version}.0 co-simulation FMU exported by grasprom {__version__}
(token <code>{token}</code>). Native C, no Python needed at run time. The tissue force
surrogate (materials {mats}) and the kinematic chain are compiled in as tables.</p>

<h2>Timing</h2>
<p>The controller runs at its sample time <code>sample_time</code> (default
{params.sample_time_s:g} s). <code>doStep(t, h)</code> requires <code>h</code> to be a
multiple of <code>sample_time</code> and runs <code>h/sample_time</code> controller steps at the
input <code>theta</code> set before the call; the outputs after the call are those of the last
step (sampled controller: no direct feedthrough, outputs respond to the input of the previous
communication point). Before the first step the outputs hold their start values.</p>

<h2>Equations (one controller step, period T)</h2>
<ol>
<li>Encoder: &theta; is quantised to one count, q = 2&pi; r / (N<sub>enc</sub> L<sub>3</sub>),
and clamped to [&theta;<sub>closed</sub>, &theta;<sub>open</sub>] (flag
<code>theta_clamped</code>; NaN holds the last valid angle).</li>
<li>Velocity: v<sub>raw</sub> = (&theta;<sub>k</sub> &minus; &theta;<sub>k&minus;1</sub>)/T,
v<sub>k</sub> = a v<sub>k&minus;1</sub> + (1&minus;a) v<sub>raw</sub>,
a = exp(&minus;2&pi; f<sub>c</sub> T) (or v = <code>theta_dot</code> when
<code>use_theta_dot</code>).</li>
<li>Kinematics: jaw gap g(&theta;) and dg/d&theta; of the derived linkage.</li>
<li>Tissue: F(g) from the surrogate (monotone cubic Hermite in the gap, aligned blending in
thickness). Virtual coupling k<sub>c</sub>: the proxy gap g<sub>p</sub> &ge; g solves
k<sub>c</sub>(g<sub>p</sub> &minus; g) = F(g<sub>p</sub>) (three safeguarded Newton steps);
rendered jaw force F<sub>g</sub> = k<sub>c</sub>(g<sub>p</sub> &minus; g)
(<code>force_jaw</code>); <code>force_tissue</code> = F(g).</li>
<li>Chain (virtual work): F<sub>i</sub> = (F<sub>g</sub> dg/d&theta; &minus;
(F<sub>0</sub> + k u) du/d&theta;) / L<sub>3</sub> (spring term only with
<code>render_spring</code>), minus damping B v / L<sub>3</sub>.</li>
<li>Torque: &tau; = F<sub>i</sub> r, saturated at &plusmn;<code>torque_limit</code>
(flag <code>saturated</code>); <code>force_handle</code> = &tau; / r.</li>
<li>Safety: <code>tissue_warning</code> when F(g) &ge; <code>force_warning</code> or
F(g) / (L<sub>jaw</sub> &pi;(D &minus; t)/2) &ge; <code>pressure_warning</code>.</li>
</ol>

<h2>Rendering of diagnosed effects (grasprom diagnose &rarr; <code>--augmented</code>)</h2>
<p>Neutral by default (the step is then exactly the one above). <code>tissue_scale</code>
multiplies F and its stiffness; <code>jaw_compliance</code> C puts the jaw in series with the
coupling, k<sub>c</sub> &rarr; 1/(1/k<sub>c</sub> + C); <code>backlash</code> b: the linkage
angle follows &theta; through a play of width b (gap, tissue, spring and virtual work use it);
<code>prony_g_i</code>, <code>prony_tau_i</code>: h<sub>i</sub> &larr;
e<sup>&minus;T/&tau;<sub>i</sub></sup> h<sub>i</sub> + &Delta;F<sub>g</sub>,
F<sub>g</sub> &rarr; max(F<sub>g</sub> + &Sigma; g<sub>i</sub> h<sub>i</sub>, 0) (quasi-linear
viscoelastic rendering); <code>friction_coulomb</code> F<sub>c</sub>,
<code>friction_load_coefficient</code> &mu;, <code>friction_viscous</code> b<sub>v</sub>:
F<sub>i</sub> += (F<sub>c</sub> + &mu; |F<sub>g</sub> dg/d&theta; / L<sub>3</sub>|) s +
b<sub>v</sub> v<sub>f</sub>, v<sub>f</sub> = &minus;v L<sub>3</sub> the finger speed (closing
&gt; 0), s = the direction of the last finger motion faster than
<code>friction_velocity_threshold</code>.</p>

<h2>Status policy</h2>
<ul>
<li>Calls in the wrong state, on unknown value references or of the wrong type, non-finite
parameters, Integer parameters outside [min, max], a step size that is not a multiple of
<code>sample_time</code>, a communication point that does not match the FMU time: rejected
with <em>Error</em> and a logged message; nothing is changed and the instance stays usable.</li>
<li>Finite Real parameters outside [min, max]: clamped, <em>Warning</em>. A thickness outside
the tabulated range of the chosen material is clamped at ExitInitializationMode
(<em>Warning</em>); inconsistent parameters (cut-off above Nyquist, diameter &le; 2 &times;
thickness) make ExitInitializationMode return <em>Error</em>.</li>
<li>Inputs outside [min, max], infinite or NaN: accepted with <em>Warning</em>; the controller
clamps <code>theta</code> to the end stops (NaN holds the last valid angle); <code>theta_dot</code>
is clamped (NaN &rarr; 0).</li>
<li>Parameters are <code>fixed</code>: set them before ExitInitializationMode (or after Reset).</li>
</ul>

<h2>Variables (SI units)</h2>
<table><tr><th>name</th><th>vr</th><th>type</th><th>causality</th><th>variability</th>
<th>unit</th><th>display</th><th>start</th><th>min</th><th>max</th><th>description</th></tr>
{chr(10).join(rows)}
</table>
</body></html>
"""


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


def compile_binary(sources_dir, out_path, fmi_version: int, cc: str = "gcc") -> Path:
    """Compile the FMU binary (shared library) from ``sources_dir`` with ``cc``."""
    if shutil.which(cc) is None:
        raise RuntimeError(f"C compiler {cc!r} not found (install gcc)")
    s = Path(sources_dir)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    files = [str(s / f) for f in ("grasp_core.c", "fmu_model.c", WRAPPER[fmi_version])]
    cmd = [cc, *CFLAGS, "-shared", f"-I{s}", "-o", str(out), *files, "-lm"]
    _run(cmd, "FMU binary build")
    return out


def export_fmu(
    out,
    params: ControllerParams | None = None,
    surrogate: Surrogate | None = None,
    fmi_version: int = 2,
    cc: str = "gcc",
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
    for v in vars_:
        if v.causality == "parameter" and v.min is not None:
            if not v.min <= v.start <= v.max:
                raise ValueError(
                    f"parameter {v.name} = {v.start:g} outside the FMU's range "
                    f"[{v.min:g}, {v.max:g}] (SI units)"
                )
    out = Path(out)
    desc = (
        "Open-loop impedance controller of a laparoscopic grasper: handle angle in, motor "
        "torque out, tissue forces from an FE surrogate (grasprom)"
    )
    with tempfile.TemporaryDirectory(prefix="grasprom_fmu_") as tmp:
        root = Path(tmp) / "fmu"
        _, token = write_sources(root / "sources", params, surrogate, fmi_version, vars_)
        binary = root / "binaries" / BINARY_DIR[fmi_version] / f"{MODEL_IDENTIFIER}.so"
        compile_binary(root / "sources", binary, fmi_version, cc)
        (root / "modelDescription.xml").write_text(
            model_description(vars_, fmi_version, token, params, desc)
        )
        (root / "documentation").mkdir()
        (root / "documentation" / "index.html").write_text(
            documentation_html(vars_, fmi_version, token, params)
        )
        tmp_fmu = Path(tmp) / "out.fmu"
        with zipfile.ZipFile(tmp_fmu, "w", zipfile.ZIP_DEFLATED) as zf:
            for path in sorted(root.rglob("*")):
                if path.is_file():
                    info = zipfile.ZipInfo(path.relative_to(root).as_posix(), (1980, 1, 1, 0, 0, 0))
                    info.compress_type = zipfile.ZIP_DEFLATED
                    info.external_attr = 0o644 << 16
                    zf.writestr(info, path.read_bytes())
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(tmp_fmu), out)
    return out


def build_driver(directory, cc: str = "gcc") -> Path:
    """Compile the C driver (``fmu_driver``: dlopen, no Python) into ``directory``."""
    if shutil.which(cc) is None:
        raise RuntimeError(f"C compiler {cc!r} not found (install gcc)")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    exe = d / "fmu_driver"
    cmd = [cc, "-std=c99", "-O2", "-g", "-Wall", "-Wextra", "-Werror", f"-I{fmi_headers_dir()}",
           "-o", str(exe), str(c_file(DRIVER_SOURCE)), "-ldl", "-lm"]  # fmt: skip
    _run(cmd, "C driver build")
    return exe
