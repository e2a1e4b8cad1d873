"""Open-loop impedance controller: handle angle in, motor torque out (Python reference).

One step, at the sample time ``T`` (default 1 ms, 1 kHz):

1. **Encoder**: the handle angle is quantised to the encoder resolution
   (``2 pi / encoder_counts_per_rev``) and clamped into the chain's range (flagged).
2. **Kinematics**: jaw gap ``g(theta)`` (mm) from :mod:`grasprom.kinematics` (derived chain).
3. **Tissue through a virtual coupling**: the tissue force ``F(g)`` comes from the
   :class:`~grasprom.surrogate.Surrogate`; where the walls meet the tissue is far stiffer (hundreds
   of N/mm) than a 1 kHz device can render passively, so the jaw is coupled to the tissue through
   a virtual spring ``k_c`` (N/mm): a proxy gap ``g_p >= g`` solves ``k_c (g_p - g) = F(g_p)``
   (three safeguarded Newton iterations in the bracket ``[g, g + F(g)/k_c]``, warm-started from the
   last proxy), and the rendered jaw force is ``Fg = k_c (g_p - g)``.  The rendered jaw stiffness
   is ``k_c k_t / (k_c + k_t) < k_c``; the coupling is reported *active* where the tissue
   stiffness ``k_t`` exceeds ``k_c``.  In the bending regime (``k_t << k_c``) the proxy sits
   ``F / k_c`` above the jaw (< 0.1 mm for 1 N at 20 N/mm).
4. **Chain**: handle force ``Fi`` from ``Fg`` by virtual work (plus the return spring when
   ``render_spring``).
5. **Damping**: virtual damping ``B`` (N m s/rad at the handle pivot) on the handle velocity,
   estimated by a backward difference and a first-order low-pass (cutoff ``velocity_cutoff_Hz``,
   exact discretisation ``a = exp(-2 pi fc T)``).
6. **Torque**: the motor drives the handle grip (at ``L3``) through a cable on a pulley of radius
   ``r``: cable tension = handle force, ``torque = (Fi + Fi_damping) r`` (N m), saturated at
   ``torque_limit_Nm`` (flagged).
7. **Safety**: ``tissue_warning`` when the tissue jaw force reaches ``force_warning_N``
   (default 50 N: colon muscle damage from about 50 N grasp force, Barrie et al. 2018) or the mean
   contact pressure reaches ``pressure_warning_MPa`` (default 0.33 MPa = 330 kPa, bowel safety
   pressure).  The mean pressure is ``F / (jaw_length x w)`` with ``w = pi (D - t) / 2`` the contact
   width of the flattened tube (FE: 46-48 mm once the walls meet); before the walls meet the
   contact is narrower, so the force threshold is the binding one there.

Sign conventions (as :mod:`grasprom.kinematics`): ``theta`` (rad inside, deg at the user surface)
decreases when closing; ``Fi > 0`` resists closing (the device pushes the handle open);
``torque > 0`` produces ``Fi > 0``.

The step allocates nothing (pure Python floats); the C core of the FMU and Arduino exports must
reproduce it (tests compare them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

from . import kinematics as kin
from .materials import MATERIAL_NAMES
from .surrogate import Surrogate

NEWTON_ITERATIONS = 3
"""Newton iterations of the virtual-coupling proxy per step (fixed: deterministic cost)."""


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
        stiffness (chosen by ``grasprom tune`` for passivity).
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
    """

    thickness_mm: float = 1.4
    material: str = "mr"
    spring_k_N_per_mm: float = kin.ChainParams().spring_k_N_per_mm
    pulley_radius_mm: float = 10.0
    damping_Nms_per_rad: float = 0.0
    velocity_cutoff_Hz: float = 30.0
    torque_limit_Nm: float = 1.0
    sample_time_s: float = 1e-3
    coupling_stiffness_N_per_mm: float = 5.0
    force_warning_N: float = 50.0
    pressure_warning_MPa: float = 0.33
    jaw_length_mm: float = 10.0
    diameter_mm: float = 30.0
    encoder_counts_per_rev: int = 4096
    render_spring: bool = True
    chain: kin.ChainParams = field(default_factory=kin.ChainParams)

    def __post_init__(self):
        if self.material not in MATERIAL_NAMES:
            raise ValueError(
                f"material {self.material!r} unknown; valid: {', '.join(MATERIAL_NAMES)}"
            )
        positive = (
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
        )
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"controller parameter {name} must be finite and > 0, got {v!r}")
        for name in ("spring_k_N_per_mm", "damping_Nms_per_rad"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"controller parameter {name} must be finite and >= 0, got {v!r}")
        if int(self.encoder_counts_per_rev) < 0:
            raise ValueError("controller parameter encoder_counts_per_rev must be >= 0")
        if self.velocity_cutoff_Hz >= 0.5 / self.sample_time_s:
            raise ValueError(
                f"velocity_cutoff_Hz={self.velocity_cutoff_Hz} must be below the Nyquist "
                f"frequency {0.5 / self.sample_time_s:g} Hz of sample_time_s={self.sample_time_s}"
            )

    @property
    def chain_params(self) -> kin.ChainParams:
        """The linkage with this controller's spring rate."""
        return replace(self.chain, spring_k_N_per_mm=self.spring_k_N_per_mm)

    @property
    def contact_width_mm(self) -> float:
        """Contact width of the flattened tube, ``pi (D - t) / 2`` (mm)."""
        return 0.5 * math.pi * (self.diameter_mm - self.thickness_mm)


