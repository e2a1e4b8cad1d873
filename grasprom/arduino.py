"""Arduino (ATmega328P) export of the impedance controller, verified with avr-gcc and simavr.

The Arduino Uno has no FPU, 2 KB RAM and 16 MHz; a 1 kHz loop leaves 1,600 cycles per step for
the controller.  The double-precision core of the FMU (``grasp_core.c``: trigonometric chain,
three Newton iterations of the coupling proxy on the Hermite surrogate) does not fit (see the
README figures), so the export uses a fixed-point core, ``csrc/grasp_fixed.c``, that evaluates
the same controller from tables this module computes in double precision:

* the rendered jaw force through the virtual coupling, ``Fg = k_c (g_p - g)`` with the proxy
  ``g_p`` solved *to convergence* on the float surrogate, along the handle angle (in encoder
  counts) for every thickness node of every material, on a dyadic grid per material (segment
  widths 2^k counts, chosen so that linear interpolation reproduces every curve within
  ``tol`` of the jaw-force full scale, the largest jaw force the export renders); thickness is a
  run-time parameter, blended linearly between nodes at ``gf_init()``;
* the chain on a uniform grid: ``a = g'(theta) / L3`` (handle force per jaw force) and the
  return-spring handle force;
* the flag thresholds (tissue warning, coupling active) in counts per thickness node.

Error budget: the rendered handle force (= torque / pulley radius) of the fixed-point core
against the Python reference on the float surrogate, in percent of the device's full-scale
handle force ``torque_limit / pulley_radius`` (the force that saturates the motor), over every
encoder position of the handle's range, every material and thicknesses on and between the
nodes.  The jaw-force error in percent of the jaw-force full scale (the quantity ``tol``
bounds on the thickness nodes) is reported too.

The host build (gcc) of the same code gives bit-identical outputs to the AVR run (simavr),
so most checks run on the host.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np
from numpy.typing import NDArray

from . import kinematics as kin
from .ccore import CSRC
from .controller import ControllerParams
from .materials import MATERIAL_NAMES
from .surrogate import Surrogate

MCU = "atmega328p"
F_CPU_HZ = 16_000_000
FLASH_BUDGET_B = 8192
"""Flash budget for tables + core (bytes)."""
RAM_BUDGET_B = 512
"""RAM budget of the core: static state + stack of the step (bytes)."""
CYCLE_BUDGET = 1600
"""Cycles per controller step: 100 us at 16 MHz."""
ERROR_BUDGET = 0.005
"""Handle-force error budget, fraction of the full-scale handle force."""

FIXED_SOURCES = ("grasp_fixed.c", "grasp_fixed.h")
SKETCH_NAME = "grasprom_controller"
FLAG_NAMES = ("contact", "tissue_warning", "coupling_active", "saturated", "theta_clamped")
_OUT_DTYPE = np.dtype(
    [("torque", "<i4"), ("fi", "<i4"), ("fg", "<i4"), ("vel", "<i4"), ("count", "<i2"),
     ("flags", "u1")]
)  # fmt: skip


# --------------------------------------------------------------------------- reference
def coupled_jaw_force(
    surrogate: Surrogate, gap_mm: NDArray, thickness_mm: float, material: str, kc: float
) -> tuple[NDArray, NDArray]:
    """Jaw force through the virtual coupling, proxy solved to convergence (vectorised).

    Solves ``kc (g_p - g) = F(g_p)`` in ``[g, g + F(g)/kc]`` by bisection (the residual
    increases with ``g_p``), to machine precision: the fixed point the controller's three
    warm-started Newton iterations track.

    Parameters
    ----------
    surrogate : Surrogate
    gap_mm : ndarray
        Kinematic jaw gaps (mm).
    thickness_mm : float
    material : str
    kc : float
        Coupling stiffness (N/mm).

    Returns
    -------
    (ndarray, ndarray)
        Rendered jaw force ``kc (g_p - g)`` (N) and the proxy gap ``g_p`` (mm).
    """
    g = np.asarray(gap_mm, dtype=float)
    f = surrogate.force(g, thickness_mm, material)
    lo, hi = g.copy(), g + f / kc
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        r = kc * (mid - g) - surrogate.force(mid, thickness_mm, material)
        neg = r < 0.0
        lo = np.where(neg, mid, lo)
        hi = np.where(neg, hi, mid)
    gp = np.where(f > 0.0, 0.5 * (lo + hi), g)
    return kc * (gp - g), gp


def _chain_terms(theta_rad: NDArray, chain: kin.ChainParams) -> tuple[NDArray, NDArray, NDArray]:
    """Gap (mm), ``a = g'/L3`` (1/rad... N per N) and spring handle force (N), no range check."""
    c = chain._c
    xc, d1, _d2, _s, _cb = kin._array_state(np.asarray(theta_rad, dtype=float), chain)
    gap = chain.gap_closed_mm + c.gap_per_xc * (xc - c.xc_closed)
    u = (c.xc_open - xc) * c.stroke_sign
    fs = chain.spring_preload_N + chain.spring_k_N_per_mm * u
    du = -d1 * c.stroke_sign
    return gap, c.gap_per_xc * d1 / chain.L3_mm, -fs * du / chain.L3_mm


def encoder_quantum_rad(params: ControllerParams) -> float:
    """Handle angle per encoder count (rad), as :class:`ImpedanceController`."""
    n = int(params.encoder_counts_per_rev)
    if n <= 0:
        raise ValueError("the Arduino export needs an encoder: encoder_counts_per_rev > 0")
    return 2.0 * math.pi * params.pulley_radius_mm / (n * params.chain_params.L3_mm)


@dataclass
class ReferenceRun:
    """Float reference outputs of one test case (arrays over the steps, SI-like units)."""

    torque_Nm: NDArray
    force_handle_N: NDArray
    force_jaw_N: NDArray
    velocity_rad_per_s: NDArray
    count: NDArray
    flags: dict[str, NDArray]


