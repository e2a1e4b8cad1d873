"""Stage 1, FE sweeps: materials, the clamped-tube models, sweeps over thickness x material,
case files and the sweep report (mm, N, MPa)."""
