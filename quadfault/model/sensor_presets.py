"""Named sensor sets measured on real flight logs, and the one reader of what a user gives as
``sensor_noise``: ``as_sensor_noise("crazyflie")``.

Each preset is a :class:`~quadfault.model.sensors.SensorNoise` whose numbers come from
``benchmarks/sensor_noise.py`` run on the logs named in :data:`MEASURED_ON` (the measurement
itself is :mod:`quadfault.diagnosis.sensor_noise`; docs/sensors.md gives the table and how
each number was taken). ``none`` is the paper's noise-free sensors.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.sensors import MODEL_FIELDS, STREAMS, SensorNoise


def _preset(name: str, **streams) -> SensorNoise:
    """A preset from per-stream dicts ``position={"white": .., "markov": .., ...}``."""
    defaults = {"white": 0.0, "markov": 0.0, "tau": 1.0, "bias": 0.0, "rate": 0.0, "latency": 0.0}
    per = {s: {**defaults, **streams.get(s, {})} for s in STREAMS}
    return SensorNoise(
        *(per[s]["white"] for s in STREAMS),
        **{k: tuple(per[s][k] for s in STREAMS) for k in MODEL_FIELDS},
        name=name,
    )


#: name -> the logs (data sets) its numbers were measured on, and how to measure them again
MEASURED_ON = {
    "none": "no noise: the paper's ideal sensors",
    "crazyflie": "the 9 flights of the nano-drone benchmark (Crazyflie 2.1 Brushless, on-board "
    "estimate at 100 Hz): python benchmarks/sensor_noise.py --dataset nanodrone "
    "DATA/nanodrone-cf21bl/*.csv.gz --preset crazyflie",
    "indiflight": "the 3 INDIflight throw flights (Betaflight-based firmware, 0.43 kg 3-inch "
    "quadrotor, 500 Hz blackbox): python benchmarks/sensor_noise.py "
    "DATA/indiflight-throws-early/*.BFL --preset indiflight",
    "px4": "a PX4 mission flight (FMUv3, ULog at its logging rates, 10-31 Hz): python "
    "benchmarks/sensor_noise.py DATA/px4-uavcan-fmuv3/esc_status_log.ulg --preset px4",
}

#: name -> SensorNoise
PRESETS: dict[str, SensorNoise] = {
    "none": SensorNoise(name="none"),
    "crazyflie": _preset(
        "crazyflie",
        position={
            "white": 0.000332,
            "markov": 0.0158,
            "tau": 0.48,
            "rate": 100.0,
            "latency": 0.0073,
        },
        velocity={
            "white": 0.00133,
            "markov": 0.0484,
            "tau": 0.42,
            "rate": 100.0,
            "latency": 0.0112,
        },
        attitude={
            "white": 0.000918,
            "markov": 0.00956,
            "tau": 0.47,
            "rate": 100.0,
            "latency": 0.00158,
        },
        gyro={"white": 0.0196, "bias": 0.000912, "rate": 100.0},
        accel={"white": 0.0274, "bias": 0.0627, "rate": 100.0},
    ),
    "indiflight": _preset(
        "indiflight",
        position={
            "white": 0.000222,
            "markov": 0.0529,
            "tau": 0.436,
            "rate": 504.0,
            "latency": 0.00138,
        },
        velocity={
            "white": 0.00332,
            "markov": 0.181,
            "tau": 0.343,
            "rate": 105.0,
        },
        attitude={"white": 8.15e-05, "markov": 0.00964, "tau": 0.418, "rate": 504.0},
        gyro={"white": 0.0122, "bias": 0.00692, "rate": 504.0},
        accel={"white": 0.151, "bias": 0.115, "rate": 504.0},
    ),
    "px4": _preset(
        "px4",
        position={"white": 0.00227},
        velocity={"white": 0.00809},
        attitude={"white": 0.000667, "markov": 0.0245, "tau": 0.224},
        gyro={"white": 0.183, "bias": 0.00331},
        accel={"white": 2.11, "bias": 0.294},
    ),
}


def names_text() -> str:
    """The presets' names, comma-separated."""
    return ", ".join(PRESETS)


def preset(name: str, where: str = "sensor_noise") -> SensorNoise:
    """The preset ``name`` (case-insensitive), or a one-line ConfigError listing them."""
    key = str(name).strip().lower()
    if key not in PRESETS:
        raise ConfigError(f"{where}: unknown sensor noise preset {name!r}; presets: {names_text()}")
    return PRESETS[key]


def as_sensor_noise(value, where: str = "sensor_noise") -> SensorNoise:
    """The sensors a user gives ``where``: None (noise-free), a SensorNoise, a preset name
    (:data:`PRESETS`), ``"P,V,A,G[,ACC]"`` or 4 or 5 numbers (white noise: position [m],
    velocity [m/s], attitude [rad], gyro [rad/s], accelerometer [m/s^2]), or a dict of the
    fields (``{"preset": "px4", "gyro": 0.01}`` starts from a preset). Bad input is a
    one-line ConfigError naming ``where``."""
    if value is None:
        return SensorNoise()
    if isinstance(value, SensorNoise):
        return value
    if isinstance(value, str):
        text = value.strip()
        if text and (text[0].isdigit() or text[0] in ".-+"):
            return _white(text.split(","), where, value)
        return preset(text, where)
    if isinstance(value, dict):
        items = dict(value)
        base = items.pop("preset", None)
        known = [f.name for f in fields(SensorNoise)]
        unknown = sorted(set(items) - set(known))
        if unknown:
            raise ConfigError(
                f"{where} has unknown keys {unknown}; choose from preset, {', '.join(known)}"
            )
        if base is None:
            return SensorNoise(**items)
        start = preset(str(base), where)
        if items and "name" not in items:
            items["name"] = f"{start.name} (changed)"
        return SensorNoise(**{**start.fields(), **items})
    if isinstance(value, (list, tuple, np.ndarray)):
        return _white(value, where, value)
    raise ConfigError(
        f"{where} must be a preset name ({names_text()}), 'P,V,A,G[,ACC]', a SensorNoise or "
        f"a dict of its fields, got {value!r}"
    )


def _white(parts, where: str, given) -> SensorNoise:
    try:
        vals = np.asarray([float(x) for x in parts], dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(
            f"{where} expects a preset name or 4 or 5 numbers (position, velocity, attitude, "
            f"gyro[, accel]), got {given!r}"
        ) from None
    if vals.ndim != 1 or len(vals) not in (4, 5):
        raise ConfigError(
            f"{where} expects 4 or 5 numbers (position, velocity, attitude, gyro[, accel]), "
            f"got {len(vals)}: {given!r}"
        )
    if not (np.all(np.isfinite(vals)) and np.all(vals >= 0)):
        raise ConfigError(f"{where} numbers must be finite and >= 0, got {given!r}")
    return SensorNoise(*vals.tolist())


__all__ = ["MEASURED_ON", "PRESETS", "names_text", "preset", "as_sensor_noise"]