def reference_run(
    params: ControllerParams,
    surrogate: Surrogate,
    material: str,
    thickness_mm: float,
    counts: Sequence[int] | NDArray,
) -> ReferenceRun:
    """The Python reference (double, float surrogate, converged coupling) on encoder counts.

    Same step as :meth:`grasprom.controller.ImpedanceController.step` with ``theta = count *
    q``, except that the coupling proxy is solved to convergence (the controller's warm-started
    Newton iterations converge to it on any realistic trajectory; see the tests).

    Parameters
    ----------
    params : ControllerParams
    surrogate : Surrogate
    material : str
    thickness_mm : float
        Inside the surrogate's range.
    counts : sequence of int
        Handle angles in encoder counts, one per step.

    Returns
    -------
    ReferenceRun
    """
    chain = params.chain_params
    q = encoder_quantum_rad(params)
    th_lo, th_hi = (math.radians(v) for v in kin.theta_range_deg(chain))
    raw = np.asarray(counts, dtype=np.int64)
    th_raw = raw * q
    clamped = (th_raw < th_lo) | (th_raw > th_hi)
    th = np.clip(th_raw, th_lo, th_hi)
    a = math.exp(-2.0 * math.pi * params.velocity_cutoff_Hz * params.sample_time_s)
    v = np.empty(len(th))
    vs, prev = 0.0, None
    for i, t in enumerate(th):
        if prev is None:
            prev = t
        vs = a * vs + (1.0 - a) * (t - prev) / params.sample_time_s
        prev = t
        v[i] = vs
    gap, ca, cb = _chain_terms(th, chain)
    f_t = surrogate.force(gap, thickness_mm, material)
    kc = params.coupling_stiffness_N_per_mm
    fg, gp = coupled_jaw_force(surrogate, gap, thickness_mm, material, kc)
    contact = f_t > 0.0
    k_p = surrogate.stiffness(gp, thickness_mm, material)
    fi = fg * ca + (cb if params.render_spring else 0.0)
    fi = fi - params.damping_Nms_per_rad * v / (chain.L3_mm * 1e-3)
    r_m = params.pulley_radius_mm * 1e-3
    torque = fi * r_m
    sat = np.abs(torque) > params.torque_limit_Nm
    torque = np.where(sat, np.copysign(params.torque_limit_Nm, torque), torque)
    area = params.jaw_length_mm * 0.5 * math.pi * (params.diameter_mm - thickness_mm)
    warn = (f_t >= params.force_warning_N) | (f_t / area >= params.pressure_warning_MPa)
    return ReferenceRun(
        torque_Nm=torque,
        force_handle_N=torque / r_m,
        force_jaw_N=fg,
        velocity_rad_per_s=v,
        count=np.round(th / q).astype(int),
        flags={
            "contact": contact,
            "tissue_warning": warn,
            "coupling_active": contact & (k_p > kc),
            "saturated": sat,
            "theta_clamped": clamped,
        },
    )


# --------------------------------------------------------------------------- tables
@dataclass
class MaterialTable:
    """Fixed-point tables of one material (see ``grasp_fixed_tables.h``)."""

    name: str
    x: list[int]  # grid counts
    k: list[int]  # log2 segment widths
    thickness_um: list[int]
    y: list[list[int]]  # per thickness, jaw force in units of 2^fg_shift mN
    warn: list[int]
    active: list[int]


