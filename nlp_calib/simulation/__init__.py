"""Simulation layer: synthetic logs with known truth, written in the log text format."""

from nlp_calib.simulation.simulate import (
    LIMITS,
    TRAJECTORIES,
    SimulatedLog,
    SimulationOptions,
    simulate,
    simulate_to_file,
    truth_path,
    write_simulation,
)

__all__ = [
    "LIMITS",
    "TRAJECTORIES",
    "SimulatedLog",
    "SimulationOptions",
    "simulate",
    "simulate_to_file",
    "truth_path",
    "write_simulation",
]
