"""Scenario configuration and named presets.

:class:`Scenario` is the one frozen configuration shared by the simulation runner and the
environments: team, noise, kinematics, target model, initial conditions and episode
length. ``paper`` is the setup of Section V exactly; ``homogeneous`` is M identical
sensors. :func:`make_scenario` picks a preset and overrides any field by keyword.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from activetrack.motion import MODELS, LinearMotionModel, make_model
from activetrack.validation import FloatArray, UnexpectedKeywordError, real_array, spd

#: Accepted ranges (SI units). Chosen so that every quantity the EKF (eq. 3, 11), the
#: planners (eq. 12-19) and the features form from them stays finite and well inside
#: float64 (products of four of them stay below 1e150), and tested at their extremes.
LENGTH_MAX = 1e9
SPEED_MAX = 1e9
STATE_MAX = 1e9
DT_RANGE = (1e-6, 1e4)
Q_MAX = 1e10
SIGMA_D2_RANGE = (1e-8, 1e8)
SIGMA_THETA2_RANGE = (1e-10, 1e2)
P0_RANGE = (1e-8, 1e16)
ORIENTATION_MAX = 1e3
N_SENSORS_MAX = 10_000
N_STEPS_MAX = 10**9
REWARD_SCALE_RANGE = (1e-12, 1e12)
MAX_TRACE_RANGE = (1e-300, 1e300)
#: Largest accepted ratio of the first predicted position variance to the smallest range
#: variance: how much one update may shrink the position covariance. The position block
#: of the posterior then keeps a condition number that float64 represents over long runs.
INFORMATION_RATIO_MAX = 1e10

_PER_SENSOR = ("sigma_d2", "sigma_theta2", "vmax", "rho", "orientation")


def _count(name: str, value: object, hi: int) -> int:
    """Return ``value`` as an ``int`` in ``[1, hi]`` (bools, floats and strings rejected)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer in [1, {hi}], got {value!r}")
    if not 1 <= value <= hi:
        raise ValueError(f"{name} must be an integer in [1, {hi}], got {value!r}")
    return int(value)


def _in_range(name: str, arr: FloatArray, lo: float, hi: float, *, zero: bool) -> None:
    """Check ``lo <= x <= hi`` (or ``x == 0`` when ``zero``) for every entry of ``arr``."""
    ok = ((arr >= lo) & (arr <= hi)) | ((arr == 0.0) & zero)
    if not np.all(ok):
        allowed = f"0 or [{lo:g}, {hi:g}]" if zero and lo > 0 else f"[{lo:g}, {hi:g}]"
        raise ValueError(f"{name} must lie in {allowed}, got {arr.tolist()!r}")


def _real(name: str, value: object, lo: float, hi: float, *, zero: bool = False) -> float:
    """Return a real scalar in range as a Python ``float``."""
    arr = real_array(name, value)
    if arr.ndim:
        raise ValueError(f"{name} must be a real number, got {value!r}")
    _in_range(name, arr, lo, hi, zero=zero)
    return float(arr)


def _vector(
    name: str, value: object, n: int, lo: float, hi: float, *, zero: bool, why: str = ""
) -> tuple:
    """Return a length-``n`` real vector in range as a tuple of floats."""
    arr = real_array(name, value)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},){why}, got {arr.shape}")
    _in_range(name, arr, lo, hi, zero=zero)
    return tuple(float(v) for v in arr)


def _sensor_values(
    name: str, value: object, m: int, lo: float, hi: float, *, zero: bool
) -> float | tuple[float, ...]:
    """Return a per-sensor field: a float for every sensor, or a tuple of ``m`` floats."""
    arr = real_array(name, value)
    if arr.ndim == 0:
        _in_range(name, arr, lo, hi, zero=zero)
        return float(arr)
    return _vector(name, arr, m, lo, hi, zero=zero)