class StepOutput(NamedTuple):
    """Outputs of one controller step (units in the names)."""

    torque_Nm: float  # motor torque, after saturation
    force_handle_N: float  # rendered handle force = torque / pulley radius (incl. damping)
    force_handle_spring_N: float  # handle force of the return spring alone
    force_jaw_N: float  # rendered jaw force (through the virtual coupling)
    force_tissue_N: float  # surrogate tissue force at the kinematic gap
    gap_mm: float
    proxy_gap_mm: float
    theta_deg: float
    velocity_rad_per_s: float
    contact: bool
    tissue_warning: bool
    coupling_active: bool
    saturated: bool
    theta_clamped: bool


class ImpedanceController:
    """Discrete-time open-loop impedance controller (Python reference implementation).

    Parameters
    ----------
    params : ControllerParams
    surrogate : Surrogate
        Tissue force table; must cover ``params.material`` and ``params.thickness_mm``.

    Examples
    --------
    >>> ctl = ImpedanceController(ControllerParams(), surrogate)   # doctest: +SKIP
    >>> out = ctl.step(math.radians(10.0))                          # doctest: +SKIP
    """

    def __init__(self, params: ControllerParams, surrogate: Surrogate):
        lo, hi = surrogate.thickness_range(params.material)
        if not lo <= params.thickness_mm <= hi:
            raise ValueError(
                f"thickness_mm={params.thickness_mm} outside the surrogate's range "
                f"[{lo:g}, {hi:g}] mm for material {params.material!r}"
            )
        self.params = params
        self.surrogate = surrogate
        self._chain = params.chain_params
        n = int(params.encoder_counts_per_rev)
        th_lo, th_hi = kin.theta_range_deg(self._chain)
        self._th_lo = math.radians(th_lo)
        self._th_hi = math.radians(th_hi)
        self._q = 2.0 * math.pi * params.pulley_radius_mm / (n * self._chain.L3_mm) if n else 0.0
        self._a = math.exp(-2.0 * math.pi * params.velocity_cutoff_Hz * params.sample_time_s)
        self._kc = params.coupling_stiffness_N_per_mm
        self._area = params.jaw_length_mm * params.contact_width_mm
        self._L3 = self._chain.L3_mm
        self.reset()

    @property
    def encoder_quantum_rad(self) -> float:
        """Handle angle per encoder count (rad); 0 without quantisation."""
        return self._q

    def reset(self, theta_rad: float | None = None) -> None:
        """Reset the state (velocity filter, previous angle, proxy)."""
        self._prev = theta_rad
        self._v = 0.0
        self._gp = math.inf

    def _tissue(self, g: float) -> tuple[float, float]:
        f, k, _ = self.surrogate.evaluate_scalar(g, self.params.thickness_mm, self.params.material)
        return f, k  # force (N) and stiffness k_t = -dF/dgap >= 0 (N/mm)

    def quantise(self, theta_rad: float) -> float:
        """Encoder quantisation of an angle (rad)."""
        q = self._q
        return q * math.floor(theta_rad / q + 0.5) if q > 0.0 else theta_rad

    def step(self, theta_rad: float) -> StepOutput:
        """Advance one sample with the measured handle angle (rad); returns the outputs."""
        p = self.params
        th = self.quantise(float(theta_rad))
        clamped = False
        if not th >= self._th_lo:  # also catches NaN
            th, clamped = self._th_lo, True
        elif th > self._th_hi:
            th, clamped = self._th_hi, True
        if self._prev is None:
            self._prev = th
        v_raw = (th - self._prev) / p.sample_time_s
        self._prev = th
        self._v = self._a * self._v + (1.0 - self._a) * v_raw
        th_deg = math.degrees(th)
        g = kin.gap_mm(th_deg, self._chain)
        f_g, k_g = self._tissue(g)
        contact = f_g > 0.0
        kc = self._kc
        if contact:
            hi = g + f_g / kc
            gp = min(max(self._gp, g), hi)
            for _ in range(NEWTON_ITERATIONS):
                f_p, k_p = self._tissue(gp)
                r = kc * (gp - g) - f_p
                gp = gp - r / (kc + k_p)
                gp = min(max(gp, g), hi)
            fg = kc * (gp - g)
            coupling_active = self._tissue(gp)[1] > kc
        else:
            gp, fg, coupling_active = g, 0.0, False
        self._gp = gp
        fi_spring = kin.spring_handle_force_N(th_deg, self._chain)
        fi = kin.handle_force_N(fg, th_deg, self._chain)  # includes the spring
        if not p.render_spring:
            fi -= fi_spring
        fi -= p.damping_Nms_per_rad * self._v / (self._L3 * 1e-3)
        r_m = p.pulley_radius_mm * 1e-3
        torque = fi * r_m
        lim = p.torque_limit_Nm
        saturated = abs(torque) > lim
        if saturated:
            torque = math.copysign(lim, torque)
        warn = f_g >= p.force_warning_N or f_g / self._area >= p.pressure_warning_MPa
        return StepOutput(
            torque_Nm=torque,
            force_handle_N=torque / r_m,
            force_handle_spring_N=fi_spring,
            force_jaw_N=fg,
            force_tissue_N=f_g,
            gap_mm=g,
            proxy_gap_mm=gp,
            theta_deg=th_deg,
            velocity_rad_per_s=self._v,
            contact=contact,
            tissue_warning=warn,
            coupling_active=coupling_active,
            saturated=saturated,
            theta_clamped=clamped,
        )


