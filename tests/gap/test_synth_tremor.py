"""Hand tremor in the synthetic trials (``grasprom synth --tremor``, issue 15's tremor-rich
trajectories): level and band measured on the trials against the request, nothing else moved."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.signal import welch

from grasprom.chain import kinematics as kin
from grasprom.cli import main
from grasprom.gap import synth_case
from grasprom.gap.synth_truth import HAND_STIFFNESS_N_PER_MM

CHAIN = kin.ChainParams()
FE_2D = Path(__file__).resolve().parents[2] / "fe_data" / "2d"


def test_tremor_has_the_requested_rms_and_band_and_leaves_the_rest(surrogate):
    kw = dict(seed=5, surrogate=surrogate, n_trials=2, material="mr")
    plain = synth_case(["latency"], **kw)
    shaky = synth_case(["latency"], **kw, tremor_deg=0.1)
    assert shaky.truth["tremor_deg"] == 0.1 and "tremor_deg" not in plain.truth
    assert shaky.truth["effects"] == plain.truth["effects"]
    for a, b in zip(plain.trials, shaky.trials):
        th0, th1 = a.data["theta_deg"].to_numpy(), b.data["theta_deg"].to_numpy()
        d = th1 - th0
        # the tremor is scaled by fade / (1 + S / k_hand), S = the handle's static stiffness
        # (N/deg, from the surrogate through the chain here); divided by that, it is the
        # free-motion tremor everywhere it is not faded out
        t_mm = a.sidecar["thickness_mm"]

        def fi(th, t_mm=t_mm):
            return kin.handle_force_N(surrogate.force(kin.gap_mm(th, CHAIN), t_mm, "mr"), th, CHAIN)

        S = np.abs(fi(np.minimum(th0 + 1e-3, 22.0)) - fi(np.maximum(th0 - 1e-3, 0.0))) / 2e-3
        k_hand = HAND_STIFFNESS_N_PER_MM * np.radians(1.0) * CHAIN.L3_mm
        scale = np.clip((22.0 - th0) / 2.0, 0.0, 1.0) / (1.0 + S / k_hand)
        free = scale > 0.5
        assert free.mean() > 0.2
        assert np.sqrt(np.mean((d[free] / scale[free]) ** 2)) == pytest.approx(0.1, rel=0.15)
        f, pxx = welch(d, fs=1000.0, nperseg=1024)
        band = (f >= 5.0) & (f <= 13.0)
        assert pxx[band].sum() / pxx.sum() > 0.9  # 6-12 Hz
        # held by the tissue: at the squeeze (handle far stiffer than the hand) it is smaller
        hold = th0 <= th0.min() + 1e-9
        assert np.sqrt(np.mean(d[hold] ** 2)) < 0.3 * 0.1
        # the force and time columns are not drawn from the tremor's stream
        assert np.array_equal(a.data["time_s"], b.data["time_s"])
    with pytest.raises(ValueError, match="tremor_deg"):
        synth_case([], seed=1, surrogate=surrogate, tremor_deg=-1.0)


def test_synth_cli_tremor(tmp_path):
    args = ["synth", "--seed", "3", "--trials", "1", "--fe", str(FE_2D)]
    assert main([*args, "--out", str(tmp_path / "t"), "--tremor", "0.05"]) == 0
    assert main([*args, "--out", str(tmp_path / "p")]) == 0
    truth = json.loads((tmp_path / "t" / "truth.json").read_text())
    assert truth["tremor_deg"] == 0.05
    (a,) = sorted((tmp_path / "t").glob("trial_*.csv"))
    (b,) = sorted((tmp_path / "p").glob("trial_*.csv"))
    d = pd.read_csv(a)["theta_deg"] - pd.read_csv(b)["theta_deg"]
    assert 0.005 < float(np.sqrt(np.mean(d**2))) < 0.05
    assert main([*args, "--out", str(tmp_path / "n"), "--tremor", "-1"]) == 2
