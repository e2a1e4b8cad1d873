"""Everything the exports generate: C headers, ctypes structures, FMI XML, documentation.

All of it comes from the one description of :mod:`grasprom.export.variables` and from the
Python objects (surrogate, chain, parameters), so nothing is copied by hand between Python, C,
the FMU and the Arduino export:

* ``grasp_tables.h`` -- surrogate curves and chain constants as exact hexadecimal
  floating-point literals (:func:`tables_source`);
* ``grasp_fmu_config.h`` -- value references, start/min/max, unit factors, the Prony term
  count, the field's node count and the SI <-> core conversions of ``fmu_model.c``
  (:func:`config_header`);
* :class:`GcParams` / :class:`GcOutput` -- ctypes mirrors of ``gc_params_t`` /
  ``gc_output_t`` made from :data:`~grasprom.export.variables.PARAMS_FIELDS` /
  :data:`~grasprom.export.variables.OUTPUT_FIELDS`;
* ``modelDescription.xml`` (FMI 2 or 3), ``sources/buildDescription.xml`` (FMI 3) and
  ``documentation/index.html`` (:func:`model_description`, :func:`build_description`,
  :func:`documentation_html`).

The C files of the exports (:data:`CORE_SOURCES`, :data:`MODEL_SOURCES`, :data:`WRAPPER`) are
listed here once too.
"""

from __future__ import annotations

import ctypes
import html
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from xml.sax.saxutils import quoteattr

from grasprom import __version__
from grasprom.chain import kinematics as kin
from grasprom.control import ControllerParams
from grasprom.control.field import FIELD_POINTS
from grasprom.export.variables import (
    ENCODER_COUNTS_MIN,
    OUTPUT_FIELDS,
    PARAMS_FIELDS,
    PRONY_MAX,
    UNITS,
    CField,
    EnumType,
    Variable,
    covered_materials,
    enum_types,
)
from grasprom.fe import MATERIAL_NAMES
from grasprom.surrogate import Surrogate

# ---------------------------------------------------------------------------------- sources
MODEL_IDENTIFIER = "GraspController"
"""Model identifier: name of the binary and of the FMI model."""
FMU_LICENSE = "MIT (see LICENSE of grasprom)"
"""``license`` of the modelDescription: the project's licence, which the FMU's code carries."""

FMI_VERSIONS = (2, 3)

CORE_SOURCES = ("grasp_core.c", "grasp_core.h")
"""The one C core (FMU, host tests, Arduino with ``GC_TABULATED``)."""
MODEL_SOURCES = ("fmu_model.c", "fmu_model.h")
WRAPPER = {2: "fmi2_wrapper.c", 3: "fmi3_wrapper.c"}


def fmu_c_files(fmi_version: int) -> tuple[str, ...]:
    """The C files compiled into the FMU binary (also listed in its XML descriptions).

    Parameters
    ----------
    fmi_version : int
        2 or 3.

    Returns
    -------
    tuple of str
    """
    return (CORE_SOURCES[0], MODEL_SOURCES[0], WRAPPER[fmi_version])


# ---------------------------------------------------------------------------------- literals
def c_double(x: float) -> str:
    """Exact C literal of a double: hexadecimal floating point, or ``(-)INFINITY``.

    Parameters
    ----------
    x : float

    Returns
    -------
    str
    """
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return float(x).hex()


def c_decimal(x: float) -> str:
    """Shortest round-trip decimal literal of a double.

    For sources also compiled by avr-gcc (32-bit ``double``): the decimal literal is rounded
    once to float there, a hexadecimal literal of the 64-bit value would be rounded twice.

    Parameters
    ----------
    x : float

    Returns
    -------
    str
    """
    return repr(float(x))


