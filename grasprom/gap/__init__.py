"""Stage 6, the sim-to-real gap: measured trials, candidate effects, the diagnosis, the
augmented model and synthetic "real" trials with withheld effects."""
