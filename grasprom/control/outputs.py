"""Files of ``grasprom tune``: ``controller.json``, ``tuning.json``, ``tuning.txt``, plots."""

from __future__ import annotations

import json
from pathlib import Path

from grasprom.control.params import save_params
from grasprom.control.plots import plot_tuning
from grasprom.control.tuning import TuningResult

__all__ = ["write_outputs"]


def write_outputs(result: TuningResult, out_dir: str | Path, plots: bool = True) -> dict[str, Path]:
    """Write ``controller.json``, ``tuning.json``, ``tuning.txt`` and the plots into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = result.to_dict()
    files = {
        "controller": out / "controller.json",
        "tuning": out / "tuning.json",
        "report": out / "tuning.txt",
    }
    save_params(result.params, files["controller"], extra={"tuning": d})
    files["tuning"].write_text(json.dumps(d, indent=2))
    files["report"].write_text(result.report() + "\n")
    if plots:
        files.update(plot_tuning(result, out))
    return files