def c_array(name: str, values: Iterable[float], ctype: str = "double") -> str:
    """A ``static const`` C array marked ``GC_TABLE`` (PROGMEM on the AVR), four per line.

    Parameters
    ----------
    name : str
    values : iterable of float
    ctype : str
        ``double`` (exact hex literals) or an integer type.

    Returns
    -------
    str
    """
    vals = list(values)
    body = ",\n    ".join(
        ", ".join(c_double(v) if ctype == "double" else str(int(v)) for v in vals[i : i + 4])
        for i in range(0, len(vals), 4)
    )
    decl = f"static const {ctype} {name}[{max(len(vals), 1)}] GC_TABLE"
    return f"{decl} = {{\n    {body or '0'}\n}};\n"


# ---------------------------------------------------------------------------------- ctypes
_CTYPES = {"double": ctypes.c_double, "int": ctypes.c_int}


def ctypes_fields(fields: Sequence[CField]) -> list[tuple[str, type]]:
    """``_fields_`` of a ctypes structure mirroring a C structure of ``grasp_core.h``.

    Parameters
    ----------
    fields : sequence of CField

    Returns
    -------
    list of (str, ctypes type)
    """
    out = []
    for f in fields:
        t = _CTYPES[f.ctype]
        out.append((f.name, t * f.length if f.length > 1 else t))
    return out


class GcParams(ctypes.Structure):
    """``gc_params_t`` (core units: mm, N/mm, MPa, deg, s), from :data:`PARAMS_FIELDS`."""

    _fields_ = ctypes_fields(PARAMS_FIELDS)


class GcOutput(ctypes.Structure):
    """``gc_output_t`` (core units: N m, N, mm, deg, rad/s), from :data:`OUTPUT_FIELDS`."""

    _fields_ = ctypes_fields(OUTPUT_FIELDS)


# ---------------------------------------------------------------------------------- tables
def chain_constants(chain: kin.ChainParams) -> dict[str, float]:
    """Constants of ``gc_chain_t`` (mm, rad, N) for a chain (spring rate is a run-time param)."""
    c = chain.constants
    return {
        "L2": chain.L2_mm,
        "d": chain.offset_d_mm,
        "h": c.h,
        "side": c.side,
        "L3": chain.L3_mm,
        "gap_closed": chain.gap_closed_mm,
        "gap_per_xc": c.gap_per_xc,
        "xc_closed": c.xc_closed,
        "xc_open": c.xc_open,
        "stroke_sign": c.stroke_sign,
        "spring_preload": chain.spring_preload_N,
        "theta_lo": math.radians(chain.theta_closed_deg),
        "theta_hi": math.radians(chain.theta_open_deg),
        "theta_lo_deg": float(chain.theta_closed_deg),
        "theta_hi_deg": float(chain.theta_open_deg),
    }


def _material_source(surrogate: Surrogate, mi: int, name: str, aligned: int) -> tuple[str, str]:
    """Arrays of one material and its ``gc_material_t`` initialiser row."""
    tab = surrogate.table(name)
    out, curves = [], []
    for ci, (xs, c0, c1, c2, c3, _x0, _xn) in enumerate(tab.s_curves):
        p = f"gc_{name}_{ci}"
        for suffix, arr in (("x", xs), ("c0", c0), ("c1", c1), ("c2", c2), ("c3", c3)):
            out.append(c_array(f"{p}_{suffix}", arr))
        curves.append(f"{{{len(xs)}, {p}_x, {p}_c0, {p}_c1, {p}_c2, {p}_c3}}")
    out.append(c_array(f"gc_{name}_t", tab.t))
    out.append(c_array(f"gc_{name}_gc", tab.gc))
    out.append(c_array(f"gc_{name}_inv_dt", tab.inv_dt))
    out.append(
        f"static const gc_curve_t gc_{name}_curves[{len(curves)}] GC_TABLE = {{\n    "
        + ",\n    ".join(curves)
        + "\n};\n"
    )
    row = (
        f"    {{{len(curves)}, gc_{name}_t, gc_{name}_gc, gc_{name}_inv_dt, "
        f"gc_{name}_curves, {c_double(tab.D)}, {aligned}}} /* {mi}: {name} */"
    )
    return "\n".join(out), row


