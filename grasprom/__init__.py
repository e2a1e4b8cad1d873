"""grasprom: FE clamping sweeps of a soft tube and reduced-order grasp models.

Submodules are imported lazily; importing :mod:`grasprom` itself is cheap.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
