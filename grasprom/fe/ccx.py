"""The 3D clamped tube as a CalculiX (``ccx``) deck: a second, independent FE code (mm, N, MPa).

:func:`write_deck` writes the case of a :class:`~grasprom.fe.model3d.CaseSpec3D` for CalculiX
on the same 1/8 tube geometry and mesh divisions, but with CalculiX's own formulation
throughout, so agreement with :func:`~grasprom.fe.model3d.run_case_3d` is a check by a second
code, not parity:

* 20-node serendipity hexahedra (``C3D20R``, reduced 2x2x2 integration: CalculiX's element for
  nearly incompressible solids) instead of 27-node Q2 with a condensed P1 pressure;
* CalculiX's hyperelastic laws: ``mr``/``nh`` as ``*HYPERELASTIC, MOONEY-RIVLIN`` with the same
  C10, C01 and the same small-strain bulk modulus (``D1 = 2 / kappa``; the volumetric energy
  ``(J - 1)^2 / D1`` differs from grasprom's ``kappa/4 (J^2 - 1 - 2 ln J)`` only at third order
  in ``J - 1``, which stays below 1 % at nu = 0.49); ``le`` as ``*HYPERELASTIC, NEO HOOKE``
  with ``C10 = mu / 2`` and the same bulk modulus (grasprom's compressible neo-Hookean differs
  in its volumetric coupling, again at O(J - 1));
* penalty surface-to-surface contact (mortar-type) with a meshed rigid jaw (flat face with the
  same edge radius) and a meshed rigid plane at ``y = 0`` for the inner walls, instead of an
  exact node-on-profile active set; ``stick`` is approximated by Coulomb friction with a large
  coefficient (:attr:`CcxOptions.stick_friction`), ``coulomb`` uses ``spec.friction``;
* CalculiX's own Newton solver and automatic incrementation (the jaw displacement ramps
  linearly over the step).

The jaw reaction is printed per increment (``*NODE PRINT ... TOTALS=ONLY``); :func:`run_ccx`
runs ``ccx`` and returns the force-gap table with the same ``gap_mm``, ``jaw_displacement_mm``
and ``force_N`` (total force on one jaw, 4 x the 1/8 model's reaction) as the 3D model.

CalculiX is a Debian package (``apt-get install calculix-ccx``); nothing here needs it except
:func:`run_ccx`.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from grasprom.fe.mesh3d import ring_nodes
from grasprom.fe.model3d import CaseSpec3D, axial_grid

CCX_PACKAGE = "calculix-ccx"
"""Debian package that provides the ``ccx`` executable."""

# ccx (Abaqus) 20-node brick: corners, then the mid-edge nodes of the bottom face, the top face
# and the vertical edges; as offsets on the structured (r, theta, z) half-index grid
_C3D20 = np.array(
    [
        (0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0), (0, 0, 2), (2, 0, 2), (2, 2, 2), (0, 2, 2),
        (1, 0, 0), (2, 1, 0), (1, 2, 0), (0, 1, 0), (1, 0, 2), (2, 1, 2), (1, 2, 2), (0, 1, 2),
        (0, 0, 1), (2, 0, 1), (2, 2, 1), (0, 2, 1),
    ]
)  # fmt: skip


@dataclass(frozen=True)
class CcxOptions:
    """Settings of the CalculiX deck that grasprom's own model does not have.

    Parameters
    ----------
    penalty_MPa_per_mm : float
        Normal contact stiffness (MPa/mm) of the linear pressure-overclosure law; 1000 MPa/mm
        lets a 1 MPa contact pressure penetrate 1 micrometre.
    stick_friction : float
        Coulomb coefficient (-) standing in for ``contact="stick"`` (no sliding): far above the
        tangential share of the jaw reaction (about 1 at most in the 3D model).  CalculiX 2.20
        did not converge with it past gaps of 13-18 mm (coefficients 2-5, stick slopes 20-1000
        MPa/mm), so stick decks serve the early bending only.
    tangential_stiffness_MPa_per_mm : float
        Stick slope of the friction law (MPa/mm).
    initial_increment, max_increment : float
        First and largest increment as a share of the jaw stroke (-).
    jaw_divisions : int
        Elements across the meshed rigid jaw (``x``); its flat half-length ``a`` (mm) gets
        ``ceil(jaw_divisions a / 8)`` of them (2 per mm at the default), its edge arc 12.
    fixed_increments : bool
        Fixed increments of ``initial_increment`` (``*STATIC, DIRECT``), so the increments land on
        known gaps, instead of CalculiX's automatic incrementation.
    """

    penalty_MPa_per_mm: float = 1000.0
    stick_friction: float = 5.0
    tangential_stiffness_MPa_per_mm: float = 1000.0
    initial_increment: float = 0.005
    max_increment: float = 0.01
    jaw_divisions: int = 16
    fixed_increments: bool = False

    def __post_init__(self) -> None:
        for name in ("penalty_MPa_per_mm", "stick_friction", "tangential_stiffness_MPa_per_mm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"invalid {name}={v!r}: > 0")
        if not (0 < self.initial_increment <= self.max_increment <= 1):
            raise ValueError(
                "invalid increments: 0 < initial_increment <= max_increment <= 1, got "
                f"{self.initial_increment!r}, {self.max_increment!r}"
            )
        if int(self.jaw_divisions) != self.jaw_divisions or self.jaw_divisions < 2:
            raise ValueError(f"invalid jaw_divisions={self.jaw_divisions!r}: an integer >= 2")


@dataclass(frozen=True)
class CcxDeck:
    """A written CalculiX input deck.

    Attributes
    ----------
    path : Path
        The ``.inp`` file.
    n_tube_nodes, n_tube_elements : int
        Size of the tube mesh (20-node hexahedra).
    stroke_mm : float
        Jaw travel (mm) over the step, from first touch (gap = D) to the final gap.
    tube_volume_mm3 : float
        Volume (mm^3) of the 1/8 tube as meshed (from the element corners), a check of the
        element orientation.
    """

    path: Path
    n_tube_nodes: int
    n_tube_elements: int
    stroke_mm: float
    tube_volume_mm3: float


@dataclass(frozen=True)
class CcxResult:
    """A CalculiX run of a 3D case.

    Attributes
    ----------
    table : pandas.DataFrame
        One row per converged increment: ``gap_mm``, ``jaw_displacement_mm``, ``force_N``
        (N, total force on one jaw, 4 x the 1/8 model's jaw reaction).
    completed : bool
        Whether ccx reached the final gap.
    wall_time_s : float
    deck : CcxDeck
    log : str
        The end of ccx's standard output.
    """

    table: pd.DataFrame
    completed: bool
    wall_time_s: float
    deck: CcxDeck
    log: str


def _tube_nodes(spec: CaseSpec3D):
    """C3D20 node positions on the structured half-index grid, ids (0 = not a node): the
    corner nodes are those of :func:`grasprom.fe.mesh3d.tube_mesh` on the model's axial grid."""
    r, th = ring_nodes(0.5 * spec.diameter_mm, spec.thickness_mm, spec.mesh)
    z = axial_grid(spec)
    x = np.outer(r, np.cos(th))
    y = np.outer(r, np.sin(th))
    x[:, -1] = 0.0
    y[:, 0] = 0.0
    shape = (2 * r.size - 1, 2 * th.size - 1, 2 * z.size - 1)
    P = np.zeros((*shape, 3))
    P[::2, ::2, ::2, 0] = x[:, :, None]
    P[::2, ::2, ::2, 1] = y[:, :, None]
    P[::2, ::2, ::2, 2] = z[None, None, :]
    # mid-edge nodes halfway along the straight edges (the chords of grasprom's hexahedra)
    P[1::2, ::2, ::2] = 0.5 * (P[:-1:2, ::2, ::2] + P[2::2, ::2, ::2])
    P[::2, 1::2, ::2] = 0.5 * (P[::2, :-1:2, ::2] + P[::2, 2::2, ::2])
    P[::2, ::2, 1::2] = 0.5 * (P[::2, ::2, :-1:2] + P[::2, ::2, 2::2])
    odd = sum(np.indices(shape)[i] % 2 for i in range(3))
    keep = odd <= 1
    ids = np.zeros(shape, dtype=np.int64)
    ids[keep] = np.arange(1, keep.sum() + 1)
    return P, ids, (r.size - 1, th.size - 1, z.size - 1)


def _tube_elements(ids: np.ndarray, ne: tuple[int, int, int]):
    """C3D20 connectivity (ne, 20) and each element's layer (0 = the inner wall)."""
    i, j, k = (a.ravel() for a in np.indices(ne))
    base = 2 * np.column_stack([i, j, k])
    corners = base[:, None, :] + _C3D20[None, :, :]
    return ids[corners[..., 0], corners[..., 1], corners[..., 2]], i


def _hex8_volume(p: np.ndarray) -> np.ndarray:
    """Volume of trilinear hexahedra from their 8 corners (ne, 8, 3), ccx order (2x2x2 Gauss)."""
    g = 1.0 / np.sqrt(3.0)
    sgn = np.array([(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1)] * 2, dtype=float)
    sgn[4:, 2] = 1.0
    vol = np.zeros(p.shape[0])
    for a in (-g, g):
        for b in (-g, g):
            for c in (-g, g):
                xi = np.array([a, b, c])
                dN = np.empty((8, 3))
                for n in range(8):
                    f = 1.0 + sgn[n] * xi
                    dN[n] = 0.125 * sgn[n] * np.array([f[1] * f[2], f[0] * f[2], f[0] * f[1]])
                vol += np.linalg.det(np.einsum("enj,nk->ejk", p, dN))
    return vol


def _jaw_profile(spec: CaseSpec3D, divisions: int) -> np.ndarray:
    """Points ``(y, z)`` (mm) of the jaw face at first touch: flat at ``y = R``, then the arc."""
    R = 0.5 * spec.diameter_mm
    r = spec.jaw_edge_radius_mm
    a = spec.flat_half_length_mm
    n_flat = max(2, int(np.ceil(divisions * a / 8.0)))
    pts = [(R, zz) for zz in np.linspace(0.0, a, n_flat + 1)]
    if r > 0:
        for ang in np.linspace(0.0, 0.5 * np.pi, 13)[1:]:
            pts.append((R + r - r * np.cos(ang), a + r * np.sin(ang)))
    return np.array(pts)


def _rigid_block(nodes: np.ndarray, first_el: int, name: str):
    """C3D8 elements of a structured two-layer rigid block (nodes ``(n1, n2, 2)``, ids).

    Face ``S1`` (corners 1-4) is the contact face, layer 0; corner order keeps the element's
    Jacobian positive for the layouts used here.
    """
    out = [f"*ELEMENT, TYPE=C3D8, ELSET={name}"]
    els = []
    n1, n2 = nodes.shape[:2]
    for a in range(n1 - 1):
        for b in range(n2 - 1):
            q = [(a, b), (a + 1, b), (a + 1, b + 1), (a, b + 1)]
            n8 = [nodes[i, j, 0] for i, j in q] + [nodes[i, j, 1] for i, j in q]
            e = first_el + len(els)
            out.append(f"{e}, " + ", ".join(map(str, n8)))
            els.append(e)
    return out, els


def _node_lines(ids: np.ndarray, xyz: np.ndarray) -> list[str]:
    return [f"{n}, {p[0]:.12g}, {p[1]:.12g}, {p[2]:.12g}" for n, p in zip(ids, xyz)]


def _jaw_block(spec: CaseSpec3D, opt: CcxOptions, width: float, first_node: int, first_el: int):
    """Rigid jaw at first touch: one layer of C3D8, 0.5 mm thick, behind the jaw face."""
    prof = _jaw_profile(spec, opt.jaw_divisions)
    tang = np.gradient(prof, axis=0)
    tang /= np.linalg.norm(tang, axis=1)[:, None]
    away = np.column_stack([tang[:, 1], -tang[:, 0]])  # (dy, dz) normal; +y on the flat part
    away *= np.sign(away[0, 0])
    xs = np.linspace(0.0, width, opt.jaw_divisions + 1)
    nid = first_node + np.arange(prof.shape[0] * xs.size * 2).reshape(prof.shape[0], xs.size, 2)
    yz = (
        prof[:, None, None, :]
        + 0.5 * np.array([0.0, 1.0])[None, None, :, None] * away[:, None, None, :]
    )
    xyz = np.empty((*nid.shape, 3))
    xyz[..., 0] = xs[None, :, None]
    xyz[..., 1:] = np.broadcast_to(yz, (*nid.shape, 2))
    out = ["*NODE, NSET=JAWN", *_node_lines(nid.ravel(), xyz.reshape(-1, 3))]
    els_out, els = _rigid_block(nid, first_el, "JAW")
    return out + els_out, els, int(nid.max()) + 1


def _floor_block(z: np.ndarray, width: float, opt: CcxOptions, first_node: int, first_el: int):
    """Rigid plane ``y = 0`` (top face) under the tube: the other half's inner wall mirrored."""
    fx = np.linspace(0.0, width, 2 * opt.jaw_divisions + 1)
    nid = first_node + np.arange(fx.size * z.size * 2).reshape(fx.size, z.size, 2)
    xyz = np.zeros((*nid.shape, 3))
    xyz[..., 0] = fx[:, None, None]
    xyz[..., 1] = np.array([0.0, -0.5])[None, None, :]
    xyz[..., 2] = z[None, :, None]
    out = ["*NODE, NSET=FLOORN", *_node_lines(nid.ravel(), xyz.reshape(-1, 3))]
    els_out, els = _rigid_block(nid, first_el, "FLOOR")
    return out + els_out, els


def _sets(spec: CaseSpec3D, ids: np.ndarray, X: np.ndarray) -> list[str]:
    """Node sets of the symmetry planes and the tube end."""
    tol = 1e-9 * spec.diameter_mm
    half = 0.5 * spec.tube_length_mm
    sets = {
        "XSYM": ids[np.abs(X[:, 0]) < tol],
        "YSYM": ids[np.abs(X[:, 1]) < tol],
        "ZSYM": ids[np.abs(X[:, 2]) < tol],
        "ENDN": ids[np.abs(X[:, 2] - half) < tol],
    }
    out = []
    for name, members in sets.items():
        out.append(f"*NSET, NSET={name}")
        out += [", ".join(map(str, members[s : s + 12])) + "," for s in range(0, members.size, 12)]
    return out


def _surface(name: str, elements, face: str) -> list[str]:
    return [f"*SURFACE, NAME={name}, TYPE=ELEMENT", *(f"{e}, {face}" for e in elements)]


def _material_lines(spec: CaseSpec3D) -> list[str]:
    """The tissue as a CalculiX hyperelastic law with grasprom's constants; the rigid parts."""
    mat = spec.make_material()
    D1 = 2.0 / mat.kappa
    out = ["*MATERIAL, NAME=TISSUE"]
    if spec.material == "le":
        out += ["*HYPERELASTIC, NEO HOOKE", f"{0.5 * mat.mu:.10g}, {D1:.10g}"]
    else:
        out += ["*HYPERELASTIC, MOONEY-RIVLIN", f"{mat.C10:.10g}, {mat.C01:.10g}, {D1:.10g}"]
    out += ["*MATERIAL, NAME=RIGID", "*ELASTIC", "210000, 0.3"]
    for elset, name in (("TUBE", "TISSUE"), ("JAW", "RIGID"), ("FLOOR", "RIGID")):
        out.append(f"*SOLID SECTION, ELSET={elset}, MATERIAL={name}")
    return out


def _contact_lines(spec: CaseSpec3D, opt: CcxOptions) -> list[str]:
    """Penalty contact: tube outer faces on the jaw, inner faces on the plane ``y = 0``."""
    behaviour = [
        "*SURFACE BEHAVIOR, PRESSURE-OVERCLOSURE=LINEAR",
        f"{opt.penalty_MPa_per_mm:.10g}, 1e-3",
    ]
    out = ["*SURFACE INTERACTION, NAME=IJAW", *behaviour]
    mu = {"stick": opt.stick_friction, "coulomb": spec.friction}.get(spec.contact)
    if mu:
        out += ["*FRICTION", f"{mu:.10g}, {opt.tangential_stiffness_MPa_per_mm:.10g}"]
    out += ["*SURFACE INTERACTION, NAME=IFLOOR", *behaviour]
    out += ["*CONTACT PAIR, INTERACTION=IJAW, TYPE=SURFACE TO SURFACE", "SOUTER, SJAW"]
    out += ["*CONTACT PAIR, INTERACTION=IFLOOR, TYPE=SURFACE TO SURFACE", "SINNER, SFLOOR"]
    return out


def _step_lines(spec: CaseSpec3D, opt: CcxOptions, stroke: float) -> list[str]:
    """Symmetry, end and rigid-body conditions; one static step closing the jaw by ``stroke``."""
    out = ["*BOUNDARY", "XSYM, 1, 1", "YSYM, 2, 2", "ZSYM, 3, 3", "FLOORN, 1, 3"]
    out += ["JAWN, 1, 1", "JAWN, 3, 3"]
    if spec.ends == "seed":
        out += ["ENDN, 1, 2"]
    if spec.plane_strain:
        out += ["TUBEN, 3, 3"]
    return out + [
        "*STEP, NLGEOM, INC=100000",
        "*STATIC, DIRECT" if opt.fixed_increments else "*STATIC",
        f"{opt.initial_increment:.10g}, 1.0, 1e-6, {opt.max_increment:.10g}",
        "*BOUNDARY",
        f"JAWN, 2, 2, {-stroke:.12g}",
        "*NODE PRINT, NSET=JAWN, TOTALS=ONLY",
        "RF",
        "*END STEP",
    ]


def write_deck(
    spec: CaseSpec3D, path: str | os.PathLike, gap_end_mm: float, options: CcxOptions | None = None
) -> CcxDeck:
    """Write the CalculiX deck of a 3D case: the jaws close from first touch to ``gap_end_mm``.

    Parameters
    ----------
    spec : CaseSpec3D
        The case (material, geometry, mesh divisions, contact, ends; ``plane_strain`` holds
        ``u_z = 0`` on every tube node, as the 3D model's).
    path : path-like
        The ``.inp`` file to write (its folder must exist).
    gap_end_mm : float
        Final jaw gap (mm), ``0 < gap_end_mm < diameter_mm``.
    options : CcxOptions, optional

    Returns
    -------
    CcxDeck
    """
    opt = options or CcxOptions()
    D = spec.diameter_mm
    if not (np.isfinite(gap_end_mm) and 0.0 < gap_end_mm < D):
        raise ValueError(f"invalid gap_end_mm={gap_end_mm!r}: between 0 and {D} mm")
    if spec.plane_strain and spec.jaw_length_mm < spec.tube_length_mm:
        raise ValueError("plane_strain=True needs a jaw at least as long as the tube")
    if spec.mesh.far_coarsening != 1:
        raise ValueError(
            "the CalculiX deck has one cross-section along the tube: far_coarsening must be 1"
        )
    stroke = 0.5 * (D - gap_end_mm)
    P, ids, ne = _tube_nodes(spec)
    conn, layer = _tube_elements(ids, ne)
    keep = ids > 0
    X = P[keep]
    n_el = conn.shape[0]
    out = ["*HEADING", f"grasprom 3D clamped tube, CalculiX reference: {spec!r}"]
    out += ["*NODE, NSET=TUBEN", *_node_lines(ids[keep], X)]
    out.append("*ELEMENT, TYPE=C3D20R, ELSET=TUBE")
    for e, c in enumerate(conn, 1):
        out += [f"{e}, " + ", ".join(map(str, c[:15])) + ",", ", ".join(map(str, c[15:]))]
    width = 0.5 * np.pi * 0.5 * D + 3.0  # the flattened half-circumference and a margin (mm)
    jaw, jaw_el, next_node = _jaw_block(spec, opt, width, X.shape[0] + 1, n_el + 1)
    floor, floor_el = _floor_block(P[0, 0, ::2, 2], width, opt, next_node, n_el + len(jaw_el) + 1)
    out += jaw + floor + _sets(spec, ids[keep], X)
    elems = np.arange(1, n_el + 1)
    # ccx faces: S4 = 2-6-7-3 is the element's r-outer face, S6 = 4-8-5-1 its r-inner face
    out += _surface("SOUTER", elems[layer == ne[0] - 1], "S4")
    out += _surface("SINNER", elems[layer == 0], "S6")
    out += _surface("SJAW", jaw_el, "S1") + _surface("SFLOOR", floor_el, "S1")
    out += _material_lines(spec) + _contact_lines(spec, opt) + _step_lines(spec, opt, stroke)
    path = Path(path)
    path.write_text("\n".join(out) + "\n")
    vol = float(_hex8_volume(X[conn[:, :8] - 1]).sum())
    return CcxDeck(path, X.shape[0], n_el, stroke, vol)


_TOTALS = re.compile(
    r"total force \(fx,fy,fz\) for set JAWN and time\s+(\S+)\s*\n\s*(\S+)\s+(\S+)\s+(\S+)"
)


def read_jaw_reactions(dat: str | os.PathLike) -> np.ndarray:
    """Step time and total jaw reaction ``(time, fx, fy, fz)`` (-, N) per increment of a ``.dat``.

    The reactions are those of the 1/8 model, in the global axes (the jaws close along ``-y``,
    so ``fy < 0`` while the tissue pushes back).
    """
    text = Path(dat).read_text()
    rows = [tuple(map(float, m.groups())) for m in _TOTALS.finditer(text)]
    return np.array(rows, dtype=float).reshape(-1, 4)


def run_ccx(
    spec: CaseSpec3D,
    workdir: str | os.PathLike,
    gap_end_mm: float,
    options: CcxOptions | None = None,
    executable: str = "ccx",
    timeout_s: float | None = None,
) -> CcxResult:
    """Write the deck of ``spec`` into ``workdir`` and run CalculiX on one thread.

    Parameters
    ----------
    spec, gap_end_mm, options
        As :func:`write_deck`.
    workdir : path-like
        Folder for ``case.inp`` and ccx's output files (created if missing).
    executable : str
        The ccx program (Debian: ``apt-get install calculix-ccx``).
    timeout_s : float, optional
        Wall-time limit (s).

    Returns
    -------
    CcxResult
        ``completed`` is False when ccx stopped before the final gap (its log says why); the
        table holds every converged increment either way.
    """
    exe = shutil.which(executable)
    if exe is None:
        raise FileNotFoundError(
            f"CalculiX program {executable!r} not found: apt-get install {CCX_PACKAGE}"
        )
    work = Path(workdir)
    work.mkdir(parents=True, exist_ok=True)
    deck = write_deck(spec, work / "case.inp", gap_end_mm, options)
    env = dict(os.environ, OMP_NUM_THREADS="1", CCX_NPROC_EQUATION_SOLVER="1")
    t0 = time.perf_counter()
    proc = subprocess.run(
        [exe, "-i", "case"], cwd=work, capture_output=True, text=True, env=env, timeout=timeout_s
    )
    wall = time.perf_counter() - t0
    dat = work / "case.dat"
    reac = read_jaw_reactions(dat) if dat.exists() else np.zeros((0, 4))
    disp = deck.stroke_mm * reac[:, 0]
    table = pd.DataFrame(
        {
            "gap_mm": spec.diameter_mm - 2.0 * disp,
            "jaw_displacement_mm": disp,
            "force_N": -4.0 * reac[:, 2],
        }
    )
    done = proc.returncode == 0 and reac.shape[0] > 0 and np.isclose(reac[-1, 0], 1.0)
    return CcxResult(table, bool(done), wall, deck, proc.stdout[-4000:] + proc.stderr[-2000:])
