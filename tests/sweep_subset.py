"""A shipped FE sweep cut down to some of its materials (issue 16: sweeps of one material).

:func:`copy_sweep` copies the cases of the chosen materials and writes the manifest
(``sweep.json``) of just those, as ``grasprom sweep --material mr ...`` leaves it.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def copy_sweep(src: str | Path, dest: str | Path, materials: Sequence[str]) -> Path:
    """Copy the cases of ``materials`` of the sweep ``src`` (e.g. ``fe_data/default``) to
    ``dest`` (created), with the manifest filtered to them.

    Parameters
    ----------
    src : str or Path
        A sweep folder (relative names are taken from the checkout).
    dest : str or Path
    materials : sequence of str

    Returns
    -------
    Path
        ``dest``.
    """
    src = ROOT / src if not Path(src).is_absolute() else Path(src)
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    mats = tuple(materials)
    for f in src.iterdir():
        if f.name.startswith(tuple(f"{m}_t" for m in mats)):
            shutil.copy(f, dest / f.name)
    man = src / "sweep.json"
    if man.is_file():
        m = json.loads(man.read_text())
        m["cases"] = [c for c in m["cases"] if c["material"] in mats]
        m["grid"]["materials"] = sorted(mats)
        run = m.get("last_run") or {}
        for key in ("done", "skipped", "failed", "partial"):
            if key in run:
                run[key] = [s for s in run[key] if s.split("_t")[0] in mats]
        (dest / "sweep.json").write_text(json.dumps(m, indent=1))
    return dest
