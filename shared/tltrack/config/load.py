"""Loading a configuration: the one path from a user's file and options to a validated Config.

Every entry point (the CLI, sensor_sim, the compose services) calls :func:`load_config`: the
TOML or JSON file, then the options given on top, then the truth file's completion
(:func:`complete_from_truth_file`), validated as the user's own (its kinds may be named by import
path, :mod:`tltrack.declare`). A received message's config never comes this way: it is
validated untrusted (:class:`~tltrack.wire.messages.EpisodeStart`).
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tltrack.config.schema import Config, ConfigError, make_config, position_of
from tltrack.config.truth_file import (
    TruthFileError,
    check_clearance,
    recorded_track,
    track_states,
)


def load_config(path: str | Path | None = None, **overrides: Any) -> Config:
    """The config of the user's TOML/JSON file (if any) with the ``overrides`` that are not None
    on top, completed from its truth file if it has one; raises ``ValueError`` naming the field,
    the file or its line."""
    data = read_mapping(path) if path is not None else {}
    given = data.get("truth_file")
    if path is not None and isinstance(given, str) and not Path(given).is_absolute():
        data["truth_file"] = str(Path(path).parent / given)  # as the file's author sees it
    data |= {k: v for k, v in overrides.items() if v is not None}
    return make_config(complete_from_truth_file(data, trusted=True), trusted=True)


def complete_from_truth_file(data: Mapping[str, Any], *, trusted: bool = False) -> dict[str, Any]:
    """A config mapping with a ``truth_file``, completed from the file: ``truth = "file"``, K the
    file's length unless the mapping sets a shorter one, and x0 the track's first state unless
    the mapping sets one. Every sensor is then checked for clearance from the track.

    The config an entry point shares so carries K and x0 explicitly: a tracker elsewhere never
    needs the file. ``trusted``: the mapping is the user's own. Raises
    :class:`~tltrack.config.truth_file.TruthFileError` or :class:`~tltrack.config.ConfigError`.
    """
    if data.get("truth_file") is None:
        return dict(data)
    out = {**data}
    if out.get("truth") not in (None, "file"):
        raise ConfigError(
            f"truth: give either truth_file or truth (the mode {out['truth']!r}), not both"
        )
    out["truth"] = "file"
    draft = make_config(out, trusted=trusted)  # the scenario, Ts and the sensors, validated
    track = recorded_track(draft)
    if "K" not in out:
        out["K"] = track.K
    elif int(out["K"]) > track.K:
        raise TruthFileError(
            f"{track.name}: K = {out['K']} steps is longer than the track ({track.K} steps of "
            f"{draft.Ts:g} s); a truth file's K may only shorten it"
        )
    if "x0" not in out:
        out["x0"] = track_states(draft, track)[0].tolist()
    cfg = make_config(out, trusted=trusted)
    where = {sid: position_of(cfg, sid) for sid in cfg.sensor_ids}
    check_clearance(track.positions[: cfg.K + 1], where, name=track.name)
    return out


def read_mapping(path: str | Path) -> dict[str, Any]:
    """The top-level table of a TOML (``.toml``) or JSON (any other name) config file, not yet
    validated."""
    p = Path(path)
    toml = p.suffix.lower() == ".toml"
    try:
        text = p.read_text(encoding="utf-8-sig")  # an editor's byte-order mark too
    except OSError as err:
        raise ConfigError(f"cannot read config file {p}: {err.strerror}") from None
    except UnicodeDecodeError as err:
        raise ConfigError(f"{p}: not UTF-8 text (byte {err.start}), so not a config") from None
    try:
        data = tomllib.loads(text) if toml else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError, RecursionError) as err:
        also = "" if toml or p.suffix.lower() == ".json" else " (a config is .toml, or else JSON)"
        why = "nested too deeply" if isinstance(err, RecursionError) else err
        raise ConfigError(f"{p}: not valid {'TOML' if toml else 'JSON'}{also}: {why}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: the top level must be a table/object")
    return data
