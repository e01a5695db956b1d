"""Sensors: what the loop measures of the true state, and how.

Five streams, in this order everywhere (:data:`STREAMS`): ``position`` [m] and ``velocity``
[m/s] (world frame), ``attitude`` [rad] (a rotation-vector perturbation ``R exp([e]x)``),
``gyro`` [rad/s] and ``accel`` [m/s^2] (body FRD; the accelerometer reads the specific force at
the step's start). Each stream has, per axis:

* **white** noise of standard deviation ``position`` .. ``accel`` [unit], a fresh draw per sample;
* **coloured** noise: second-order Gauss-Markov (critically damped: a first-order
  Gauss-Markov process passed through a first-order low-pass of the same time constant
  ``tau / COLOURED_SHAPE``), stationary standard deviation ``markov`` [unit], its
  autocorrelation ``(1 + s) exp(-s)`` (``s`` the lag over that time constant) falling to
  ``1/e`` at the lag ``tau`` [s]; stepped exactly per sample (:func:`_coloured_step`) and started
  from its stationary distribution. An onboard estimator's error is smooth (its states
  integrate the IMU between corrections); a first-order process of the same variance and
  ``tau`` has a rough path whose steps, seen by a controller differentiating them at the
  physics rate, shake a simulated vehicle that flies on them;
* a **bias**: constant over a flight, drawn at its start with standard deviation ``bias``;
* a **rate** [Hz]: sampled every ``1/rate`` s and held in between (0: every physics step);
* a **latency** [s]: the sample measures the truth of ``latency`` earlier (whole physics steps).

So position, velocity and attitude can look like an onboard estimator's output (a filter's
coloured, delayed output at its own rate) and gyro and accelerometer like raw sensors (white
noise with the vibration of the motors, a bias). Named sets measured on real logs are in
:mod:`quadfault.model.sensor_presets` (``as_sensor_noise("crazyflie")``).

Draws (from the vehicle's generator, inside the compiled loop): with white noise only (no
coloured noise, bias, rate or latency) per physics step ``p`` (3), ``v`` (3), attitude (3, only
when its std is non-zero), ``w`` (3) -- all of them whenever any std is non-zero -- and then,
after the motors' draws, the accelerometer (3, when its std is non-zero). With the full model:
at a flight's first measurement each stream's bias (3, when non-zero) and coloured start (2 per
axis, when non-zero), in stream order; then at each sample of a stream its coloured step (2 per
axis) and its white noise (3), each only when non-zero. No noise draws nothing.

:func:`measure3` / :func:`accelerometer3` (white noise) and :func:`measure_model` /
:func:`accelerometer_model` (the full model, with a per-vehicle state :func:`state_width`
wide) are the kernels; :meth:`SensorNoise.measure` runs the white kernels on one state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.rotation import expm3, mat3, matmul3, store3, store33, vec3

#: the measured streams, in the order of every per-stream tuple
STREAMS = ("position", "velocity", "attitude", "gyro", "accel")
#: their units
UNITS = ("m", "m/s", "rad", "rad/s", "m/s^2")
#: the per-stream fields of the full model, in the kernels' column order
MODEL_FIELDS = ("markov", "tau", "bias", "rate", "latency")

#: kernel row: 5 white stds, any noise, full model, then per stream MODEL_FIELDS
ROW_WIDTH = 7 + 5 * len(MODEL_FIELDS)
#: per-vehicle state: [initialised, measurements since], per stream [phase, bias 3,
#: coloured 3, held 9, the coloured noise's driving process 3], then the latency ring (rows of
#: p 3, v 3, R 9, w 3, specific force 3)
_HEAD, _STREAM, _RING = 2, 19, 21
#: the coloured noise's time constant is ``tau / COLOURED_SHAPE``: ``(1 + s) exp(-s) = 1/e`` at
#: ``s = COLOURED_SHAPE``, so that its autocorrelation falls to ``1/e`` at ``tau`` (how
#: :mod:`quadfault.diagnosis.sensor_noise` measures ``tau``)
COLOURED_SHAPE = 2.146193220620583


def _five(name: str, value, default: float) -> tuple:
    """``value`` as a tuple of five floats (one per stream), or a one-line error."""
    if value is None:
        return (float(default),) * 5
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(
            f"sensor noise {name} must be 5 numbers ({', '.join(STREAMS)}), got {value!r}"
        ) from None
    if arr.ndim == 0:
        arr = np.full(5, float(arr))
    if arr.shape != (5,):
        raise ConfigError(
            f"sensor noise {name} must have 5 values ({', '.join(STREAMS)}), got shape {arr.shape}"
        )
    return tuple(float(x) for x in arr)


@dataclass(frozen=True)
class SensorNoise:
    """The sensors of a flight (noise-free by default, as in the paper; see the module
    docstring for the model).

    Attributes:
        position [m], velocity [m/s], attitude [rad], gyro [rad/s], accel [m/s^2]: standard
            deviation of each stream's white noise per sample.
        markov: per stream (:data:`STREAMS` order), the stationary standard deviation of its
            second-order Gauss-Markov noise [unit] (the module docstring).
        tau: per stream, that noise's correlation time [s].
        bias: per stream, the standard deviation of its constant per-flight bias [unit].
        rate: per stream, its sample rate [Hz] (held in between; 0: every physics step).
        latency: per stream, its delay [s] (rounded to whole physics steps).
        name: the preset these numbers come from ("" for numbers given by hand).

    Every per-stream field takes 5 numbers or one number for all five.
    :func:`quadfault.model.sensor_presets.as_sensor_noise` builds one from what a user gives (a
    preset name, ``"P,V,A,G[,ACC]"``, a dict or numbers).
    """

    position: float = 0.0
    velocity: float = 0.0
    attitude: float = 0.0
    gyro: float = 0.0
    accel: float = 0.0
    markov: tuple = (0.0,) * 5
    tau: tuple = (1.0,) * 5
    bias: tuple = (0.0,) * 5
    rate: tuple = (0.0,) * 5
    latency: tuple = (0.0,) * 5
    name: str = ""

    def __post_init__(self):
        for k in STREAMS:
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ConfigError(f"sensor noise {k} must be a number >= 0, got {v!r}")
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"sensor noise {k} must be >= 0, got {v!r}")
            object.__setattr__(self, k, float(v))
        for k, default in zip(MODEL_FIELDS, (0.0, 1.0, 0.0, 0.0, 0.0)):
            five = _five(k, getattr(self, k), default)
            for s, x in zip(STREAMS, five):
                if not (math.isfinite(x) and x >= 0):
                    raise ConfigError(f"sensor noise {k} of {s} must be >= 0, got {x!r}")
                if k == "tau" and x <= 0:
                    raise ConfigError(f"sensor noise tau of {s} must be > 0 [s], got {x!r}")
            object.__setattr__(self, k, five)
        if not isinstance(self.name, str):
            raise ConfigError(f"sensor noise name must be a string, got {self.name!r}")

    def fields(self) -> dict:
        """The fields as a dict (``SensorNoise(**noise.fields())`` is ``noise``)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def replace(self, **changes) -> SensorNoise:
        return SensorNoise(**{**self.fields(), **changes})

    # -- what it is ---------------------------------------------------------------------------
    @property
    def white(self) -> tuple:
        """The white standard deviations, per stream."""
        return tuple(getattr(self, k) for k in STREAMS)

    @property
    def model(self) -> bool:
        """Whether anything beyond white noise is set (coloured noise, bias, rate, latency)."""
        return any(any(getattr(self, k)) for k in ("markov", "bias", "rate", "latency"))

    @property
    def any(self) -> bool:
        """Whether the measurement differs from the truth at all."""
        return any(self.white) or self.model

    def stream(self, name: str) -> dict:
        """One stream's numbers: ``white, markov, tau, bias, rate, latency``."""
        if name not in STREAMS:
            raise ConfigError(f"unknown sensor stream {name!r}; choose from {', '.join(STREAMS)}")
        s = STREAMS.index(name)
        return {"white": getattr(self, name), **{k: getattr(self, k)[s] for k in MODEL_FIELDS}}

    def describe(self) -> dict:
        """A JSON-ready description (recordings' ``meta.sensor_noise``)."""
        out = {"name": self.name} if self.name else {}
        out.update({s: self.stream(s) for s in STREAMS})
        return out

    @property
    def constants(self) -> tuple:
        """The white kernels' form: ``(position, velocity, attitude, gyro, accel, any)``."""
        return (*(float(x) for x in self.white), bool(self.any))

    @property
    def row(self) -> np.ndarray:
        """The loop's row (:data:`ROW_WIDTH`): the white stds, any, full model, then per
        stream ``markov, tau, bias, rate, latency``."""
        per = np.array([getattr(self, k) for k in MODEL_FIELDS], dtype=float).T  # (5, 5)
        return np.concatenate(
            [np.array(self.white), [float(self.any), float(self.model)], per.ravel()]
        )

    def state_width(self, dt: float) -> int:
        """Columns of the per-vehicle state the full model needs at physics step ``dt``."""
        return state_width(self.row[None], dt)

    def measure(self, state, specific_force, rng: np.random.Generator):
        """Noisy copy (white noise) of one ``state`` (a ``RigidBodyState``) and of the
        accelerometer reading ``specific_force`` (None: not measured), drawn from ``rng``."""
        if self.model:
            raise ConfigError(
                "SensorNoise.measure draws white noise only; coloured noise, bias, rate and "
                "latency need a flight's state (quadfault.model.flight.Flight)"
            )
        out = (np.empty(3), np.empty(3), np.empty((3, 3)), np.empty(3))
        _measure_one(*(np.asarray(x, dtype=float) for x in state), self.constants, rng, *out)
        sf = None
        if specific_force is not None:
            sf = np.array(
                _accelerometer_one(np.asarray(specific_force, dtype=float), self.constants, rng)
            )
        return RigidBodyState(*out), sf


