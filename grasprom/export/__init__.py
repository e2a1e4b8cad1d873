"""Stage 5, exports: the C core binding, the FMU (FMI 2.0 / 3.0) and the Arduino package."""
