"""REST request and response models (kept apart from the SLAM core's own configuration models)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool

RUN_ID_PATTERN = r"^r-[0-9]{8}-[0-9]{4,9}$"
WORLD_NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
MAX_SPEED = 1000.0  # real-time factor

RunStatus = Literal["queued", "running", "finished", "stopped", "interrupted", "error"]
Mapper = Literal["logodds", "paper"]
Speed = Annotated[float, Field(gt=0.0, le=MAX_SPEED)] | Literal["max"]
WorldName = Annotated[str, Field(min_length=1, max_length=64, pattern=WORLD_NAME_PATTERN)]
NoiseOverrides = dict[str, float] | Literal["off"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Health(BaseModel):
    status: Literal["ok"] = "ok"


# -- run configuration ------------------------------------------------------------------------
class RunOptions(_Strict):
    """Run settings a client may give; anything left out comes from the default run configuration."""

    world: WorldName | None = Field(default=None, description="built-in or uploaded world (simulator only)")
    mapper: Mapper | None = None
    resolution: float | None = Field(default=None, gt=0.0, le=1.0, description="map cell side [m]")
    seed: int | None = Field(default=None, ge=0, le=2**63 - 1)
    speed: Speed | None = Field(default=None, description='real-time factor, or "max" for as fast as possible')
    time_limit_s: float | None = Field(
        default=None, gt=0.0, le=1e6, description="stop when the map has not changed for this long [s sim]"
    )
    noise: NoiseOverrides | None = Field(
        default=None, description='simulator noise: field overrides (see SimNoise), or "off" for an exact simulator'
    )
    max_steps: int | None = Field(default=None, ge=1, le=1_000_000, description="safety cap on engine steps")
    end_when_mapped: StrictBool | None = Field(
        default=None,
        description="end once nothing in reach is unresolved and the map has settled; false walks every cell, "
        "as the paper's robot does",
    )


class RunDefaults(_Strict):
    """The default run configuration (``GET``/``PUT /api/config``): every field has a value."""

    world: WorldName
    mapper: Mapper
    resolution: float = Field(gt=0.0, le=1.0)
    seed: int = Field(ge=0, le=2**63 - 1)
    speed: Speed
    time_limit_s: float = Field(gt=0.0, le=1e6)
    noise: NoiseOverrides = Field(default_factory=dict)
    max_steps: int = Field(ge=1, le=1_000_000)
    end_when_mapped: StrictBool = True


class RunCreate(RunOptions):
    """``POST /api/runs``."""


class ConfigUpdate(RunOptions):
    """``PUT /api/config``: the fields given replace the current defaults; the rest stay."""


class RunPatch(_Strict):
    """``PATCH /api/runs/{id}``: settings that can change while a run goes on."""

    speed: Speed


# -- views ---------------------------------------------------------------------------------------
class GridInfo(BaseModel):
    rows: int
    cols: int
    resolution: float  # [m]
    origin: tuple[float, float]  # map frame position of the grid's minimum corner [m]


class Progress(BaseModel):
    step: int = 0
    sim_time_s: float = 0.0
    explored: float | None = Field(default=None, description="share of the reachable area mapped free (simulator)")
    frontier: int | None = None


class RunView(BaseModel):
    id: str
    status: RunStatus
    hardware: Literal["sim", "pi"]
    world: str | None
    mapper: Mapper
    resolution: float
    seed: int
    speed: float | Literal["max"]
    time_limit_s: float
    noise: dict[str, float] | Literal["off"]
    max_steps: int
    end_when_mapped: bool
    grid: GridInfo
    created_at: str  # ISO 8601, UTC
    started_at: str | None = None
    ended_at: str | None = None
    wall_time_s: float | None = None
    progress: Progress
    terminated_by: str | None = None
    metrics: dict[str, Any] | None = None
    error: str | None = None
    downloads: dict[str, str] = Field(default_factory=dict)


class WorldInfo(BaseModel):
    name: str
    source: Literal["builtin", "uploaded"]
    description: str
    width_m: float
    height_m: float
    obstacles: int
    start: dict[str, float]  # x, y [m], theta_deg


class ErrorItem(BaseModel):
    loc: list[str | int]
    msg: str
    type: str


class ErrorBody(BaseModel):
    detail: str | list[ErrorItem]
