"""Stage 4, the controller: parameters, the open-loop impedance controller (Python reference),
simulation of trajectories and passivity tuning with python-control."""
