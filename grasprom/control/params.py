"""Controller parameters (:class:`ControllerParams`) and their JSON file form.

``grasprom tune`` writes ``controller.json`` with :func:`save_params`; every consumer (simulate,
the FMU and Arduino exports, the gap diagnosis) reads it back with :func:`load_params`.  The
dict form (:func:`params_to_dict`, :func:`params_from_dict`) nests the chain geometry and
carries a format version.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from grasprom.chain import kinematics as kin
from grasprom.fe import MATERIAL_NAMES

__all__ = [
    "CONTROLLER_FILE_VERSION",
    "MAX_PRONY_TERMS",
    "OBSERVER_DELAY_MAX",
    "RENDERINGS",
    "ControllerParams",
    "load_params",
    "params_from_dict",
    "params_to_dict",
    "save_params",
]

OBSERVER_DELAY_MAX = 4
"""Largest ``observer_delay_samples`` (the C core keeps that many torques)."""

MAX_PRONY_TERMS = 4
"""Largest number of Prony terms the controller renders (the C core has room for 4)."""

CONTROLLER_FILE_VERSION = 1
"""``format_version`` of the controller parameter files."""

_POSITIVE_FIELDS = (
    "thickness_mm",
    "pulley_radius_mm",
    "velocity_cutoff_Hz",
    "torque_limit_Nm",
    "sample_time_s",
    "coupling_stiffness_N_per_mm",
    "force_warning_N",
    "pressure_warning_MPa",
    "jaw_length_mm",
    "diameter_mm",
    "tissue_scale",
    "friction_velocity_threshold_mm_per_s",
    "stiffness_limit_Nm_per_rad",
    "observer_max_damping_Nms_per_rad",
)
"""Numeric fields that must be finite and > 0."""

RENDERINGS = ("coupling", "clipped")
"""Rendering schemes of the tissue (``ControllerParams.rendering``)."""

_NON_NEGATIVE_RATES = ("spring_k_N_per_mm", "damping_Nms_per_rad")
"""Spring rate and virtual damping: finite and >= 0."""

_NON_NEGATIVE_EFFECTS = (
    "jaw_compliance_mm_per_N",
    "backlash_deg",
    "friction_coulomb_N",
    "friction_load_coefficient",
    "friction_viscous_N_s_per_mm",
)
"""Rendered instrument effects (0 = off): numbers, finite and >= 0."""

_PRONY_FIELDS = ("prony_g", "prony_tau_s")

PARAMETER_RANGES: dict[str, tuple[float, float]] = {
    "spring_k_N_per_mm": (0.0, 1e3),
    "damping_Nms_per_rad": (0.0, 10.0),
    "velocity_cutoff_Hz": (0.01, 1e5),
    "pulley_radius_mm": (1.0, 500.0),
    "torque_limit_Nm": (1e-6, 100.0),
    "sample_time_s": (1e-5, 1.0),
    "coupling_stiffness_N_per_mm": (1e-3, 1e5),
    "force_warning_N": (1e-3, 1e5),
    "pressure_warning_MPa": (1e-6, 1e3),
    "jaw_length_mm": (0.1, 1e3),
    "diameter_mm": (1.0, 1e3),
    "tissue_scale": (1e-3, 1e3),
    "jaw_compliance_mm_per_N": (0.0, 1e3),
    "backlash_deg": (0.0, 28.0),
    "friction_coulomb_N": (0.0, 1e3),
    "friction_load_coefficient": (0.0, 10.0),
    "friction_viscous_N_s_per_mm": (0.0, 1e3),
    "friction_velocity_threshold_mm_per_s": (1e-3, 1e4),
    "prony_g": (0.0, 100.0),
    "prony_tau_s": (1e-6, 1e6),
    "stiffness_limit_Nm_per_rad": (1e-6, 1e6),
    "observer_stiffness_factor": (1.0, 1e3),
    "observer_max_damping_Nms_per_rad": (1e-9, 100.0),
}
"""[min, max] of every real controller parameter in its own unit (the field name's): enforced
by :class:`ControllerParams` for every command (simulate, tune, build, both exports), and the
FMU declares the same ranges in SI (``grasprom.export.variables`` is generated from this)."""

ENCODER_COUNTS_RANGE = (16, 1 << 30)
"""``encoder_counts_per_rev``: 0 (no quantisation) or within this range (counts/rev)."""

_BOOLEAN_FIELDS = ("render_spring", "passivity_observer")


@dataclass(frozen=True)
class ControllerParams:
    """Parameters of the open-loop impedance controller (units in the names).

    Parameters
    ----------
    thickness_mm : float
        Colon wall thickness (mm); must lie in the surrogate's range.
    material : str
        ``mr``, ``nh`` or ``le``.
    spring_k_N_per_mm : float
        Return-spring rate of the instrument (N/mm), overrides the chain's.
    pulley_radius_mm : float
        Motor pulley radius (mm): torque = cable tension x radius.
    damping_Nms_per_rad : float
        Virtual damping B at the handle pivot (N m s/rad), on the filtered velocity.
    velocity_cutoff_Hz : float
        Cutoff of the first-order velocity low-pass filter (Hz).
    torque_limit_Nm : float
        Motor torque saturation (N m), symmetric.
    sample_time_s : float
        Controller period T (s).
    coupling_stiffness_N_per_mm : float
        Virtual coupling stiffness k_c at the jaw (N/mm): the bound on the rendered jaw
        stiffness.  The defaults of ``k_c``, ``B`` and the cutoff are what ``grasprom tune``
        chooses for the default device (b = 0.01 N m s/rad) at 1 kHz: passive everywhere with a
        margin of 1.26.
    force_warning_N : float
        Tissue-safety threshold on the jaw force (N).
    pressure_warning_MPa : float
        Tissue-safety threshold on the mean contact pressure (MPa).
    jaw_length_mm : float
        Length of tube under the jaws (mm), as in the FE model (contact area for the pressure).
    diameter_mm : float
        Tube outer diameter (mm), for the contact width of the flattened tube.
    encoder_counts_per_rev : int
        Resolution of the motor-shaft encoder (counts/rev, 4 x lines for a quadrature
        encoder); 0 disables quantisation.  The handle turns ``r / L3`` times the motor, so one
        count is ``2 pi r / (counts L3)`` rad of handle.
    render_spring : bool
        Include the instrument's return spring in the rendered handle force.
    chain : kinematics.ChainParams
        Linkage geometry (``spring_k_N_per_mm`` above replaces its spring rate).
    tissue_scale : float
        Factor on the surrogate tissue force and stiffness (1, > 0); ``tissue_stiffness_scale``
        of the augmented model.
    jaw_compliance_mm_per_N : float
        Series compliance of jaw and mechanism ``C`` (mm/N, >= 0): the coupling becomes
        ``k_c,eff = 1 / (1/k_c + C)`` (proxy gap ``g + (C + 1/k_c) Fg``).
    backlash_deg : float
        Total play width between the encoder and the linkage (deg of handle, >= 0).
    friction_coulomb_N : float
        Coulomb friction at the finger (N, >= 0), in the direction of the last motion.
    friction_load_coefficient : float
        Load-proportional Coulomb friction (1, >= 0): ``mu |Fi_t|`` with ``Fi_t`` the tissue part
        of the handle force (N).
    friction_viscous_N_s_per_mm : float
        Viscous friction at the finger (N s/mm of finger speed, >= 0); a virtual damping of
        ``b L3^2 1e-3`` N m s/rad at the handle pivot.
    friction_velocity_threshold_mm_per_s : float
        Finger speed (mm/s, > 0) above which the friction direction follows the motion; below
        it the last direction is kept.
    prony_g : tuple of float
        Prony coefficients ``g_i`` (1, >= 0) of the quasi-linear viscoelastic jaw force, at most
        :data:`MAX_PRONY_TERMS`; the instantaneous stiffness is ``1 + sum g_i`` times the relaxed.
    prony_tau_s : tuple of float
        Relaxation times ``tau_i`` (s, > 0), as many as ``prony_g``.
    rendering : str
        How the tissue is rendered: ``"clipped"`` (default: the tissue's own force-angle curve
        wherever its handle stiffness is below ``stiffness_limit_Nm_per_rad`` and the stiffest
        passive wall beyond, tabulated along the angle: :mod:`grasprom.control.field`) or
        ``"coupling"`` (the earlier scheme: a virtual coupling ``k_c`` in series with the
        tissue, solved for a proxy gap each step; it softens even the soft regime).
    stiffness_limit_Nm_per_rad : float
        ``K_lim`` of the clipped rendering: the largest handle stiffness rendered (N m/rad at
        the pivot, > 0).  Default 6.2: the passive bound of the default device (b = 0.01 N m s/rad
        with a safety factor of 1.25, one sample of delay, the default ``B`` and cutoff) at 1 kHz.
    passivity_observer : bool
        Time-domain passivity observer / controller (Hannaford & Ryu 2002; Ryu, Kwon &
        Hannaford 2004) on the handle port: the energy the controller has put into the handle
        is observed and, while it is positive, dissipated by an added damping
        (:mod:`grasprom.control.impedance`).  Needs ``rendering = "clipped"`` (refused with the
        coupling, whose proxy already bounds the rendered stiffness by ``k_c``).
    observer_stiffness_factor : float
        With the observer on, the clipped field is built with the limit
        ``stiffness_limit_Nm_per_rad * factor`` (1, >= 1; default 5: walls five times stiffer
        than the fixed Colgate bound, the observer keeps the loop passive).
    observer_max_damping_Nms_per_rad : float
        Cap ``alpha_max`` of the observer's added damping (N m s/rad at the handle pivot, > 0).
        Default 0.5: at 1 kHz a damping ``alpha`` on the one-sample-delayed, filtered velocity
        of the default handle (J = 2e-3 kg m^2) stays well-behaved while ``alpha T / J`` is
        well below 1 (0.25 here; the delayed damper itself goes unstable near ``J / T`` = 2);
        it is 50 times the device's physical damping b, and at a closing speed of 0.5 rad/s
        it asks 0.25 N m, a quarter of the default torque limit.  Measured
        (``tests/control/test_observer.py``): 0.1 to 1 all settle the 5x wall, 0.5 settles the
        hold below one encoder count at all three closing speeds.
    observer_delay_samples : int
        Samples between a step's output and the torque acting on the handle, beyond the
        zero-order hold (0 to :data:`OBSERVER_DELAY_MAX`; default 1, the device's documented
        ``delay_samples``): the observer charges each interval with the torque that drove it.
        Set it to the real device's delay (0 for an FMU importer that applies the torque over
        the next communication step).
    """

    thickness_mm: float = 1.4
    material: str = "mr"
    spring_k_N_per_mm: float = kin.ChainParams().spring_k_N_per_mm
    pulley_radius_mm: float = 10.0
    damping_Nms_per_rad: float = 0.001867
    velocity_cutoff_Hz: float = 200.0
    torque_limit_Nm: float = 1.0
    sample_time_s: float = 1e-3
    coupling_stiffness_N_per_mm: float = 0.95
    force_warning_N: float = 50.0
    pressure_warning_MPa: float = 0.33
    jaw_length_mm: float = 10.0
    diameter_mm: float = 30.0
    encoder_counts_per_rev: int = 4096
    render_spring: bool = True
    chain: kin.ChainParams = field(default_factory=kin.ChainParams)
    tissue_scale: float = 1.0
    jaw_compliance_mm_per_N: float = 0.0
    backlash_deg: float = 0.0
    friction_coulomb_N: float = 0.0
    friction_load_coefficient: float = 0.0
    friction_viscous_N_s_per_mm: float = 0.0
    friction_velocity_threshold_mm_per_s: float = 2.0
    prony_g: tuple[float, ...] = ()
    prony_tau_s: tuple[float, ...] = ()
    rendering: str = "clipped"
    stiffness_limit_Nm_per_rad: float = 6.2
    passivity_observer: bool = False
    observer_stiffness_factor: float = 5.0
    observer_max_damping_Nms_per_rad: float = 0.5
    observer_delay_samples: int = 1

    def __post_init__(self) -> None:
        _check_material(self)
        _check_rendering(self)
        _check_booleans(self)
        _check_observer(self)
        _check_scalars(self)
        _normalise_prony(self)
        _check_prony(self)
        _check_ranges(self)
        _check_sampling(self)

    @property
    def chain_params(self) -> kin.ChainParams:
        """The linkage with this controller's spring rate."""
        return replace(self.chain, spring_k_N_per_mm=self.spring_k_N_per_mm)

    @property
    def contact_width_mm(self) -> float:
        """Contact width of the flattened tube, ``pi (D - t) / 2`` (mm)."""
        return 0.5 * math.pi * (self.diameter_mm - self.thickness_mm)

    @property
    def coupling_effective_N_per_mm(self) -> float:
        """Coupling in series with the jaw compliance, ``1 / (1/k_c + C)`` (N/mm; k_c at C = 0)."""
        kc, c = self.coupling_stiffness_N_per_mm, self.jaw_compliance_mm_per_N
        return kc if c == 0 else 1.0 / (1.0 / kc + c)

    @property
    def field_stiffness_limit_Nm_per_rad(self) -> float:
        """Stiffness limit the clipped field is built with (N m/rad at the pivot).

        ``stiffness_limit_Nm_per_rad``, times ``observer_stiffness_factor`` with the passivity
        observer on.
        """
        k = self.stiffness_limit_Nm_per_rad
        return k * self.observer_stiffness_factor if self.passivity_observer else k

    @property
    def friction_rendered(self) -> bool:
        """Whether any friction term is on."""
        return (
            self.friction_coulomb_N > 0
            or self.friction_load_coefficient > 0
            or self.friction_viscous_N_s_per_mm > 0
        )


