"""Service settings: defaults, then ``config/server.toml``, then ``SONARSLAM_*`` variables, then flags."""

from __future__ import annotations

import ipaddress
import secrets
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, SecretStr, ValidationError, field_validator
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    TomlConfigSettingsSource,
)

from robot.config import CONFIG_DIR, error_message
from robot.errors import ConfigError

SERVER_TOML = CONFIG_DIR / "server.toml"
DEFAULT_WEB_DIR = Path(__file__).resolve().parent.parent / "web"
LOOPBACK_NAMES = ("localhost", "ip6-localhost")


class ServerSettings(BaseSettings):
    """Everything ``sonarslam serve`` can be told. Invalid values stop the service at start-up."""

    model_config = SettingsConfigDict(env_prefix="SONARSLAM_", extra="forbid", frozen=True)

    host: str = Field(default="127.0.0.1", min_length=1, max_length=255)  # bind address
    port: int = Field(default=8000, ge=0, le=65535)  # 0 = any free port
    hardware: Literal["sim", "pi"] = "sim"
    data_dir: Path = Path("data")  # SQLite database, uploaded worlds and one folder per run
    token: SecretStr | None = None  # bearer token for control endpoints (generated off loopback)
    view_access: Literal["open", "token"] = "open"  # whether viewing (GET, WebSocket) needs the token too
    cors_origins: tuple[str, ...] = ()  # browser origins allowed to call the API from other sites
    max_concurrent_runs: int = Field(default=2, ge=1, le=64)  # simulator only; hardware runs one at a time
    # Where a simulated run's step engine runs: a child process of its own (the event loop never shares the
    # interpreter lock with it), or a thread of the service as real hardware always does (for profiling).
    sim_engine: Literal["process", "thread"] = "process"
    max_queued_runs: int = Field(default=16, ge=0, le=1000)  # runs waiting for a slot before 429 (simulator)
    checkpoint_interval_s: float = Field(default=3.0, gt=0.0, le=3600.0)  # map checkpoint period [s wall]
    ws_queue_size: int = Field(default=64, ge=2, le=100_000)  # messages a viewer may fall behind before merging
    # Messages per second per viewer, at most; faster steps are merged. 25 rather than 30: with 50
    # viewers of a max-speed room1 run it cut the bytes from 5.0-5.5 % of resending the grid to 4.6 %
    # and the run's slowdown from +8-17 % to +8-10 %, for a pose latency p99 of 31 ms instead of 24.
    ws_max_rate_hz: float = Field(default=25.0, ge=1.0, le=10_000.0)
    # Offer permessage-deflate to viewers (browsers accept it): about a third of the bytes on the wire, for
    # a compressor per viewer (~45 kB) and the loop's CPU: 50 compressed viewers slowed a max-speed run by
    # 40-58 % while engines ran on a thread of the service, +0.6-1.9 % in child processes (docs/protocol.md).
    # On: SONARSLAM_WS_COMPRESSION=true, or ws_compression = true in config/server.toml.
    ws_compression: bool = False
    max_body_bytes: int = Field(default=1 << 20, ge=1024, le=1 << 30)  # any request body
    max_world_bytes: int = Field(default=256 << 10, ge=256, le=64 << 20)  # an uploaded world file
    max_grid_cells: int = Field(default=250_000, ge=100, le=50_000_000)  # rows x cols of one run's map
    run_config_file: Path | None = None  # TOML overriding [slam], [sim_noise] or the robot (as `run --config`)
    pi_config_file: Path | None = None  # robot-pi.toml for --hardware pi (default config/robot-pi.toml)
    web_dir: Path = DEFAULT_WEB_DIR  # static page served at /
    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        return (init_settings, env_settings, TomlConfigSettingsSource(settings_cls, toml_file=SERVER_TOML))

    @field_validator("token")
    @classmethod
    def _token_strength(cls, value: SecretStr | None) -> SecretStr | None:
        if value is not None and len(value.get_secret_value()) < 8:
            raise ValueError("the token must be at least 8 characters")
        return value

    @field_validator("cors_origins", mode="before")
    @classmethod
    def _origins(cls, value: Any) -> Any:
        if isinstance(value, str):  # a comma-separated list is easier to type than JSON
            return tuple(v.strip() for v in value.split(",") if v.strip())
        return value

    @property
    def loopback_only(self) -> bool:
        """True when only this machine can reach the service."""
        if self.host in LOOPBACK_NAMES:
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False

    @property
    def token_required(self) -> bool:
        """Control endpoints need the token when one is set, and always off loopback."""
        return self.token is not None or not self.loopback_only

    @property
    def token_value(self) -> str | None:
        return self.token.get_secret_value() if self.token is not None else None

    @property
    def concurrent_runs(self) -> int:
        return 1 if self.hardware != "sim" else self.max_concurrent_runs


def with_token(settings: ServerSettings) -> tuple[ServerSettings, bool]:
    """Settings whose token is set whenever one is required; True if it had to be generated."""
    if settings.token_required and settings.token is None:
        return settings.model_copy(update={"token": SecretStr(secrets.token_urlsafe(24))}), True
    return settings, False


def load_settings(**overrides: Any) -> ServerSettings:
    """Build the settings, turning a validation failure into a one-line ConfigError."""
    try:
        return ServerSettings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in err["loc"]) or "settings"
        msg = error_message(err)
        got = "" if where == "token" else f" (got {err.get('input')!r})"  # never echo a secret
        raise ConfigError(f"server setting {where}: {msg}{got}") from None
