"""Deformed shapes of the 3D clamped tube: cross-sections for the sweep report, VTU for ParaView.

* :func:`section` -- the deformed wall at the jaw mid-plane (outer and inner wall, mm) and the
  deformed top line of the outer wall along the tube axis: small enough for the case sidecar
  (``fe_info["sections"]``, written by the 3D sweep runner at :data:`SECTION_GAPS_MM`);
* :func:`plot_sections` -- PNG of the deformed cross-sections (mirrored to the full ring) and the
  side view of the top line at those gaps;
* :func:`write_vtu` -- the deformed 1/8 mesh (27-node hexahedra, displacement as point data) as a
  VTU file through meshio (optional dependency ``grasprom[vtu]``).

Lengths in mm, forces in N.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from grasprom.fe.mesh3d import Disc3D

SECTION_GAPS_MM = (25.0, 15.0, 8.0, 4.0)
"""Gaps (mm) at which the 3D sweep records a cross-section, plus the last converged gap."""


def section(disc: Disc3D, u: np.ndarray, gap_mm: float, force_N: float) -> dict[str, Any]:
    """Deformed mid-plane cross-section and top line of the 1/8 model (mm), JSON-ready.

    Parameters
    ----------
    disc : Disc3D
        The discretisation (reference node positions, wall node sets).
    u : numpy.ndarray
        Nodal displacements (mm), ``3 n_nodes``.
    gap_mm, force_N : float
        Jaw gap (mm) and force on one jaw (N) of this state.

    Returns
    -------
    dict
        ``gap_mm``, ``force_N``, ``outer_xy_mm`` and ``inner_xy_mm`` (deformed ``(x, y)`` of the
        wall at ``z = 0``, ordered from ``x = 0`` to ``y = 0``) and ``top_zy_mm`` (deformed
        ``(z, y)`` of the outer wall on ``x = 0``, ordered along the axis).
    """
    xyz = disc.X + u.reshape(-1, 3)

    def ordered(nodes: np.ndarray, key: np.ndarray) -> list[list[float]]:
        idx = nodes[np.argsort(key[nodes])]
        return np.round(xyz[idx][:, :2], 5).tolist()

    angle = np.arctan2(disc.X[:, 1], disc.X[:, 0])
    outer = disc.outer_nodes[disc.on_z0[disc.outer_nodes]]
    inner = np.union1d(disc.inner_nodes, np.flatnonzero(disc.on_y0))
    r = np.hypot(disc.X[:, 0], disc.X[:, 1])
    # the inner wall: within a tenth of the wall of the smallest radius (Q2 edge nodes of the
    # trilinear geometry sit on chords, slightly inside the circle)
    inner = inner[disc.on_z0[inner] & (r[inner] <= r.min() + 0.1 * (r.max() - r.min()))]
    top = disc.outer_nodes[disc.on_x0[disc.outer_nodes]]
    top = top[np.argsort(disc.X[top, 2])]
    return {
        "gap_mm": float(gap_mm),
        "force_N": float(force_N),
        "outer_xy_mm": ordered(outer, -angle),
        "inner_xy_mm": ordered(inner, -angle),
        "top_zy_mm": np.round(xyz[top][:, [2, 1]], 5).tolist(),
    }


class SectionRecorder:
    """``on_step`` callback of :func:`grasprom.fe.model3d.run_case_3d` keeping cross-sections.

    Records the first converged state at or below each gap of ``gaps_mm`` and always the
    latest state (kept as ``last``), so a case that stops early still has its final shape.
    """

    def __init__(self, gaps_mm: Sequence[float] = SECTION_GAPS_MM) -> None:
        self._pending = sorted((float(g) for g in gaps_mm), reverse=True)
        self.sections: list[dict[str, Any]] = []
        self.last: dict[str, Any] | None = None
        self._last_state: tuple[Disc3D, np.ndarray, float, float] | None = None

    def __call__(self, disc: Disc3D, u: np.ndarray, gap_mm: float, force_N: float) -> None:
        """Called after each converged step with the state (mm, N)."""
        while self._pending and gap_mm <= self._pending[0] + 1e-9:
            self._pending.pop(0)
            if not self.sections or self.sections[-1]["gap_mm"] != gap_mm:
                self.sections.append(section(disc, u, gap_mm, force_N))
        self._last_state = (disc, u.copy(), gap_mm, force_N)

    def result(self) -> list[dict[str, Any]]:
        """The recorded sections, the final state last (gap decreasing)."""
        out = list(self.sections)
        if self._last_state is not None and (not out or out[-1]["gap_mm"] != self._last_state[2]):
            out.append(section(*self._last_state))
        return out


def _mirror_ring(xy: np.ndarray) -> np.ndarray:
    """The quarter wall ``(x >= 0, y >= 0)`` mirrored to the full ring, as one closed line."""
    q1 = xy[::-1]  # from y = 0 to x = 0
    q2 = xy * [-1, 1]  # x = 0 to y = 0 on the left
    q3 = q1 * [-1, -1]
    q4 = xy * [1, -1]
    return np.vstack([q1, q2, q3, q4, q1[:1]])


def plot_sections(sections: Sequence[dict[str, Any]], title: str, path: str | os.PathLike[str]):
    """Deformed cross-sections at the jaw mid-plane and the top line along the tube (PNG).

    Parameters
    ----------
    sections : sequence of dict
        As :func:`section` (e.g. ``fe_info["sections"]`` of a 3D case sidecar).
    title : str
        Figure title (e.g. the case stem).
    path : str or path-like
        PNG to write.

    Returns
    -------
    pathlib.Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 4.2))
    FigureCanvasAgg(fig)
    ax_s, ax_t = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.6]})
    for i, s in enumerate(sections):
        c = f"C{i}"
        lab = f"gap {s['gap_mm']:.2f} mm, {s['force_N']:.3g} N"
        for key, ls in (("outer_xy_mm", "-"), ("inner_xy_mm", "--")):
            ring = _mirror_ring(np.asarray(s[key]))
            ax_s.plot(ring[:, 0], ring[:, 1], ls, color=c, lw=1.0,
                      label=lab if key == "outer_xy_mm" else None)  # fmt: skip
        zy = np.asarray(s["top_zy_mm"])
        ax_t.plot(np.concatenate([-zy[::-1, 0], zy[:, 0]]),
                  np.concatenate([zy[::-1, 1], zy[:, 1]]), color=c, lw=1.0, label=lab)  # fmt: skip
    ax_s.set_aspect("equal")
    ax_s.set_xlabel("x (mm)")
    ax_s.set_ylabel("y (mm), jaws move along y")
    ax_s.set_title("cross-section at the jaw mid-plane\n(solid: outer wall, dashed: inner)",
                   fontsize=9)  # fmt: skip
    ax_t.set_xlabel("z (mm), along the tube; jaw at |z| <= L_jaw / 2")
    ax_t.set_ylabel("y of the outer wall's top line (mm)")
    ax_t.set_title("side view: the ovalisation decays along the tube", fontsize=9)
    ax_t.legend(fontsize=7)
    for a in (ax_s, ax_t):
        a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    return out