def _check_material(p: ControllerParams) -> None:
    """The material must be one of the FE materials."""
    if p.material not in MATERIAL_NAMES:
        raise ValueError(f"material {p.material!r} unknown; valid: {', '.join(MATERIAL_NAMES)}")


def _check_rendering(p: ControllerParams) -> None:
    """The rendering must be one of :data:`RENDERINGS`."""
    if p.rendering not in RENDERINGS:
        raise ValueError(
            f"controller parameter rendering {p.rendering!r} unknown; "
            f"valid: {', '.join(RENDERINGS)}"
        )


def _check_observer(p: ControllerParams) -> None:
    """Observer flag a bool, factor finite and >= 1, and the observer only with ``clipped``."""
    if not isinstance(p.passivity_observer, bool):
        raise ValueError(
            f"controller parameter passivity_observer must be true or false, got "
            f"{p.passivity_observer!r}"
        )
    f = p.observer_stiffness_factor
    if isinstance(f, bool) or not (isinstance(f, int | float) and math.isfinite(f) and f >= 1):
        raise ValueError(
            f"controller parameter observer_stiffness_factor must be finite and >= 1, got {f!r}"
        )
    d = p.observer_delay_samples
    if isinstance(d, bool) or not isinstance(d, int) or not 0 <= d <= OBSERVER_DELAY_MAX:
        raise ValueError(
            f"controller parameter observer_delay_samples must be an integer in "
            f"[0, {OBSERVER_DELAY_MAX}], got {d!r}"
        )
    if p.passivity_observer and p.rendering != "clipped":
        raise ValueError(
            f"controller parameter passivity_observer=True needs rendering='clipped' (got "
            f"{p.rendering!r}): the observer renders the clipped field beyond the Colgate bound; "
            "the virtual coupling has no field to stiffen"
        )


