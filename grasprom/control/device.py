"""Models the tuner designs against: the haptic handle (:class:`DeviceParams`) and the hand.

Both are linear models about the handle pivot: inertia, viscous damping and Coulomb friction of
the device, a mass-spring-damper of the fingers (:class:`HandParams`), with the computation delay
and the motor torque limit of the drive.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from grasprom.control.params import ControllerParams

__all__ = [
    "DEVICE_FILE_FORMAT",
    "DEVICE_FILE_VERSION",
    "DeviceParams",
    "HandParams",
    "apply_device",
    "device_from_dict",
    "device_to_dict",
    "load_device",
    "save_device",
]

DEVICE_FILE_FORMAT = "grasprom-device"
"""``format`` of a device file (:func:`load_device`)."""

DEVICE_FILE_VERSION = 1
"""``format_version`` of a device file."""


@dataclass(frozen=True)
class DeviceParams:
    """Haptic handle (device) model about the handle pivot (SI units in the names).

    The values are representative assumptions for a cable-driven one-axis handle, not a
    datasheet of a built device; identify ``J``, ``b`` and ``f_c`` on the real handle (free decay,
    torque ramps) and rerun ``grasprom tune``: the passive coupling stiffness scales linearly
    with ``b``.

    Parameters
    ----------
    inertia_kg_m2 : float
        Handle inertia at the handle pivot, kg m^2, including the motor rotor reflected through
        the cable (motor turns ``L3 / r`` = 5.41 times the handle): default 2e-3 (a rotor of
        about 6.5e-5 kg m^2, the class of a 50-100 W flat brushless motor, x 5.41^2 = 1.9e-3,
        plus about 1e-4 for the handle lever); 0.68 kg equivalent at the finger (``J / L3^2``).
    damping_Nms_per_rad : float
        Physical viscous damping ``b`` at the handle pivot, N m s/rad: default 0.01 (3.4 N s/m
        at the finger: motor, bearings and cable; the order of desktop haptic devices, cf.
        the identified devices of Colgate & Brown 1994 and Abbott & Okamura 2005).  The
        passivity bounds scale with it.
    coulomb_Nm : float
        Coulomb friction at the handle pivot, N m: default 0.01 (0.18 N at the finger).
    torque_constant_Nm_per_A : float
        Motor torque constant, N m/A (default 0.1).
    current_limit_A : float
        Amplifier current limit, A (default 10); motor torque limit = constant x limit = 1 N m
        (the controller's default ``torque_limit_Nm``: 100 N of cable tension at r = 10 mm).
    delay_samples : int
        Computation delay in samples between the encoder read and the torque update (default 1:
        the torque computed from sample k is applied from k + 1, then held).
    encoder_counts_per_rev : int or None
        Motor encoder resolution (counts/rev, 4 x lines); None (default): the controller's
        ``encoder_counts_per_rev`` (4096).  :func:`apply_device` copies it into the controller.
    pulley_radius_mm : float or None
        Motor pulley radius (mm); None (default): the controller's ``pulley_radius_mm`` (10).

    Notes
    -----
    Sample time ``T`` and the encoder quantum (handle rad per count, ``2 pi r / (counts L3)``,
    :attr:`~grasprom.control.impedance.ImpedanceController.encoder_quantum_rad`) come from the
    :class:`~grasprom.control.params.ControllerParams`.
    """

    inertia_kg_m2: float = 2.0e-3
    damping_Nms_per_rad: float = 0.01
    coulomb_Nm: float = 0.01
    torque_constant_Nm_per_A: float = 0.1
    current_limit_A: float = 10.0
    delay_samples: int = 1
    encoder_counts_per_rev: int | None = None
    pulley_radius_mm: float | None = None

    def __post_init__(self) -> None:
        for name in (
            "inertia_kg_m2",
            "damping_Nms_per_rad",
            "torque_constant_Nm_per_A",
            "current_limit_A",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"DeviceParams.{name} must be finite and > 0, got {v!r}")
        if not (math.isfinite(self.coulomb_Nm) and self.coulomb_Nm >= 0):
            raise ValueError(f"DeviceParams.coulomb_Nm must be >= 0, got {self.coulomb_Nm!r}")
        if int(self.delay_samples) != self.delay_samples or self.delay_samples < 0:
            raise ValueError(
                f"DeviceParams.delay_samples must be an integer >= 0, got {self.delay_samples!r}"
            )
        _check_optional(self)

    @property
    def torque_limit_Nm(self) -> float:
        """Motor torque limit, N m (``torque constant x current limit``)."""
        return self.torque_constant_Nm_per_A * self.current_limit_A


def _check_optional(d: DeviceParams) -> None:
    """Encoder counts (integer >= 0) and pulley radius (finite, > 0 mm) when given."""
    n = d.encoder_counts_per_rev
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 0):
        raise ValueError(f"DeviceParams.encoder_counts_per_rev must be an integer >= 0, got {n!r}")
    r = d.pulley_radius_mm
    if r is not None and not (
        isinstance(r, int | float) and not isinstance(r, bool) and math.isfinite(r) and r > 0
    ):
        raise ValueError(f"DeviceParams.pulley_radius_mm must be finite and > 0 mm, got {r!r}")


def apply_device(params: ControllerParams, device: DeviceParams) -> ControllerParams:
    """The controller parameters on this device: motor torque limit, encoder and pulley.

    ``torque_limit_Nm`` becomes ``min(params.torque_limit_Nm, device.torque_limit_Nm)`` (N m);
    ``encoder_counts_per_rev`` and ``pulley_radius_mm`` (mm) are the device's when it gives
    them.

    Parameters
    ----------
    params : ControllerParams
    device : DeviceParams

    Returns
    -------
    ControllerParams
    """
    over: dict[str, Any] = {"torque_limit_Nm": min(params.torque_limit_Nm, device.torque_limit_Nm)}
    if device.encoder_counts_per_rev is not None:
        over["encoder_counts_per_rev"] = device.encoder_counts_per_rev
    if device.pulley_radius_mm is not None:
        over["pulley_radius_mm"] = float(device.pulley_radius_mm)
    return replace(params, **over)


def device_to_dict(device: DeviceParams) -> dict[str, Any]:
    """JSON-ready dict of a device (the file form of :func:`load_device`), SI units in names."""
    d = {"format": DEVICE_FILE_FORMAT, "format_version": DEVICE_FILE_VERSION}
    d.update({f.name: getattr(device, f.name) for f in fields(device)})
    return d


def device_from_dict(d: dict[str, Any], source: str = "device") -> DeviceParams:
    """Inverse of :func:`device_to_dict`; missing keys take the documented defaults.

    Errors name ``source`` and the key: unknown keys, wrong format/version, values that are
    not numbers or out of range.

    Parameters
    ----------
    d : dict
        Keys of :class:`DeviceParams` (plus the optional ``format``, ``format_version``,
        ``comment``, ``identification``).
    source : str
        Name of the file (or object) in the error messages.

    Returns
    -------
    DeviceParams
    """
    d = dict(d)
    fmt = d.pop("format", DEVICE_FILE_FORMAT)
    if fmt != DEVICE_FILE_FORMAT:
        raise ValueError(f"{source}: format {fmt!r}, expected {DEVICE_FILE_FORMAT!r}")
    version = d.pop("format_version", DEVICE_FILE_VERSION)
    if version != DEVICE_FILE_VERSION:
        raise ValueError(f"{source}: format_version {version!r}, expected {DEVICE_FILE_VERSION}")
    d.pop("comment", None)
    d.pop("identification", None)  # written by grasprom identify (values, uncertainties)
    known = [f.name for f in fields(DeviceParams)]
    unknown = sorted(set(d) - set(known))
    if unknown:
        raise ValueError(
            f"{source}: unknown key(s) {', '.join(unknown)}; valid: {', '.join(known)}"
        )
    for k, v in d.items():
        optional = k in ("encoder_counts_per_rev", "pulley_radius_mm") and v is None
        if not optional and (isinstance(v, bool) or not isinstance(v, int | float)):
            raise ValueError(f"{source}: key {k!r} must be a number, got {v!r}")
        if k in ("delay_samples", "encoder_counts_per_rev") and isinstance(v, float):
            if not v.is_integer():
                raise ValueError(f"{source}: key {k!r} must be an integer, got {v!r}")
            d[k] = int(v)
    try:
        return DeviceParams(**d)
    except ValueError as exc:
        raise ValueError(f"{source}: key {str(exc).split()[0].split('.')[-1]!r}: {exc}") from None


def load_device(path: str | os.PathLike[str]) -> DeviceParams:
    """Read a device file (JSON object of :class:`DeviceParams` keys, SI units in the names).

    Example file (the defaults, every key optional)::

        {"format": "grasprom-device", "format_version": 1,
         "inertia_kg_m2": 0.002, "damping_Nms_per_rad": 0.01, "coulomb_Nm": 0.01,
         "torque_constant_Nm_per_A": 0.1, "current_limit_A": 10.0, "delay_samples": 1,
         "encoder_counts_per_rev": 4096, "pulley_radius_mm": 10.0}

    Parameters
    ----------
    path : str or PathLike

    Returns
    -------
    DeviceParams

    Raises
    ------
    ValueError
        Unreadable file, not a JSON object, unknown key, bad value (the message names the file
        and the key).
    """
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{p}: cannot read the device file ({exc})") from None
    if not isinstance(d, dict):
        raise ValueError(f"{p}: expected a JSON object of device parameters")
    return device_from_dict(d, source=str(p))


def save_device(device: DeviceParams, path: str | os.PathLike[str]) -> Path:
    """Write a device file (:func:`device_to_dict` as JSON); returns its path."""
    p = Path(path)
    p.write_text(json.dumps(device_to_dict(device), indent=2) + "\n")
    return p


@dataclass(frozen=True)
class HandParams:
    """Mass-spring-damper of the fingers at the grip, along the finger travel (SI units).

    Defaults: the order of the index-fingertip impedance identified by Hajian & Howe (1997,
    "Identification of the mechanical impedance at the human finger tip", J. Biomech. Eng.
    119(1):109-114) at grip forces of a few newtons: a mass of grams, a damping of a few N s/m
    and a stiffness of a few hundred N/m, both rising with the grip force; the grip here is
    one effective finger.  Converted to the handle pivot through ``L3``:
    ``J_h = m L3^2``, ``b_h = c L3^2``, ``k_h = k L3^2``.

    Parameters
    ----------
    mass_kg : float
        Effective finger mass at the grip, kg (default 0.01).
    damping_Ns_per_m : float
        Finger damping, N s/m (default 2.0).
    stiffness_N_per_m : float
        Finger stiffness, N/m (default 300).
    """

    mass_kg: float = 0.01
    damping_Ns_per_m: float = 2.0
    stiffness_N_per_m: float = 300.0

    def __post_init__(self) -> None:
        for name in ("mass_kg", "damping_Ns_per_m", "stiffness_N_per_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"HandParams.{name} must be finite and >= 0, got {v!r}")

    def at_pivot(self, L3_mm: float) -> tuple[float, float, float]:
        """``(J_h kg m^2, b_h N m s/rad, k_h N m/rad)`` at the handle pivot for a grip at L3."""
        r2 = (L3_mm * 1e-3) ** 2
        return self.mass_kg * r2, self.damping_Ns_per_m * r2, self.stiffness_N_per_m * r2