def _absent_material_row(mi: int, name: str, aligned: int) -> str:
    """The ``gc_material_t`` row of a material the surrogate does not hold: no curves
    (``gc_check_params`` refuses it)."""
    return (f"    {{0, 0, 0, 0, 0, {c_double(0.0)}, {aligned}}} /* {mi}: {name}, not in this "
            "export's surrogate */")  # fmt: skip


def tables_source(surrogate: Surrogate, chain: kin.ChainParams) -> str:
    """C source of ``grasp_tables.h``: ``GC_MATERIALS[]`` (order mr, nh, le) and ``GC_CHAIN``.

    ``GC_MATERIALS`` is indexed by the material code, the same everywhere (0 mr, 1 nh, 2 le:
    :data:`grasprom.fe.materials.MATERIAL_NAMES`); a material the surrogate does not hold has
    a row without curves (``n_curves`` 0), which ``gc_check_params`` refuses.

    Raises
    ------
    ValueError
        If the surrogate holds none of the materials.
    """
    covered = covered_materials(surrogate)
    aligned = 1 if surrogate.scheme == "aligned" else 0
    out = [
        "/* Generated by grasprom.export.codegen.tables_source -- do not edit.",
        f" * surrogate FE hash {surrogate.fe_hash}, scheme {surrogate.scheme};",
        f" * materials covered: {', '.join(covered)} (GC_MATERIALS is indexed by the material "
        "code; a material not covered has no curves);",
        " * units: gap mm, thickness mm, force N; chain mm, rad, N.",
        " * GC_TABLE: PROGMEM on the AVR (grasp_core.h). */",
        "#ifndef GRASP_TABLES_H",
        "#define GRASP_TABLES_H",
        '#include "grasp_core.h"',
        "#include <math.h>",
        "",
    ]
    mats = []
    for mi, name in enumerate(MATERIAL_NAMES):
        if name not in covered:
            mats.append(_absent_material_row(mi, name, aligned))
            continue
        arrays, row = _material_source(surrogate, mi, name, aligned)
        out.append(arrays)
        mats.append(row)
    out.append(f"#define GC_N_MATERIALS {len(mats)}")
    out.append("static const gc_material_t GC_MATERIALS[GC_N_MATERIALS] GC_TABLE = {")
    out.append(",\n".join(mats))
    out.append("};\n")
    cc = chain_constants(chain)
    out.append("static const gc_chain_t GC_CHAIN = {")
    out.append(",\n".join(f"    {c_double(v)} /* {k} */" for k, v in cc.items()))
    out.append("};\n")
    out.append("#endif")
    return "\n".join(out) + "\n"


def write_tables_header(surrogate: Surrogate, chain: kin.ChainParams, directory) -> Path:
    """Write ``grasp_tables.h`` into ``directory``; returns its path."""
    path = Path(directory) / "grasp_tables.h"
    path.write_text(tables_source(surrogate, chain))
    return path


# ---------------------------------------------------------------------------------- C header
_GF_TYPES = {
    "Real": "GF_REAL",
    "Integer": "GF_INTEGER",
    "Enumeration": "GF_ENUMERATION",
    "Boolean": "GF_BOOLEAN",
}
_GF_CAUSALITY = {
    "independent": "GF_INDEPENDENT",
    "parameter": "GF_PARAMETER",
    "input": "GF_INPUT",
    "output": "GF_OUTPUT",
}


def _unit_factor_macros(vars_: list[Variable]) -> list[str]:
    """``GF_TO_CORE_<name>`` / ``GF_TO_SI_<name>``: SI <-> core unit factors (exact)."""
    lines = []
    for v in vars_:
        s = v.spec
        if s is None or s.core_field is None or s.core_unit is None:
            continue
        if s.causality == "parameter":
            lines.append(
                f"#define GF_TO_CORE_{v.name} {c_double(s.to_core)} /* {s.unit} -> {s.core_unit} */"
            )
        else:
            lines.append(
                f"#define GF_TO_SI_{v.name} {c_double(s.to_si)} /* {s.core_unit} -> {s.unit} */"
            )
    return lines