def _check_scalars(p: ControllerParams) -> None:
    """Positive, non-negative and effect fields, in the order of the field groups."""
    for name in _POSITIVE_FIELDS:
        v = getattr(p, name)
        if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ValueError(f"controller parameter {name} must be finite and > 0, got {v!r}")
    for name in _NON_NEGATIVE_RATES:
        v = getattr(p, name)
        if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
            raise ValueError(f"controller parameter {name} must be finite and >= 0, got {v!r}")
    for name in _NON_NEGATIVE_EFFECTS:
        v = getattr(p, name)
        if isinstance(v, bool) or not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
            raise ValueError(f"controller parameter {name} must be finite and >= 0, got {v!r}")


def _check_booleans(p: ControllerParams) -> None:
    """Flags must be true or false (``"no"`` or 0 is a mistake, not a falsy value)."""
    for name in _BOOLEAN_FIELDS:
        v = getattr(p, name)
        if not isinstance(v, bool):
            raise ValueError(f"controller parameter {name} must be true or false, got {v!r}")


def _check_ranges(p: ControllerParams) -> None:
    """Every real parameter within :data:`PARAMETER_RANGES`, the encoder counts within theirs."""
    for name, (lo, hi) in PARAMETER_RANGES.items():
        values = getattr(p, name)
        for i, v in enumerate(values if isinstance(values, tuple) else (values,)):
            if isinstance(v, bool) or not (isinstance(v, int | float) and lo <= v <= hi):
                where = f"{name}[{i}]" if isinstance(values, tuple) else name
                raise ValueError(
                    f"controller parameter {where} = {v!r} outside its range [{lo:g}, {hi:g}] "
                    "(unit in the name)"
                )
    n = p.encoder_counts_per_rev
    lo, hi = ENCODER_COUNTS_RANGE
    if isinstance(n, bool) or not isinstance(n, int) or not (n == 0 or lo <= n <= hi):
        raise ValueError(
            f"controller parameter encoder_counts_per_rev = {n!r} must be an integer, 0 (no "
            f"quantisation) or in [{lo}, {hi}] counts per revolution"
        )


