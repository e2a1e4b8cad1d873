"""Open-loop impedance controller: handle angle in, motor torque out (Python reference).

One step, at the sample time ``T`` (default 1 ms, 1 kHz):

1. **Encoder**: the handle angle is quantised to the encoder resolution (one count of the
   motor encoder, ``2 pi r / (counts L3)`` rad of handle) and clamped into the chain's range
   (flagged; a NaN angle holds the last valid one, also flagged).
2. **Kinematics**: jaw gap ``g(theta)`` (mm) from :mod:`grasprom.kinematics` (derived chain).
3. **Tissue through a virtual coupling**: the tissue force ``F(g)`` comes from the
   :class:`~grasprom.surrogate.Surrogate`; where the walls meet the tissue is far stiffer (hundreds
   of N/mm) than a 1 kHz device can render passively, so the jaw is coupled to the tissue through
   a virtual spring ``k_c`` (N/mm): a proxy gap ``g_p >= g`` solves ``k_c (g_p - g) = F(g_p)``
   (three safeguarded Newton iterations in the bracket ``[g, g + F(g)/k_c]``, warm-started from the
   last proxy; 30 on the first contact after a reset), and the rendered jaw force is
   ``Fg = k_c (g_p - g)``.  The rendered jaw stiffness is ``k_c k_t / (k_c + k_t) < k_c``; the
   coupling is reported *active* where the tissue stiffness ``k_t`` exceeds ``k_c``.  In the
   bending regime (``k_t << k_c``) the proxy sits ``F / k_c`` above the jaw (about 1 mm for 1 N
   at the tuned ``k_c`` = 0.95 N/mm: the price of passivity at 1 kHz, see ``grasprom tune``).
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

Rendered instrument effects (the augmented model of ``grasprom diagnose``, mapped by
:func:`grasprom.gap.diagnosis.controller_params_from_augmented`; every one is off at its
default, and the step is then bit-identical to the one without them):

* **Backlash** ``backlash_deg`` (total play width ``b``): between the encoder and the linkage sits
  a play operator, ``theta_c = min(max(theta_c, theta - b/2), theta + b/2)`` (started at the first
  angle, kept in the chain's range); gap, tissue, spring and virtual work use the chain angle
  ``theta_c`` (output ``theta_chain_deg``), ``theta_deg`` stays the encoder angle.
* **Tissue stiffness scale** ``tissue_scale``: surrogate force and stiffness times the factor.
* **Jaw compliance** ``jaw_compliance_mm_per_N`` (``C``): a series compliance of jaw and
  mechanism, rendered inside the coupling, ``k_c,eff = 1 / (1/k_c + C)``: the proxy gap is
  ``g + (C + 1/k_c) Fg`` (the real gap ``g + C Fg`` plus the coupling's own stretch).
* **Viscoelasticity** ``prony_g``, ``prony_tau_s`` (at most 4 terms): quasi-linear viscoelastic
  Prony series on the coupled (relaxed) jaw force ``Fg``: ``h_i <- exp(-T/tau_i) h_i + dFg``,
  ``Fg,r = max(Fg + sum g_i h_i, 0)`` (the jaws cannot pull); the instantaneous stiffness is
  ``(1 + sum g_i)`` times the relaxed one (``grasprom tune`` accounts for it).
* **Mechanism friction** ``friction_coulomb_N``, ``friction_load_coefficient``,
  ``friction_viscous_N_s_per_mm``: at the finger, ``dFi = (Fc + mu |Fi_t|) s + b v_f`` with
  ``v_f = -L3 theta'`` the finger speed (mm/s, > 0 closing, from the velocity used for the
  damping), ``Fi_t = Fg,r g'/L3`` the tissue part of the handle force and ``s`` the direction of
  the last finger motion faster than ``friction_velocity_threshold_mm_per_s`` (+1 closing, -1
  opening, 0 before the first; kept while slower: stiction memory); output
  ``force_handle_friction_N``.  Friction resists the motion (closing: ``dFi > 0``).  The viscous
  term is a virtual damping ``b L3^2`` on the same filtered velocity: ``grasprom tune`` adds it to
  ``B`` in the passivity condition.

Measurement effects of the augmented model (force-sensor offset/gain, latency) are not rendered:
``grasprom simulate --augmented`` applies them to an extra output column only.

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

from grasprom.chain import kinematics as kin
from grasprom.fe import MATERIAL_NAMES
from grasprom.surrogate import Surrogate

NEWTON_ITERATIONS = 3
"""Newton iterations of the virtual-coupling proxy per step (fixed: deterministic cost)."""

COLD_START_ITERATIONS = 30
"""Newton iterations on the first contact step after a reset (no warm start yet)."""

MAX_PRONY_TERMS = 4
"""Largest number of Prony terms the controller renders (the C core has room for 4)."""


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
            "tissue_scale",
            "friction_velocity_threshold_mm_per_s",
        )
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"controller parameter {name} must be finite and > 0, got {v!r}")
        for name in ("spring_k_N_per_mm", "damping_Nms_per_rad"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"controller parameter {name} must be finite and >= 0, got {v!r}")
        for name in (
            "jaw_compliance_mm_per_N",
            "backlash_deg",
            "friction_coulomb_N",
            "friction_load_coefficient",
            "friction_viscous_N_s_per_mm",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"controller parameter {name} must be finite and >= 0, got {v!r}")
        for name in ("prony_g", "prony_tau_s"):
            v = getattr(self, name)
            if isinstance(v, str) or not isinstance(v, tuple | list):
                raise ValueError(
                    f"controller parameter {name} must be a list of numbers, got {v!r}"
                )
            if not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
                raise ValueError(f"controller parameter {name} must hold numbers, got {v!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if len(self.prony_g) != len(self.prony_tau_s):
            raise ValueError(
                f"controller parameters prony_g ({len(self.prony_g)} terms) and prony_tau_s "
                f"({len(self.prony_tau_s)} terms) must have the same length"
            )
        if len(self.prony_g) > MAX_PRONY_TERMS:
            raise ValueError(
                f"controller parameter prony_g: at most {MAX_PRONY_TERMS} Prony terms, got "
                f"{len(self.prony_g)}"
            )
        for i, (g, tau) in enumerate(zip(self.prony_g, self.prony_tau_s)):
            if not (math.isfinite(g) and g >= 0):
                raise ValueError(
                    f"controller parameter prony_g[{i}] must be finite and >= 0, got {g!r}"
                )
            if not (math.isfinite(tau) and tau > 0):
                raise ValueError(
                    f"controller parameter prony_tau_s[{i}] must be finite and > 0 s, got {tau!r}"
                )
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

    @property
    def coupling_effective_N_per_mm(self) -> float:
        """Coupling in series with the jaw compliance, ``1 / (1/k_c + C)`` (N/mm; k_c at C = 0)."""
        kc, c = self.coupling_stiffness_N_per_mm, self.jaw_compliance_mm_per_N
        return kc if c == 0 else 1.0 / (1.0 / kc + c)

    @property
    def friction_rendered(self) -> bool:
        """Whether any friction term is on."""
        return (
            self.friction_coulomb_N > 0
            or self.friction_load_coefficient > 0
            or self.friction_viscous_N_s_per_mm > 0
        )


class _StepFields(NamedTuple):
    torque_Nm: float  # motor torque, after saturation
    force_handle_N: float  # rendered handle force = torque / pulley radius (incl. damping)
    force_handle_spring_N: float  # handle force of the return spring alone
    force_jaw_N: float  # rendered jaw force (through the virtual coupling; Prony included)
    force_tissue_N: float  # (scaled) surrogate tissue force at the kinematic gap
    gap_mm: float  # kinematic gap at the chain angle
    proxy_gap_mm: float
    theta_deg: float  # encoder angle (quantised, clamped)
    velocity_rad_per_s: float
    contact: bool
    tissue_warning: bool
    coupling_active: bool
    saturated: bool
    theta_clamped: bool
    theta_chain_deg: float  # chain angle behind the backlash (= theta_deg without backlash)
    force_handle_friction_N: float  # rendered friction at the finger (0 without friction)


class StepOutput(_StepFields):
    """Outputs of one controller step (units in the names).

    The two trailing fields, ``theta_chain_deg`` and ``force_handle_friction_N``, may be omitted
    by an implementation that renders neither backlash nor friction: they then default to
    ``theta_deg`` and 0.0, their values in that case.
    """

    __slots__ = ()

    def __new__(
        cls,
        torque_Nm: float,
        force_handle_N: float,
        force_handle_spring_N: float,
        force_jaw_N: float,
        force_tissue_N: float,
        gap_mm: float,
        proxy_gap_mm: float,
        theta_deg: float,
        velocity_rad_per_s: float,
        contact: bool,
        tissue_warning: bool,
        coupling_active: bool,
        saturated: bool,
        theta_clamped: bool,
        theta_chain_deg: float | None = None,
        force_handle_friction_N: float = 0.0,
    ) -> StepOutput:
        return _tuple_new(
            cls,
            (
                torque_Nm,
                force_handle_N,
                force_handle_spring_N,
                force_jaw_N,
                force_tissue_N,
                gap_mm,
                proxy_gap_mm,
                theta_deg,
                velocity_rad_per_s,
                contact,
                tissue_warning,
                coupling_active,
                saturated,
                theta_clamped,
                theta_deg if theta_chain_deg is None else theta_chain_deg,
                force_handle_friction_N,
            ),
        )


_tuple_new = tuple.__new__


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
        self._kc = params.coupling_effective_N_per_mm
        self._area = params.jaw_length_mm * params.contact_width_mm
        self._L3 = self._chain.L3_mm
        self._scale = params.tissue_scale
        self._hb = 0.5 * math.radians(params.backlash_deg)
        self._pg = params.prony_g
        self._pa = [math.exp(-params.sample_time_s / tau) for tau in params.prony_tau_s]
        self._np = len(params.prony_g)
        self._fric = params.friction_rendered
        self.reset()

    @property
    def encoder_quantum_rad(self) -> float:
        """Handle angle per encoder count (rad); 0 without quantisation."""
        return self._q

    def reset(self, theta_rad: float | None = None) -> None:
        """Reset the state (velocity filter, previous angle, proxy, play, friction, Prony)."""
        self._prev = theta_rad
        self._v = 0.0
        self._gp = math.inf
        self._play = None  # chain angle behind the backlash (rad), set on the first step
        self._sdir = 0.0  # friction direction: +1 closing, -1 opening, 0 not moved yet
        self._h = [0.0] * self._np  # Prony states (N)
        self._fg_prev = 0.0  # coupled jaw force of the previous step (N)

    def _tissue(self, g: float) -> tuple[float, float]:
        f, k, _ = self.surrogate.evaluate_scalar(g, self.params.thickness_mm, self.params.material)
        s = self._scale
        if s != 1.0:
            f = f * s
            k = k * s
        return f, k  # force (N) and stiffness k_t = -dF/dgap >= 0 (N/mm)

    def quantise(self, theta_rad: float) -> float:
        """Encoder quantisation of an angle (rad)."""
        q = self._q
        return q * math.floor(theta_rad / q + 0.5) if q > 0.0 else theta_rad

    def step(self, theta_rad: float, theta_dot: float | None = None) -> StepOutput:
        """Advance one sample; returns the outputs.

        Parameters
        ----------
        theta_rad : float
            Measured handle angle (rad).
        theta_dot : float, optional
            Measured handle velocity (rad/s, e.g. from a tachometer or the host simulation).
            When given and finite, the damping acts on it instead of the filtered backward
            difference (the filter still runs); ``velocity_rad_per_s`` then reports it.
        """
        p = self.params
        th = float(theta_rad)
        clamped = False
        if th != th:  # NaN: hold the last valid angle
            th = self._prev if self._prev is not None else self._th_hi
            clamped = True
        elif math.isinf(th):
            th = self._th_hi if th > 0 else self._th_lo
            clamped = True
        else:
            clamped = not self._th_lo <= th <= self._th_hi
            th = self.quantise(th)
        th = min(max(th, self._th_lo), self._th_hi)  # a count can round past the end stop
        if self._prev is None:
            self._prev = th
        v_raw = (th - self._prev) / p.sample_time_s
        self._prev = th
        self._v = self._a * self._v + (1.0 - self._a) * v_raw
        thc = th  # chain angle: the encoder angle through the play
        hb = self._hb
        if hb > 0.0:
            y = th if self._play is None else self._play
            y = min(max(y, th - hb), th + hb)
            y = min(max(y, self._th_lo), self._th_hi)
            self._play = y
            thc = y
        th_deg = math.degrees(th)
        thc_deg = math.degrees(thc)
        g = kin.gap_mm(thc_deg, self._chain)
        f_g, k_g = self._tissue(g)
        contact = f_g > 0.0
        kc = self._kc
        if contact:
            hi = g + f_g / kc
            n_iter = NEWTON_ITERATIONS if self._gp != math.inf else COLD_START_ITERATIONS
            gp = min(max(self._gp, g), hi)
            for _ in range(n_iter):
                f_p, k_p = self._tissue(gp)
                r = kc * (gp - g) - f_p
                gp = gp - r / (kc + k_p)
                gp = min(max(gp, g), hi)
            fg = kc * (gp - g)
            coupling_active = self._tissue(gp)[1] > kc
        else:
            gp, fg, coupling_active = g, 0.0, False
        self._gp = gp
        fgr = fg  # rendered jaw force
        if self._np:
            d = fg - self._fg_prev
            self._fg_prev = fg
            h, pa, pg = self._h, self._pa, self._pg
            acc = 0.0
            for i in range(self._np):
                h[i] = pa[i] * h[i] + d
                acc += pg[i] * h[i]
            fgr = fg + acc
            if fgr < 0.0:
                fgr = 0.0
        fi_spring = kin.spring_handle_force_N(thc_deg, self._chain)
        fi = kin.handle_force_N(fgr, thc_deg, self._chain)  # includes the spring
        if not p.render_spring:
            fi -= fi_spring
        v_damp = self._v
        if theta_dot is not None and math.isfinite(theta_dot):
            v_damp = float(theta_dot)
        f_fric = 0.0
        if self._fric:
            vf = -v_damp * self._L3  # finger speed, mm/s, > 0 closing
            thr = p.friction_velocity_threshold_mm_per_s
            if vf > thr:
                self._sdir = 1.0
            elif vf < -thr:
                self._sdir = -1.0
            fit = fgr * kin.dgap_dtheta_mm_per_rad(thc_deg, self._chain) / self._L3
            f_fric = (
                p.friction_coulomb_N + p.friction_load_coefficient * abs(fit)
            ) * self._sdir + p.friction_viscous_N_s_per_mm * vf
            fi += f_fric
        fi -= p.damping_Nms_per_rad * v_damp / (self._L3 * 1e-3)
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
            force_jaw_N=fgr,
            force_tissue_N=f_g,
            gap_mm=g,
            proxy_gap_mm=gp,
            theta_deg=th_deg,
            velocity_rad_per_s=v_damp,
            contact=contact,
            tissue_warning=warn,
            coupling_active=coupling_active,
            saturated=saturated,
            theta_clamped=clamped,
            theta_chain_deg=thc_deg,
            force_handle_friction_N=f_fric,
        )


CONTROLLER_FILE_VERSION = 1


def params_to_dict(params: ControllerParams) -> dict:
    """JSON-ready dict of the parameters (``chain`` nested), with a format version."""
    from dataclasses import fields

    d = {f.name: getattr(params, f.name) for f in fields(params) if f.name != "chain"}
    for name in ("prony_g", "prony_tau_s"):
        d[name] = list(d[name])
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


# ----------------------------------------------------------------------------------------------
# trajectories (grasprom simulate)
# ----------------------------------------------------------------------------------------------

TRAJECTORY_COLUMNS = ("time_s", "theta_deg")

SIMULATION_COLUMNS = (
    "time_s",
    "theta_deg",
    "gap_mm",
    "force_jaw_N",
    "force_handle_N",
    "force_handle_spring_N",
    "torque_Nm",
    "contact",
    "tissue_warning",
    "force_tissue_N",
    "proxy_gap_mm",
    "velocity_rad_per_s",
    "coupling_active",
    "saturated",
    "theta_clamped",
    "theta_chain_deg",
    "force_handle_friction_N",
)


def validate_trajectory(df, params: ControllerParams, source: str = "trajectory"):
    """Check a trajectory table (``time_s``, ``theta_deg``); errors name the row and column.

    Returns float arrays ``(time_s, theta_deg)``.
    """
    import warnings

    import numpy as np
    import pandas as pd

    missing = [c for c in TRAJECTORY_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(
            f"{source}: missing column(s) {', '.join(missing)} (need time_s, theta_deg)"
        )
    if len(df) < 2:
        raise ValueError(f"{source}: needs at least 2 rows, got {len(df)}")
    out = []
    for col in TRAJECTORY_COLUMNS:
        vals = np.asarray(pd.to_numeric(df[col], errors="coerce"), dtype=float)
        bad = np.flatnonzero(~np.isfinite(vals))
        if bad.size:
            raise ValueError(
                f"{source}: column {col!r}, row {int(bad[0]) + 1}: not a finite number "
                f"({df[col].iloc[bad[0]]!r})"
            )
        out.append(vals)
    t, th = out
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        raise ValueError(
            f"{source}: column 'time_s' must increase strictly; row {int(bad[0]) + 2} "
            f"({t[bad[0] + 1]!r} s) does not follow row {int(bad[0]) + 1} ({t[bad[0]]!r} s)"
        )
    lo, hi = kin.theta_range_deg(params.chain_params)
    bad = np.flatnonzero((th < lo - 1e-9) | (th > hi + 1e-9))
    if bad.size:
        raise ValueError(
            f"{source}: column 'theta_deg', row {int(bad[0]) + 1}: {th[bad[0]]!r} deg outside "
            f"the chain's range [{lo:g}, {hi:g}] deg"
        )
    if np.ptp(th) > 0 and np.abs(th).max() <= 0.4:
        warnings.warn(
            f"{source}: theta_deg stays within 0.4 deg -- is it in radians? "
            "(the column must be in degrees)",
            stacklevel=2,
        )
    return t, th


def simulate(trajectory, params: ControllerParams, surrogate: Surrogate, source="trajectory"):
    """Run the controller on a handle-angle trajectory (the reference for all exports).

    The controller runs at its own rate ``1 / sample_time_s`` from the first to the last
    trajectory time; the angle is interpolated linearly between trajectory rows (a trajectory
    sampled at the controller rate is used as is).

    Parameters
    ----------
    trajectory : pandas.DataFrame
        Columns ``time_s`` (s, strictly increasing) and ``theta_deg`` (deg, in the chain range).
    params : ControllerParams
    surrogate : Surrogate

    Returns
    -------
    pandas.DataFrame
        One row per controller step, columns :data:`SIMULATION_COLUMNS`.
    """
    import numpy as np
    import pandas as pd

    t, th = validate_trajectory(trajectory, params, source)
    T = params.sample_time_s
    n = int(math.floor((t[-1] - t[0]) / T + 1e-9)) + 1
    ticks = t[0] + T * np.arange(n)
    theta = np.interp(ticks, t, th)
    ctl = ImpedanceController(params, surrogate)
    rows = [ctl.step(math.radians(x)) for x in theta]
    out = pd.DataFrame(rows, columns=StepOutput._fields)
    out.insert(0, "time_s", ticks)
    return out[list(SIMULATION_COLUMNS)]


def grasp_trajectory(
    *,
    close_s: float = 1.0,
    hold_s: float = 2.0,
    open_s: float = 1.0,
    theta_open_deg: float = 22.0,
    theta_closed_deg: float = 0.0,
    sample_time_s: float = 1e-3,
):
    """A grasp-hold-release handle trajectory (cosine ramps), columns ``time_s, theta_deg``."""
    import numpy as np
    import pandas as pd

    def ramp(a, b, dur):
        m = max(int(round(dur / sample_time_s)), 1)
        s = np.arange(m) / m
        return a + (b - a) * 0.5 * (1 - np.cos(np.pi * s))

    th = np.concatenate(
        [
            ramp(theta_open_deg, theta_closed_deg, close_s),
            np.full(max(int(round(hold_s / sample_time_s)), 1), theta_closed_deg),
            ramp(theta_closed_deg, theta_open_deg, open_s),
            [theta_open_deg],
        ]
    )
    return pd.DataFrame({"time_s": sample_time_s * np.arange(th.size), "theta_deg": th})
