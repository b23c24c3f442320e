"""Foundation layer: the package's errors and warnings, its version, numpy helpers and file writing.

Every other layer may import from here; nothing here imports from another layer.
"""