def _normalise_prony(p: ControllerParams) -> None:
    """``prony_g`` and ``prony_tau_s`` must be lists of numbers; stored as tuples of float."""
    for name in _PRONY_FIELDS:
        v = getattr(p, name)
        if isinstance(v, str) or not isinstance(v, tuple | list):
            raise ValueError(f"controller parameter {name} must be a list of numbers, got {v!r}")
        if not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
            raise ValueError(f"controller parameter {name} must hold numbers, got {v!r}")
        object.__setattr__(p, name, tuple(float(x) for x in v))


def _check_prony(p: ControllerParams) -> None:
    """Matching lengths, at most :data:`MAX_PRONY_TERMS`, ``g_i >= 0`` and ``tau_i > 0`` (s)."""
    if len(p.prony_g) != len(p.prony_tau_s):
        raise ValueError(
            f"controller parameters prony_g ({len(p.prony_g)} terms) and prony_tau_s "
            f"({len(p.prony_tau_s)} terms) must have the same length"
        )
    if len(p.prony_g) > MAX_PRONY_TERMS:
        raise ValueError(
            f"controller parameter prony_g: at most {MAX_PRONY_TERMS} Prony terms, got "
            f"{len(p.prony_g)}"
        )
    for i, (g, tau) in enumerate(zip(p.prony_g, p.prony_tau_s)):
        if not (math.isfinite(g) and g >= 0):
            raise ValueError(
                f"controller parameter prony_g[{i}] must be finite and >= 0, got {g!r}"
            )
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(
                f"controller parameter prony_tau_s[{i}] must be finite and > 0 s, got {tau!r}"
            )


