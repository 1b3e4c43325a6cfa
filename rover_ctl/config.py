"""The daemon's one configuration object.

Every tunable number of the daemon lives here as a named, documented field of a section
dataclass, with its unit in the name. ``Config`` groups the sections; ``load_config`` reads a TOML
file whose tables are the section names (``[robot]``, ``[link]``, ...) and applies dotted
``section.field=value`` overrides from the command line. Unknown sections or keys and values of the
wrong type are refused with a one-line error naming the file and key.

The SITL emulator has its own parameters (``sitl.params``): it stands for the physical rover and
shares nothing with the daemon but the wire.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


class ConfigError(ValueError):
    """A configuration file or override that cannot be used; the message names what and where."""


@dataclass
class RobotParams:
    """The rover as the controller knows it (defaults: the paper's robot)."""

    track_m: float = 0.32
    """Distance between the left and right wheel contact lines."""
    wheel_radius_m: float = 0.07
    max_wheel_rpm: float = 200.0
    """Wheel speed the navigator may command at most (the paper's forward_fast peak)."""
    footprint_length_m: float = 0.45
    footprint_width_m: float = 0.40

    @property
    def max_speed_mps(self) -> float:
        """Top ground speed: wheel rpm -> rad/s -> m/s."""
        import math

        return self.max_wheel_rpm * 2.0 * math.pi / 60.0 * self.wheel_radius_m


@dataclass
class LinkParams:
    """The vehicle link: how the daemon talks to the rover (or the SITL)."""

    vehicle_url: str = "tcp:127.0.0.1:5760"
    """pymavlink connection string of the vehicle (udp/tcp/serial)."""
    gcs_url: str = "udpout:127.0.0.1:14550"
    """pymavlink connection string of the ground-station link."""
    source_system: int = 255
    """Our system id on the vehicle link; ArduPilot accepts RC overrides only from SYSID_MYGCS (255)."""
    source_component: int = 190
    heartbeat_period_s: float = 1.0
    override_timeout_s: float = 1.0
    """The vehicle's RC override timeout: overrides must be refreshed faster than this."""


@dataclass
class Config:
    """All sections. Add a section by adding a dataclass field here."""

    robot: RobotParams = field(default_factory=RobotParams)
    link: LinkParams = field(default_factory=LinkParams)


def _coerce(value: Any, current: Any, where: str) -> Any:
    if isinstance(current, bool):
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "1", "0", "yes", "no"):
            return value.lower() in ("true", "1", "yes")
        raise ConfigError(f"{where}: expected true/false, got {value!r}")
    if isinstance(current, (int, float)) and not isinstance(current, bool):
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: expected a number, got {value!r}") from None
        if isinstance(current, int) and not isinstance(value, float):
            if number != int(number):
                raise ConfigError(f"{where}: expected a whole number, got {value!r}")
            return int(number)
        return number
    if isinstance(current, str):
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if isinstance(current, (list, tuple)):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        return type(current)(value)
    return value


def _apply(section: Any, values: dict[str, Any], where: str) -> None:
    names = {f.name for f in dataclasses.fields(section)}
    for key, value in values.items():
        if key not in names:
            raise ConfigError(f"{where}: unknown key {key!r} (known: {', '.join(sorted(names))})")
        current = getattr(section, key)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, dict):
                raise ConfigError(f"{where}.{key}: expected a table")
            _apply(current, value, f"{where}.{key}")
        else:
            setattr(section, key, _coerce(value, current, f"{where}.{key}"))


def load_config(path: str | Path | None = None, overrides: list[str] | None = None) -> Config:
    """Defaults, then the TOML file at ``path``, then ``section.key=value`` overrides."""
    config = Config()
    if path is not None:
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ConfigError(f"{path}: no such config file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: invalid TOML: {exc}") from None
        _apply(config, data, str(path))
    for item in overrides or []:
        key, sep, value = item.partition("=")
        if not sep or "." not in key:
            raise ConfigError(f"--set {item!r}: expected section.key=value")
        *sections, leaf = key.strip().split(".")
        nested: dict[str, Any] = {leaf: value.strip()}
        for name in reversed(sections):
            nested = {name: nested}
        _apply(config, nested, "--set")
    return config
