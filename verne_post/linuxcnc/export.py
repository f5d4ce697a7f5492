"""A LinuxCNC 2.9 configuration of the machine in joint space: ``verne.ini``, ``verne.hal``, ``verne.tbl``.

The program's axis words are the joints (X Y Z = sliders rho1..rho3 in mm, A C = tilt theta1 and
rotary theta2 in degrees, or the letters of the machine's controller profile), so LinuxCNC runs
it with ``trivkins``: joint i is axis letter i, one to one. The configuration is a simulation:
each joint's ``motor-pos-cmd`` is looped back to its ``motor-pos-fb``, homing happens at once
(``HOME_SEARCH_VEL = 0``), the emergency stop and the tool changer are looped back. It runs as
``linuxcnc DIR/verne.ini``; comments marked ``REAL HARDWARE`` say what a machine must add.

Limits come from the machine file: travel (mm, degrees), velocity (per s) and acceleration (per
s^2) of each joint. LinuxCNC 2.9's planner has no jerk limit, so the machine's jerks are not
written. A continuous rotary gets wide soft limits (:data:`CONTINUOUS_LIMIT`).

``time_scale`` K writes the configuration that runs the same motion K times faster (for
``simulate``): velocities times K, accelerations times K^2, the servo period divided by K
(the program's F words and dwells must be scaled by the caller).

A pure function of its arguments: it writes files and starts nothing.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from ..errors import InputError, OutputError
from ..machine import Machine

__all__ = ["CONTINUOUS_LIMIT", "INI_NAME", "SERVO_PERIOD_NS", "export_config", "joint_home"]

#: The files written, in the configuration directory.
INI_NAME = "verne.ini"
HAL_NAME = "verne.hal"
TOOL_TABLE_NAME = "verne.tbl"
PARAMETER_FILE_NAME = "verne.var"

#: Servo period at time scale 1 (ns): 1 ms, LinuxCNC's usual servo thread.
SERVO_PERIOD_NS = 1_000_000

#: Soft limits (degrees) of a continuous rotary: LinuxCNC wants a range; no program goes there.
CONTINUOUS_LIMIT = 1.0e6

_NAMES = ("rho1", "rho2", "rho3", "theta1", "theta2")
_ROTARY_LETTERS = "ABC"


def _is_rotary(k: int) -> bool:
    return k >= 3


def joint_home(machine: Machine, home: Iterable[float] | None = None) -> np.ndarray:
    """The home position (5,) in mm and degrees: ``home`` (mm, degrees) if given, else the machine
    file's ``positions.home``, else the middle of each joint's travel (0 for a continuous rotary)."""
    if home is not None:
        values = np.asarray(list(home), dtype=float).reshape(-1)
        if values.shape != (5,) or not np.all(np.isfinite(values)):
            raise InputError(f"the home position must be 5 finite numbers (mm, deg), got {values.size}")
        return values
    if machine.positions.home is not None:
        position = machine.positions.home
        return np.array([getattr(position, name) for name in _NAMES], dtype=float)
    out = []
    for name in _NAMES:
        joint = getattr(machine.joints, name)
        out.append(0.0 if joint.continuous else 0.5 * (joint.min + joint.max))
    return np.array(out)


def _limits(machine: Machine, k: int) -> tuple[float, float]:
    joint = getattr(machine.joints, _NAMES[k])
    if joint.continuous:
        return -CONTINUOUS_LIMIT, CONTINUOUS_LIMIT
    return float(joint.min), float(joint.max)


def _number(value: float) -> str:
    text = f"{value:.9g}"
    return text if "e" not in text else f"{value:.12f}".rstrip("0").rstrip(".")


def export_config(machine: Machine, directory: str | Path, *, home: Iterable[float] | None = None,
                  time_scale: float = 1.0, tools: Mapping[int, float] | None = None,
                  name: str | None = None) -> Path:
    """Write ``verne.ini``, ``verne.hal`` and ``verne.tbl`` for ``machine`` into ``directory``
    (created if missing); return the INI file's path.

    ``home``: the joint position (mm, degrees) the machine homes at, at once (default
    :func:`joint_home`). ``time_scale`` K > 0: the motion K times faster (see the module). ``tools``:
    tool number to length (mm) for the tool table, over the machine file's tools (the program
    changes tools with ``T.. M6``; LinuxCNC refuses a tool its table does not hold).
    """
    if not (isinstance(time_scale, (int, float)) and math.isfinite(time_scale) and 0.01 <= time_scale <= 100):
        raise InputError(f"time scale {time_scale!r} is out of range (0.01 to 100)")
    profile = machine.controller.profile()
    letters = tuple(letter.upper() for letter in profile.axes)
    for k, letter in enumerate(letters):
        if (letter in _ROTARY_LETTERS) != _is_rotary(k):
            kind = "a rotary" if _is_rotary(k) else "a linear"
            raise InputError(f"controller.axes: {_NAMES[k]} is {kind} joint but LinuxCNC's axis {letter} is "
                             f"{'rotary' if letter in _ROTARY_LETTERS else 'linear'}: give it a "
                             f"{'A, B or C' if _is_rotary(k) else 'X, Y, Z, U, V or W'} letter")
    home_position = joint_home(machine, home)
    for k in range(5):
        low, high = _limits(machine, k)
        if not low <= home_position[k] <= high:
            raise InputError(f"the home position of {_NAMES[k]} ({home_position[k]:g}) is outside its travel "
                             f"({low:g} to {high:g})")
    scale = float(time_scale)
    period = max(1, round(SERVO_PERIOD_NS / scale))
    joints = [getattr(machine.joints, n) for n in _NAMES]
    velocity = [j.velocity * scale for j in joints]
    acceleration = [j.acceleration * scale**2 for j in joints]
    table = {number: tool.length for number, tool in machine.tools.items()}
    table.update(tools or {})
    coordinates = "".join(letters)
    title = name or machine.name

    ini = _ini(title, coordinates, letters, period, velocity, acceleration, home_position,
               [_limits(machine, k) for k in range(5)], scale)
    hal = _hal(title)
    tbl = "".join(f"T{n} P{n} Z0 D0 ;tool {n}, {length:g} mm (joint-space program: no length offset)\n"
                  for n, length in sorted(table.items()))
    folder = Path(directory)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for file_name, text in ((INI_NAME, ini), (HAL_NAME, hal), (TOOL_TABLE_NAME, tbl)):
            (folder / file_name).write_text(text, encoding="utf-8")
    except OSError as error:
        raise OutputError(f"cannot write the LinuxCNC configuration: {error.strerror or error}", str(folder)) from None
    return folder / INI_NAME


def _ini(title: str, coordinates: str, letters: tuple[str, ...], period: int, velocity: list[float],
         acceleration: list[float], home: np.ndarray, limits: list[tuple[float, float]], scale: float) -> str:
    linear_v = math.sqrt(sum(v**2 for v in velocity[:3]))
    linear_a = math.sqrt(sum(a**2 for a in acceleration[:3]))
    angular_v = math.sqrt(sum(v**2 for v in velocity[3:]))
    angular_a = math.sqrt(sum(a**2 for a in acceleration[3:]))
    scaled = "" if scale == 1.0 else (
        f"# TIME SCALE {scale:g}: velocities x {scale:g}, accelerations x {scale**2:g}, servo period / {scale:g}:\n"
        f"# the motion of time scale 1, {scale:g} times faster (for verne-post simulate, not for a machine).\n")
    out = [
        f"# LinuxCNC 2.9 configuration of {title} in joint space, written by verne-post (machine export linuxcnc).",
        "# The program's axis words are the joints (trivkins: joint i = axis letter i). A SIMULATION as",
        "# written: motor-pos-cmd is looped back to motor-pos-fb, homing is immediate. Run: linuxcnc verne.ini",
        "# REAL HARDWARE must add: drivers and encoder feedback in verne.hal (instead of the loopback),",
        "# a real emergency stop chain, limit and home switches with HOME_SEARCH_VEL / HOME_LATCH_VEL,",
        "# following-error limits tuned to the drives, and a real tool changer (or M6 remapped).",
        *([scaled.rstrip("\n")] if scaled else []),
        "",
        "[EMC]",
        "VERSION = 1.1",
        f"MACHINE = {title}",
        "DEBUG = 0",
        "",
        "[DISPLAY]",
        "# Any LinuxCNC display; verne-post simulate starts none.",
        "DISPLAY = axis",
        "POSITION_OFFSET = MACHINE",
        "POSITION_FEEDBACK = COMMANDED",
        "MAX_FEED_OVERRIDE = 1.0",
        "INTRO_GRAPHIC =",
        "INTRO_TIME = 0",
        "",
        "[TASK]",
        "TASK = milltask",
        "CYCLE_TIME = 0.001",
        "",
        "[RS274NGC]",
        f"PARAMETER_FILE = {PARAMETER_FILE_NAME}",
        "",
        "[EMCMOT]",
        "EMCMOT = motmod",
        "COMM_TIMEOUT = 1.0",
        "BASE_PERIOD = 0",
        f"SERVO_PERIOD = {period}",
        "",
        "[EMCIO]",
        "EMCIO = io",
        "CYCLE_TIME = 0.010",
        f"TOOL_TABLE = {TOOL_TABLE_NAME}",
        "",
        "[HAL]",
        f"HALFILE = {HAL_NAME}",
        "",
        "[KINS]",
        f"KINEMATICS = trivkins coordinates={coordinates}",
        "JOINTS = 5",
        "",
        "[TRAJ]",
        f"COORDINATES = {coordinates}",
        "LINEAR_UNITS = mm",
        "ANGULAR_UNITS = degree",
        "# The vector limits of the planner, on the sliders (X Y Z) and on the rotaries: never tighter",
        "# than the joints' own limits together (the joints' limits below are what binds).",
        f"DEFAULT_LINEAR_VELOCITY = {_number(linear_v)}",
        f"MAX_LINEAR_VELOCITY = {_number(linear_v)}",
        f"DEFAULT_LINEAR_ACCELERATION = {_number(linear_a)}",
        f"MAX_LINEAR_ACCELERATION = {_number(linear_a)}",
        f"DEFAULT_ANGULAR_VELOCITY = {_number(angular_v)}",
        f"MAX_ANGULAR_VELOCITY = {_number(angular_v)}",
        f"DEFAULT_ANGULAR_ACCELERATION = {_number(angular_a)}",
        f"MAX_ANGULAR_ACCELERATION = {_number(angular_a)}",
        "NO_FORCE_HOMING = 0",
        "",
    ]
    for k, letter in enumerate(letters):
        low, high = limits[k]
        out += [
            f"[AXIS_{letter}]",
            f"MIN_LIMIT = {_number(low)}",
            f"MAX_LIMIT = {_number(high)}",
            f"MAX_VELOCITY = {_number(velocity[k])}",
            f"MAX_ACCELERATION = {_number(acceleration[k])}",
            "",
        ]
    for k in range(5):
        low, high = limits[k]
        rotary = _is_rotary(k)
        unit = "deg" if rotary else "mm"
        out += [
            f"[JOINT_{k}]",
            f"# {_NAMES[k]} ({'table ' + ('tilt' if k == 3 else 'rotary') if rotary else 'slider'}), {unit}",
            f"TYPE = {'ANGULAR' if rotary else 'LINEAR'}",
            f"MIN_LIMIT = {_number(low)}",
            f"MAX_LIMIT = {_number(high)}",
            f"MAX_VELOCITY = {_number(velocity[k])}",
            f"MAX_ACCELERATION = {_number(acceleration[k])}",
            "BACKLASH = 0.0",
            "# REAL HARDWARE: following-error limits of the drives.",
            "FERROR = 1.0",
            "MIN_FERROR = 0.1",
            "# Homes at once where it stands, at HOME (HOME_SEARCH_VEL 0). REAL HARDWARE: home switches,",
            "# HOME_SEARCH_VEL, HOME_LATCH_VEL, HOME_OFFSET of the switch, HOME_SEQUENCE.",
            f"HOME = {_number(float(home[k]))}",
            f"HOME_OFFSET = {_number(float(home[k]))}",
            "HOME_SEARCH_VEL = 0",
            "HOME_LATCH_VEL = 0",
            "HOME_USE_INDEX = 0",
            "HOME_IGNORE_LIMITS = 0",
            "HOME_SEQUENCE = 0",
            "",
        ]
    return "\n".join(out) + "\n"


def _hal(title: str) -> str:
    lines = [
        f"# HAL of {title} in joint space (verne-post machine export linuxcnc): a simulation.",
        "# The launcher (linuxcnc verne.ini) has loaded tpmod, homemod and io (iocontrol) before this file.",
        "loadrt [KINS]KINEMATICS",
        "loadrt [EMCMOT]EMCMOT base_period_nsec=[EMCMOT]BASE_PERIOD servo_period_nsec=[EMCMOT]SERVO_PERIOD "
        "num_joints=[KINS]JOINTS",
        "addf motion-command-handler servo-thread",
        "addf motion-controller servo-thread",
        "",
        "# REAL HARDWARE: send joint.N.motor-pos-cmd to the drives and feed the encoders to joint.N.motor-pos-fb",
        "# (with a PID where the drives take velocity), and the amplifiers' enable from joint.N.amp-enable-out.",
    ]
    lines += [f"net j{k}-pos joint.{k}.motor-pos-cmd => joint.{k}.motor-pos-fb" for k in range(5)]
    lines += [
        "",
        "# REAL HARDWARE: the emergency stop chain into iocontrol.0.emc-enable-in.",
        "net estop-loop iocontrol.0.user-enable-out => iocontrol.0.emc-enable-in",
        "# REAL HARDWARE: the tool changer's handshake (or M6 remapped); here every change is done at once.",
        "net tool-prep-loop iocontrol.0.tool-prepare => iocontrol.0.tool-prepared",
        "net tool-change-loop iocontrol.0.tool-change => iocontrol.0.tool-changed",
    ]
    return "\n".join(lines) + "\n"
