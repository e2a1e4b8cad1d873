"""The one interface description agrees with the C headers, the ctypes mirrors and the XML."""

from __future__ import annotations

import ctypes
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET

import pytest

from grasprom.control import MAX_PRONY_TERMS, ControllerParams
from grasprom.control.field import COMPLIANCE_BISECTIONS, FIELD_POINTS
from grasprom.control.params import OBSERVER_DELAY_MAX, RENDERINGS
from grasprom.export import OUTPUT_COLUMNS
from grasprom.export.codegen import (
    GcOutput,
    GcParams,
    config_header,
    model_description,
)
from grasprom.export.variables import (
    FLAG_NAMES,
    OUTPUT_FIELDS,
    PARAMS_FIELDS,
    PRONY_MAX,
    RENDERING_CODES,
    SPECS,
    UNITS,
    variables,
)
from grasprom.paths import c_dir, c_file


def _layout_program(structs: dict[str, type]) -> str:
    """C source printing ``sizeof`` and every field's ``offsetof`` of the core structures."""
    lines = ['#include <stddef.h>', '#include <stdio.h>', '#include "grasp_core.h"',
             "int main(void) {"]  # fmt: skip
    for cname, struct in structs.items():
        lines.append(f'    printf("{cname} %zu\\n", sizeof({cname}));')
        for name, _ in struct._fields_:
            lines.append(f'    printf("{cname}.{name} %zu\\n", offsetof({cname}, {name}));')
    lines.append('    printf("GC_PRONY_MAX %d\\n", GC_PRONY_MAX);')
    for name in ("GC_FIELD_POINTS", "GC_FIELD_N", "GC_RENDER_COUPLING", "GC_RENDER_CLIPPED"):
        lines.append(f'    printf("{name} %d\\n", {name});')
    lines += ["    return 0;", "}"]
    return "\n".join(lines) + "\n"


def test_ctypes_structs_match_the_c_structs(tmp_path):
    """sizeof / offsetof of gc_params_t and gc_output_t (gcc) = the generated ctypes mirrors."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc not found")
    structs = {"gc_params_t": GcParams, "gc_output_t": GcOutput}
    src = tmp_path / "layout.c"
    src.write_text(_layout_program(structs))
    exe = tmp_path / "layout"
    subprocess.run(["gcc", "-std=c99", "-Wall", "-Werror", f"-I{c_dir() / 'include'}", "-o",
                    str(exe), str(src)], check=True)  # fmt: skip
    got = dict(line.rsplit(" ", 1) for line in subprocess.check_output([str(exe)], text=True)
               .splitlines())  # fmt: skip
    for cname, struct in structs.items():
        assert int(got[cname]) == ctypes.sizeof(struct), cname
        for name, _ in struct._fields_:
            assert int(got[f"{cname}.{name}"]) == getattr(struct, name).offset, (cname, name)
    assert int(got["GC_PRONY_MAX"]) == MAX_PRONY_TERMS
    assert int(got["GC_FIELD_POINTS"]) == FIELD_POINTS == int(got["GC_FIELD_N"])  # host: table
    assert int(got["GC_RENDER_COUPLING"]) == RENDERING_CODES["coupling"] == 0
    assert int(got["GC_RENDER_CLIPPED"]) == RENDERING_CODES["clipped"] == 1


def test_prony_count_agrees_everywhere(surrogate):
    """Python's MAX_PRONY_TERMS is the Prony count of the C headers, the structs and the FMU."""
    assert PRONY_MAX == MAX_PRONY_TERMS
    header = c_file("grasp_core.h").read_text()
    assert int(re.search(r"#define GC_PRONY_MAX (\d+)", header).group(1)) == MAX_PRONY_TERMS
    for f in ("prony_g", "prony_tau"):
        assert next(x for x in PARAMS_FIELDS if x.name == f).length == MAX_PRONY_TERMS
        assert getattr(GcParams, f).size == MAX_PRONY_TERMS * ctypes.sizeof(ctypes.c_double)
    names = [v.name for v in variables(ControllerParams(), surrogate)]
    for prefix in ("prony_g_", "prony_tau_"):
        assert [n for n in names if n.startswith(prefix)] == [
            f"{prefix}{i + 1}" for i in range(MAX_PRONY_TERMS)
        ]
    # the tabulated step unrolls one term per GF_PRONY_TERM(i)
    core = c_file("grasp_core.c").read_text()
    unrolled = sorted({int(i) for i in re.findall(r"GF_PRONY_TERM\((\d)\)\s*$", core, re.M)})
    assert unrolled == list(range(MAX_PRONY_TERMS))
    cfg = config_header(variables(ControllerParams(), surrogate), "{token}")
    assert f"#define GF_PRONY_MAX {MAX_PRONY_TERMS}" in cfg