def _core_params_function(vars_: list[Variable]) -> list[str]:
    """``gf_core_params()``: the ``gc_params_t`` of the SI parameter values."""
    lines = [
        "/* the core parameters (mm, N/mm, MPa, deg) from the SI variables */",
        "static void gf_core_params(const double *v, gc_params_t *p) {",
    ]
    ctype = {f.name: f.ctype for f in PARAMS_FIELDS}
    for v in vars_:
        s = v.spec
        if s is None or s.causality != "parameter" or s.core_field is None:
            continue
        x = f"v[GF_VR_{v.name}]"
        if s.type == "Boolean":
            x = f"{x} != 0.0"
        elif ctype[s.core_field.split("[")[0]] == "int":
            x = f"(int){x}"
        elif s.core_unit is not None:
            x = f"{x} * GF_TO_CORE_{v.name}"
        lines.append(f"    p->{s.core_field} = {x};")
    return lines + ["}"]


def _write_outputs_function(vars_: list[Variable]) -> list[str]:
    """``gf_write_outputs()``: the SI output variables of a ``gc_output_t``."""
    lines = [
        "/* the SI output variables from the core outputs */",
        "static void gf_write_outputs(const gc_output_t *o, double *v) {",
    ]
    for v in vars_:
        s = v.spec
        if s is None or s.causality != "output":
            continue
        x = f"o->{s.core_field}"
        if s.type == "Boolean":
            x = f"{x} != 0"
        elif s.core_unit is not None:
            x = f"{x} * GF_TO_SI_{v.name}"
        lines.append(f"    v[GF_VR_{v.name}] = {x};")
    return lines + ["}"]


def _enum_items(v: Variable) -> tuple[int, str]:
    """``gf_var_t.items`` and ``items_text`` of a variable: for an Enumeration, the bit mask of
    its item values and the C string naming them (a value in [min, max] that is not an item is
    refused by the FMU); 0 and ``NULL`` otherwise."""
    t = v.enum
    if t is None:
        return 0, "NULL"
    if max(t.item_values) > 31 or min(t.item_values) < 0:
        raise ValueError(f"enumeration {t.name}: item values must be in 0 .. 31")
    text = f"{t.name} items {t.listing()}" + (f", {t.scope}" if t.scope else "")
    return sum(1 << x for x in t.item_values), c_string(text)


