"""Simulated hardware that behaves like the real thing at the driver boundary, and the scene synthesiser."""
