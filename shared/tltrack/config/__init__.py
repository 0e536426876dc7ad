"""The configuration: its schema (:mod:`~tltrack.config.schema`), derived from the components'
declarations; its loading from the user's files (:mod:`~tltrack.config.load`), recorded truths
included (:mod:`~tltrack.config.truth_file`); and the plugin kinds a process is told to import
(:mod:`~tltrack.config.plugins`)."""

from tltrack.config.load import load_config, read_mapping
from tltrack.config.schema import (
    PRESET_OVERRIDES,
    PRIMARY,
    Config,
    ConfigError,
    DetectionSpec,
    FilterKindName,
    LinkSpec,
    ModeSpec,
    SensorSpec,
    SourceSpec,
    describe_validation_error,
    detection_of,
    make_config,
    position_of,
    preset_values,
)

__all__ = [
    "PRESET_OVERRIDES",
    "PRIMARY",
    "Config",
    "ConfigError",
    "DetectionSpec",
    "FilterKindName",
    "LinkSpec",
    "ModeSpec",
    "SensorSpec",
    "SourceSpec",
    "describe_validation_error",
    "detection_of",
    "load_config",
    "make_config",
    "position_of",
    "preset_values",
    "read_mapping",
]