@dataclass
class FixedTables:
    """Everything ``grasp_fixed_config.h`` and ``grasp_fixed_tables.h`` hold.

    Attributes are the generated constants (``GF_*``, integers) and per-material tables; see
    :meth:`config_source` / :meth:`tables_source` for units and scalings.
    """

    params: ControllerParams
    tol: float
    jaw_fs_N: float
    q_rad: float
    n_lo: int
    n_top: int
    n_contact: int
    fg_shift: int
    ch_shift: int
    ch_a: list[int]
    ch_b: list[int]
    fi_limit_mN: int
    r_q8: int
    vel_b: int
    kd: int
    kd_shift: int
    materials: list[MaterialTable] = field(default_factory=list)
    fixed_point: bool = True
    fe_hash: str = ""

    @property
    def nx_max(self) -> int:
        """Largest grid of any material (size of the RAM node table)."""
        return max(len(m.x) for m in self.materials)

    @property
    def table_bytes(self) -> int:
        """Flash of the tables (bytes, without alignment)."""
        n = 4 * len(self.ch_a)
        for m in self.materials:
            n += 3 * len(m.x) - 1 + 2 * len(m.thickness_um) * (3 + len(m.x)) + 18
        return n

    def config_source(self) -> str:
        """C source of ``grasp_fixed_config.h`` (scalar constants)."""
        p = self.params
        lines = [
            "/* Generated by grasprom.arduino -- do not edit.",
            f" * Export: tol {self.tol:g} (jaw-force table tolerance, fraction of the jaw-force "
            f"full scale {self.jaw_fs_N:.6g} N), surrogate FE hash {self.fe_hash}.",
            f" * Controller: pulley {p.pulley_radius_mm:g} mm, torque limit "
            f"{p.torque_limit_Nm:g} N m, coupling {p.coupling_stiffness_N_per_mm:g} N/mm,",
            f" *   spring {p.spring_k_N_per_mm:g} N/mm (render {int(p.render_spring)}), damping "
            f"{p.damping_Nms_per_rad:g} N m s/rad, velocity cutoff {p.velocity_cutoff_Hz:g} Hz,",
            f" *   sample time {p.sample_time_s:g} s, encoder {p.encoder_counts_per_rev} "
            f"counts/rev, warnings {p.force_warning_N:g} N / {p.pressure_warning_MPa:g} MPa.",
            " */",
            "#ifndef GRASP_FIXED_CONFIG_H",
            "#define GRASP_FIXED_CONFIG_H",
            "",
        ]
        if not self.fixed_point:
            lines += ["#define GF_FLOAT 1 /* float build of the same code path */", ""]
        defs = [
            (
                "GF_N_MATERIALS",
                len(self.materials),
                "materials: " + ", ".join(f"{i} {m.name}" for i, m in enumerate(self.materials)),
            ),
            ("GF_NX_MAX", self.nx_max, "largest angle grid (RAM node table)"),
            ("GF_N_LO", self.n_lo, "closed end of the handle range, counts"),
            ("GF_N_TOP", self.n_top, "open end of the handle range, counts"),
            ("GF_N_CONTACT", self.n_contact, "jaws touch the tube for count < GF_N_CONTACT"),
            ("GF_FG_SHIFT", self.fg_shift, "jaw-force table unit: 2^GF_FG_SHIFT mN"),
            ("GF_CH_SHIFT", self.ch_shift, "chain grid step: 2^GF_CH_SHIFT counts"),
            ("GF_CH_N", len(self.ch_a), "chain grid nodes"),
            ("GF_FI_LIMIT_MN", f"{self.fi_limit_mN}L", "handle force at the torque limit, mN"),
            ("GF_TORQUE_LIMIT_UNM", f"{round(p.torque_limit_Nm * 1e6)}L", "torque limit, uN m"),
            ("GF_R_Q8", f"{self.r_q8}L", "pulley radius, mm Q8 (torque uNm = Fi mN * r mm)"),
            ("GF_VEL_B", f"{self.vel_b}u", "(1 - a) of the velocity low-pass, Q16"),
            ("GF_KD", f"{self.kd}u", "damping, mN per count/sample, Q GF_KD_SHIFT"),
            ("GF_KD_SHIFT", self.kd_shift, ""),
            ("GF_RENDER_SPRING", int(p.render_spring), "render the return spring"),
            ("GF_SAMPLE_US", f"{round(p.sample_time_s * 1e6)}UL", "controller period, us"),
        ]
        for name, val, doc in defs:
            lines.append(f"#define {name} {val}" + (f" /* {doc} */" if doc else ""))
        lines += [
            f"#define GF_Q_RAD {self.q_rad!r} /* handle angle per count, rad */",
            "",
            "#endif",
        ]
        return "\n".join(lines) + "\n"

    def tables_source(self) -> str:
        """C source of ``grasp_fixed_tables.h`` (PROGMEM tables, included by grasp_fixed.c)."""
        p = self.params

        def arr(ctype: str, name: str, vals: Sequence[int], doc: str) -> str:
            body = ",\n    ".join(
                ", ".join(str(int(v)) for v in vals[i : i + 12]) for i in range(0, len(vals), 12)
            )
            return (
                f"/* {doc} */\nstatic const {ctype} {name}[{len(vals)}] GF_PROGMEM = {{\n"
                f"    {body}\n}};\n"
            )

        out = [
            "/* Generated by grasprom.arduino -- do not edit.  Included by grasp_fixed.c only.",
            " *",
            f" * Angle: count n <-> handle angle theta = n * {self.q_rad!r} rad (one encoder count",
            f" * of the motor: 2 pi r / (counts L3)); handle range [{self.n_lo}, {self.n_top}].",
            " * Chain (uniform grid n = GF_N_LO + i 2^GF_CH_SHIFT, linear interpolation):",
            " *   gf_ch_a = g'(theta) / L3, jaw-to-handle force ratio by virtual work, Q15;",
            f" *   gf_ch_b = return-spring handle force, mN (spring {p.spring_k_N_per_mm:g} N/mm, "
            f"preload {p.chain.spring_preload_N:g} N).",
            " * Per material (dyadic grid x, segment [x[i], x[i+1]) of width 2^k[i] counts):",
            " *   t: thickness nodes, um; y: rendered jaw force kc (g_p - g) with the proxy g_p",
            " *   solved to convergence on the float surrogate, units 2^GF_FG_SHIFT mN, one row",
            " *   of nx values per thickness (jaw force 0 for n >= GF_N_CONTACT);",
            " *   warn / active: largest count with tissue warning / coupling active per",
            f" *   thickness (GF_N_LO - 1 = never).  Grid tolerance {self.tol:g} x "
            f"{self.jaw_fs_N:.6g} N (jaw-force full scale).",
            " */",
            "#ifndef GRASP_FIXED_TABLES_H",
            "#define GRASP_FIXED_TABLES_H",
            "",
            arr("uint16_t", "gf_ch_a", self.ch_a, "g'/L3, Q15"),
            arr("int16_t", "gf_ch_b", self.ch_b, "spring handle force, mN"),
        ]
        descs = []
        for m in self.materials:
            nm = f"gf_{m.name}"
            out.append(arr("uint16_t", f"{nm}_x", m.x, f"{m.name}: grid, counts"))
            out.append(arr("uint8_t", f"{nm}_k", m.k, f"{m.name}: log2 segment widths"))
            out.append(arr("uint16_t", f"{nm}_t", m.thickness_um, f"{m.name}: thickness, um"))
            flat = [v for row in m.y for v in row]
            out.append(arr("uint16_t", f"{nm}_y", flat, f"{m.name}: jaw force, rows by thickness"))
            out.append(arr("int16_t", f"{nm}_warn", m.warn, f"{m.name}: tissue-warning counts"))
            out.append(arr("int16_t", f"{nm}_active", m.active, f"{m.name}: coupling-active"))
            descs.append(
                f"    {{{nm}_x, {nm}_k, {nm}_t, {nm}_y, {nm}_warn, {nm}_active, {len(m.x)}, "
                f"{len(m.thickness_um)}}}"
            )
        out.append("static const gf_material_t gf_materials[GF_N_MATERIALS] GF_PROGMEM = {")
        out.append(",\n".join(descs))
        out.append("};\n")
        out.append("#endif")
        return "\n".join(out) + "\n"


def _dyadic_grid(curves: NDArray, eps: float, n_span: int) -> tuple[list[int], list[int]]:
    """Dyadic breakpoints (offsets from 0) reproducing every row of ``curves`` within ``eps``.

    ``curves[:, j]`` is the value at offset ``j`` (``0 <= j <= n_span``); values beyond are
    taken as the last one.  Returns the node offsets and log2 widths of the segments.
    """
    top = 1
    while top < n_span:
        top *= 2
    ext = np.concatenate([curves, np.repeat(curves[:, -1:], top + 1 - curves.shape[1], 1)], 1)
    starts: list[tuple[int, int]] = []

    def rec(a: int, k: int) -> None:
        b = a + (1 << k)
        if k > 1:  # width 2 at least: the core interpolates with a 16 - k bit shift
            idx = np.arange(a, b + 1)
            lin = ext[:, a : a + 1] + (ext[:, b : b + 1] - ext[:, a : a + 1]) * (idx - a) / (b - a)
            if np.max(np.abs(lin - ext[:, a : b + 1])) > eps:
                rec(a, k - 1)
                rec(a + (1 << (k - 1)), k - 1)
                return
        starts.append((a, k))

    rec(0, int(round(math.log2(top))))
    kept = [(a, k) for a, k in starts if a < n_span]
    xs = [a for a, _ in kept] + [kept[-1][0] + (1 << kept[-1][1])]
    return xs, [k for _, k in kept]


