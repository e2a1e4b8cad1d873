"""Hand tremor in the synthetic trials (``grasprom synth --tremor``, issue 15's tremor-rich
trajectories): level and band measured on the trials against the request, nothing else moved."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.signal import welch

from grasprom.cli import main
from grasprom.gap import synth_case

FE_2D = Path(__file__).resolve().parents[2] / "fe_data" / "2d"


def test_tremor_has_the_requested_rms_and_band_and_leaves_the_rest(surrogate):
    plain = synth_case(["latency"], seed=5, surrogate=surrogate, n_trials=2)
    shaky = synth_case(["latency"], seed=5, surrogate=surrogate, n_trials=2, tremor_deg=0.1)
    assert shaky.truth["tremor_deg"] == 0.1 and "tremor_deg" not in plain.truth
    assert shaky.truth["effects"] == plain.truth["effects"]
    for a, b in zip(plain.trials, shaky.trials):
        th0, th1 = a.data["theta_deg"].to_numpy(), b.data["theta_deg"].to_numpy()
        d = th1 - th0
        away = th0 < 15.0  # away from the open stop, where the tremor fades out
        assert np.sqrt(np.mean(d[away] ** 2)) == pytest.approx(0.1, rel=0.15)
        f, pxx = welch(d[away], fs=1000.0, nperseg=512)
        band = (f >= 5.0) & (f <= 13.0)
        assert pxx[band].sum() / pxx.sum() > 0.9  # 6-12 Hz
        # the force and time columns are not drawn from the tremor's stream
        assert np.array_equal(a.data["time_s"], b.data["time_s"])
    with pytest.raises(ValueError, match="tremor_deg"):
        synth_case([], seed=1, surrogate=surrogate, tremor_deg=-1.0)


def test_synth_cli_tremor(tmp_path, capsys):
    out = tmp_path / "t"
    assert main(["synth", "--out", str(out), "--seed", "3", "--trials", "1", "--tremor", "0.05",
                 "--fe", str(FE_2D)]) == 0  # fmt: skip
    (csv,) = sorted(out.glob("trial_*.csv"))
    th = pd.read_csv(csv)["theta_deg"].to_numpy()
    v = np.diff(th)
    assert np.count_nonzero(np.diff(np.sign(v[np.abs(v) > 1e-9])) != 0) > 20  # reversals
