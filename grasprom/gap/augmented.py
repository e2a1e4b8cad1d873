"""The augmented model: the baseline chain plus the fitted effects of a diagnosis, as the JSON
``augmented_model.json`` (building, writing and loading it) and as a handle-force model along an
angle trajectory (:class:`AugmentedModel`)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from grasprom.chain import kinematics as kin
from grasprom.gap.effects import EFFECT_ORDER, EFFECTS, linear_params, nonlinear_params
from grasprom.gap.formats import FORMAT_AUGMENTED, FORMAT_VERSION
from grasprom.gap.model import combine, evaluate_model, visco_index
from grasprom.gap.prepare import prepare_arrays
from grasprom.gap.trials import FloatArray
from grasprom.surrogate import Surrogate


@dataclass
class AugmentedModel:
    """The baseline chain plus fitted effects (loaded from the augmented-model JSON).

    Parameters
    ----------
    effects : dict
        Effect name (:data:`EFFECTS`) -> parameter name -> reported value (units of
        :attr:`ParamSpec.unit`).
    chain : kinematics.ChainParams
        Instrument chain the effects were fitted with.
    meta : dict
        The other keys of the file (verdict, surrogate, held-out RMS...).
    """

    effects: dict[str, dict[str, float]]
    chain: kin.ChainParams
    meta: dict[str, Any] = field(default_factory=dict)

    def handle_force_N(
        self,
        time_s: FloatArray,
        theta_deg: FloatArray,
        thickness_mm: float,
        material: str,
        surrogate: Surrogate,
    ) -> FloatArray:
        """Augmented-model handle force along an angle trajectory (static chain, vectorised).

        The diagnosis' own model (:func:`~grasprom.gap.model.evaluate_model` /
        :func:`~grasprom.gap.model.combine`), measurement effects included; independent of the
        controller step.

        Parameters
        ----------
        time_s : ndarray
            Sample times, s (strictly increasing).
        theta_deg : ndarray
            Measured handle angle, deg.
        thickness_mm : float
            Nominal wall thickness, mm.
        material : str
        surrogate : Surrogate

        Returns
        -------
        ndarray
            Handle force, N (return spring included).
        """
        prep = prepare_arrays(time_s, theta_deg, thickness_mm, material, self.chain)
        names = [e for e in EFFECT_ORDER if e in self.effects]
        nl = [self.effects[e][p.name] - p.offset for e, p in nonlinear_params(names)]
        coef = np.array([self.effects[e][p.name] - p.offset for e, p in linear_params(names)])
        f0, phi, tis = evaluate_model(prep, names, nl, surrogate, self.chain)
        return combine(f0, phi, tis, coef, visco_index(names))


def augmented_dict(
    chain: kin.ChainParams,
    surrogate: Surrogate,
    effects: list[dict[str, Any]],
    verdict: str,
    rms_before_N: float,
    rms_after_N: float,
) -> dict[str, Any]:
    """The augmented-model JSON object (before :func:`~grasprom.gap.formats.jsonable`).

    Parameters
    ----------
    chain : kinematics.ChainParams
        Chain of the diagnosis.
    surrogate : Surrogate
        Surrogate of the baseline (source and FE hash are recorded).
    effects : list of dict
        ``name``, ``params``, ``uncertainty``, ``units`` per explaining effect (empty unless
        the verdict is ``explained``).
    verdict : str
        Label of the verdict.
    rms_before_N, rms_after_N : float
        Held-out RMS (N) of the baseline and of the augmented model.
    """
    return {
        "format": FORMAT_AUGMENTED,
        "format_version": FORMAT_VERSION,
        "baseline": "static derived chain + surrogate (grasprom.diagnosis)",
        "chain": {f: getattr(chain, f) for f in chain.__dataclass_fields__ if f != "_c"},
        "surrogate": {"source": surrogate.source, "fe_hash": surrogate.fe_hash},
        "effects": effects,
        "verdict": verdict,
        "heldout_rms_before_N": rms_before_N,
        "heldout_rms_after_N": rms_after_N if verdict == "explained" else rms_before_N,
    }


def save_augmented(augmented: dict[str, Any], path: str | Path) -> Path:
    """Write the augmented-model dict (from :class:`Diagnosis`) as JSON."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(augmented, indent=2))
    return p


def _read_augmented_json(p: Path) -> dict[str, Any]:
    """The JSON object of an augmented-model file of the right format and version."""
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{p}: cannot read augmented model ({e})") from None
    if not isinstance(d, dict):
        raise ValueError(f"{p}: not a {FORMAT_AUGMENTED} file (expected a JSON object)")
    if d.get("format") != FORMAT_AUGMENTED or d.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{p}: not a {FORMAT_AUGMENTED} v{FORMAT_VERSION} file "
            f"(format={d.get('format')!r}, format_version={d.get('format_version')!r})"
        )
    return d


def load_augmented(path: str | Path) -> AugmentedModel:
    """Load an augmented-model JSON written by ``grasprom diagnose``.

    Raises
    ------
    ValueError
        Wrong format or version, unknown effect or parameter (naming the file).
    """
    p = Path(path)
    d = _read_augmented_json(p)
    effects: dict[str, dict[str, float]] = {}
    for e in d.get("effects", []):
        name = e.get("name")
        if name not in EFFECTS:
            raise ValueError(f"{p}: unknown effect {name!r}")
        want = {q.name for q in EFFECTS[name].params}
        got = set(e.get("params", {}))
        if want != got:
            raise ValueError(
                f"{p}: effect {name!r} needs parameters {sorted(want)}, got {sorted(got)}"
            )
        effects[name] = {k: float(v) for k, v in e["params"].items()}
    try:
        chain = kin.ChainParams(**d.get("chain", {}))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{p}: chain: {exc}") from None
    return AugmentedModel(effects, chain, {k: v for k, v in d.items() if k != "effects"})