def c_string(text: str) -> str:
    """A C string literal of an ASCII ``text`` (quotes and backslashes escaped)."""
    if not text.isascii():
        raise ValueError(f"C string must be ASCII: {text!r}")
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def config_header(vars_: list[Variable], token: str) -> str:
    """C source of ``grasp_fmu_config.h`` (value references, the variable table, unit factors
    and the SI <-> core conversions of ``fmu_model.c``)."""
    lines = [
        "/* Generated by grasprom.export.codegen.config_header -- do not edit.  Values SI. */",
        "#ifndef GRASP_FMU_CONFIG_H",
        "#define GRASP_FMU_CONFIG_H",
        "#include <math.h>",
        '#include "fmu_model.h"',
        "",
        f'#define GF_MODEL_IDENTIFIER "{MODEL_IDENTIFIER}"',
        f'#define GF_TOKEN "{token}"',
        f"#define GF_N_VARS {len(vars_)}",
        f"#define GF_PRONY_MAX {PRONY_MAX} /* Prony terms of the variables (GC_PRONY_MAX) */",
        f"#define GF_FIELD_POINTS {FIELD_POINTS} /* clipped field nodes (GC_FIELD_POINTS) */",
        f"#define GF_ENCODER_COUNTS_MIN {ENCODER_COUNTS_MIN} /* encoder_counts: 0 or >= this */",
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
        mask, text = _enum_items(v)
        rows.append(
            f'    {{"{v.name}", {_GF_TYPES[v.type]}, {_GF_CAUSALITY[v.causality]}, '
            f"{c_double(start)}, {c_double(lo)}, {c_double(hi)}, "
            f"{int(v.variability == 'tunable')}, {mask}u, {text}}}"
        )
    lines.append(",\n".join(rows))
    lines += ["};", ""]
    lines += ["#if GF_PRONY_MAX != GC_PRONY_MAX", '#error "GF_PRONY_MAX != GC_PRONY_MAX"', "#endif"]
    lines += [
        "#if GF_FIELD_POINTS != GC_FIELD_POINTS",
        '#error "GF_FIELD_POINTS != GC_FIELD_POINTS"',
        "#endif",
    ]
    tunable = [v.spec.core_field for v in vars_ if v.variability == "tunable"]
    copy = " ".join(f"(dst)->{f} = (src)->{f};" for f in tunable)
    lines += ["/* the core fields of the tunable parameters (set in step mode) */",
              f"#define GF_COPY_TUNABLE(dst, src) do {{ {copy} }} while (0)", ""]  # fmt: skip
    lines += _unit_factor_macros(vars_)
    lines += _core_params_function(vars_)
    lines += _write_outputs_function(vars_)
    lines += ["#endif", "", "#endif", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- XML
FMI3_TYPE = {"Real": "Float64", "Integer": "Int32", "Enumeration": "Enumeration",
             "Boolean": "Boolean"}  # fmt: skip
"""FMI 3 element of each variable type (an Enumeration is read with fmi3Get/SetInt64; in
FMI 2 with fmi2Get/SetInteger)."""

LOG_CATEGORIES = (
    ("logEvents", "informational messages (with debug logging on)"),
    ("logStatusWarning", "clamped values"),
    ("logStatusError", "rejected calls and values, wrong-state calls"),
)


def xml_number(x: float | int, type_: str) -> str:
    """A start/min/max value as written in the XML (and the documentation)."""
    if type_ == "Boolean":
        return "true" if x else "false"
    if type_ in ("Integer", "Enumeration"):
        return str(int(x))
    return repr(float(x))


def units_xml(indent: str = "  ") -> list[str]:
    """``<UnitDefinitions>`` of :data:`UNITS` (same in FMI 2 and 3)."""
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


def _type_attrs(v: Variable) -> str:
    attrs = [f'declaredType="{v.enum.name}"'] if v.enum is not None else []
    if v.unit:
        attrs.append(f'unit="{v.unit}"')
    if v.display_unit:
        attrs.append(f'displayUnit="{v.display_unit}"')
    if v.start is not None:
        attrs.append(f'start="{xml_number(v.start, v.type)}"')
    if v.type != "Boolean":
        if v.min is not None:
            attrs.append(f'min="{xml_number(v.min, v.type)}"')
        if v.max is not None:
            attrs.append(f'max="{xml_number(v.max, v.type)}"')
    return " ".join(attrs)


def enum_types_xml(types: list[EnumType], fmi_version: int, indent: str = "  ") -> list[str]:
    """``<TypeDefinitions>`` of the enumeration types (empty list without any).

    FMI 2: ``<SimpleType name=...><Enumeration><Item .../>``; FMI 3: ``<EnumerationType
    name=...><Item .../>``; the item values are :attr:`EnumType.item_values` (a subset keeps
    the values of the full enumeration).
    """
    if not types:
        return []
    lines = [f"{indent}<TypeDefinitions>"]
    for t in types:
        tag = "SimpleType" if fmi_version == 2 else "EnumerationType"
        lines.append(f'{indent}  <{tag} name="{t.name}" description={quoteattr(t.description)}>')
        pad = indent + ("      " if fmi_version == 2 else "    ")
        if fmi_version == 2:
            lines.append(f"{indent}    <Enumeration>")
        lines += [f'{pad}<Item name="{n}" value="{i}" description={quoteattr(d)}/>'
                  for i, (n, d) in zip(t.item_values, t.items)]  # fmt: skip
        if fmi_version == 2:
            lines.append(f"{indent}    </Enumeration>")
        lines.append(f"{indent}  </{tag}>")
    lines.append(f"{indent}</TypeDefinitions>")
    return lines


def generation_date_and_time() -> str:
    """``generationDateAndTime`` (UTC, ISO 8601): ``SOURCE_DATE_EPOCH`` if set, else now.

    ``SOURCE_DATE_EPOCH`` (reproducible-builds.org) makes two exports byte-identical.
    """
    import datetime as dt
    import os

    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    when = (dt.datetime.fromtimestamp(int(epoch), dt.timezone.utc) if epoch
            else dt.datetime.now(dt.timezone.utc))  # fmt: skip
    return when.replace(microsecond=0).strftime("%Y-%m-%dT%H:%M:%SZ")


def _md_head(fmi_version: int, token: str, description: str, step: float) -> list[str]:
    """Root element and ``<CoSimulation>`` of the modelDescription."""
    head = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<fmiModelDescription",
        f'  fmiVersion="{fmi_version}.0"',
        f'  modelName="{MODEL_IDENTIFIER}"',
        (f'  guid="{token}"' if fmi_version == 2 else f'  instantiationToken="{token}"'),
        f"  description={quoteattr(description)}",
        '  author="grasprom"',
        f'  version="{__version__}"',
        f'  license="{FMU_LICENSE}"',
        f'  generationTool="grasprom {__version__}"',
        f'  generationDateAndTime="{generation_date_and_time()}"',
        '  variableNamingConvention="flat"',
    ]
    if fmi_version == 2:
        head.append('  numberOfEventIndicators="0">')
        sources = "".join(f'\n      <File name="{f}"/>' for f in fmu_c_files(2))
        return head + [
            f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}"',
            '    canHandleVariableCommunicationStepSize="true"',
            '    canInterpolateInputs="false" maxOutputDerivativeOrder="0"',
            '    canRunAsynchronuously="false" canBeInstantiatedOnlyOncePerProcess="false"',
            '    canNotUseMemoryManagementFunctions="false" canGetAndSetFMUstate="true"',
            '    canSerializeFMUstate="true" providesDirectionalDerivative="false">',
            f"    <SourceFiles>{sources}\n    </SourceFiles>",
            "  </CoSimulation>",
        ]
    head[-1] += ">"
    return head + [
        f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}"',
        '    canHandleVariableCommunicationStepSize="true" hasEventMode="false"',
        f'    fixedInternalStepSize="{step!r}"',
        '    canBeInstantiatedOnlyOncePerProcess="false" canGetAndSetFMUState="true"',
        '    canSerializeFMUState="true" providesDirectionalDerivatives="false"',
        '    providesAdjointDerivatives="false" canReturnEarlyAfterIntermediateUpdate="false"',
        '    providesIntermediateUpdate="false" maxOutputDerivativeOrder="0"/>',
    ]