def write_vtu(
    path: str | os.PathLike[str], disc: Disc3D, u: np.ndarray, cells: np.ndarray | None = None
):
    """The deformed 1/8 mesh as VTU (ParaView): 27-node hexahedra, displacement point data.

    Parameters
    ----------
    path : str or path-like
        ``.vtu`` file to write.
    disc : Disc3D
        Discretisation (reference node positions, mm).
    u : numpy.ndarray
        Nodal displacements (mm), ``3 n_nodes``.
    cells : numpy.ndarray, optional
        ``(n_elements, 27)`` node indices in skfem's ``ElementHex2`` order; default the
        discretisation's own (:meth:`Disc3D.output_mesh`, which also writes the nodes tied at a
        zone interface of a coarsened far zone, interpolated).  Only for a mesh without such
        an interface, where they are ``disc.edofs[:, ::3] // 3``.

    Returns
    -------
    pathlib.Path
    """
    try:
        import meshio
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("writing VTU needs meshio: pip install 'grasprom[vtu]'") from exc
    X, disp, own = disc.output_mesh(u)
    if cells is None:
        cells = own
    elif disc.out_X is not None:
        raise ValueError("write_vtu: this mesh has tied nodes (far_coarsening > 1); omit cells")
    ordered = cells[:, vtk_hex27_order()]
    c = X[ordered[:, [0, 1, 3, 4]]]  # corners 0, 1, 3, 4 of every cell
    vol = np.einsum("ei,ei->e", np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), c[:, 3] - c[:, 0])
    if np.all(vol < 0):  # skfem's mapping of this mesh is left-handed: mirror the VTK cell
        ordered = cells[:, vtk_hex27_order(mirror=True)]
    mesh = meshio.Mesh(
        points=X + disp,
        cells=[("hexahedron27", ordered)],
        point_data={"displacement_mm": disp, "reference_position_mm": X},
    )
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    mesh.write(out)
    return out


VTK_HEX27_REFERENCE = np.array(
    [[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [0, 0, 2], [2, 0, 2], [2, 2, 2], [0, 2, 2],
     [1, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0], [1, 0, 2], [2, 1, 2], [1, 2, 2], [0, 1, 2],
     [0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1],
     [0, 1, 1], [2, 1, 1], [1, 0, 1], [1, 2, 1], [1, 1, 0], [1, 1, 2], [1, 1, 1]]
) / 2.0  # fmt: skip
"""Reference coordinates of VTK's triquadratic hexahedron (``VTK_TRIQUADRATIC_HEXAHEDRON``):
8 corners, 12 edge midpoints, the 6 face centres in the order x = 0, x = 1, y = 0, y = 1,
z = 0, z = 1, then the centre."""


def vtk_hex27_order(mirror: bool = False) -> np.ndarray:
    """Permutation: VTK triquadratic-hexahedron node ``k`` is skfem ``ElementHex2`` node ``p[k]``.

    Matched on the reference coordinates of the two elements (skfem's ``doflocs``); with
    ``mirror`` the VTK cell's first reference axis runs the other way (``xi -> 1 - xi``), which
    turns a left-handed skfem mapping into a right-handed VTK cell.
    """
    import skfem

    ref = np.asarray(skfem.ElementHex2().doflocs, dtype=float)
    vtk = VTK_HEX27_REFERENCE.copy()
    if mirror:
        vtk[:, 0] = 1.0 - vtk[:, 0]
    d = np.abs(vtk[:, None, :] - ref[None, :, :]).sum(axis=2)
    perm = d.argmin(axis=1)
    if not (np.allclose(d.min(axis=1), 0.0) and len(set(perm.tolist())) == 27):
        raise RuntimeError("skfem's ElementHex2 nodes do not match VTK's hexahedron27")
    return perm