def build_tables(
    surrogate: Surrogate, params: ControllerParams, tol: float = 0.01, *, fixed_point: bool = True
) -> FixedTables:
    """Compute the fixed-point tables of an export.

    Parameters
    ----------
    surrogate : Surrogate
        Must hold every material of :data:`grasprom.materials.MATERIAL_NAMES`.
    params : ControllerParams
        Controller parameters baked into the tables (chain, spring, coupling, pulley, limits,
        filter, damping, encoder); thickness and material stay run-time parameters.
    tol : float
        Grid tolerance: linear interpolation reproduces every tabulated jaw-force curve within
        ``tol`` times the jaw-force full scale (the largest rendered jaw force of the tables,
        over every material, thickness node and handle angle); smaller = more flash.
    fixed_point : bool
        Recorded for the config header (``GF_FLOAT`` when False).

    Returns
    -------
    FixedTables
    """
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be finite and > 0, got {tol!r}")
    missing = [m for m in MATERIAL_NAMES if m not in surrogate.materials]
    if missing:
        raise ValueError(f"surrogate lacks material(s) {', '.join(missing)}")
    if params.torque_limit_Nm > 8.0:
        raise ValueError("torque_limit_Nm > 8 N m overflows the fixed-point torque (uN m, Q8)")
    chain = params.chain_params
    q = encoder_quantum_rad(params)
    lo, hi = (math.radians(v) for v in kin.theta_range_deg(chain))
    n_lo, n_top = math.ceil(lo / q - 1e-9), math.floor(hi / q + 1e-9)
    if n_top > 30000 or n_lo < -30000:
        raise ValueError("encoder resolution too fine for 16-bit counts")
    counts = np.arange(n_lo, n_top + 1)
    gap, _, _ = _chain_terms(counts * q, chain)
    d = surrogate.diameter_mm
    n_contact = int(counts[np.argmax(gap >= d)]) if np.any(gap >= d) else n_top + 1
    kc = params.coupling_stiffness_N_per_mm

    # jaw-force curves, thresholds
    span = n_contact - n_lo
    cn = np.arange(n_lo, n_contact + 1)
    g_c, _, _ = _chain_terms(cn * q, chain)
    mats_raw = []
    fg_max = 0.0
    for name in MATERIAL_NAMES:
        ts = surrogate.thicknesses(name)
        rows, warn, active = [], [], []
        for t in ts:
            fg, gp = coupled_jaw_force(surrogate, g_c, t, name, kc)
            fg[-1] = 0.0  # n_contact: no contact
            rows.append(fg)
            f_t = surrogate.force(g_c, t, name)
            area = params.jaw_length_mm * 0.5 * math.pi * (params.diameter_mm - t)
            w = (f_t >= params.force_warning_N) | (f_t / area >= params.pressure_warning_MPa)
            a = (f_t > 0) & (surrogate.stiffness(gp, t, name) > kc)
            warn.append(int(cn[w].max()) if np.any(w) else n_lo - 1)
            active.append(int(cn[a].max()) if np.any(a) else n_lo - 1)
        fg_max = max(fg_max, max(float(r.max()) for r in rows))
        mats_raw.append((name, ts, np.array(rows), warn, active))
    eps = tol * fg_max
    fg_shift = 0
    while fg_max * 1000.0 / (1 << fg_shift) > 32000:  # int16 node values and differences
        fg_shift += 1
    unit = (1 << fg_shift) * 1e-3  # N per table unit
    materials = []
    for name, ts, rows, warn, active in mats_raw:
        xs, ks = _dyadic_grid(rows, max(eps - 0.5 * unit, 0.5 * eps), span)
        if len(xs) > 255:
            raise ValueError(f"tol {tol:g} needs {len(xs)} grid nodes for {name} (max 255)")
        ext = np.concatenate([rows, np.zeros((rows.shape[0], xs[-1] + 1 - rows.shape[1]))], 1)
        y = [[int(round(r[x] / unit)) for x in xs] for r in ext]
        materials.append(
            MaterialTable(
                name=name,
                x=[n_lo + x for x in xs],
                k=ks,
                thickness_um=[int(round(t * 1000)) for t in ts],
                y=y,
                warn=warn,
                active=active,
            )
        )

    # chain tables on a uniform grid (error a tenth of the jaw tolerance)
    _, ca_all, cb_all = _chain_terms(counts * q, chain)
    if float(np.max(ca_all)) >= 2.0:
        raise ValueError("g'/L3 >= 2 overflows the Q15 chain table")
    ch_shift = 0
    for s in range(8, -1, -1):
        nodes = n_lo + (np.arange(((n_top - n_lo) >> s) + 2) << s)
        _, na, nb = _chain_terms(nodes * q, chain)
        ia = np.interp(counts, nodes, na)
        ib = np.interp(counts, nodes, nb) if params.render_spring else cb_all
        err = np.max(np.abs(ia - ca_all)) * fg_max + np.max(np.abs(ib - cb_all))
        if err <= 0.1 * eps:
            ch_shift = s
            break
    nodes = n_lo + (np.arange(((n_top - n_lo) >> ch_shift) + 2) << ch_shift)
    _, na, nb = _chain_terms(nodes * q, chain)
    ch_a = [int(round(v * 32768)) for v in na]
    ch_b = [int(round(v * 1000)) for v in nb]

    r_mm = params.pulley_radius_mm
    a_f = math.exp(-2.0 * math.pi * params.velocity_cutoff_Hz * params.sample_time_s)
    kd_val = (
        1000.0 * params.damping_Nms_per_rad * q / (params.sample_time_s * chain.L3_mm * 1e-3)
    )  # mN per count/sample
    kd_shift = 0
    kd_shift = 8 if kd_val * 256 <= 65535 else 0  # a byte shift is free on the AVR
    kd = int(round(kd_val * (1 << kd_shift)))
    if kd > 65535:
        raise ValueError("damping too large for the fixed-point gain")
    return FixedTables(
        params=params,
        tol=tol,
        jaw_fs_N=fg_max,
        q_rad=q,
        n_lo=n_lo,
        n_top=n_top,
        n_contact=n_contact,
        fg_shift=fg_shift,
        ch_shift=ch_shift,
        ch_a=ch_a,
        ch_b=ch_b,
        fi_limit_mN=int(round(params.torque_limit_Nm / (r_mm * 1e-3) * 1000.0)),
        r_q8=int(round(r_mm * 256)),
        vel_b=int(round((1.0 - a_f) * 65536)),
        kd=kd,
        kd_shift=kd_shift,
        materials=materials,
        fixed_point=fixed_point,
        fe_hash=surrogate.fe_hash,
    )