@dataclass(frozen=True)
class Scenario:
    """A tracking scenario (all lengths in metres, times in seconds, angles in radians).

    Every field is converted and validated once, at construction, and stored converted:
    counts as ``int``, scalars as ``float``, per-sensor fields as a ``float`` (the same for
    every sensor) or a tuple of M floats, vectors as tuples of floats, ``P0`` as a tuple
    (its diagonal) or a tuple of tuples. An invalid value raises a ``ValueError`` naming
    the field and its accepted range; strings, bools, ``None``, complex numbers, NaN and
    inf are rejected wherever a number is expected.

    Attributes (accepted ranges in brackets):
        name: label of the preset it came from (a string).
        n_sensors: team size M [1, 10000].
        sigma_d2, sigma_theta2: per-sensor range (m^2) [1e-8, 1e8] and bearing (rad^2)
            [1e-10, 1e2] noise variances; a scalar applies to every sensor.
        vmax: per-sensor maximum speed [0, 1e9]; the reach per step ``r = vmax dt``
            (eq. 13) must also be at most 1e9.
        rho: per-sensor minimum distance to the predicted target (eq. 14) [0, 1e9].
        orientation: per-sensor heading ``phi_i`` subtracted from the bearing (eq. 4),
            magnitude at most 1e3.
        dt: time step [1e-6, 1e4].
        motion: ``"cv"`` (eq. 39), ``"ca"``, or any :class:`LinearMotionModel` (its state
            dimension n is then the model's).
        q: continuous process noise intensity of the ``"cv"``/``"ca"`` models [0, 1e10].
        x0: true initial target state; x0_hat: initial estimate (n entries, magnitudes at
            most 1e9); P0: its covariance, the diagonal (n entries) or a full symmetric
            positive definite n x n matrix, diagonal entries in [1e-8, 1e16].
        target_init: ``"fixed"`` uses x0 and x0_hat as given; ``"gaussian"`` draws the true
            state from ``N(x0_hat, P0)`` so the filter starts consistent.
        sensor_center, sensor_radius: sensors start uniformly (by area) in this disk
            (coordinates magnitude at most 1e9, radius [0, 1e9]).
        n_steps: episode length in time steps [1, 1e9]; ``make_scenario`` also accepts
            PettingZoo's name for it, ``max_cycles``.
        max_trace: optional early termination when the posterior trace exceeds it
            [1e-300, 1e300], or None.
        reward_scale: the environments' reward is ``-reward_scale * trace`` (1 = the paper)
            [1e-12, 1e12].

    One coupled limit: the first predicted position variance (from P0, the model and q)
    may be at most 1e10 times the smallest range variance, so that one update never
    shrinks the position covariance beyond what float64 represents.
    """

    name: str = "paper"
    n_sensors: int = 3
    sigma_d2: float | tuple[float, ...] = (2.0, 4.0, 4.0)
    sigma_theta2: float | tuple[float, ...] = (0.25, 0.5, 0.5)
    vmax: float | tuple[float, ...] = 10.0
    rho: float | tuple[float, ...] = 2.0
    orientation: float | tuple[float, ...] = 0.0
    dt: float = 0.1
    motion: str | LinearMotionModel = "cv"
    q: float = 10.0
    x0: tuple[float, ...] = (0.0, 0.0, -8.0, 6.0)
    x0_hat: tuple[float, ...] = (2.0, -2.0, 0.0, 0.0)
    P0: tuple[float, ...] | tuple[tuple[float, ...], ...] = (4.0, 4.0, 100.0, 100.0)
    target_init: str = "fixed"
    sensor_center: tuple[float, float] = (20.0, 0.0)
    sensor_radius: float = 5.0
    n_steps: int = 50
    max_trace: float | None = None
    reward_scale: float = 1.0
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        def put(name: str, value: object) -> None:
            object.__setattr__(self, name, value)

        if not isinstance(self.name, str):
            raise ValueError(f"name must be a string, got {self.name!r}")
        m = _count("n_sensors", self.n_sensors, N_SENSORS_MAX)
        put("n_sensors", m)
        put("n_steps", _count("n_steps", self.n_steps, N_STEPS_MAX))
        put("dt", _real("dt", self.dt, *DT_RANGE))
        put("q", _real("q", self.q, 0.0, Q_MAX, zero=True))
        put("sensor_radius", _real("sensor_radius", self.sensor_radius, 0.0, LENGTH_MAX))
        put("reward_scale", _real("reward_scale", self.reward_scale, *REWARD_SCALE_RANGE))
        if self.max_trace is not None:
            put("max_trace", _real("max_trace", self.max_trace, *MAX_TRACE_RANGE))
        if not isinstance(self.target_init, str) or self.target_init not in ("fixed", "gaussian"):
            raise ValueError(f"target_init must be 'fixed' or 'gaussian', got {self.target_init!r}")
        if not isinstance(self.motion, LinearMotionModel) and (
            not isinstance(self.motion, str) or self.motion not in MODELS
        ):
            raise ValueError(
                f"motion must be one of {sorted(MODELS)} or a LinearMotionModel, "
                f"got {self.motion!r}"
            )
        put(
            "sensor_center",
            _vector("sensor_center", self.sensor_center, 2, -LENGTH_MAX, LENGTH_MAX, zero=True),
        )
        ranges = {
            "sigma_d2": (*SIGMA_D2_RANGE, False),
            "sigma_theta2": (*SIGMA_THETA2_RANGE, False),
            "vmax": (0.0, SPEED_MAX, True),
            "rho": (0.0, LENGTH_MAX, True),
            "orientation": (-ORIENTATION_MAX, ORIENTATION_MAX, True),
        }
        for key, (lo, hi, zero) in ranges.items():
            put(key, _sensor_values(key, getattr(self, key), m, lo, hi, zero=zero))
        reach = np.asarray(self.vmax) * self.dt
        if np.any(reach > LENGTH_MAX):
            raise ValueError(
                f"vmax * dt (the reach r of eq. 13) must be at most {LENGTH_MAX:g}, "
                f"got vmax={self.vmax!r}, dt={self.dt!r}"
            )
        n = self.model.dim
        why = f" (the state of motion={getattr(self.motion, 'name', self.motion)!r})"
        for key in ("x0", "x0_hat"):
            value = getattr(self, key)
            put(key, _vector(key, value, n, -STATE_MAX, STATE_MAX, zero=True, why=why))
        put("P0", self._converted_p0(n))
        self._check_information_ratio()

    def _converted_p0(self, n: int) -> tuple:
        """Return P0 converted (a tuple, or a tuple of tuples), checked SPD and in range."""
        P0 = real_array("P0", self.P0)
        if P0.shape not in ((n,), (n, n)):
            raise ValueError(
                f"P0 must have shape ({n},) or ({n}, {n}) (the state of "
                f"motion={getattr(self.motion, 'name', self.motion)!r}), got {P0.shape}"
            )
        _in_range("P0 diagonal", np.diag(P0) if P0.ndim == 2 else P0, *P0_RANGE, zero=False)
        if P0.ndim == 1:
            return tuple(float(v) for v in P0)
        spd("P0", P0)
        return tuple(tuple(float(v) for v in row) for row in P0)

    def _check_information_ratio(self) -> None:
        """Check the coupled limit of the class docstring (one update's variance reduction)."""
        P1 = self.model.predict(np.zeros(self.model.dim), self.initial_cov)[1]
        ratio = float(np.max(np.diag(P1)[:2])) / float(np.min(self.per_sensor("sigma_d2")))
        if not ratio <= INFORMATION_RATIO_MAX:
            raise ValueError(
                "sigma_d2 is too small for the predicted position variance "
                f"({ratio:.3g} times larger; at most {INFORMATION_RATIO_MAX:g}): "
                "raise sigma_d2 or lower q, dt or P0"
            )

    # Derived arrays -------------------------------------------------------------------
    @property
    def model(self) -> LinearMotionModel:
        """Return the target motion model (built once)."""
        if "model" not in self._cache:
            if isinstance(self.motion, LinearMotionModel):
                self._cache["model"] = self.motion
            else:
                self._cache["model"] = make_model(self.motion, self.q, self.dt)
        return self._cache["model"]

    @property
    def initial_cov(self) -> FloatArray:
        """Return P0 as a full matrix (a fresh copy; validated once)."""
        if "P0" not in self._cache:
            P0 = np.asarray(self.P0, dtype=np.float64)
            self._cache["P0"] = np.diag(P0) if P0.ndim == 1 else P0
        return self._cache["P0"].copy()

    def per_sensor(self, name: str) -> FloatArray:
        """Return the per-sensor parameter ``name`` as an (M,) array."""
        if name not in _PER_SENSOR:
            raise ValueError(f"name must be one of {list(_PER_SENSOR)}, got {name!r}")
        values = np.asarray(getattr(self, name), dtype=np.float64)
        return np.broadcast_to(values, (self.n_sensors,)).copy()

    @property
    def r(self) -> FloatArray:
        """Return the per-sensor reach ``r_i = vmax_i dt`` (eq. 13)."""
        return self.per_sensor("vmax") * self.dt

    def replace(self, **overrides: Any) -> Scenario:
        """Return a copy with fields overridden (validated)."""
        return make_scenario(self, **overrides)

    def to_dict(self) -> dict[str, Any]:
        """Return the fields as JSON-friendly values (a custom motion model by name)."""
        out = {}
        for f in dataclasses.fields(self):
            if f.name.startswith("_"):
                continue
            v = getattr(self, f.name)
            out[f.name] = v.name if isinstance(v, LinearMotionModel) else v
        return out


