"""Open-loop impedance controller: handle angle in, motor torque out (Python reference).

:class:`ImpedanceController` runs one step per sample with the
:class:`~grasprom.control.params.ControllerParams` and returns a :class:`StepOutput`.

One step, at the sample time ``T`` (default 1 ms, 1 kHz):

1. **Encoder**: the handle angle is quantised to the encoder resolution (one count of the
   motor encoder, ``2 pi r / (counts L3)`` rad of handle) and clamped into the chain's range
   (flagged; a NaN angle holds the last valid one, also flagged).
2. **Kinematics**: jaw gap ``g(theta)`` (mm) from :mod:`grasprom.chain.kinematics` (derived chain).
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
:func:`grasprom.gap.controller_params_from_augmented`; every one is off at its
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

Time-domain passivity observer / controller (``passivity_observer``, Hannaford & Ryu 2002,
"Time-domain passivity control of haptic interfaces", IEEE T-RA 18(1); Ryu, Kwon & Hannaford
2004), with ``rendering = "clipped"`` only; the field is then built with the limit
``stiffness_limit_Nm_per_rad * observer_stiffness_factor``, beyond the fixed Colgate bound:

* **Observer** (after the field, Prony terms and spring give the static handle force ``Fs_k``,
  N): the energy the controller has put into the handle port beyond what the ideal continuous
  rendering of ``Fs`` would have (J),
  ``W_k = W_{k-1} + (Fh_{k-1-d} - (Fs_{k-1} + Fs_k) / 2) (L3 1e-3) (theta_k - theta_{k-1})``,
  with ``theta`` the encoder angle (a NaN input holds the last angle and adds nothing),
  ``Fh_j`` the saturated handle force of step ``j`` (``torque_j / r``; ``tau = Fh L3`` is the
  torque at the handle pivot, ``torque L3 / r``) and ``d = observer_delay_samples``: the
  torque computed at step ``j`` acts on the handle over ``[j + d, j + d + 1]`` (the device's
  computation delay, :class:`~grasprom.control.DeviceParams` ``delay_samples``, 1), so the
  interval ``[k-1, k]`` was driven by step ``k-1-d``.  ``W = 0`` and no history at the first
  step.  Two choices differ from the textbook ``W_k = W_{k-1} + tau_{k-1} dtheta``, both
  measured in ``tests/control/test_observer.py`` (1 kHz, field 5x the Colgate bound):
  (a) the *delay*: with one sample of delay the torque of step ``k-1`` is not the one that
  drove the interval, the observer then sees about a third of the energy the delayed spring
  generates, and the loop keeps its limit cycle (0.74 J generated, as without the observer);
  (b) the *reference energy* ``(Fs_{k-1} + Fs_k) / 2 dtheta`` (trapezoid along the sampled path;
  Ryu, Preusche, Hannaford & Hirzinger 2005, "Time domain passivity control with reference
  energy following", IEEE T-RO 21(4)): without it the energy stored in the squeezed wall is a
  passivity credit the oscillation feeds on before the controller acts (0.55 J generated).
* **Controller**: the energy to dissipate is ``W_k`` minus what the controller has already
  planned and not yet seen measured (``sum alpha_j v_j^2 T`` of the last ``d`` steps, whose
  torques have not acted yet); if it is ``> 0`` and the velocity of the damping ``v``
  (filtered estimate or ``theta_dot``) is non-zero, ``alpha = min(W / (T v^2), alpha_max)``
  (N m s/rad, ``alpha_max = observer_max_damping_Nms_per_rad``; evaluated as ``alpha_max`` if
  ``W >= alpha_max T v^2``, else ``W / (T v^2)``, which never divides by an underflowed
  ``v^2 = 0``) adds ``-alpha v / (L3 1e-3)`` to the handle force, after the field, Prony terms,
  spring, friction and the virtual damping ``B``, before the saturation (step 6); its planned
  dissipation ``alpha v^2 T`` is remembered for ``d`` steps.  It is not subtracted from ``W``
  itself: the next observer updates measure it (its torque is part of ``Fh``), and counting it
  twice would give the observer a credit it never had.  What ``alpha_max`` leaves undissipated
  stays in ``W`` for the next steps.  Not rendered by the Arduino fixed-point export (refused).

Measurement effects of the augmented model (force-sensor offset/gain, latency) are not rendered:
``grasprom simulate --augmented`` applies them to an extra output column only.

Sign conventions (as :mod:`grasprom.chain.kinematics`): ``theta`` (rad inside, deg at the user
surface) decreases when closing; ``Fi > 0`` resists closing (the device pushes the handle open);
``torque > 0`` produces ``Fi > 0``.

The step allocates nothing (pure Python floats); the C core of the FMU and Arduino exports must
reproduce it (tests compare them).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from grasprom.chain import kinematics as kin
from grasprom.control.field import Field, build_field, prony_factor
from grasprom.control.params import ControllerParams
from grasprom.fe import MATERIAL_NAMES
from grasprom.surrogate import Surrogate

__all__ = ["COLD_START_ITERATIONS", "NEWTON_ITERATIONS", "ImpedanceController", "StepOutput"]

NEWTON_ITERATIONS = 3
"""Newton iterations of the virtual-coupling proxy per step (fixed: deterministic cost)."""

COLD_START_ITERATIONS = 30
"""Newton iterations on the first contact step after a reset (no warm start yet)."""


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

    Raises
    ------
    ValueError
        If it does not (the message names the materials / thickness range it covers).

    Examples
    --------
    >>> ctl = ImpedanceController(ControllerParams(), surrogate)   # doctest: +SKIP
    >>> out = ctl.step(math.radians(10.0))                          # doctest: +SKIP
    """

    def __init__(self, params: ControllerParams, surrogate: Surrogate) -> None:
        if params.material not in surrogate.materials:
            covered = [m for m in MATERIAL_NAMES if m in surrogate.materials]
            raise ValueError(
                f"material {params.material!r} is not in the surrogate, which covers "
                f"{', '.join(covered)} (the materials of its FE sweep; add it with "
                f"grasprom sweep --material {params.material} ...)"
            )
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
        self._d = int(params.observer_delay_samples)
        self._field = self._build_field() if params.rendering == "clipped" else None
        self.reset()

    def _build_field(self) -> Field:
        """The stiffness-clipped field of this case (:mod:`grasprom.control.field`)."""
        p = self.params
        return build_field(
            lambda g: self._tissue(g)[0],
            self._chain,
            p.field_stiffness_limit_Nm_per_rad,
            render_spring=p.render_spring,
            compliance_mm_per_N=p.jaw_compliance_mm_per_N,
            prony_factor=prony_factor(p.prony_g),
        )

    @property
    def field(self) -> Field | None:
        """The tabulated field of the clipped rendering (None with the coupling)."""
        return self._field

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
        self._w = 0.0  # observed energy into the handle (J)
        self._w_theta = None  # encoder angle of the previous step (rad), set on the first step
        self._fs_prev = 0.0  # static handle force of the previous step (N)
        self._fh_hist = [0.0] * (self._d + 1)  # handle forces of steps k-1 .. k-1-d (N)
        self._pc_hist = [0.0] * (self._d + 1)  # planned dissipation of steps k-1 .. k-1-d (J)
        self._pc_new = 0.0
        self._alpha = 0.0  # observer damping of the last step (N m s/rad)

    def _tissue(self, g: float) -> tuple[float, float]:
        """Surrogate force (N) and stiffness (N/mm) at the gap ``g`` (mm), times the scale."""
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

        The stages (module docstring) run in this order, each a small method; the C core of
        the exports mirrors them operation for operation.

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
        th, clamped = self._encoder(float(theta_rad))
        self._filter_velocity(th)
        thc = self._through_play(th) if self._hb > 0.0 else th
        th_deg = math.degrees(th)
        thc_deg = math.degrees(thc)
        g = kin.gap_mm(thc_deg, self._chain)
        f_g = self._tissue(g)[0]
        contact = f_g > 0.0
        if self._field is not None:
            fg, coupling_active = self._field.jaw_force_N(thc)
            gp = g
        elif contact:
            gp, fg, coupling_active = self._couple(g, f_g)
        else:
            gp, fg, coupling_active = g, 0.0, False
        self._gp = gp
        fgr = self._relax(fg) if self._np else fg  # rendered jaw force
        fi_spring = kin.spring_handle_force_N(thc_deg, self._chain)
        fi = kin.handle_force_N(fgr, thc_deg, self._chain)  # includes the spring
        if not p.render_spring:
            fi -= fi_spring
        v_damp = self._v
        if theta_dot is not None and math.isfinite(theta_dot):
            v_damp = float(theta_dot)
        fs = fi  # static handle force (N): field or coupling, Prony terms, spring
        f_fric = 0.0
        if self._fric:
            f_fric = self._friction(v_damp, fgr, thc_deg)
            fi += f_fric
        fi -= p.damping_Nms_per_rad * v_damp / (self._L3 * 1e-3)
        if p.passivity_observer:
            fi -= self._observe(th, v_damp, fs) * v_damp / (self._L3 * 1e-3)
        r_m = p.pulley_radius_mm * 1e-3
        torque = fi * r_m
        lim = p.torque_limit_Nm
        saturated = abs(torque) > lim
        if saturated:
            torque = math.copysign(lim, torque)
        if p.passivity_observer:
            self._observer_push(torque / r_m)
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

    @property
    def observer_energy_J(self) -> float:
        """Energy the controller has put into the handle, ``W`` (J; 0 without the observer)."""
        return self._w

    @property
    def observer_damping_Nms_per_rad(self) -> float:
        """Damping ``alpha`` the observer added in the last step (N m s/rad at the pivot)."""
        return self._alpha

    def _observe(self, th: float, v_damp: float, fs: float) -> float:
        """Passivity observer and controller (module docstring): the added damping (N m s/rad).

        ``th`` is the encoder angle (rad), ``v_damp`` the velocity of the damping (rad/s) and
        ``fs`` the static handle force of this step (N); updates the observed energy ``W`` (J).
        """
        d = self._d
        if self._w_theta is None:
            self._w_theta = th
            self._fs_prev = fs
        fs_mean = 0.5 * (self._fs_prev + fs)
        self._w = self._w + (self._fh_hist[d] - fs_mean) * (self._L3 * 1e-3) * (th - self._w_theta)
        self._w_theta = th
        self._fs_prev = fs
        pending = 0.0
        for i in range(d):
            pending += self._pc_hist[i]
        we = self._w - pending
        alpha = 0.0
        self._pc_new = 0.0
        if we > 0.0 and v_damp != 0.0:
            amax = self.params.observer_max_damping_Nms_per_rad
            tv = self.params.sample_time_s * (v_damp * v_damp)
            alpha = amax if we >= amax * tv else we / tv
            self._pc_new = alpha * tv
        self._alpha = alpha
        return alpha

    def _observer_push(self, fh: float) -> None:
        """Remember this step's (saturated) handle force (N) and planned dissipation (J)."""
        h, e = self._fh_hist, self._pc_hist
        for i in range(self._d, 0, -1):
            h[i] = h[i - 1]
            e[i] = e[i - 1]
        h[0] = fh
        e[0] = self._pc_new

    def _encoder(self, th: float) -> tuple[float, bool]:
        """Encoder angle (rad, quantised, in range) and whether the input was clamped.

        A NaN holds the last valid angle (the open end before the first), an infinity goes to
        its end stop; both are flagged.
        """
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
        return th, clamped

    def _filter_velocity(self, th: float) -> None:
        """Backward difference of the encoder angle ``th`` (rad) through the low-pass (rad/s)."""
        if self._prev is None:
            self._prev = th
        v_raw = (th - self._prev) / self.params.sample_time_s
        self._prev = th
        self._v = self._a * self._v + (1.0 - self._a) * v_raw

    def _through_play(self, th: float) -> float:
        """Chain angle (rad) behind the backlash play operator, for the encoder angle ``th``."""
        hb = self._hb
        y = th if self._play is None else self._play
        y = min(max(y, th - hb), th + hb)
        y = min(max(y, self._th_lo), self._th_hi)
        self._play = y
        return y

    def _couple(self, g: float, f_g: float) -> tuple[float, float, bool]:
        """Virtual coupling at the kinematic gap ``g`` (mm) with tissue force ``f_g`` > 0 (N).

        Safeguarded Newton on ``k_c (g_p - g) = F(g_p)`` in ``[g, g + f_g / k_c]``, warm-started
        from the last proxy.  Returns the proxy gap (mm), the coupled jaw force (N) and whether
        the coupling is active (tissue stiffer than ``k_c`` at the proxy).
        """
        kc = self._kc
        hi = g + f_g / kc
        n_iter = NEWTON_ITERATIONS if self._gp != math.inf else COLD_START_ITERATIONS
        gp = min(max(self._gp, g), hi)
        for _ in range(n_iter):
            f_p, k_p = self._tissue(gp)
            r = kc * (gp - g) - f_p
            gp = gp - r / (kc + k_p)
            gp = min(max(gp, g), hi)
        fg = kc * (gp - g)
        return gp, fg, self._tissue(gp)[1] > kc

    def _relax(self, fg: float) -> float:
        """Prony series on the coupled jaw force ``fg`` (N): the rendered jaw force (N, >= 0)."""
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
        return fgr

    def _friction(self, v_damp: float, fgr: float, thc_deg: float) -> float:
        """Rendered mechanism friction at the finger (N, > 0 resists closing).

        ``v_damp`` is the handle velocity of the damping (rad/s), ``fgr`` the rendered jaw force
        (N) and ``thc_deg`` the chain angle (deg); updates the remembered friction direction.
        """
        p = self.params
        vf = -v_damp * self._L3  # finger speed, mm/s, > 0 closing
        thr = p.friction_velocity_threshold_mm_per_s
        if vf > thr:
            self._sdir = 1.0
        elif vf < -thr:
            self._sdir = -1.0
        fit = fgr * kin.dgap_dtheta_mm_per_rad(thc_deg, self._chain) / self._L3
        return (
            p.friction_coulomb_N + p.friction_load_coefficient * abs(fit)
        ) * self._sdir + p.friction_viscous_N_s_per_mm * vf
