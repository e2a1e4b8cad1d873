"""Stage 3, the grasper's kinematic chain: jaw force from handle force through the linkage, cam
and return spring (mm, N, degrees at the surface, radians inside).

Everything lives in :mod:`grasprom.chain.kinematics` (used as ``from grasprom.chain import
kinematics as kin``); :class:`ChainParams` is re-exported here for convenience.
"""

from grasprom.chain import kinematics
from grasprom.chain.kinematics import ChainParams

__all__ = ["ChainParams", "kinematics"]