def test_flag_names_agree_everywhere(surrogate):
    """Flag names and bits: Python, gc_output_t, gf_output_t.flags bits, FMU outputs, XML."""
    header = c_file("grasp_core.h").read_text()
    for bit, name in enumerate(FLAG_NAMES):
        m = re.search(rf"#define GF_{name.upper()} 0x([0-9a-fA-F]+)u", header)
        assert m and int(m.group(1), 16) == 1 << bit, name
    int_fields = [f.name for f in OUTPUT_FIELDS if f.ctype == "int"]
    assert int_fields == list(FLAG_NAMES)
    bool_outputs = [n for n, (_, factor) in OUTPUT_COLUMNS.items() if factor is None]
    assert bool_outputs == list(FLAG_NAMES)
    md = model_description(variables(ControllerParams(), surrogate), 2, "{t}", ControllerParams(),
                           "d")  # fmt: skip
    root = ET.fromstring(md)
    xml_bools = [
        sv.get("name")
        for sv in root.iter("ScalarVariable")
        if sv.get("causality") == "output" and sv.find("Boolean") is not None
    ]
    assert xml_bools == list(FLAG_NAMES)


def test_every_core_field_is_mapped_once():
    """Every gc_params_t element is set by exactly one FMU parameter, every output field used
    by the FMU exists, and the unit factors are exact reciprocals."""
    elements = []
    for f in PARAMS_FIELDS:
        elements += [f.name] if f.length == 1 else [f"{f.name}[{i}]" for i in range(f.length)]
    mapped = [s.core_field for s in SPECS if s.causality == "parameter" and s.core_field]
    assert sorted(mapped) == sorted(elements)
    out_fields = {f.name for f in OUTPUT_FIELDS}
    assert all(s.core_field in out_fields for s in SPECS if s.causality == "output")
    for s in SPECS:
        if s.core_unit is not None:
            assert s.core_unit in [d for d, _ in UNITS[s.unit][1]], s.name
            assert s.to_si * s.to_core == 1.0 and 1.0 / s.to_si == s.to_core, s.name


def test_fmu_model_uses_the_generated_conversions():
    """fmu_model.c has no unit literals of its own: it calls the generated conversions."""
    src = c_file("fmu_model.c").read_text()
    assert "gf_core_params(" in src and "gf_write_outputs(" in src
    assert not re.search(r"\* 1e-?[36]\b|180\.0 / 3\.14", src)


# the value references of the FMU before the clipped rendering (issue 13): they stay as they are
VARIABLES_BEFORE_RENDERING = (
    "time theta theta_dot thickness material spring_k damping velocity_cutoff pulley_radius "
    "torque_limit sample_time coupling_stiffness force_warning pressure_warning jaw_length "
    "diameter tissue_scale jaw_compliance backlash friction_coulomb friction_load_coefficient "
    "friction_viscous friction_velocity_threshold prony_g_1 prony_g_2 prony_g_3 prony_g_4 "
    "prony_tau_1 prony_tau_2 prony_tau_3 prony_tau_4 encoder_counts render_spring "
    "use_theta_dot torque force_handle force_jaw force_tissue gap velocity contact "
    "tissue_warning coupling_active saturated theta_clamped"
).split()


def test_field_constants_agree_everywhere(surrogate):
    """FIELD_POINTS and the bisection count of Python are the C header's; the FMU config checks
    its node count against the core's; the rendering codes follow RENDERINGS."""
    header = c_file("grasp_core.h").read_text()
    assert int(re.search(r"#define GC_FIELD_POINTS (\d+)", header).group(1)) == FIELD_POINTS
    bis = re.search(r"#define GC_COMPLIANCE_BISECTIONS (\d+)", header)
    assert int(bis.group(1)) == COMPLIANCE_BISECTIONS
    cfg = config_header(variables(ControllerParams(), surrogate), "{token}")
    assert f"#define GF_FIELD_POINTS {FIELD_POINTS}" in cfg
    assert "#if GF_FIELD_POINTS != GC_FIELD_POINTS" in cfg
    assert list(RENDERING_CODES) == list(RENDERINGS) == ["coupling", "clipped"]
    assert list(RENDERING_CODES.values()) == [0, 1]
    # the field table is a compile-time option, off on the AVR (2 KB of RAM)
    assert re.search(r"#if defined\(__AVR__\)\s*#define GC_FIELD_N 0", header)