def _check_sampling(p: ControllerParams) -> None:
    """Encoder counts >= 0 and the velocity cutoff below the Nyquist frequency (Hz)."""
    if int(p.encoder_counts_per_rev) < 0:
        raise ValueError("controller parameter encoder_counts_per_rev must be >= 0")
    if p.velocity_cutoff_Hz >= 0.5 / p.sample_time_s:
        raise ValueError(
            f"velocity_cutoff_Hz={p.velocity_cutoff_Hz} must be below the Nyquist "
            f"frequency {0.5 / p.sample_time_s:g} Hz of sample_time_s={p.sample_time_s}"
        )


# ----------------------------------------------------------------------------------------------
# dict and JSON file form
# ----------------------------------------------------------------------------------------------


def params_to_dict(params: ControllerParams) -> dict[str, Any]:
    """JSON-ready dict of the parameters (``chain`` nested), with a format version."""
    d = {f.name: getattr(params, f.name) for f in fields(params) if f.name != "chain"}
    for name in ("prony_g", "prony_tau_s"):
        d[name] = list(d[name])
    d["chain"] = {f.name: getattr(params.chain, f.name) for f in fields(params.chain) if f.init}
    d["format_version"] = CONTROLLER_FILE_VERSION
    return d


def params_from_dict(d: dict[str, Any], source: str = "controller parameters") -> ControllerParams:
    """Inverse of :func:`params_to_dict`; unknown keys and bad values name ``source``."""
    d = dict(d)
    version = d.pop("format_version", CONTROLLER_FILE_VERSION)
    if version != CONTROLLER_FILE_VERSION:
        raise ValueError(
            f"{source}: format_version {version!r}, expected {CONTROLLER_FILE_VERSION}"
        )
    d.pop("tuning", None)  # tuning report stored alongside by grasprom tune
    chain = d.pop("chain", None)
    known = {f for f in ControllerParams.__dataclass_fields__}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"{source}: unknown key(s) {', '.join(unknown)}")
    try:
        if chain is not None:
            d["chain"] = kin.ChainParams(**chain)
        return ControllerParams(**d)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: {exc}") from None


def load_params(path: str | os.PathLike[str]) -> ControllerParams:
    """Read controller parameters from a JSON file (as written by ``grasprom tune``)."""
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p}: cannot read controller parameters ({exc})") from None
    if not isinstance(d, dict):
        raise ValueError(f"{p}: expected a JSON object")
    return params_from_dict(d, source=str(p))


def save_params(
    params: ControllerParams, path: str | os.PathLike[str], extra: dict[str, Any] | None = None
) -> None:
    """Write controller parameters (and optional ``extra`` keys, e.g. ``tuning``) as JSON.

    Atomic, mode 0644 (:func:`grasprom.fe.atomicio.atomic_write_json`); a failed write raises
    an ``OSError`` naming ``path`` and leaves nothing behind.
    """
    from grasprom.fe.atomicio import atomic_write_json

    d = params_to_dict(params)
    if extra:
        d.update(extra)
    atomic_write_json(path, d)