def state_width(rows: np.ndarray, dt: float) -> int:
    """Columns of the per-vehicle state of sensor ``rows`` (N, :data:`ROW_WIDTH`) at physics
    step ``dt`` [s]: 0 without the full model, else the streams' and the latency ring's."""
    rows = np.asarray(rows, dtype=float).reshape(-1, ROW_WIDTH)
    if not rows[:, 6].any():
        return 0
    lat = rows[:, 7 + 4 :: len(MODEL_FIELDS)]
    delay = int(np.max(np.round(lat / dt))) if lat.size else 0
    ring = delay + 1 if delay > 0 else 0
    return _HEAD + 5 * _STREAM + ring * _RING


# -- white noise (the paper's sensors) ---------------------------------------------------------
@jit(inner=True)
def _normal3(std, gen):
    """``std z`` with three standard normals drawn in component order."""
    a = std * gen.standard_normal()
    b = std * gen.standard_normal()
    c = std * gen.standard_normal()
    return (a, b, c)


@jit(inner=True)
def _noisy3(x, std, gen):
    """``x + std z`` with three standard normals drawn in component order."""
    a = x[0] + std * gen.standard_normal()
    b = x[1] + std * gen.standard_normal()
    c = x[2] + std * gen.standard_normal()
    return (a, b, c)