def test_rendering_parameters_are_appended_and_mapped(surrogate):
    """rendering (Integer 0/1) and stiffness_limit (Real, N.m/rad) are FMU parameters after
    every existing variable (whose value references are unchanged), generated into the XML,
    the config header and the ctypes structure."""
    for p in (ControllerParams(), ControllerParams(rendering="clipped",
                                                   stiffness_limit_Nm_per_rad=3.5)):  # fmt: skip
        vars_ = {v.name: v for v in variables(p, surrogate)}
        names = list(vars_)
        assert names[: len(VARIABLES_BEFORE_RENDERING)] == VARIABLES_BEFORE_RENDERING
        assert names[len(VARIABLES_BEFORE_RENDERING) :][:2] == ["rendering", "stiffness_limit"]
        r, k = vars_["rendering"], vars_["stiffness_limit"]
        assert (r.type, r.causality, r.variability) == ("Enumeration", "parameter", "fixed")
        assert (r.min, r.max, r.start) == (0, 1, RENDERING_CODES[p.rendering])
        assert "0 coupling, 1 clipped" in r.description
        assert (k.type, k.causality, k.unit, k.display_unit) == ("Real", "parameter", "N.m/rad",
                                                                 None)  # fmt: skip
        assert k.start == p.stiffness_limit_Nm_per_rad and k.min <= k.start <= k.max
        for version in (2, 3):
            root = ET.fromstring(model_description(list(vars_.values()), version, "{t}", p, "d"))
            tag = "ScalarVariable" if version == 2 else "*"
            xml = {e.get("name"): e for e in root.iter(tag) if e.get("valueReference")}
            assert int(xml["rendering"].get("valueReference")) == len(VARIABLES_BEFORE_RENDERING)
            el = xml["rendering"].find("Enumeration") if version == 2 else xml["rendering"]
            assert el.get("declaredType") == "Rendering"
            assert int(el.get("start")) == RENDERING_CODES[p.rendering]
            el = xml["stiffness_limit"].find("Real") if version == 2 else xml["stiffness_limit"]
            assert el.get("unit") == "N.m/rad" and float(el.get("start")) == k.start
        assert 'Unit name="N.m/rad"' in model_description(list(vars_.values()), 2, "{t}", p, "d")
        cfg = config_header(list(vars_.values()), "{token}")
        assert "p->rendering = (int)v[GF_VR_rendering];" in cfg
        assert "p->stiffness_limit = v[GF_VR_stiffness_limit];" in cfg
    assert [f.name for f in PARAMS_FIELDS[-6:-4]] == ["rendering", "stiffness_limit"]
    assert [f.ctype for f in PARAMS_FIELDS[-6:-4]] == ["int", "double"]
    assert GcParams.rendering.size == ctypes.sizeof(ctypes.c_int)


OBSERVER_VARIABLES = [
    "passivity_observer",
    "observer_stiffness_factor",
    "observer_max_damping",
    "observer_delay",
]


def test_observer_parameters_are_appended_and_mapped(surrogate):
    """The passivity observer's parameters follow every existing variable (whose value
    references are unchanged) and are generated into the XML, the config header and ctypes."""
    p = ControllerParams(rendering="clipped", passivity_observer=True,
                         observer_stiffness_factor=4.0, observer_max_damping_Nms_per_rad=0.3,
                         observer_delay_samples=2)  # fmt: skip
    vars_ = {v.name: v for v in variables(p, surrogate)}
    names = list(vars_)
    n0 = len(VARIABLES_BEFORE_RENDERING) + 2
    assert names[:n0] == [*VARIABLES_BEFORE_RENDERING, "rendering", "stiffness_limit"]
    assert names[n0:] == OBSERVER_VARIABLES
    po, f, a, d = (vars_[n] for n in OBSERVER_VARIABLES)
    assert (po.type, po.causality, po.start) == ("Boolean", "parameter", 1)
    assert (f.type, f.unit, f.start, f.min) == ("Real", None, 4.0, 1.0)
    assert (a.type, a.unit, a.start) == ("Real", "N.m.s/rad", 0.3) and a.min > 0
    assert (d.type, d.start, d.min, d.max) == ("Integer", 2, 0, OBSERVER_DELAY_MAX)
    off = {v.name: v for v in variables(ControllerParams(), surrogate)}
    assert off["passivity_observer"].start == 0
    for version in (2, 3):
        root = ET.fromstring(model_description(list(vars_.values()), version, "{t}", p, "d"))
        tag = "ScalarVariable" if version == 2 else "*"
        xml = {e.get("name"): e for e in root.iter(tag) if e.get("valueReference")}
        for i, n in enumerate(OBSERVER_VARIABLES):
            assert int(xml[n].get("valueReference")) == n0 + i
    cfg = config_header(list(vars_.values()), "{token}")
    assert "p->passivity_observer = v[GF_VR_passivity_observer] != 0.0;" in cfg
    assert "p->observer_stiffness_factor = v[GF_VR_observer_stiffness_factor];" in cfg
    assert "p->observer_max_damping = v[GF_VR_observer_max_damping];" in cfg
    assert "p->observer_delay = (int)v[GF_VR_observer_delay];" in cfg
    assert [f.name for f in PARAMS_FIELDS[-4:]] == [
        "passivity_observer", "observer_stiffness_factor", "observer_max_damping",
        "observer_delay",
    ]  # fmt: skip
    assert [f.ctype for f in PARAMS_FIELDS[-4:]] == ["int", "double", "double", "int"]
    header = c_file("grasp_core.h").read_text()
    delay_max = re.search(r"#define GC_OBS_DELAY_MAX (\d+)", header)
    assert int(delay_max.group(1)) == OBSERVER_DELAY_MAX
