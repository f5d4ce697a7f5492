"""Independent references for the timing tests: ruckig's time-optimal one-axis move."""

from __future__ import annotations

from ruckig import InputParameter, Result, Ruckig, Trajectory


def ruckig_time(length: float, velocity: float, acceleration: float, jerk: float) -> float:
    """Duration (s) of ruckig's time-optimal rest-to-rest move over ``length`` on one axis within
    the given velocity, acceleration and jerk (units of length per s, s^2, s^3)."""
    inp = InputParameter(1)
    inp.current_position, inp.target_position = [0.0], [length]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [velocity], [acceleration], [jerk]
    trajectory = Trajectory(1)
    assert Ruckig(1).calculate(inp, trajectory) in (Result.Working, Result.Finished)
    return trajectory.duration