@jit(inner=True)
def measure3(p, v, R, w, noise, gen):
    """The measured state ``(p, v, R, w)`` (tuples; see the module docstring for the draws)
    with ``noise`` = :attr:`SensorNoise.constants` (white noise only)."""
    if not noise[5]:
        return p, v, R, w
    pm = _noisy3(p, noise[0], gen)
    vm = _noisy3(v, noise[1], gen)
    Rm = R
    if noise[2] != 0.0:
        Rm = matmul3(R, expm3(_normal3(noise[2], gen)))
    wm = _noisy3(w, noise[3], gen)
    return pm, vm, Rm, wm


@jit(inner=True)
def accelerometer3(sf, noise, gen):
    """The accelerometer reading of the specific force ``sf`` [m/s^2] (body FRD), white
    noise only."""
    if noise[4] == 0.0:
        return sf
    return _noisy3(sf, noise[4], gen)


# -- the full model --------------------------------------------------------------------------
@jit(inner=True)
def _start(row, st, dt, gen):
    """A flight's first measurement: each stream's bias and coloured start, in stream order;
    every stream samples at this measurement."""
    for s in range(5):
        b = _HEAD + _STREAM * s
        c = 7 + 5 * s
        st[b] = 1.0 - (dt * row[c + 3] if row[c + 3] > 0.0 else 1.0)
        for a in range(3):
            st[b + 1 + a] = 0.0
            st[b + 4 + a] = 0.0
        if row[c + 2] > 0.0:
            for a in range(3):
                st[b + 1 + a] = row[c + 2] * gen.standard_normal()
        if row[c] > 0.0:  # stationary: cov(drive, out) = markov^2 [[2, 1], [1, 1]]
            for a in range(3):
                st[b + 4 + a] = row[c] * gen.standard_normal()
                st[b + 16 + a] = st[b + 4 + a] + row[c] * gen.standard_normal()
    st[0] = 1.0
    st[1] = 0.0


