"""Models the tuner designs against: the haptic handle (:class:`DeviceParams`) and the hand.

Both are linear models about the handle pivot: inertia, viscous damping and Coulomb friction of
the device, a mass-spring-damper of the fingers (:class:`HandParams`), with the computation delay
and the motor torque limit of the drive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["DeviceParams", "HandParams"]


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

    @property
    def torque_limit_Nm(self) -> float:
        """Motor torque limit, N m (``torque constant x current limit``)."""
        return self.torque_constant_Nm_per_A * self.current_limit_A


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
