"""The dashboard's settings: environment ``TLTRACK_DASHBOARD_<FIELD>`` or ``--<field>``."""

from __future__ import annotations

from pydantic import Field
from pydantic_settings import SettingsConfigDict
from tltrack.live.service import ServiceSettings

NAME = "dashboard"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8050


class Settings(ServiceSettings):
    """Loopback by default: the page shows referee data, so exposing it is an explicit choice
    (``TLTRACK_DASHBOARD_HOST=0.0.0.0`` in a container, behind a published port)."""

    model_config = SettingsConfigDict(
        env_prefix="TLTRACK_DASHBOARD_", cli_prog_name=NAME, env_ignore_empty=True
    )

    host: str = Field(DEFAULT_HOST, min_length=1, description="address to serve the page on")
    port: int = Field(DEFAULT_PORT, ge=1, le=65535, description="TCP port of the page")
    poll_ms: int = Field(250, ge=50, le=10_000, description="how often the page refreshes")
    max_episodes: int = Field(4, ge=1, le=64, description="episodes kept in memory")
    max_steps: int = Field(20_000, ge=1, le=1_000_000, description="steps kept per series")
    max_filters: int = Field(8, ge=1, le=64, description="estimate streams kept per episode")
    max_points: int = Field(2_000, ge=10, le=100_000, description="points per series sent")