PRESETS: dict[str, dict[str, Any]] = {
    # Section V: heterogeneous team of three, CV target, 50 steps of 0.1 s.
    "paper": {},
    # M identical sensors (the paper's sensor 1), target started from N(x0_hat, P0).
    "homogeneous": {
        "name": "homogeneous",
        "n_sensors": 4,
        "sigma_d2": 2.0,
        "sigma_theta2": 0.25,
        "target_init": "gaussian",
    },
}


def _same(a: object, b: object) -> bool:
    """Return whether ``a == b`` is plainly true (False for arrays and incomparable values)."""
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


def make_scenario(scenario: str | Scenario = "paper", **overrides: Any) -> Scenario:
    """Return the named preset (or a given scenario) with ``overrides`` applied.

    Per-sensor fields given as a tuple of the preset's length are dropped when only
    ``n_sensors`` changes, so ``make_scenario("paper", n_sensors=5)`` keeps working: the
    first sensor's value is then used for every sensor. ``max_cycles`` (PettingZoo's
    episode-length keyword) is accepted as ``n_steps``. An unknown keyword raises
    :class:`~activetrack.validation.UnexpectedKeywordError` (a ``TypeError`` worded like
    Python's, and a ``ValueError``).
    """
    if isinstance(scenario, Scenario):
        base = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(Scenario) if f.init}
    elif isinstance(scenario, str) and scenario in PRESETS:
        base = {f.name: f.default for f in dataclasses.fields(Scenario) if f.init}
        base.update(PRESETS[scenario])
    else:
        raise ValueError(
            f"scenario must be one of {sorted(PRESETS)} or a Scenario, got {scenario!r}"
        )
    if "max_cycles" in overrides:
        cycles = overrides.pop("max_cycles")
        if "n_steps" in overrides and not _same(overrides["n_steps"], cycles):
            raise ValueError(
                f"max_cycles is n_steps: give one of them, got max_cycles={cycles!r} "
                f"and n_steps={overrides['n_steps']!r}"
            )
        overrides["n_steps"] = cycles
    for key in overrides:
        if key not in base:
            raise UnexpectedKeywordError(
                f"make_scenario() got an unexpected keyword argument {key!r}; "
                f"valid scenario fields: {sorted(base)} (and max_cycles for n_steps)"
            )
    m = overrides.get("n_sensors", base["n_sensors"])
    if isinstance(m, (int, np.integer)) and not isinstance(m, (bool, np.bool_)):
        for key in _PER_SENSOR:  # (an invalid n_sensors is reported by Scenario)
            val = base[key]
            if key not in overrides and isinstance(val, (tuple, list)) and len(val) != m:
                base[key] = val[0]
    base.update(overrides)
    return Scenario(**base)
