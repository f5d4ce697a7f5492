"""Machine description: a frozen, validated model of the YAML machine file.

User-facing units are mm and degrees (YAML); :class:`Geometry` is what the kinematics use
(mm, and radians everywhere inside the kinematics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Annotated

import yaml
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, ValidationError, model_validator

from .errors import InputError

_STRICT = ConfigDict(extra="forbid", frozen=True)
Length = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


@dataclass(frozen=True)
class Geometry:
    """Identified dimensions of the VERNE (mm), paper notation; ``delta`` = P to tool tip.

    ``delta`` = ``spindle_nose`` + ``tool_length``. Only the differences D1-d1 and D2-d2 enter
    the closure equations (paper eq. 3-5).
    """

    D1_minus_d1: float
    D2_minus_d2: float
    R1: float
    r1: float
    L1: float
    R2: float
    r4: float
    L2: float
    L3: float
    spindle_nose: float
    da: float
    dt: float
    tool_length: float = 0.0

    @property
    def delta(self) -> float:
        """Distance from the platform centre P to the tool tip U (mm)."""
        return self.spindle_nose + self.tool_length

    @property
    def alpha_max(self) -> float:
        """Largest |alpha| (rad) without rod crossing in leg I: R1 cos(alpha) > r1."""
        return math.acos(self.r1 / self.R1)

    def with_tool_length(self, tool_length: float) -> Geometry:
        return replace(self, tool_length=float(tool_length))


class GeometryConfig(BaseModel):
    model_config = _STRICT
    D1_minus_d1: Finite
    D2_minus_d2: Finite
    R1: Length
    r1: Length
    L1: Length
    R2: Length
    r4: Length
    L2: Length
    L3: Length
    spindle_nose: Length
    da: Finite
    dt: Finite

    @model_validator(mode="after")
    def _leg_one_is_a_trapezium(self) -> GeometryConfig:
        if self.r1 >= self.R1:
            raise ValueError("r1 must be smaller than R1 (leg I rods would always cross)")
        return self


class JointLimits(BaseModel):
    """One joint: position range (mm or degrees) and its velocity/acceleration/jerk limits (per s)."""

    model_config = _STRICT
    min: Finite | None = None
    max: Finite | None = None
    continuous: bool = False
    velocity: PositiveFloat
    acceleration: PositiveFloat
    jerk: PositiveFloat

    @model_validator(mode="after")
    def _range(self) -> JointLimits:
        if self.continuous:
            if self.min is not None or self.max is not None:
                raise ValueError("a continuous joint has no min/max")
        else:
            if self.min is None or self.max is None:
                raise ValueError("min and max are required unless continuous: true")
            if self.min >= self.max:
                raise ValueError(f"min ({self.min}) must be smaller than max ({self.max})")
        return self


class Joints(BaseModel):
    model_config = _STRICT
    rho1: JointLimits
    rho2: JointLimits
    rho3: JointLimits
    theta1: JointLimits
    theta2: JointLimits

    @model_validator(mode="after")
    def _only_rotary_may_be_continuous(self) -> Joints:
        for name in ("rho1", "rho2", "rho3", "theta1"):
            if getattr(self, name).continuous:
                raise ValueError(f"{name} cannot be continuous")
        return self


class Singularity(BaseModel):
    """Thresholds below which a pose is reported (see kinematics.jacobian.Margins)."""

    model_config = _STRICT
    serial_min: Annotated[float, Field(ge=0, lt=1)]
    parallel_min: Annotated[float, Field(ge=0, lt=1)]
    machine_min: Annotated[float, Field(ge=0, lt=1)]
    rod_clearance_min: Annotated[float, Field(ge=0, allow_inf_nan=False)]


class Pole(BaseModel):
    model_config = _STRICT
    cone: Annotated[float, Field(gt=0, lt=90)]
    max_theta2_rate: PositiveFloat


class TimingConfig(BaseModel):
    """Time-parametrisation settings."""

    model_config = _STRICT
    rotary_feed: PositiveFloat = 3600.0  # deg/min: rotary speed of blocks where the tip stands still
    corner_angle: Annotated[float, Field(gt=0, le=180)] = 30.0  # deg: sharper corners stop the motion


class Tool(BaseModel):
    model_config = _STRICT
    length: Annotated[float, Field(ge=0, allow_inf_nan=False)]


class GcodeConfig(BaseModel):
    model_config = _STRICT
    linear_decimals: Annotated[int, Field(ge=0, le=8)] = 4
    angular_decimals: Annotated[int, Field(ge=0, le=8)] = 4
    feed_decimals: Annotated[int, Field(ge=0, le=8)] = 5
    block_numbers: bool = False
    block_number_step: Annotated[int, Field(ge=1)] = 10


class Machine(BaseModel):
    """A whole machine file. Lengths mm, angles degrees (as written in the YAML)."""

    model_config = _STRICT
    name: str
    geometry: GeometryConfig
    joints: Joints
    singularity: Singularity
    pole: Pole
    tools: dict[Annotated[int, Field(ge=0)], Tool] = Field(default_factory=dict)
    work_offset: tuple[Finite, Finite, Finite] = (0.0, 0.0, 0.0)
    gcode: GcodeConfig = GcodeConfig()
    timing: TimingConfig = TimingConfig()
    source: str = "verne.yaml"

    def kinematic_geometry(self, tool_length: float = 0.0) -> Geometry:
        """The :class:`Geometry` for the kinematics with the given tool length (mm)."""
        return Geometry(**self.geometry.model_dump(), tool_length=float(tool_length))

    @property
    def geom(self) -> Geometry:
        """Geometry with tool length 0 (Delta = spindle nose distance, the paper's tables)."""
        return self.kinematic_geometry(0.0)



DEFAULT_MACHINE = "verne.yaml"


def _format_validation_error(error: ValidationError) -> str:
    first = error.errors()[0]
    path = ".".join(str(p) for p in first["loc"]) or "(top level)"
    message = first["msg"]
    if first["type"] == "extra_forbidden":
        message = "unknown key"
    more = f" (and {error.error_count() - 1} more)" if error.error_count() > 1 else ""
    return f"{path}: {message}{more}"


def load_machine(path: str | Path | None = None) -> Machine:
    """Read and validate a machine YAML file; ``None`` gives the VERNE shipped with the package."""
    if path is None:
        text = (resources.files("verne_post") / "machines" / DEFAULT_MACHINE).read_text()
        source = DEFAULT_MACHINE
    else:
        source = str(path)
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read machine file: {exc}", source) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise InputError(f"invalid YAML: {getattr(exc, 'problem', exc)}", source,
                         None if line is None else line + 1) from None
    if not isinstance(data, dict):
        raise InputError("machine file must be a YAML mapping", source)
    try:
        return Machine.model_validate({**data, "source": Path(source).name})
    except ValidationError as exc:
        raise InputError(f"invalid machine: {_format_validation_error(exc)}", source) from None