@jit(inner=True)
def _due(row, st, s, dt):
    """Whether stream ``s`` samples at this measurement (its phase advanced by ``dt``)."""
    b = _HEAD + _STREAM * s
    rate = row[7 + 5 * s + 3]
    st[b] += dt * rate if rate > 0.0 else 1.0
    if st[b] < 1.0 - 1e-9:  # (a rate that divides the physics rate: no step lost to rounding)
        return False
    st[b] = st[b] - 1.0 if st[b] < 2.0 else 0.0
    return True


@jit(inner=True)
def _coloured_step(st, b, sm, r, gen):
    """One exact step of stream ``b``'s coloured noise (3 axes), ``r`` the step over its time
    constant: the driving first-order process ``d`` (``st[b+16:b+19]``) and its low-pass
    ``x`` (``st[b+4:b+7]``, the error), ``d' = -d / T + noise``, ``x' = (d - x) / T``.
    ``[d, x] <- exp(-r) [[1, 0], [r, 1]] [d, x] + L z`` with ``L L^T`` the exact covariance
    of one step, ``markov^2 [[2 (1 - E), 1 - E (1 + 2r)], [., 1 - E (1 + 2r + 2r^2)]]``,
    ``E = exp(-2r)``; the stationary covariance ``markov^2 [[2, 1], [1, 1]]`` is kept."""
    a = math.exp(-r)
    E = a * a
    q11 = 2.0 * sm * sm * (1.0 - E)
    q12 = sm * sm * (1.0 - E * (1.0 + 2.0 * r))
    q22 = sm * sm * (-math.expm1(-2.0 * r) - E * (2.0 * r + 2.0 * r * r))
    l11 = math.sqrt(q11)
    l21 = q12 / l11
    l22 = math.sqrt(max(0.0, q22 - l21 * l21))
    for k in range(3):
        d, x = st[b + 16 + k], st[b + 4 + k]
        z1, z2 = gen.standard_normal(), gen.standard_normal()
        st[b + 16 + k] = a * d + l11 * z1
        st[b + 4 + k] = a * (r * d + x) + l21 * z1 + l22 * z2


@jit(inner=True)
def _error3(row, st, s, white, dt, gen):
    """A new sample's error of stream ``s``: bias + coloured (one step) + white (3 floats)."""
    b = _HEAD + _STREAM * s
    c = 7 + 5 * s
    sm = row[c]
    if sm > 0.0:
        h = 1.0 / row[c + 3] if row[c + 3] > 0.0 else dt
        _coloured_step(st, b, sm, h * COLOURED_SHAPE / row[c + 1], gen)
    e0 = st[b + 1] + st[b + 4]
    e1 = st[b + 2] + st[b + 5]
    e2 = st[b + 3] + st[b + 6]
    if white > 0.0:
        e0 += white * gen.standard_normal()
        e1 += white * gen.standard_normal()
        e2 += white * gen.standard_normal()
    return (e0, e1, e2)


@jit(inner=True)
def _held3(st, s):
    b = _HEAD + _STREAM * s + 7
    return (st[b], st[b + 1], st[b + 2])


@jit(inner=True)
def _hold3(st, s, x):
    b = _HEAD + _STREAM * s + 7
    for k in range(3):
        st[b + k] = x[k]


@jit(inner=True)
def _ring_rows(st):
    return (st.shape[0] - _HEAD - 5 * _STREAM) // _RING


@jit(inner=True)
def _delayed(row, s, n, rows, dt):
    """The ring row holding measurement ``n - d`` of stream ``s`` (its latency, ``d`` steps)."""
    d = int(round(row[7 + 5 * s + 4] / dt))
    d = min(d, rows - 1)
    return (max(n - d, 0) % rows) * _RING + _HEAD + 5 * _STREAM