CONTROLLER_FILE_VERSION = 1


def params_to_dict(params: ControllerParams) -> dict:
    """JSON-ready dict of the parameters (``chain`` nested), with a format version."""
    from dataclasses import fields

    d = {f.name: getattr(params, f.name) for f in fields(params) if f.name != "chain"}
    d["chain"] = {f.name: getattr(params.chain, f.name) for f in fields(params.chain) if f.init}
    d["format_version"] = CONTROLLER_FILE_VERSION
    return d


def params_from_dict(d: dict, source: str = "controller parameters") -> ControllerParams:
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


def load_params(path) -> ControllerParams:
    """Read controller parameters from a JSON file (as written by ``grasprom tune``)."""
    import json
    from pathlib import Path

    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{p}: cannot read controller parameters ({exc})") from None
    if not isinstance(d, dict):
        raise ValueError(f"{p}: expected a JSON object")
    return params_from_dict(d, source=str(p))


def save_params(params: ControllerParams, path, extra: dict | None = None) -> None:
    """Write controller parameters (and optional ``extra`` keys, e.g. ``tuning``) as JSON."""
    import json
    import os
    import tempfile
    from pathlib import Path

    p = Path(path)
    d = params_to_dict(params)
    if extra:
        d.update(extra)
    fd, tmp = tempfile.mkstemp(dir=p.parent if str(p.parent) else ".", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(d, fh, indent=2)
    os.replace(tmp, p)