def _md_variables(vars_: list[Variable], fmi_version: int) -> list[str]:
    """``<ModelVariables>``."""
    lines = ["  <ModelVariables>"]
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
            lines.append(f"    <{FMI3_TYPE[v.type]} {common}{' ' + ta if ta else ''}/>")
    lines.append("  </ModelVariables>")
    return lines


def _md_structure(vars_: list[Variable], fmi_version: int) -> list[str]:
    """``<ModelStructure>``: the outputs, no direct feedthrough."""
    lines = ["  <ModelStructure>"]
    outputs = [v for v in vars_ if v.causality == "output"]
    if fmi_version == 2:
        lines.append("    <Outputs>")
        # index: 1-based position in ModelVariables (= vr + 1); no direct feedthrough
        lines += [f'      <Unknown index="{v.vr + 1}" dependencies=""/>' for v in outputs]
        lines.append("    </Outputs>")
    else:
        lines += [f'    <Output valueReference="{v.vr}" dependencies=""/>' for v in outputs]
    lines.append("  </ModelStructure>")
    return lines


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
    lines = _md_head(fmi_version, token, description, step) + units_xml()
    lines += enum_types_xml(enum_types(vars_), fmi_version)
    lines.append("  <LogCategories>")
    lines += [f'    <Category name="{n}" description="{d}"/>' for n, d in LOG_CATEGORIES]
    lines.append("  </LogCategories>")
    lines.append(f'  <DefaultExperiment startTime="0.0" stopTime="{stop!r}" stepSize="{step!r}"/>')
    lines += _md_variables(vars_, fmi_version)
    lines += _md_structure(vars_, fmi_version)
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def build_description() -> str:
    """``sources/buildDescription.xml`` (FMI 3)."""
    files = "\n".join(f'      <SourceFile name="{f}"/>' for f in fmu_c_files(3))
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
def _doc_rows(vars_: list[Variable], fmi_version: int) -> str:
    """Rows of the variable table of the documentation."""

    def cell(x) -> str:
        return "" if x is None else html.escape(str(x))

    def fmt(x, type_: str) -> str:
        return "" if x is None else xml_number(x, type_)

    rows = []
    for v in vars_:
        t = v.type if fmi_version == 2 else FMI3_TYPE[v.type]
        if v.enum is not None:
            t = f"{t} ({v.enum.name})"
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
    return "\n".join(rows)


