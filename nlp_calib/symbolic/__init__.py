"""Symbolic layer: SE(2) and the robust kernels as CasADi expressions (CasADi only, no data)."""
