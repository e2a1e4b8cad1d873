"""Sample rate of the synthetic trials (``synth_case(rate_hz=...)``, ``grasprom synth
--rate-hz``): the default reproduces the earlier 1 kHz trials bit for bit, and a 2 kHz trial is
the same physics sampled twice as often with white sensor noise at every sample (what a real
2 kHz acquisition records; an interpolated 1 kHz trial is not)."""

import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.signal import welch

from grasprom.chain import kinematics as kin
from grasprom.cli import main
from grasprom.gap import synth_case
from grasprom.gap.signals import noise_sigma
from grasprom.gap.synth_effects import SYNTH_EFFECTS, random_effect_params
from grasprom.gap.synth_truth import TrialSpec, simulate_trial

CHAIN = kin.ChainParams()
FE_2D = Path(__file__).resolve().parents[2] / "fe_data" / "2d"

DIGEST_CASES = [
    (["mechanism_friction", "latency"], dict(seed=11, n_trials=2, gap_channel=True,
                                             tremor_deg=0.05)),
    (["tissue_viscoelasticity", "sensor_drift"], dict(seed=4, n_trials=2)),
    (["backlash", "jaw_compliance"], dict(seed=7, n_trials=1, gap_channel=True)),
    ([], dict(seed=3, n_trials=2, jaw_load_cell=False)),
]  # fmt: skip
DIGESTS_1KHZ = {
    "x86-64 Linux where it was first made (CI passes with it)": (
        "937242999ae8705bcfb30ebd4448258089365408b17f545b892080c1574c7ed5"
    ),
    "x86-64, numpy SIMD up to X86_V3, no AVX-512 (AMD EPYC)": (
        "c4009878b7a769ba98b84877be6ca319975ec04a96d1f949437fea3de99dbc6f"
    ),
}
"""SHA-256 of the trials of :data:`DIGEST_CASES` (column names, then the float64 bytes of the
table, trial after trial) made by the code before ``rate_hz`` existed (commit 5252c1f, on the
fe_data/2d surrogate): ``PYTHONPATH=<checkout of 5252c1f> python`` running
:func:`_digest` (numpy 2.4.6, pandas 3.1.1, scipy 1.17.1, Linux), one per platform: numpy's
maths kernels differ in the last bit between the SIMD levels they dispatch to
(``numpy.show_config()``, *SIMD Extensions*).  On another platform, regenerate it from that
commit there and add it."""


def _digest(surrogate, **kw) -> str:
    h = hashlib.sha256()
    for effects, case_kw in DIGEST_CASES:
        for tr in synth_case(effects, surrogate=surrogate, **case_kw, **kw).trials:
            h.update(",".join(tr.data.columns).encode())
            h.update(tr.data.to_numpy(dtype="float64").tobytes())
    return h.hexdigest()


def test_default_rate_reproduces_the_1khz_trials_bit_for_bit(surrogate):
    digest = _digest(surrogate)
    assert digest in DIGESTS_1KHZ.values()
    assert _digest(surrogate, rate_hz=1000.0) == digest
    for effects, kw in DIGEST_CASES[:2]:
        a = synth_case(effects, surrogate=surrogate, **kw)
        b = synth_case(effects, surrogate=surrogate, **kw, rate_hz=1000)
        assert a.truth == b.truth and "rate_hz" not in a.truth
        for ta, tb in zip(a.trials, b.trials):
            pd.testing.assert_frame_equal(ta.data, tb.data, check_exact=True)
            assert np.all(np.diff(ta.data["time_s"]) == pytest.approx(0.001, abs=1e-9))


def _d2_lag1(x: np.ndarray) -> float:
    """Lag-1 autocorrelation of the second difference (-2/3 for white noise)."""
    d2 = np.diff(x, 2)
    return float(np.corrcoef(d2[:-1], d2[1:])[0, 1])


@pytest.mark.parametrize(
    ("effects", "seed"),
    [([], 3), (["mechanism_friction"], 5), (["latency", "sensor_drift"], 8)],
)
def test_2khz_is_the_same_case_at_twice_the_samples_with_white_noise(surrogate, effects, seed):
    kw = dict(seed=seed, surrogate=surrogate, n_trials=3)
    a = synth_case(effects, **kw)
    b = synth_case(effects, **kw, rate_hz=2000.0)
    # same truth and, trial by trial, the same conditions and real thickness
    assert b.truth.pop("rate_hz") == 2000.0
    assert a.truth == b.truth
    assert [t.sidecar for t in a.trials] == [t.sidecar for t in b.trials]
    for ta, tb in zip(a.trials, b.trials):
        t1, t2 = ta.data["time_s"].to_numpy(), tb.data["time_s"].to_numpy()
        # five segments of round(d f) or floor(d f) samples each: |n2 - 2 n1| <= 5
        assert abs(t2.size - 2 * t1.size) <= 5
        assert np.diff(t2) == pytest.approx(np.full(t2.size - 1, 0.0005), abs=1e-9)
        assert t2[-1] == pytest.approx(t1[-1], abs=0.003)  # same duration
        for col, truth in (("force_handle_N", "noise_N"), ("force_jaw_N", "jaw_noise_N")):
            f2 = tb.data[col].to_numpy()
            # the diagnosis' noise estimate recovers the truth's rms per sample
            assert noise_sigma(f2) == pytest.approx(a.truth[truth], rel=0.1)
            # independent samples: the second difference of white noise has lag-1
            # autocorrelation (-2 - 2) / (1 + 4 + 1) = -2/3
            assert _d2_lag1(f2) == pytest.approx(-2.0 / 3.0, abs=0.04)
        # an interpolated 1 kHz trial is no 2 kHz acquisition: every second second difference
        # is 0, and the noise estimate collapses (the old --acquisition 2khz)
        f1 = ta.data["force_handle_N"].to_numpy()
        fi = np.interp(np.arange(t1[0], t1[-1], 0.0005), t1, f1)
        assert noise_sigma(fi) < 0.05 * a.truth["noise_N"]