_DOC_EQUATIONS = """<h2>Equations (one controller step, period T)</h2>
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
parameters, Integer parameters outside [min, max], Enumeration values that are not one of
the type's items here (a <code>material</code> the FMU's FE sweep did not have), a step size
that is not a multiple of
<code>sample_time</code>, a communication point that does not match the FMU time: rejected
with <em>Error</em> and a logged message; nothing is changed and the instance stays usable.</li>
<li>Finite Real parameters outside [min, max]: clamped, <em>Warning</em>. A thickness outside
the tabulated range of the chosen material is clamped at ExitInitializationMode
(<em>Warning</em>); inconsistent parameters (cut-off above Nyquist, diameter &le; 2 &times;
thickness) make ExitInitializationMode return <em>Error</em>.</li>
<li>Inputs outside [min, max], infinite or NaN: accepted with <em>Warning</em> (<code>theta</code>
within 1e-9 rad of an end stop counts as inside: an importer interpolating an input held at the
stop lands an ulp outside it); the controller
clamps <code>theta</code> to the end stops (NaN holds the last valid angle); <code>theta_dot</code>
is clamped (NaN &rarr; 0).</li>
<li>Parameters are <code>fixed</code> (set them before ExitInitializationMode, or after Reset)
except the <code>tunable</code> ones (variability column), which may also change between
steps.</li>
</ul>
"""
"""The fixed part of the documentation: equations, rendering of the effects, status policy."""


def _doc_clipped() -> str:
    """The documentation's section on the clipped rendering (``rendering`` = 1)."""
    return f"""<h2>Clipped rendering (<code>rendering</code> = 1)</h2>
<p>Instead of the virtual coupling (step 4), the rendered jaw force is interpolated linearly at
the linkage angle in a table of {FIELD_POINTS} nodes over the angle range, built
at ExitInitializationMode: the static handle force of the tissue (behind the jaw compliance,
and of the return spring when rendered), Fi<sub>s</sub> = F(g) dg/d&theta; / L<sub>3</sub> + S,
tracked from the open end with a slope of at most K<sub>g</sub> = <code>stiffness_limit</code> /
(L<sub>3</sub> (1 + &Sigma; g<sub>i</sub>)) per rad, the stiffest passive wall; the table holds the
jaw force of the track, (Fi<sub>r</sub> &minus; S) L<sub>3</sub> / (dg/d&theta;).
<code>coupling_active</code> reports where the limit acts; <code>force_tissue</code> stays
F(g). The Prony terms, the chain, friction, damping and saturation follow as above.</p>
"""


