"""grasprom: FE clamping sweeps of a soft tube and reduced-order grasp models.

Submodules are imported lazily; importing :mod:`grasprom` itself is cheap.
``from grasprom import Surrogate`` imports :mod:`grasprom.surrogate` (numpy only) on first use.
"""

__version__ = "0.1.0"

__all__ = ["__version__", "Surrogate"]


def __getattr__(name: str):
    if name == "Surrogate":
        from grasprom.surrogate import Surrogate

        return Surrogate
    raise AttributeError(f"module 'grasprom' has no attribute {name!r}")
