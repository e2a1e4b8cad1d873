"""``grasprom simulate --rendering``: the default is the clipped rendering (issue 13), exact in
the soft regime; ``--rendering coupling`` selects the earlier virtual coupling, which softens it."""

from __future__ import annotations

import pandas as pd
import pytest

from grasprom.cli import main
from grasprom.control import ControllerParams


def _ratio_at(out: pd.DataFrame, level_N: float) -> float:
    """Rendered / tissue jaw force at the first step where the tissue force reaches a level."""
    row = out[out["force_tissue_N"] >= level_N].iloc[0]
    return float(row["force_jaw_N"] / row["force_tissue_N"])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    traj = d / "close.csv"
    pd.DataFrame({"time_s": [0.0, 4.0], "theta_deg": [22.0, 0.0]}).to_csv(traj, index=False)
    out = {}
    for name, extra in (("default", []), ("coupling", ["--rendering", "coupling"]),
                        ("clipped", ["--rendering", "clipped"])):  # fmt: skip
        dest = d / f"{name}.csv"
        args = ["simulate", "--trajectory", str(traj), "--out", str(dest), "--material", "mr"]
        assert main([*args, "--thickness", "1.4", *extra]) == 0
        out[name] = pd.read_csv(dest)
    return out


def test_default_rendering_is_clipped(runs):
    assert ControllerParams().rendering == "clipped"
    pd.testing.assert_frame_equal(runs["default"], runs["clipped"])


def test_clipped_is_exact_in_the_soft_regime_and_the_coupling_is_not(runs):
    # tissue force 0.5 N on mr 1.4 mm lies in the bending regime, below the stiffness bound
    soft = runs["default"][runs["default"]["force_tissue_N"] >= 0.5].iloc[0]
    assert soft["tissue_stiffness_N_per_mm"] <= 0.9 * soft["stiffness_limit_N_per_mm"]
    assert _ratio_at(runs["default"], 0.5) == pytest.approx(1.0, abs=0.02)
    assert _ratio_at(runs["coupling"], 0.5) < 0.95  # k_c in series: k_c / (k_c + k_t)