@jit(inner=True)
def _vec_at(st, at):
    return (st[at], st[at + 1], st[at + 2])


@jit(inner=True)
def _mat_at(st, at):
    return (
        st[at],
        st[at + 1],
        st[at + 2],
        st[at + 3],
        st[at + 4],
        st[at + 5],
        st[at + 6],
        st[at + 7],
        st[at + 8],
    )


@jit(inner=True)
def _plus3(x, e):
    return (x[0] + e[0], x[1] + e[1], x[2] + e[2])


@jit(inner=True)
def measure_model(p, v, R, w, row, st, dt, gen):
    """The measured state ``(p, v, R, w)`` with the full model: ``row`` the vehicle's
    :attr:`SensorNoise.row`, ``st`` its state (:func:`state_width`; column 0 zeroed at a
    flight's start), ``dt`` the physics step [s]."""
    if st[0] == 0.0:
        _start(row, st, dt, gen)
    n = int(st[1])
    rows = _ring_rows(st)
    pd, vd, Rd, wd = p, v, R, w
    if rows > 0:
        at = (n % rows) * _RING + _HEAD + 5 * _STREAM
        for k in range(3):
            st[at + k] = p[k]
            st[at + 3 + k] = v[k]
            st[at + 15 + k] = w[k]
        for k in range(9):
            st[at + 6 + k] = R[k]
        pd = _vec_at(st, _delayed(row, 0, n, rows, dt))
        vd = _vec_at(st, _delayed(row, 1, n, rows, dt) + 3)
        Rd = _mat_at(st, _delayed(row, 2, n, rows, dt) + 6)
        wd = _vec_at(st, _delayed(row, 3, n, rows, dt) + 15)
    st[1] = n + 1.0
    if _due(row, st, 0, dt):
        _hold3(st, 0, _plus3(pd, _error3(row, st, 0, row[0], dt, gen)))
    if _due(row, st, 1, dt):
        _hold3(st, 1, _plus3(vd, _error3(row, st, 1, row[1], dt, gen)))
    b = _HEAD + 2 * _STREAM + 7
    if _due(row, st, 2, dt):
        Rm = matmul3(Rd, expm3(_error3(row, st, 2, row[2], dt, gen)))
        for k in range(9):
            st[b + k] = Rm[k]
    if _due(row, st, 3, dt):
        _hold3(st, 3, _plus3(wd, _error3(row, st, 3, row[3], dt, gen)))
    return _held3(st, 0), _held3(st, 1), _mat_at(st, b), _held3(st, 3)


@jit(inner=True)
def accelerometer_model(sf, row, st, dt, gen):
    """The accelerometer reading of the specific force ``sf`` [m/s^2] (body FRD) at the
    step of the last :func:`measure_model`, with the full model."""
    if st[0] == 0.0:  # (never measured: nothing to delay or hold yet)
        return sf
    n = int(st[1]) - 1
    rows = _ring_rows(st)
    sd = sf
    if rows > 0:
        at = (n % rows) * _RING + _HEAD + 5 * _STREAM
        for k in range(3):
            st[at + 18 + k] = sf[k]
        sd = _vec_at(st, _delayed(row, 4, n, rows, dt) + 18)
    if _due(row, st, 4, dt):
        _hold3(st, 4, _plus3(sd, _error3(row, st, 4, row[4], dt, gen)))
    return _held3(st, 4)


@jit
def _measure_one(p, v, R, w, noise, gen, out_p, out_v, out_R, out_w):
    pm, vm, Rm, wm = measure3(vec3(p), vec3(v), mat3(R), vec3(w), noise, gen)
    store3(out_p, pm)
    store3(out_v, vm)
    store33(out_R, Rm)
    store3(out_w, wm)


@jit
def _accelerometer_one(sf, noise, gen):
    return accelerometer3(vec3(sf), noise, gen)


__all__ = [
    "COLOURED_SHAPE",
    "MODEL_FIELDS",
    "ROW_WIDTH",
    "STREAMS",
    "UNITS",
    "SensorNoise",
    "accelerometer3",
    "accelerometer_model",
    "measure3",
    "measure_model",
    "state_width",
]
