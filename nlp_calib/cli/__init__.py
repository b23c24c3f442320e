"""Command-line layer: ``nlp-calib`` (also ``python -m nlp_calib``). The only layer that prints."""

from nlp_calib.cli.main import main

__all__ = ["main"]