def write_core(tables: FixedTables, directory: str | Path) -> list[Path]:
    """Write the core sources and the generated headers into ``directory``."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for f in FIXED_SOURCES:
        shutil.copy(CSRC / f, d / f)
        paths.append(d / f)
    (d / "grasp_fixed_config.h").write_text(tables.config_source())
    (d / "grasp_fixed_tables.h").write_text(tables.tables_source())
    return paths + [d / "grasp_fixed_config.h", d / "grasp_fixed_tables.h"]


# --------------------------------------------------------------------------- test vectors
@dataclass
class TestCase:
    """One run of the core: material, thickness (um) and the encoder counts of every step."""

    material: str
    thickness_um: int
    counts: NDArray


def sweep_counts(tables: FixedTables, step_open: int = 5) -> NDArray:
    """Close one count per step from beyond the open end to beyond the closed end, reopen."""
    close = np.arange(tables.n_top + 3, tables.n_lo - 4, -1)
    reopen = np.arange(tables.n_lo - 3, tables.n_top + 4, step_open)
    return np.concatenate([close, reopen]).astype(np.int16)


def default_cases(tables: FixedTables, surrogate: Surrogate, dense: bool = False) -> list[TestCase]:
    """Every material at several thicknesses (nodes, between nodes, ends, beyond the range).

    ``dense``: every thickness node and every midpoint (the error figures); otherwise four
    thicknesses per material (the AVR run).
    """
    counts = sweep_counts(tables)
    cases = []
    for m in tables.materials:
        t = m.thickness_um
        if dense:
            ths = sorted(set(t) | {(a + b) // 2 for a, b in zip(t[:-1], t[1:])})
        else:
            ths = [t[0], (t[len(t) // 2] + t[len(t) // 2 + 1]) // 2 + 7, t[len(t) // 2], t[-1]]
        cases += [TestCase(m.name, th, counts) for th in ths]
    return cases


def vectors_source(tables: FixedTables, cases: Sequence[TestCase]) -> str:
    """C source of ``gf_vectors.h`` for :file:`gf_test_main.c`."""
    names = [m.name for m in tables.materials]
    allc: list[int] = []
    starts: dict[bytes, int] = {}  # identical count sequences are stored once
    rows = []
    for c in cases:
        key = np.asarray(c.counts, dtype=np.int16).tobytes()
        if key not in starts:
            starts[key] = len(allc)
            allc += [int(v) for v in c.counts]
        rows.append(
            f"    {{{names.index(c.material)}, {c.thickness_um}, {starts[key]}, {len(c.counts)}}}"
        )
    body = ",\n    ".join(
        ", ".join(str(v) for v in allc[i : i + 16]) for i in range(0, len(allc), 16)
    )
    return (
        "/* Generated by grasprom.arduino: test vectors. */\n"
        f"#define GT_N_CASES {len(cases)}\n"
        f"static const gt_case_t gt_cases[GT_N_CASES] = {{\n" + ",\n".join(rows) + "\n};\n"
        f"static const int16_t gt_counts[{len(allc)}] GT_PROGMEM = {{\n    {body}\n}};\n"
    )


@dataclass
class CoreRun:
    """Outputs of the C core on a list of cases (raw integers, as the C structure)."""

    init_rc: list[int]
    outputs: list[NDArray]  # structured arrays (_OUT_DTYPE), one per case
    raw: bytes


def parse_output(data: bytes, cases: Sequence[TestCase]) -> CoreRun:
    """Split the byte stream of :file:`gf_test_main.c` into cases."""
    pos, rcs, outs = 0, [], []
    for c in cases:
        rcs.append(int(np.frombuffer(data, np.int8, 1, pos)[0]))
        pos += 1
        n = len(c.counts)
        outs.append(np.frombuffer(data, _OUT_DTYPE, n, pos))
        pos += n * _OUT_DTYPE.itemsize
    if pos != len(data):
        raise RuntimeError(f"core output has {len(data)} bytes, expected {pos}")
    return CoreRun(rcs, outs, data)


def _run(cmd: list[str], what: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    res = subprocess.run(cmd, capture_output=True, cwd=cwd)
    if res.returncode != 0:
        raise RuntimeError(
            f"{what} failed:\n{' '.join(cmd)}\n{res.stderr.decode(errors='replace')}"
        )
    return res


def _need(tool: str, package: str) -> str:
    path = shutil.which(tool)
    if path is None:
        raise RuntimeError(f"{tool} not found (Debian: apt-get install {package})")
    return path


def run_host(tables: FixedTables, cases: Sequence[TestCase], directory: str | Path) -> CoreRun:
    """Build the core + test driver for the host (gcc -Wall -Wextra -Werror) and run it."""
    _need("gcc", "gcc")
    d = Path(directory)
    write_core(tables, d)
    shutil.copy(CSRC / "gf_test_main.c", d / "gf_test_main.c")
    (d / "gf_vectors.h").write_text(vectors_source(tables, cases))
    exe = d / "gf_host_test"
    _run(["gcc", "-O2", "-std=c99", "-Wall", "-Wextra", "-Werror", "-o", str(exe),
          str(d / "grasp_fixed.c"), str(d / "gf_test_main.c"), "-lm"], "host build")  # fmt: skip
    return parse_output(_run([str(exe)], "host run").stdout, cases)


AVR_CFLAGS = ["-mmcu=" + MCU, "-Os", "-std=gnu99", "-Wall", "-Wextra", "-Werror",
              f"-DF_CPU={F_CPU_HZ}UL"]  # fmt: skip


def build_avr_test(
    tables: FixedTables, cases: Sequence[TestCase], directory: str | Path, mcu: str = MCU
) -> Path:
    """Cross-compile the core + test driver (vectors in flash) with avr-gcc; returns the ELF."""
    _need("avr-gcc", "gcc-avr avr-libc")
    d = Path(directory)
    write_core(tables, d)
    shutil.copy(CSRC / "gf_test_main.c", d / "gf_test_main.c")
    (d / "gf_vectors.h").write_text(vectors_source(tables, cases))
    elf = d / "gf_avr_test.elf"
    flags = [f if not f.startswith("-mmcu") else f"-mmcu={mcu}" for f in AVR_CFLAGS]
    _run(["avr-gcc", *flags, "-o", str(elf), str(d / "grasp_fixed.c"),
          str(d / "gf_test_main.c"), "-lm"], "avr-gcc build of the test firmware")  # fmt: skip
    return elf


def build_harness(directory: str | Path) -> Path:
    """Compile the libsimavr harness (:file:`gf_simavr_harness.c`) with gcc."""
    _need("gcc", "gcc")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    exe = d / "gf_simavr_harness"
    _run(["gcc", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe),
          str(CSRC / "gf_simavr_harness.c"), "-lsimavr"],
         "simavr harness build (Debian: apt-get install simavr libsimavr-dev)")  # fmt: skip
    return exe


@dataclass
class AvrRun:
    """Outputs and per-step cycle counts of a simavr run."""

    run: CoreRun
    cycles: NDArray  # per step, calibration subtracted


def run_simavr(
    elf: str | Path, cases: Sequence[TestCase], directory: str | Path, mcu: str = MCU
) -> AvrRun:
    """Run a test firmware under libsimavr; outputs and cycles per ``gf_step`` call."""
    d = Path(directory)
    harness = build_harness(d)
    out, cyc = d / "avr_out.bin", d / "avr_cycles.txt"
    _run([str(harness), str(elf), mcu, str(F_CPU_HZ), str(out), str(cyc)], "simavr run")
    cycles = np.loadtxt(cyc, dtype=np.int64, ndmin=1)
    calib = cycles[0]
    return AvrRun(parse_output(out.read_bytes(), cases), cycles[1:] - calib)


@dataclass
class SizeFigures:
    """Flash and RAM of the core + tables on the AVR (bytes), from avr-size."""

    flash_B: int  # text + data of a firmware with the core, minus an empty one
    ram_static_B: int  # data + bss, minus the empty firmware
    stack_B: int  # stack of gf_step (avr-gcc -fstack-usage), + 2 bytes return address
    ram_B: int  # static + stack


def _avr_size(elf: Path) -> tuple[int, int, int]:
    res = _run(["avr-size", "-A", str(elf)], "avr-size")
    sec = {}
    for line in res.stdout.decode().splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].startswith(".") and parts[1].isdigit():
            sec[parts[0]] = int(parts[1])
    return sec.get(".text", 0), sec.get(".data", 0), sec.get(".bss", 0)


def measure_size(tables: FixedTables, directory: str | Path) -> SizeFigures:
    """Flash/RAM of the core + tables: a minimal firmware with and without the core."""
    _need("avr-gcc", "gcc-avr avr-libc")
    _need("avr-size", "binutils-avr")
    d = Path(directory)
    write_core(tables, d)
    (d / "size_main.c").write_text(
        '#include "grasp_fixed.h"\n'
        "static gf_state_t s;\nvolatile int16_t in;\nvolatile int32_t out;\n"
        "int main(void) {\n    gf_output_t o;\n    gf_init(&s, 0, 1400);\n"
        "    for (;;) { gf_step(&s, in, &o); out = o.torque_uNm + o.flags; }\n}\n"
    )
    (d / "empty_main.c").write_text(
        "#include <stdint.h>\nvolatile int16_t in;\nvolatile int32_t out;\n"
        "int main(void) {\n    for (;;) { out = in; }\n}\n"
    )
    _run(["avr-gcc", *AVR_CFLAGS, "-fstack-usage", "-o", str(d / "size.elf"),
          str(d / "grasp_fixed.c"), str(d / "size_main.c"), "-lm"], "avr-gcc size build",
         cwd=d)  # fmt: skip
    _run(["avr-gcc", *AVR_CFLAGS, "-o", str(d / "empty.elf"), str(d / "empty_main.c")],
         "avr-gcc empty build")  # fmt: skip
    t1, d1, b1 = _avr_size(d / "size.elf")
    t0, d0, b0 = _avr_size(d / "empty.elf")
    stack = 0
    for su in d.glob("*.su"):
        for line in su.read_text().splitlines():
            m = re.match(r".*:(gf_step|gf_segment|mulq16)\s+(\d+)", line)
            if m:
                stack += int(m.group(2)) + 2
    static = (d1 + b1) - (d0 + b0)
    return SizeFigures((t1 + d1) - (t0 + d0), static, stack, static + stack)


# --------------------------------------------------------------------------- error figures
@dataclass
class ErrorFigures:
    """Fixed-point core vs the float reference."""

    handle_pct_fs: float  # max |dFi| / (torque_limit / r), percent
    jaw_pct_fs: float  # max |dFg| / jaw-force full scale of the tables, percent
    flag_mismatch: dict[str, int]  # steps where a flag differs
    steps: int


def error_figures(
    tables: FixedTables, surrogate: Surrogate, cases: Sequence[TestCase], run: CoreRun
) -> ErrorFigures:
    """Compare a core run with :func:`reference_run` on the same cases."""
    p = tables.params
    fs = p.torque_limit_Nm / (p.pulley_radius_mm * 1e-3)
    e_h = e_j = 0.0
    mism = dict.fromkeys(FLAG_NAMES, 0)
    steps = 0
    for c, out in zip(cases, run.outputs):
        ref = reference_run(p, surrogate, c.material, c.thickness_um / 1000.0, c.counts)
        e_h = max(e_h, float(np.max(np.abs(out["fi"] * 1e-3 - ref.force_handle_N))))
        e_j = max(e_j, float(np.max(np.abs(out["fg"] * 1e-3 - ref.force_jaw_N))))
        for bit, name in enumerate(FLAG_NAMES):
            mism[name] += int(np.sum(((out["flags"] >> bit) & 1).astype(bool) != ref.flags[name]))
        steps += len(c.counts)
    return ErrorFigures(100.0 * e_h / fs, 100.0 * e_j / tables.jaw_fs_N, mism, steps)


def clamp_thickness_cases(tables: FixedTables, surrogate: Surrogate) -> list[TestCase]:
    """Thickness clamped at both ends (the core flags it in gf_init's return code)."""
    m = tables.materials[0]
    counts = sweep_counts(tables, 50)
    return [TestCase(m.name, m.thickness_um[0] - 100, counts),
            TestCase(m.name, m.thickness_um[-1] + 300, counts)]  # fmt: skip


# --------------------------------------------------------------------------- export
SKETCH_TEMPLATE = r"""// grasprom impedance controller for an Arduino Uno (ATmega328P).
// Generated by grasprom (grasprom.arduino.export_arduino).
//
// Reads the motor's quadrature encoder with pin-change interrupts on pins 2 and 3 (INT0/INT1),
// runs one controller step every GF_SAMPLE_US microseconds, and drives the motor through a
// PWM pin and a direction pin (any H-bridge with PWM + DIR inputs, e.g. a DRV8871 or an
// L298N with EN = PWM).  The motor turns the handle through a cable on a pulley: one encoder
// count of the motor is GF_Q_RAD rad of handle, torque = handle force x pulley radius.
//
// Start with the handle released (fully open): the count is then GF_N_TOP.  Set
// ENCODER_SIGN to -1 if the count rises while closing the handle.  The PWM duty is
// |torque| / torque limit x 255 (calibrate your motor driver so that full duty gives the
// torque limit).  Outputs on the serial port (115200 baud): count, torque (uN m), flags.
#include "grasp_fixed.h"

#define PIN_ENC_A 2
#define PIN_ENC_B 3
#define PIN_PWM 9
#define PIN_DIR 8
#define PIN_WARNING LED_BUILTIN
#define ENCODER_SIGN 1
#define MATERIAL 0        // 0 mr, 1 nh, 2 le
#define THICKNESS_UM 1400 // colon wall thickness, um (clamped into the tables' range)

static volatile int32_t encoder = 0;
static volatile uint8_t enc_state = 0;
static gf_state_t ctl;
static unsigned long next_us;
static uint16_t report = 0;

// quadrature decoding: +1 / -1 per valid transition of (A, B), 4 counts per line
static const int8_t QDEC[16] = {0, -1, 1, 0, 1, 0, 0, -1, -1, 0, 0, 1, 0, 1, -1, 0};

static void on_edge() {
  uint8_t s = (uint8_t)((digitalRead(PIN_ENC_A) << 1) | digitalRead(PIN_ENC_B));
  enc_state = (uint8_t)(((enc_state << 2) | s) & 0x0F);
  encoder += QDEC[enc_state];
}

void setup() {
  pinMode(PIN_ENC_A, INPUT_PULLUP);
  pinMode(PIN_ENC_B, INPUT_PULLUP);
  pinMode(PIN_PWM, OUTPUT);
  pinMode(PIN_DIR, OUTPUT);
  pinMode(PIN_WARNING, OUTPUT);
  analogWrite(PIN_PWM, 0);
  enc_state = (uint8_t)((digitalRead(PIN_ENC_A) << 1) | digitalRead(PIN_ENC_B));
  attachInterrupt(digitalPinToInterrupt(PIN_ENC_A), on_edge, CHANGE);
  attachInterrupt(digitalPinToInterrupt(PIN_ENC_B), on_edge, CHANGE);
  Serial.begin(115200);
  if (gf_init(&ctl, MATERIAL, THICKNESS_UM) & GF_THICKNESS_CLAMPED) {
    Serial.println(F("thickness clamped into the tabulated range"));
  }
  next_us = micros();
}

void loop() {
  gf_output_t out;
  int32_t enc;
  long n;
  uint32_t duty;
  if ((long)(micros() - next_us) < 0) return;
  next_us += GF_SAMPLE_US;
  noInterrupts();
  enc = encoder;
  interrupts();
  n = (long)GF_N_TOP - ENCODER_SIGN * enc;
  if (n > 32767L) n = 32767L;
  if (n < -32768L) n = -32768L;
  gf_step(&ctl, (int16_t)n, &out);
  // torque > 0 pushes the handle open (resists closing)
  duty = (uint32_t)(out.force_handle_mN < 0 ? -out.force_handle_mN : out.force_handle_mN);
  duty = (duty * 255UL) / (uint32_t)GF_FI_LIMIT_MN;
  digitalWrite(PIN_DIR, out.force_handle_mN >= 0 ? HIGH : LOW);
  analogWrite(PIN_PWM, (int)(duty > 255UL ? 255UL : duty));
  digitalWrite(PIN_WARNING, (out.flags & GF_TISSUE_WARNING) ? HIGH : LOW);
  if (++report >= 100) {  // 10 Hz status line
    report = 0;
    Serial.print(out.count);
    Serial.print(' ');
    Serial.print(out.torque_uNm);
    Serial.print(' ');
    Serial.println(out.flags, HEX);
  }
}
"""

MAKEFILE_TEMPLATE = """# Build the sketch with Debian's arduino-mk
# (apt-get install arduino-mk arduino-core-avr gcc-avr avr-libc):
#   make            -> build-uno/{name}_.hex
#   make upload     -> flash the board on MONITOR_PORT
ARDUINO_DIR = /usr/share/arduino
ARDMK_DIR = /usr/share/arduino
AVR_TOOLS_DIR = /usr
BOARD_TAG = uno
MONITOR_PORT ?= /dev/ttyACM0
# Debian's arduino-core-avr with avr-gcc 5.4 lacks DECIMAL_DIG
CPPFLAGS += -DDECIMAL_DIG=__DECIMAL_DIG__
CFLAGS_STD = -std=gnu99
include /usr/share/arduino/Arduino.mk
"""


@dataclass
class ArduinoExport:
    """Result of :func:`export_arduino`: written files and the measured budget figures.

    Figures are ``None`` when the tool that measures them is missing (the export itself only
    needs Python).
    """

    out_dir: Path
    sketch_dir: Path
    files: list[Path]
    fixed_point: bool
    tol: float
    table_bytes: int
    grid_nodes: dict[str, int]
    jaw_fs_N: float
    flash_B: int | None = None
    ram_B: int | None = None
    cycles_max: int | None = None
    cycles_mean: float | None = None
    error_handle_pct_fs: float | None = None
    error_jaw_pct_fs: float | None = None
    flag_mismatch: dict[str, int] | None = None
    notes: list[str] = field(default_factory=list)

    def within_budget(self) -> bool:
        """True when every measured figure meets the default budget."""
        checks = [
            (self.flash_B, FLASH_BUDGET_B),
            (self.ram_B, RAM_BUDGET_B),
            (self.cycles_max, CYCLE_BUDGET),
            (self.error_handle_pct_fs, 100 * ERROR_BUDGET),
        ]
        return all(v is None or v <= lim for v, lim in checks)

    def summary(self) -> str:
        """Human-readable budget table."""

        def f(v: object, unit: str, lim: object) -> str:
            return f"{'n/a' if v is None else v}{unit} (budget {lim}{unit})"

        cyc = self.cycles_max
        err = None if self.error_handle_pct_fs is None else round(self.error_handle_pct_fs, 3)
        jaw = None if self.error_jaw_pct_fs is None else round(self.error_jaw_pct_fs, 3)
        lines = [
            f"Arduino export ({'fixed point' if self.fixed_point else 'float'}, tol {self.tol:g})"
            f" -> {self.sketch_dir}",
            f"  flash tables+core: {f(self.flash_B, ' B', FLASH_BUDGET_B)}; "
            f"tables {self.table_bytes} B, grid nodes {self.grid_nodes}",
            f"  RAM (static + step stack): {f(self.ram_B, ' B', RAM_BUDGET_B)}",
            f"  cycles per step (max): {f(cyc, '', CYCLE_BUDGET)}",
            f"  max handle-force error: {f(err, ' % FS', 100 * ERROR_BUDGET)}; "
            f"jaw force {jaw} % of the jaw-force full scale {self.jaw_fs_N:.4g} N",
        ]
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def export_arduino(
    out_dir: str | Path,
    *,
    surrogate: Surrogate,
    params: ControllerParams,
    tol: float = 0.01,
    fixed_point: bool = True,
    measure: bool = True,
) -> ArduinoExport:
    """Write the Arduino export and measure it against the budget.

    Writes ``out_dir/grasprom_controller/``: the sketch (``grasprom_controller.ino``), the core
    (``grasp_fixed.c/.h``), the generated ``grasp_fixed_config.h`` and ``grasp_fixed_tables.h``
    (PROGMEM, fixed point, units and grids in the comments) and a ``Makefile`` for Debian's
    arduino-mk.

    Parameters
    ----------
    out_dir : str or Path
        Output directory (created).
    surrogate : Surrogate
        Tissue force table (all three materials).
    params : ControllerParams
        Controller parameters baked into the export; material and thickness are set in the
        sketch (``MATERIAL``, ``THICKNESS_UM``: default ``params.material`` /
        ``params.thickness_mm``) and can be changed at run time with ``gf_init``.
    tol : float
        Jaw-force table tolerance, fraction of the jaw-force full scale (largest rendered jaw
        force of the export): smaller = more flash, less error.
    fixed_point : bool
        Integer arithmetic (default) or the float build of the same code (``GF_FLOAT``).
    measure : bool
        Measure the budget figures: error on the host (gcc), flash/RAM (avr-gcc, avr-size),
        cycles (simavr); a missing tool leaves its figure ``None`` with a note.

    Returns
    -------
    ArduinoExport
    """
    tables = build_tables(surrogate, params, tol, fixed_point=fixed_point)
    out = Path(out_dir)
    sk = out / SKETCH_NAME
    files = write_core(tables, sk)
    ino = sk / f"{SKETCH_NAME}.ino"
    text = SKETCH_TEMPLATE.replace(
        "#define MATERIAL 0        // 0 mr, 1 nh, 2 le",
        f"#define MATERIAL {MATERIAL_NAMES.index(params.material)}        // 0 mr, 1 nh, 2 le",
    ).replace(
        "#define THICKNESS_UM 1400", f"#define THICKNESS_UM {round(params.thickness_mm * 1000)}"
    )
    ino.write_text(text)
    mk = sk / "Makefile"
    mk.write_text(MAKEFILE_TEMPLATE.format(name=SKETCH_NAME))
    res = ArduinoExport(
        out_dir=out,
        sketch_dir=sk,
        files=[*files, ino, mk],
        fixed_point=fixed_point,
        tol=tol,
        table_bytes=tables.table_bytes,
        grid_nodes={m.name: len(m.x) for m in tables.materials},
        jaw_fs_N=tables.jaw_fs_N,
    )
    if measure:
        _measure_into(res, tables, surrogate)
    return res


def _measure_into(res: ArduinoExport, tables: FixedTables, surrogate: Surrogate) -> None:
    with tempfile.TemporaryDirectory(prefix="grasprom_arduino_") as tmp:
        t = Path(tmp)
        dense = default_cases(tables, surrogate, dense=True)
        try:
            if tables.fixed_point:
                run = run_host(tables, dense, t / "host")
                e = error_figures(tables, surrogate, dense, run)
                res.error_handle_pct_fs = e.handle_pct_fs
                res.error_jaw_pct_fs = e.jaw_pct_fs
                res.flag_mismatch = e.flag_mismatch
        except RuntimeError as exc:
            res.notes.append(f"host error figures skipped: {exc}".splitlines()[0])
        try:
            sz = measure_size(tables, t / "size")
            res.flash_B, res.ram_B = sz.flash_B, sz.ram_B
        except RuntimeError as exc:
            res.notes.append(f"flash/RAM not measured: {exc}".splitlines()[0])
        try:
            cases = default_cases(tables, surrogate)
            elf = build_avr_test(tables, cases, t / "avr")
            avr = run_simavr(elf, cases, t / "avr")
            res.cycles_max = int(avr.cycles.max())
            res.cycles_mean = float(avr.cycles.mean())
            if not tables.fixed_point:
                e = error_figures(tables, surrogate, cases, avr.run)
                res.error_handle_pct_fs = e.handle_pct_fs
                res.error_jaw_pct_fs = e.jaw_pct_fs
                res.flag_mismatch = e.flag_mismatch
        except RuntimeError as exc:
            res.notes.append(f"cycles not measured: {exc}".splitlines()[0])


def export_main(
    out_dir: str | Path,
    *,
    surrogate: Surrogate,
    params: ControllerParams,
    tol: float = 0.01,
    fixed_point: bool = True,
    stream: TextIO | None = None,
) -> int:
    """CLI helper: export, print the budget table; 0 if within budget, 1 otherwise.

    Parameters are those of :func:`export_arduino`; ``stream`` defaults to stdout.
    """
    import sys

    s = stream or sys.stdout
    res = export_arduino(
        out_dir, surrogate=surrogate, params=params, tol=tol, fixed_point=fixed_point
    )
    print(res.summary(), file=s)
    if not res.within_budget():
        print("export written, but OUTSIDE the default budget (see above)", file=s)
        return 1
    return 0
