"""Evaluation tables of one material: Hermite intervals of every thickness curve and the blend
across thickness (vectorised with numpy, and a pure-Python scalar path).

See :mod:`grasprom.surrogate` for the interpolation scheme and the behaviour outside the table.

Units: gaps and thicknesses in mm, forces in N, dF/dgap in N/mm.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Sequence

import numpy as np

from grasprom.surrogate.build import Curve

_MAX_BUCKETS = 32768  # uniform lookup buckets per curve (replace binary search)
_CHUNK = 16384  # vectorised evaluation works on cache-sized chunks

THICKNESS_TOL_MM = 1e-9
"""Thickness tolerance (mm) accepted at the ends of the swept range."""


class SplineTable:
    """Evaluation tables of one material (numpy arrays and pure-Python lists)."""

    def __init__(self, curves: Sequence[Curve], diameter_mm: float) -> None:
        self.curves = tuple(curves)
        n = len(self.curves)
        self.D = float(diameter_mm)
        self.t = [c.thickness_mm for c in self.curves]
        self.gc = [c.contact_gap_mm for c in self.curves]
        self.inv_dt = [1.0 / (self.t[i + 1] - self.t[i]) for i in range(n - 1)] or [0.0]
        # scalar path: per curve (xs, c0, c1, c2, c3, x0, xn)
        self.s_curves = []
        xs, c0s, c1s, c2s, c3s, start, last = [], [], [], [], [], [], []
        for c in self.curves:
            c0, c1, c2, c3 = c.coefficients()
            x = list(c.gap_mm)
            self.s_curves.append((x, c0, c1, c2, c3, x[0], x[-1]))
            start.append(len(xs))
            last.append(len(xs) + len(c0) - 1)
            xs.extend(x[:-1])
            c0s += c0
            c1s += c1
            c2s += c2
            c3s += c3
        self.a_t = np.array(self.t)
        self.a_gc = np.array(self.gc)
        self.a_inv_dt = np.array(self.inv_dt)
        self.a_x = np.array(xs)
        # right end of each interval; +inf for the last interval of a curve
        self.a_xnext = np.array(xs[1:] + [math.inf])
        self.a_xnext[np.array(last)] = math.inf
        self.a_c0 = np.array(c0s)
        self.a_c1 = np.array(c1s)
        self.a_c2 = np.array(c2s)
        self.a_c3 = np.array(c3s)
        self.a_x0 = np.array([c.gap_mm[0] for c in self.curves])
        self.a_xn = np.array([c.gap_mm[-1] for c in self.curves])
        # uniform bucket tables replace binary search: bucket -> interval index
        bstart, binvw, bidx = [], [], []
        for i, c in enumerate(self.curves):
            x = np.asarray(c.gap_mm)
            span = x[-1] - x[0]
            nb = int(min(_MAX_BUCKETS, math.ceil(2.0 * span / np.diff(x).min()) + 1))
            invw = nb / span
            edges = x[0] + np.arange(nb + 1) / invw
            loc = np.clip(np.searchsorted(x, edges, side="right") - 1, 0, len(x) - 2)
            bstart.append(sum(len(v) for v in bidx))
            binvw.append(invw)
            bidx.append(loc + start[i])
        self.a_bstart = np.array(bstart)
        self.a_binvw = np.array(binvw)
        self.a_bidx = np.concatenate(bidx).astype(np.intp)
        self.a_bmax = np.array([bstart[i] + len(bidx[i]) - 1 for i in range(n)])
        # thickness buckets
        ta = self.a_t
        if n > 1:
            nbt = int(min(_MAX_BUCKETS, math.ceil(2.0 * (ta[-1] - ta[0]) / np.diff(ta).min()) + 1))
            self.t_invw = nbt / (ta[-1] - ta[0])
            tedges = ta[0] + np.arange(nbt + 1) / self.t_invw
            self.t_bidx = np.clip(np.searchsorted(ta, tedges, side="right") - 1, 0, n - 2)
            self.t_next = np.append(ta[1:-1], math.inf)  # right end of interval i (inf last)
        self.tmin = self.t[0]
        self.tmax = self.t[-1]

    # ---------------------------------------------------------------- vectorised
    def eval_curves(self, ci: np.ndarray, x: np.ndarray, want_d: bool):
        """Force, dF/dgap and out-of-range mask of curves ``ci`` at gaps ``x`` (flat arrays)."""
        x0 = self.a_x0[ci]
        xn = self.a_xn[ci]
        xc = np.minimum(np.maximum(x, x0), xn)
        b = ((xc - x0) * self.a_binvw[ci]).astype(np.intp)
        b += self.a_bstart[ci]
        np.minimum(b, self.a_bmax[ci], out=b)
        k = self.a_bidx[b]
        # the bucket may round by one: exact correction against the node gaps
        k -= xc < self.a_x[k]
        while True:
            up = xc >= self.a_xnext[k]
            if not up.any():
                break
            k += up
        h = xc - self.a_x[k]
        c1 = self.a_c1[k]
        c2 = self.a_c2[k]
        c3 = self.a_c3[k]
        f = c3 * h
        f += c2
        f *= h
        f += c1
        f *= h
        f += self.a_c0[k]
        below = x < x0
        # linear continuation below the last FE gap (h = 0 there, slope c1 = node derivative)
        f += c1 * (x - xc)
        inside = x < xn
        f *= inside  # 0 N at and above first touch
        np.maximum(f, 0.0, out=f)
        if not want_d:
            return f, None, below
        df = 3.0 * c3 * h
        df += 2.0 * c2
        df *= h
        df += c1
        df *= inside
        return f, df, below

    def evaluate(self, gap, thickness, scheme: str, want_d: bool, want_flag: bool):
        """Force, dF/dgap and out-of-range flag at broadcast gaps and thicknesses (vectorised).

        Parameters
        ----------
        gap, thickness : array_like
            Jaw gaps (finite) and wall thicknesses (within the swept range), mm.
        scheme : str
            ``"aligned"`` or ``"naive"`` thickness blend.
        want_d, want_flag : bool
            Also compute dF/dgap (N/mm) / return the flag.

        Returns
        -------
        tuple
            ``(force_N, dforce_dgap or None, flag or None)``, arrays of the broadcast shape.
        """
        g = np.asarray(gap, dtype=float)
        t = np.asarray(thickness, dtype=float)
        shape = np.broadcast_shapes(g.shape, t.shape)
        g = np.broadcast_to(g, shape).ravel()
        t = np.broadcast_to(t, shape).ravel()
        if not np.isfinite(g).all():
            raise ValueError("gap_mm must be finite")
        if t.size and not (
            t.min() >= self.tmin - THICKNESS_TOL_MM and t.max() <= self.tmax + THICKNESS_TOL_MM
        ):
            raise ValueError(
                f"thickness_mm outside the swept range [{self.tmin:g}, {self.tmax:g}] mm "
                f"(got {t.min():g}..{t.max():g}); use clamp_thickness() to clamp and flag"
            )
        size = g.size
        f = np.empty(size)
        d = np.empty(size) if want_d else None
        fl = np.empty(size, dtype=bool)
        for a in range(0, size, _CHUNK):  # cache-sized chunks
            sl = slice(a, a + _CHUNK)
            fc, dc, flc = self._evaluate_flat(g[sl], t[sl], scheme, want_d)
            f[sl] = fc
            fl[sl] = flc
            if want_d:
                d[sl] = dc
        return (
            f.reshape(shape),
            None if d is None else d.reshape(shape),
            fl.reshape(shape) if want_flag else None,
        )

    def _evaluate_flat(self, g: np.ndarray, t: np.ndarray, scheme: str, want_d: bool):
        n = len(self.t)
        if n == 1:
            ci = np.zeros(g.size, dtype=np.intp)
            return self.eval_curves(ci, g, want_d)
        tb = ((t - self.tmin) * self.t_invw).astype(np.intp)
        np.clip(tb, 0, self.t_bidx.size - 1, out=tb)
        i = self.t_bidx[tb]
        i -= (t < self.a_t[i]) & (i > 0)
        i += t >= self.t_next[i]
        w = (t - self.a_t[i]) * self.a_inv_dt[i]
        np.clip(w, 0.0, 1.0, out=w)
        v = 1.0 - w
        j = i + 1
        if scheme == "aligned":
            gca = self.a_gc[i]
            gcb = self.a_gc[j]
            dgc = gca - gcb
            gct = gca - w * dgc
            idn = 1.0 / (self.D - gct)
            r = (self.D - g) * idn
            r *= dgc
            xa = g + w * r
            xb = g - v * r
        else:
            xa = xb = g
        fa, da, ba = self.eval_curves(i, xa, want_d)
        fb, db, bb = self.eval_curves(j, xb, want_d)
        f = v * fa
        f += w * fb
        dfdg = None
        if want_d:
            if scheme == "aligned":
                ra = (self.D - gca) * idn
                rb = (self.D - gcb) * idn
                dfdg = v * (da * ra) + w * (db * rb)
            else:
                dfdg = v * da + w * db
        flag = (ba & (v > 0)) | (bb & (w > 0))
        return f, dfdg, flag

    # ---------------------------------------------------------------- scalar
    def _curve_scalar(self, i: int, x: float) -> tuple[float, float, bool]:
        xs, c0, c1, c2, c3, x0, xn = self.s_curves[i]
        if x >= xn:
            return 0.0, 0.0, False
        if x < x0:
            f = c0[0] + c1[0] * (x - x0)  # linear continuation, flagged
            return (f if f > 0.0 else 0.0), c1[0], True
        k = bisect_right(xs, x) - 1
        last = len(c0) - 1
        if k > last:
            k = last
        h = x - xs[k]
        a1 = c1[k]
        a2 = c2[k]
        a3 = c3[k]
        f = ((a3 * h + a2) * h + a1) * h + c0[k]
        return (f if f > 0.0 else 0.0), (3.0 * a3 * h + 2.0 * a2) * h + a1, False

    def scalar(self, gap: float, t: float, scheme: str) -> tuple[float, float, bool]:
        """Force (N), dF/dgap (N/mm) and out-of-range flag at one gap and thickness (mm).

        Pure Python floats (bisection on precomputed lists); same numbers as :meth:`evaluate`.
        """
        if not (gap == gap and gap not in (math.inf, -math.inf)):
            raise ValueError(f"gap_mm must be finite, got {gap!r}")
        if not (self.tmin - THICKNESS_TOL_MM <= t <= self.tmax + THICKNESS_TOL_MM):
            raise ValueError(
                f"thickness_mm {t!r} outside the swept range [{self.tmin:g}, {self.tmax:g}] mm;"
                " use clamp_thickness() to clamp and flag"
            )
        ts = self.t
        n = len(ts)
        if n == 1:
            return self._curve_scalar(0, gap)
        i = bisect_right(ts, t) - 1
        if i < 0:
            i = 0
        elif i > n - 2:
            i = n - 2
        w = (t - ts[i]) * self.inv_dt[i]
        if w < 0.0:
            w = 0.0
        elif w > 1.0:
            w = 1.0
        v = 1.0 - w
        if scheme == "aligned":
            D = self.D
            gca = self.gc[i]
            gcb = self.gc[i + 1]
            dgc = gca - gcb
            gct = gca - w * dgc
            idn = 1.0 / (D - gct)
            r = (D - gap) * idn * dgc
            fa, da, ba = self._curve_scalar(i, gap + w * r)
            fb, db, bb = self._curve_scalar(i + 1, gap - v * r)
            dfdg = v * (da * ((D - gca) * idn)) + w * (db * ((D - gcb) * idn))
        else:
            fa, da, ba = self._curve_scalar(i, gap)
            fb, db, bb = self._curve_scalar(i + 1, gap)
            dfdg = v * da + w * db
        flag = (ba and v > 0.0) or (bb and w > 0.0)
        return v * fa + w * fb, dfdg, flag