def _doc_observer() -> str:
    """The documentation's section on the passivity observer (``passivity_observer``)."""
    return """<h2>Passivity observer (<code>passivity_observer</code>)</h2>
<p>With the clipped rendering only (the FMU refuses it with the coupling at
ExitInitializationMode): the field is built with <code>stiffness_limit</code> &times;
<code>observer_stiffness_factor</code>, and a time-domain passivity observer / controller
(Hannaford &amp; Ryu 2002; reference energy: Ryu et al. 2005) keeps the handle port passive.
Each step, W &larr; W + (Fh<sub>k&minus;1&minus;d</sub> &minus; (Fs<sub>k&minus;1</sub> +
Fs<sub>k</sub>)/2) L<sub>3</sub> (&theta;<sub>k</sub> &minus; &theta;<sub>k&minus;1</sub>) (J):
Fh the saturated handle force of the step whose torque drove the interval (d =
<code>observer_delay</code>), Fs the static handle force (field, Prony terms, spring). If W minus
the dissipation planned in the last d steps is positive and the velocity v of the damping is not
0, the damping &alpha; = min(W / (T v<sup>2</sup>), <code>observer_max_damping</code>) adds
&minus;&alpha; v / L<sub>3</sub> to the handle force before the saturation.</p>
"""


def _doc_enums(vars_: list[Variable], fmi_version: int) -> str:
    """The enumeration types with their items and the variables that use them."""
    access = ("fmi2GetInteger / fmi2SetInteger" if fmi_version == 2
              else "fmi3GetInt64 / fmi3SetInt64")  # fmt: skip
    parts = []
    for t in enum_types(vars_):
        users = ", ".join(f"<code>{v.name}</code>" for v in vars_ if v.enum == t)
        items = "".join(f"<li>{i} <code>{html.escape(n)}</code>: {html.escape(d)}</li>"
                        for i, (n, d) in zip(t.item_values, t.items))  # fmt: skip
        note = (f"<p>Only these: {html.escape(t.scope)}; any other value is refused with "
                "<em>Error</em>.</p>" if t.scope else "")  # fmt: skip
        parts.append(f"<p><code>{t.name}</code> ({html.escape(t.description)}; {users}; "
                     f"read and written with {access}):</p><ul>{items}</ul>{note}")  # fmt: skip
    return "\n".join(parts)


def _doc_platforms(platforms: Sequence[tuple[str, str]]) -> str:
    """The binaries of the FMU (folder, what it needs) and the sources."""
    rows = "".join(f"<li><code>binaries/{d}</code>: {html.escape(n)}</li>" for d, n in platforms)
    return (f"<ul>{rows}<li><code>sources/</code>: the C sources (C99, libm) to build for any "
            "other platform, e.g. <code>fmpy compile</code>.</li></ul>")  # fmt: skip


def documentation_html(
    vars_: list[Variable],
    fmi_version: int,
    token: str,
    params: ControllerParams,
    platforms: Sequence[tuple[str, str]] = (),
) -> str:
    """``documentation/index.html``: variables, enumerations, platforms, equations, timing and
    status policy.

    Parameters
    ----------
    vars_ : list of Variable
    fmi_version : int
    token : str
        GUID / instantiation token.
    params : ControllerParams
        Start values (sample time).
    platforms : sequence of (str, str)
        Binary folders in the FMU and what each needs to load.
    """
    mat = next((v.enum for v in vars_ if v.name == "material" and v.enum is not None), None)
    mats = ", ".join(f"{i} = {m}" for i, m in zip(mat.item_values, mat.names)) if mat else ""
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
communication point). After ExitInitializationMode the outputs are already those of the
controller at the start angle (no jump at t = 0).</p>

<h2>Enumerations</h2>
{_doc_enums(vars_, fmi_version)}

<h2>Platforms</h2>
{_doc_platforms(platforms)}

{_DOC_EQUATIONS}
{_doc_clipped()}
{_doc_observer()}
<h2>Variables (SI units)</h2>
<table><tr><th>name</th><th>vr</th><th>type</th><th>causality</th><th>variability</th>
<th>unit</th><th>display</th><th>start</th><th>min</th><th>max</th><th>description</th></tr>
{_doc_rows(vars_, fmi_version)}
</table>
</body></html>
"""
