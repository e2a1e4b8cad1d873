"""Stage 3, the grasper's kinematic chain: jaw force from handle force through the linkage, cam
and return spring (mm, N, degrees at the surface, radians inside)."""