SPECS = (
    TrialSpec(1.3, "mr", 0.5, 2.0, 1.5, 0.3, 0.3, 20.0),  # fast close to 20 N
    TrialSpec(1.6, "le", 2.0, 1.5, 0.6, 0.25, 0.2, 8.0),  # slow close, fast reopening
)
"""Trial conditions of whole milliseconds: the 2 kHz samples of even index are at the 1 kHz
sample times."""


@pytest.mark.parametrize("effect", ["none", *SYNTH_EFFECTS])
def test_2khz_noise_free_physics_agrees_with_1khz_at_common_times(surrogate, effect):
    """Noise-free trials (``noise_N = 0``) of the same truth at 1 and 2 kHz, compared at the
    1 kHz times: the angle is the same, the forces agree well within the smallest sensor noise
    of the synthetic cases (0.03 N rms)."""
    rng = np.random.default_rng(0)
    effects = {} if effect == "none" else {effect: random_effect_params(effect, rng)}
    for spec in SPECS:
        a, b = (
            simulate_trial(spec, effects, surrogate, CHAIN, np.random.default_rng(1), 0.0, 0.0,
                           rate_hz=r)[0]
            for r in (1000.0, 2000.0)
        )  # fmt: skip
        assert len(b) == 2 * len(a)
        assert np.array_equal(b["time_s"].to_numpy()[::2], a["time_s"].to_numpy())
        assert np.array_equal(b["theta_deg"].to_numpy()[::2], a["theta_deg"].to_numpy())
        dj = a["force_jaw_N"].to_numpy() - b["force_jaw_N"].to_numpy()[::2]
        assert np.sqrt(np.mean(dj**2)) < 0.005
        f1, f2 = a["force_handle_N"].to_numpy(), b["force_handle_N"].to_numpy()
        if effect == "latency":
            # the sensor lag y[n] = a y[n-1] + (1 - a) x[n] follows a ramp (dt/2) earlier than the
            # continuous lag: the 2 kHz trace is (1 - 0.5) ms / 2 = 0.25 ms later than the 1 kHz
            # one; shifted back, it agrees
            t1, t2 = a["time_s"].to_numpy(), b["time_s"].to_numpy()
            f2 = np.interp(t1 + 0.00025, t2, f2)
        else:
            f2 = f2[::2]
        d = f1 - f2
        assert np.sqrt(np.mean(d**2)) < 0.01
        assert np.quantile(np.abs(d), 0.99) < 0.03


def test_2khz_tremor_keeps_its_band_and_level(surrogate):
    """The tremor's band-pass is designed at the trial's rate: at 2 kHz still 6-12 Hz."""
    kw = dict(seed=5, surrogate=surrogate, n_trials=1, material="mr", rate_hz=2000.0)
    plain = synth_case([], **kw).trials[0].data["theta_deg"].to_numpy()
    shaky = synth_case([], **kw, tremor_deg=0.1).trials[0].data["theta_deg"].to_numpy()
    d = shaky - plain
    f, pxx = welch(d, fs=2000.0, nperseg=2048)
    band = (f >= 5.0) & (f <= 13.0)
    assert pxx[band].sum() / pxx.sum() > 0.9
    free = plain >= CHAIN.theta_open_deg - 1e-9  # the hand rests on the open stop: faded out
    assert np.all(d[free] == 0.0)
    assert 0.02 < float(np.sqrt(np.mean(d**2))) <= 0.1


@pytest.mark.parametrize("bad", [50.0, 99.9, 20000.5, float("nan"), float("inf"), "2000", True])
def test_rate_hz_is_validated(surrogate, bad):
    with pytest.raises(ValueError, match="rate_hz: must be a sample rate of 100 to 20000 Hz"):
        synth_case([], seed=1, surrogate=surrogate, n_trials=1, rate_hz=bad)


def test_synth_cli_rate_hz(tmp_path):
    args = ["synth", "--seed", "3", "--trials", "1", "--fe", str(FE_2D)]
    assert main([*args, "--out", str(tmp_path / "f"), "--rate-hz", "2000"]) == 0
    assert main([*args, "--out", str(tmp_path / "s")]) == 0
    assert json.loads((tmp_path / "f" / "truth.json").read_text())["rate_hz"] == 2000.0
    fast = pd.read_csv(tmp_path / "f" / "trial_01.csv")
    slow = pd.read_csv(tmp_path / "s" / "trial_01.csv")
    assert np.diff(fast["time_s"]) == pytest.approx(np.full(len(fast) - 1, 0.0005), abs=1e-9)
    assert abs(len(fast) - 2 * len(slow)) <= 5
    assert main([*args, "--out", str(tmp_path / "n"), "--rate-hz", "50"]) == 2
