"""The one description of the exported interface: FMU variables, C structures, units, flags.

Everything the exports share between Python, C, XML and the Arduino header is declared here
once and generated from here (:mod:`grasprom.export.codegen`):

* :data:`UNITS` -- SI units with their display units; the display factors are also the factors
  from SI to the C core's units (mm, N/mm, MPa, deg, ...), exact reciprocals of the factors to
  SI (tested);
* :data:`PRONY_MAX` -- Prony terms of the C core, :data:`grasprom.control.MAX_PRONY_TERMS`;
* :data:`RENDERING_CODES` -- the C codes of the rendering schemes (``gc_params_t.rendering``);
* :data:`FLAG_NAMES` -- the output flags: ``int`` fields of ``gc_output_t``, bits of
  ``gf_output_t.flags`` (``GF_CONTACT`` = bit 0, ...), Boolean outputs of the FMU;
* :data:`PARAMS_FIELDS` / :data:`OUTPUT_FIELDS` -- the C layout of ``gc_params_t`` /
  ``gc_output_t`` (``grasp_core.h``), mirrored by the generated ctypes structures;
* :data:`SPECS` -- the FMU variables in value-reference order: name, type, causality,
  variability, unit, display unit, the :class:`~grasprom.control.ControllerParams` field and the
  C field they map to (and the core unit, which gives the SI factor), static limits,
  description.  :func:`variables` resolves the start values and the limits that depend on the
  parameters and the surrogate;
* the materials an export covers: those of its surrogate (:func:`covered_materials`, in
  :data:`grasprom.fe.MATERIAL_NAMES` order); the ``Material`` enumeration lists only them with
  their fixed values (0 mr, 1 nh, 2 le: :func:`material_type`), the C tables keep the codes
  (a material not covered has an empty row) and the FMU and the firmware refuse the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from grasprom.chain import kinematics as kin
from grasprom.control import MAX_PRONY_TERMS, PARAMETER_RANGES, ControllerParams
from grasprom.control.params import ENCODER_COUNTS_RANGE, OBSERVER_DELAY_MAX, RENDERINGS
from grasprom.fe import MATERIAL_NAMES
from grasprom.surrogate import Surrogate

# ---------------------------------------------------------------------------------- units
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
    "N.m/rad": ({"kg": 1, "m": 2, "s": -2, "rad": -1}, []),
    "Hz": ({"s": -1}, []),
    "Pa": ({"kg": 1, "m": -1, "s": -2}, [("kPa", 1e-3), ("MPa", 1e-6)]),
    "m/N": ({"kg": -1, "s": 2}, [("mm/N", 1e3)]),
    "N.s/m": ({"kg": 1, "s": -1}, [("N.s/mm", 1e-3)]),
    "m/s": ({"m": 1, "s": -1}, [("mm/s", 1e3)]),
}


def display_factor(unit: str, display_unit: str) -> float:
    """Factor from ``unit`` (SI) to one of its display units: ``display = factor * SI``.

    Parameters
    ----------
    unit : str
        A key of :data:`UNITS`.
    display_unit : str
        One of its display units.

    Returns
    -------
    float
    """
    for name, factor in UNITS[unit][1]:
        if name == display_unit:
            return factor
    raise KeyError(f"unit {unit!r} has no display unit {display_unit!r}")


# ---------------------------------------------------------------------------------- C core
PRONY_MAX = MAX_PRONY_TERMS
"""Prony terms of the C core (``GC_PRONY_MAX``); unused terms have g = 0 (they add exactly 0)."""
PRONY_TAU_PAD = 1.0
"""Time constant (s) of the unused Prony terms (any positive value)."""

RENDERING_CODES: dict[str, int] = {name: i for i, name in enumerate(RENDERINGS)}
"""``gc_params_t.rendering`` of each :data:`grasprom.control.RENDERINGS` scheme: 0 coupling
(``GC_RENDER_COUPLING``), 1 clipped (``GC_RENDER_CLIPPED``)."""


@dataclass(frozen=True)
class EnumType:
    """An FMI enumeration type (FMI 2 ``SimpleType``/``Enumeration``, FMI 3 ``EnumerationType``).

    Parameters
    ----------
    name : str
        Type name (``declaredType`` of its variables).
    description : str
    items : tuple of (str, str)
        (item name, description), in value order.
    values : tuple of int
        The items' values, the codes the C core takes (empty: their positions 0, 1, ...).  A
        subset of a fixed enumeration keeps the values of the full one (:func:`material_type`).
    scope : str
        What the items are (appended to the refusal of a value that is not one, e.g. "the
        materials of the FE sweep this FMU was built from"; empty: nothing).
    """

    name: str
    description: str
    items: tuple[tuple[str, str], ...]
    values: tuple[int, ...] = ()
    scope: str = ""

    @property
    def names(self) -> tuple[str, ...]:
        """Item names in value order."""
        return tuple(n for n, _ in self.items)

    @property
    def item_values(self) -> tuple[int, ...]:
        """The items' values (the codes of the C core), in item order."""
        return self.values or tuple(range(len(self.items)))

    def value_of(self, name: str) -> int:
        """The value (C code) of the item ``name``.

        Raises
        ------
        ValueError
            If it is not an item of this type (the message lists the items).
        """
        if name not in self.names:
            raise ValueError(f"{name!r} is not an item of {self.name} ({self.listing()})")
        return self.item_values[self.names.index(name)]

    def listing(self) -> str:
        """The items as ``"0 mr, 2 le"`` (value and name, in item order)."""
        return ", ".join(f"{v} {n}" for v, n in zip(self.item_values, self.names))


_MATERIAL_ITEMS = {
    "mr": "Mooney-Rivlin, C10 0.085 MPa, C01 0.0565 MPa (Guachi et al. 2020)",
    "nh": "neo-Hookean, small-strain shear modulus of mr (0.283 MPa)",
    "le": "linear elastic E 5.18 MPa (Guachi et al. 2020), large-strain compressible neo-Hookean",
}
_RENDERING_ITEMS = {
    "coupling": "virtual coupling k_c to a proxy on the tissue curve",
    "clipped": "stiffness-clipped field of stiffness_limit, no virtual coupling",
}
MATERIAL_TYPE = EnumType(
    "Material", "tissue material model", tuple((m, _MATERIAL_ITEMS[m]) for m in MATERIAL_NAMES)
)
"""Enumeration of the ``material`` parameter: :data:`grasprom.fe.MATERIAL_NAMES` in order
(values 0 mr, 1 nh, 2 le); an export lists the materials its surrogate covers
(:func:`material_type`)."""


def covered_materials(surrogate: Surrogate) -> tuple[str, ...]:
    """The materials of :data:`grasprom.fe.MATERIAL_NAMES` the surrogate holds, in that order
    (the materials an export covers).

    Parameters
    ----------
    surrogate : Surrogate

    Returns
    -------
    tuple of str

    Raises
    ------
    ValueError
        If it holds none of them.
    """
    out = tuple(m for m in MATERIAL_NAMES if m in surrogate.materials)
    if not out:
        raise ValueError(
            f"the surrogate holds none of the materials {', '.join(MATERIAL_NAMES)} "
            f"(it has {', '.join(surrogate.materials) or 'none'})"
        )
    return out


def material_type(materials: tuple[str, ...] = MATERIAL_NAMES) -> EnumType:
    """The ``Material`` enumeration of an export covering ``materials``.

    Its items are those materials in :data:`grasprom.fe.MATERIAL_NAMES` order with their fixed
    values (``mr`` 0, ``nh`` 1, ``le`` 2, whichever are left out); all of them: exactly
    :data:`MATERIAL_TYPE`.

    Parameters
    ----------
    materials : tuple of str
        Names from :data:`grasprom.fe.MATERIAL_NAMES` (e.g. :func:`covered_materials`).

    Returns
    -------
    EnumType
    """
    unknown = [m for m in materials if m not in MATERIAL_NAMES]
    if unknown or not materials:
        raise ValueError(f"materials must be some of {', '.join(MATERIAL_NAMES)}, got {materials}")
    mats = tuple(m for m in MATERIAL_NAMES if m in materials)
    if mats == MATERIAL_NAMES:
        return MATERIAL_TYPE
    return replace(
        MATERIAL_TYPE,
        items=tuple((m, _MATERIAL_ITEMS[m]) for m in mats),
        values=tuple(MATERIAL_NAMES.index(m) for m in mats),
        scope="the materials of the FE sweep this FMU was built from",
    )


def material_check(params: ControllerParams, surrogate: Surrogate) -> tuple[str, ...]:
    """The materials an export of ``surrogate`` covers; raises if ``params.material`` is not one.

    Parameters
    ----------
    params : ControllerParams
        Its material is the export's start value (FMU) or boot case (Arduino).
    surrogate : Surrogate

    Returns
    -------
    tuple of str
        :func:`covered_materials`.

    Raises
    ------
    ValueError
        If the surrogate does not hold ``params.material`` (the message names what it holds).
    """
    mats = covered_materials(surrogate)
    if params.material not in mats:
        raise ValueError(
            f"the controller's material {params.material!r} is not in the surrogate, which "
            f"covers {', '.join(mats)}: set the material of the parameters to one of these, or "
            f"add it to the FE sweep (grasprom sweep --material {params.material} ...)"
        )
    return mats


RENDERING_TYPE = EnumType(
    "Rendering", "tissue rendering scheme", tuple((r, _RENDERING_ITEMS[r]) for r in RENDERINGS)
)
"""Enumeration of the ``rendering`` parameter: values :data:`RENDERING_CODES`."""

FLAG_NAMES = ("contact", "tissue_warning", "coupling_active", "saturated", "theta_clamped")
"""Output flags in bit order (``GF_CONTACT`` = 0x01, ...; the ``int`` fields of ``gc_output_t``)."""


@dataclass(frozen=True)
class CField:
    """One field of a C structure of ``grasp_core.h``.

    Parameters
    ----------
    name : str
        C field name.
    ctype : str
        ``double`` or ``int``.
    length : int
        Array length (1: a scalar).
    """

    name: str
    ctype: str = "double"
    length: int = 1


PARAMS_FIELDS: tuple[CField, ...] = (
    CField("thickness"),
    CField("material", "int"),
    *(
        CField(n)
        for n in (
            "spring_k",
            "pulley_radius",
            "damping",
            "velocity_cutoff",
            "torque_limit",
            "sample_time",
            "coupling_k",
            "force_warning",
            "pressure_warning",
            "jaw_length",
            "diameter",
            "encoder_counts",
        )
    ),
    CField("render_spring", "int"),
    *(
        CField(n)
        for n in (
            "tissue_scale",
            "jaw_compliance",
            "backlash_deg",
            "friction_coulomb",
            "friction_load",
            "friction_viscous",
            "friction_vthr",
        )
    ),
    CField("prony_g", length=PRONY_MAX),
    CField("prony_tau", length=PRONY_MAX),
    CField("rendering", "int"),
    CField("stiffness_limit"),
    CField("passivity_observer", "int"),
    CField("observer_stiffness_factor"),
    CField("observer_max_damping"),
    CField("observer_delay", "int"),
)
"""Layout of ``gc_params_t`` (``grasp_core.h``), in C order."""

OUTPUT_FIELDS: tuple[CField, ...] = (
    *(
        CField(n)
        for n in (
            "torque",
            "force_handle",
            "force_handle_spring",
            "force_jaw",
            "force_tissue",
            "gap",
            "proxy_gap",
            "theta_deg",
            "velocity",
        )
    ),
    *(CField(n, "int") for n in FLAG_NAMES),
    CField("theta_chain_deg"),
    CField("force_handle_friction"),
)
"""Layout of ``gc_output_t`` (``grasp_core.h``), in C order."""


def prony_padded(params: ControllerParams) -> tuple[list[float], list[float]]:
    """``(g, tau)`` of the controller's Prony series padded to :data:`PRONY_MAX` terms.

    Parameters
    ----------
    params : ControllerParams

    Returns
    -------
    (list of float, list of float)
        Coefficients (1) and time constants (s), :data:`PRONY_MAX` each.
    """
    g, tau = list(params.prony_g), list(params.prony_tau_s)
    if len(g) > PRONY_MAX:
        raise ValueError(f"the C core renders at most {PRONY_MAX} Prony terms, got {len(g)}")
    pad = PRONY_MAX - len(g)
    return g + [0.0] * pad, tau + [PRONY_TAU_PAD] * pad


# ---------------------------------------------------------------------------------- FMU
THETA_DOT_MAX = 1e3
"""Bound of the ``theta_dot`` input (rad/s); larger values are clamped."""
ENCODER_COUNTS_MIN, ENCODER_COUNTS_MAX = ENCODER_COUNTS_RANGE
"""``encoder_counts``: 0 (no quantisation) or in [min, max] (the range ControllerParams
enforces; the FMU refuses 1..min-1 at ExitInitializationMode)."""


@dataclass(frozen=True)
class VarSpec:
    """Static description of one FMU variable (the rows of :data:`SPECS`).

    Parameters
    ----------
    name : str
        FMI variable name (and ``GF_VR_<name>`` in C).
    type : str
        ``Real``, ``Integer``, ``Enumeration`` or ``Boolean``.
    causality, variability : str
    description : str
    unit, display_unit : str or None
        SI unit (a key of :data:`UNITS`) and display unit.
    params_field : str or None
        :class:`ControllerParams` field of a parameter (``prony_g[i]``: padded element).
    core_field : str or None
        Field of ``gc_params_t`` (parameters) or ``gc_output_t`` (outputs) it maps to.
    core_unit : str or None
        Unit of ``params_field`` / ``core_field``, a display unit of ``unit`` (None: SI).
    column : str or None
        Column of :func:`grasprom.control.simulate` an output corresponds to.
    min, max : float or None
        Static limits (SI); limits that depend on the surrogate are set by :func:`variables`.
    enum : EnumType or None
        The declared type of an ``Enumeration``.
    """

    name: str
    type: str
    causality: str
    variability: str
    description: str
    unit: str | None = None
    display_unit: str | None = None
    params_field: str | None = None
    core_field: str | None = None
    core_unit: str | None = None
    column: str | None = None
    min: float | None = None
    max: float | None = None
    enum: EnumType | None = None

    @property
    def to_core(self) -> float:
        """Factor from SI to the core unit (``core = to_core * SI``; 1 without a core unit)."""
        if self.core_unit is None or self.unit is None:
            return 1.0
        return display_factor(self.unit, self.core_unit)

    @property
    def to_si(self) -> float:
        """Factor from the core unit to SI (``SI = to_si * core``), the exact reciprocal."""
        return 1.0 / self.to_core


TUNABLE_PARAMETERS = ("damping", "torque_limit", "force_warning", "pressure_warning")
"""FMU parameters an importer may change between steps (``variability="tunable"``): gains and
thresholds the controller step reads directly, with no state derived from them at
initialisation (the filter pole, the field table, the Prony factors are; those stay fixed)."""


def _param(name, params_field, core_field, unit, display, core_unit, desc) -> VarSpec:
    """A Real, fixed parameter; its [min, max] is :data:`grasprom.control.PARAMETER_RANGES`
    (the range ``ControllerParams`` enforces) in SI."""
    variability = "tunable" if name in TUNABLE_PARAMETERS else "fixed"
    s = VarSpec(name, "Real", "parameter", variability, desc, unit, display, params_field,
                core_field, core_unit, None)  # fmt: skip
    lo, hi = PARAMETER_RANGES[params_field.split("[")[0]]
    return replace(s, min=lo * s.to_si, max=hi * s.to_si)


def _output(name, type_, desc, core_field, column, unit=None, display=None, core_unit=None):
    """A discrete output (limits are set by :func:`variables`)."""
    return VarSpec(name, type_, "output", "discrete", desc, unit, display, None, core_field,
                   core_unit, column)  # fmt: skip


_MATERIALS_DESC = MATERIAL_TYPE.listing()
_RENDERINGS_DESC = ", ".join(f"{i} {m}" for m, i in RENDERING_CODES.items())

_PARAMETERS: tuple[VarSpec, ...] = (
    _param(
        "spring_k",
        "spring_k_N_per_mm",
        "spring_k",
        "N/m",
        "N/mm",
        "N/mm",
        "return-spring rate of the instrument",
    ),
    _param(
        "damping",
        "damping_Nms_per_rad",
        "damping",
        "N.m.s/rad",
        None,
        None,
        "virtual damping at the handle pivot, on the handle velocity",
    ),
    _param(
        "velocity_cutoff",
        "velocity_cutoff_Hz",
        "velocity_cutoff",
        "Hz",
        None,
        None,
        "cutoff of the first-order low-pass filter of the velocity estimate "
        "(must be below the Nyquist frequency 0.5/sample_time)",
    ),
    _param(
        "pulley_radius",
        "pulley_radius_mm",
        "pulley_radius",
        "m",
        "mm",
        "mm",
        "motor pulley radius: torque = cable tension x radius",
    ),
    _param(
        "torque_limit",
        "torque_limit_Nm",
        "torque_limit",
        "N.m",
        None,
        None,
        "motor torque saturation (symmetric)",
    ),
    _param(
        "sample_time",
        "sample_time_s",
        "sample_time",
        "s",
        "ms",
        None,
        "controller period; the communication step must be a multiple of it",
    ),
    _param(
        "coupling_stiffness",
        "coupling_stiffness_N_per_mm",
        "coupling_k",
        "N/m",
        "N/mm",
        "N/mm",
        "virtual coupling stiffness at the jaw (bound on the rendered jaw stiffness)",
    ),
    _param(
        "force_warning",
        "force_warning_N",
        "force_warning",
        "N",
        None,
        None,
        "tissue-safety threshold on the tissue jaw force",
    ),
    _param(
        "pressure_warning",
        "pressure_warning_MPa",
        "pressure_warning",
        "Pa",
        "kPa",
        "MPa",
        "tissue-safety threshold on the mean contact pressure",
    ),
    _param(
        "jaw_length",
        "jaw_length_mm",
        "jaw_length",
        "m",
        "mm",
        "mm",
        "length of tube under the jaws (contact area for the mean pressure)",
    ),
    _param(
        "diameter",
        "diameter_mm",
        "diameter",
        "m",
        "mm",
        "mm",
        "tube outer diameter (contact width of the flattened tube); must exceed 2 x thickness",
    ),
    # rendering of diagnosed effects (grasprom diagnose -> --augmented); neutral defaults
    _param(
        "tissue_scale",
        "tissue_scale",
        "tissue_scale",
        None,
        None,
        None,
        "factor on the tissue force and stiffness (tissue_stiffness_scale)",
    ),
    _param(
        "jaw_compliance",
        "jaw_compliance_mm_per_N",
        "jaw_compliance",
        "m/N",
        "mm/N",
        "mm/N",
        "series compliance of jaw + mechanism: coupling 1/(1/k_c + C) (jaw_compliance)",
    ),
    _param(
        "backlash",
        "backlash_deg",
        "backlash_deg",
        "rad",
        "deg",
        "deg",
        "play between the encoder and the linkage, total width (backlash)",
    ),
    _param(
        "friction_coulomb",
        "friction_coulomb_N",
        "friction_coulomb",
        "N",
        None,
        None,
        "Coulomb friction at the finger, in the direction of the last motion (mechanism_friction)",
    ),
    _param(
        "friction_load_coefficient",
        "friction_load_coefficient",
        "friction_load",
        None,
        None,
        None,
        "load-proportional Coulomb friction, x |tissue handle force|",
    ),
    _param(
        "friction_viscous",
        "friction_viscous_N_s_per_mm",
        "friction_viscous",
        "N.s/m",
        "N.s/mm",
        "N.s/mm",
        "viscous friction at the finger, on the finger speed",
    ),
    _param(
        "friction_velocity_threshold",
        "friction_velocity_threshold_mm_per_s",
        "friction_vthr",
        "m/s",
        "mm/s",
        "mm/s",
        "finger speed above which the friction direction follows the motion",
    ),
    *(
        _param(
            f"prony_g_{i + 1}",
            f"prony_g[{i}]",
            f"prony_g[{i}]",
            None,
            None,
            None,
            f"Prony coefficient {i + 1} of the viscoelastic jaw-force rendering "
            "(tissue_viscoelasticity; 0 = term off)",
        )
        for i in range(PRONY_MAX)
    ),
    *(
        _param(
            f"prony_tau_{i + 1}",
            f"prony_tau_s[{i}]",
            f"prony_tau[{i}]",
            "s",
            None,
            None,
            f"relaxation time of Prony term {i + 1}",
        )
        for i in range(PRONY_MAX)
    ),
)

_FLAG_DESCRIPTIONS = {
    "contact": "the jaws touch the tissue (surrogate force > 0)",
    "tissue_warning": "tissue force or mean contact pressure reached its threshold",
    "coupling_active": "tissue stiffer than the virtual coupling (rendering is bounded); "
    "clipped rendering: the stiffness limit acts",
    "saturated": "the torque hit torque_limit",
    "theta_clamped": "theta was outside its range, infinite or NaN",
}

SPECS: tuple[VarSpec, ...] = (
    VarSpec("time", "Real", "independent", "continuous", "simulation time", unit="s"),
    VarSpec(
        "theta",
        "Real",
        "input",
        "continuous",
        "handle angle (decreases when closing; 0 = closed end stop, as in grasprom "
        "simulate); clamped into [min, max], NaN holds the last valid angle",
        unit="rad",
        display_unit="deg",
    ),
    VarSpec(
        "theta_dot",
        "Real",
        "input",
        "continuous",
        "handle angular velocity, used for the damping when use_theta_dot is true "
        "(else ignored: the velocity is estimated from theta)",
        unit="rad/s",
        display_unit="deg/s",
        min=-THETA_DOT_MAX,
        max=THETA_DOT_MAX,
    ),
    VarSpec(
        "thickness",
        "Real",
        "parameter",
        "fixed",
        "colon wall thickness (clamped into the tabulated range of the material)",
        unit="m",
        display_unit="mm",
        params_field="thickness_mm",
        core_field="thickness",
        core_unit="mm",
    ),
    VarSpec(
        "material",
        "Enumeration",
        "parameter",
        "fixed",
        "tissue material model: " + _MATERIALS_DESC,
        params_field="material",
        core_field="material",
        min=0,
        max=len(MATERIAL_NAMES) - 1,
        enum=MATERIAL_TYPE,
    ),
    *_PARAMETERS,
    VarSpec(
        "encoder_counts",
        "Integer",
        "parameter",
        "fixed",
        "motor encoder resolution in counts per revolution (0: no quantisation of theta; "
        f"otherwise at least {ENCODER_COUNTS_RANGE[0]})",
        params_field="encoder_counts_per_rev",
        core_field="encoder_counts",
        min=0,
        max=ENCODER_COUNTS_MAX,
    ),
    VarSpec(
        "render_spring",
        "Boolean",
        "parameter",
        "fixed",
        "include the instrument's return spring in the rendered handle force",
        params_field="render_spring",
        core_field="render_spring",
    ),
    VarSpec(
        "use_theta_dot",
        "Boolean",
        "parameter",
        "fixed",
        "damp the theta_dot input instead of the filtered backward-difference estimate",
    ),
    _output(
        "torque", "Real", "motor torque command, after saturation", "torque", "torque_Nm", "N.m"
    ),
    _output(
        "force_handle",
        "Real",
        "rendered handle force (positive resists closing) = torque / pulley_radius",
        "force_handle",
        "force_handle_N",
        "N",
    ),
    _output(
        "force_jaw",
        "Real",
        "rendered jaw force through the virtual coupling",
        "force_jaw",
        "force_jaw_N",
        "N",
    ),
    _output(
        "force_tissue",
        "Real",
        "tissue force of the surrogate at the kinematic gap",
        "force_tissue",
        "force_tissue_N",
        "N",
    ),
    _output("gap", "Real", "jaw gap from the kinematic chain", "gap", "gap_mm", "m", "mm", "mm"),
    _output(
        "velocity",
        "Real",
        "handle velocity used for the damping (filtered estimate or theta_dot)",
        "velocity",
        "velocity_rad_per_s",
        "rad/s",
        "deg/s",
    ),
    *(_output(n, "Boolean", _FLAG_DESCRIPTIONS[n], n, n) for n in FLAG_NAMES),
    # appended after the outputs: the value references above stay as they were
    VarSpec(
        "rendering",
        "Enumeration",
        "parameter",
        "fixed",
        "tissue rendering scheme: " + _RENDERINGS_DESC + " (1: the stiffness-clipped "
        "field of stiffness_limit, no virtual coupling)",
        params_field="rendering",
        core_field="rendering",
        min=0,
        max=len(RENDERINGS) - 1,
        enum=RENDERING_TYPE,
    ),
    _param(
        "stiffness_limit",
        "stiffness_limit_Nm_per_rad",
        "stiffness_limit",
        "N.m/rad",
        None,
        None,
        "largest handle stiffness of the clipped rendering, at the handle "
        "pivot (the field's slope bound K_lim; rendering 1 only)",
    ),
    # appended after rendering/stiffness_limit: the time-domain passivity observer (issue 13)
    VarSpec(
        "passivity_observer",
        "Boolean",
        "parameter",
        "fixed",
        "time-domain passivity observer / controller on the handle port (needs rendering "
        "1; the field is then built with stiffness_limit x observer_stiffness_factor)",
        params_field="passivity_observer",
        core_field="passivity_observer",
    ),
    _param(
        "observer_stiffness_factor",
        "observer_stiffness_factor",
        "observer_stiffness_factor",
        None,
        None,
        None,
        "factor on stiffness_limit of the clipped field with the passivity observer on",
    ),
    _param(
        "observer_max_damping",
        "observer_max_damping_Nms_per_rad",
        "observer_max_damping",
        "N.m.s/rad",
        None,
        None,
        "cap of the damping the passivity controller adds, at the handle pivot",
    ),
    VarSpec(
        "observer_delay",
        "Integer",
        "parameter",
        "fixed",
        "samples between a step's output and its torque acting on the handle (the "
        "observer charges each interval with the torque that drove it; 0 for an importer "
        "that applies the torque over the next communication step)",
        params_field="observer_delay_samples",
        core_field="observer_delay",
        min=0,
        max=OBSERVER_DELAY_MAX,
    ),
)
"""The FMU's variables in value-reference order (vr = position)."""


def spec(name: str) -> VarSpec:
    """The row of :data:`SPECS` named ``name``."""
    return next(s for s in SPECS if s.name == name)


def enum_types(vars_: list[Variable]) -> list[EnumType]:
    """The enumeration types the variables declare, once each, in order of first use."""
    out: list[EnumType] = []
    for v in vars_:
        if v.enum is not None and v.enum not in out:
            out.append(v.enum)
    return out


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
        ``Real``, ``Integer``, ``Enumeration`` or ``Boolean`` (FMI 3: Float64, Int32,
        Enumeration, Boolean).
    causality : str
        ``independent``, ``input``, ``parameter`` or ``output``.
    variability : str
        ``continuous``, ``discrete`` or ``fixed``.
    description : str
    unit, display_unit : str or None
        Unit (a key of :data:`UNITS`) and display unit (Real only).
    start, min, max : float or None
        SI values (Boolean: start 0/1, no min/max; independent: none).
    spec : VarSpec or None
        The row of :data:`SPECS` it was made from (C field, core unit).
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
    spec: VarSpec | None = None

    @property
    def enum(self) -> EnumType | None:
        """The declared type of an ``Enumeration`` (None otherwise)."""
        return None if self.spec is None else self.spec.enum

    @property
    def initial(self) -> str | None:
        """``exact`` for outputs (start values hold until the first step), else default."""
        return "exact" if self.causality == "output" else None


def core_value(params: ControllerParams, params_field: str) -> float | int:
    """A :class:`ControllerParams` value as the C core takes it (core units).

    Parameters
    ----------
    params : ControllerParams
    params_field : str
        Field name; ``prony_g[i]`` / ``prony_tau_s[i]`` are padded to :data:`PRONY_MAX` terms
        (g = 0 terms add exactly 0); ``material`` gives the index into
        :data:`grasprom.fe.MATERIAL_NAMES`, ``rendering`` its :data:`RENDERING_CODES` code.

    Returns
    -------
    float or int
    """
    if params_field.endswith("]"):
        name, idx = params_field[:-1].split("[")
        g, tau = prony_padded(params)
        return float((g if name == "prony_g" else tau)[int(idx)])
    if params_field == "material":
        return MATERIAL_NAMES.index(params.material)
    if params_field == "rendering":
        return RENDERING_CODES[params.rendering]
    return getattr(params, params_field)


def si_start(s: VarSpec, params: ControllerParams) -> float | int | bool:
    """SI value of a parameter with a :class:`ControllerParams` field.

    Parameters
    ----------
    s : VarSpec
        A row with ``params_field``.
    params : ControllerParams

    Returns
    -------
    float (Real), int (Integer) or bool (Boolean)
    """
    raw = core_value(params, s.params_field)
    if s.type == "Boolean":
        return bool(raw)
    if s.type in ("Integer", "Enumeration"):
        return int(raw)
    return float(raw) * s.to_si


def _nice_ceil(x: float) -> float:
    """Round up to two significant digits."""
    if x <= 0:
        return 0.0
    e = 10.0 ** (math.floor(math.log10(x)) - 1)
    return math.ceil(x / e - 1e-9) * e


def derived_values(params: ControllerParams, surrogate: Surrogate) -> dict[str, dict[str, float]]:
    """Start values and limits (SI) that depend on the chain, the surrogate or other limits.

    Parameters
    ----------
    params : ControllerParams
    surrogate : Surrogate

    Returns
    -------
    dict
        Variable name -> ``{"start": ..., "min": ..., "max": ...}`` (the keys it sets).
    """
    chain = params.chain_params
    m_per_mm = spec("gap").to_si
    th_lo_deg, th_hi_deg = kin.theta_range_deg(chain)
    th_lo, th_hi = math.radians(th_lo_deg), math.radians(th_hi_deg)
    gaps = [kin.gap_mm(th_lo_deg + (th_hi_deg - th_lo_deg) * i / 400, chain) for i in range(401)]
    tl_max = spec("torque_limit").max
    r_min = spec("pulley_radius").min
    v_max = _nice_ceil(max((th_hi - th_lo) / spec("sample_time").min, THETA_DOT_MAX))
    mats = covered_materials(surrogate)
    return {
        "theta": {"start": th_hi, "min": th_lo, "max": th_hi},
        "thickness": {
            "min": min(surrogate.thickness_range(m)[0] for m in mats) * m_per_mm,
            "max": max(surrogate.thickness_range(m)[1] for m in mats) * m_per_mm,
        },
        "torque": {"min": -tl_max, "max": tl_max},
        "force_handle": {"min": -tl_max / r_min, "max": tl_max / r_min},
        # no declared max: the tissue scale, the Prony terms and the surrogate's range above
        # the FE force cap make any bound either violated or meaningless (issue 17)
        "force_jaw": {"min": 0.0},
        "force_tissue": {"min": 0.0},
        "gap": {
            "start": kin.gap_mm(th_hi_deg, chain) * m_per_mm,
            "min": min(gaps) * m_per_mm - 1e-6,
            "max": max(gaps) * m_per_mm + 1e-6,
        },
        "velocity": {"min": -v_max, "max": v_max},
    }


def _default_start(s: VarSpec) -> float | int | None:
    """Start of a variable without a parameter field: none (independent), 0 otherwise."""
    if s.causality == "independent":
        return None
    return 0 if s.type == "Boolean" else 0.0


def material_spec(materials: tuple[str, ...]) -> VarSpec:
    """The row of ``material`` for an export covering ``materials``: its enumeration
    (:func:`material_type`), description and [min, max] list only those (values fixed).

    Parameters
    ----------
    materials : tuple of str
        E.g. :func:`covered_materials`.

    Returns
    -------
    VarSpec
    """
    t = material_type(materials)
    desc = "tissue material model: " + t.listing() + (f" ({t.scope})" if t.scope else "")
    vals = t.item_values
    return replace(spec("material"), description=desc, min=min(vals), max=max(vals), enum=t)


def variables(params: ControllerParams, surrogate: Surrogate) -> list[Variable]:
    """The FMU's variables, in value-reference order (the single source of the C config
    header, the modelDescription and the documentation).

    Parameters
    ----------
    params : ControllerParams
        Start values of the parameters.
    surrogate : Surrogate
        Materials, thickness range and force bound: the ``material`` enumeration lists the
        materials it covers (:func:`material_spec`).

    Returns
    -------
    list of Variable

    Raises
    ------
    ValueError
        If the surrogate does not cover ``params.material`` (:func:`material_check`).
    """
    mat_spec = material_spec(material_check(params, surrogate))
    derived = derived_values(params, surrogate)
    out: list[Variable] = []
    for vr, s in enumerate(SPECS):
        s = mat_spec if s.name == "material" else s
        if s.params_field is not None:
            start = si_start(s, params)
            start = int(start) if s.type == "Boolean" else start
        else:
            start = _default_start(s)
        d = derived.get(s.name, {})
        out.append(
            Variable(
                s.name,
                vr,
                s.type,
                s.causality,
                s.variability,
                s.description,
                unit=s.unit,
                display_unit=s.display_unit,
                start=d.get("start", start),
                min=d.get("min", s.min),
                max=d.get("max", s.max),
                spec=s,
            )
        )
    return out


def start_values(params: ControllerParams) -> dict[str, float | int | bool]:
    """FMU parameter values (SI, by variable name) equivalent to ``params``.

    For ``simulate_fmu(..., start_values=...)`` or any importer; the chain geometry and the
    surrogate are compiled into the FMU and cannot be changed this way.
    """
    return {s.name: si_start(s, params) for s in SPECS if s.params_field is not None}


OUTPUT_COLUMNS: dict[str, tuple[str, float | None]] = {
    s.name: (s.column, None if s.type == "Boolean" else s.to_si)
    for s in SPECS
    if s.causality == "output"
}
"""FMU output -> (column of :func:`~grasprom.control.simulate`, factor to SI;
None: Boolean)."""
