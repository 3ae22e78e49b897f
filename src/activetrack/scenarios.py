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

from activetrack.motion import LinearMotionModel, make_model
from activetrack.validation import FloatArray, as_finite, per_sensor, positive, spd


@dataclass(frozen=True)
class Scenario:
    """A tracking scenario (all lengths in metres, times in seconds).

    Attributes:
        name: label of the preset it came from.
        n_sensors: team size M.
        sigma_d2, sigma_theta2: per-sensor range (m^2) and bearing (rad^2) noise variances;
            a scalar applies to every sensor.
        vmax: per-sensor maximum speed; the reach per step is ``r = vmax dt`` (eq. 13).
        rho: per-sensor minimum distance to the predicted target (eq. 14).
        orientation: per-sensor heading ``phi_i`` subtracted from the bearing (eq. 4).
        dt: time step.
        motion: ``"cv"`` (eq. 39), ``"ca"``, or any :class:`LinearMotionModel`.
        q: continuous process noise intensity of the ``"cv"``/``"ca"`` models.
        x0: true initial target state; x0_hat: initial estimate; P0: its covariance
            (a full matrix or the diagonal).
        target_init: ``"fixed"`` uses x0 and x0_hat as given; ``"gaussian"`` draws the true
            state from ``N(x0_hat, P0)`` so the filter starts consistent.
        sensor_center, sensor_radius: sensors start uniformly (by area) in this disk.
        n_steps: episode length in time steps.
        max_trace: optional early termination when the posterior trace exceeds it.
        reward_scale: the environments' reward is ``-reward_scale * trace`` (1 = the paper).
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
        if not isinstance(self.n_sensors, (int, np.integer)) or self.n_sensors < 1:
            raise ValueError(f"n_sensors must be an integer >= 1, got {self.n_sensors!r}")
        if not isinstance(self.n_steps, (int, np.integer)) or self.n_steps < 1:
            raise ValueError(f"n_steps must be an integer >= 1, got {self.n_steps!r}")
        positive("dt", self.dt)
        positive("q", self.q, allow_zero=True)
        positive("sensor_radius", self.sensor_radius, allow_zero=True)
        positive("reward_scale", self.reward_scale)
        if self.max_trace is not None:
            positive("max_trace", self.max_trace)
        if self.target_init not in ("fixed", "gaussian"):
            raise ValueError(f"target_init must be 'fixed' or 'gaussian', got {self.target_init!r}")
        as_finite("sensor_center", self.sensor_center, (2,))
        for name in ("sigma_d2", "sigma_theta2"):
            per_sensor(name, getattr(self, name), self.n_sensors)
        per_sensor("vmax", self.vmax, self.n_sensors, allow_zero=True)
        per_sensor("rho", self.rho, self.n_sensors, allow_zero=True)
        orient = as_finite("orientation", self.orientation)
        if orient.ndim and orient.shape != (self.n_sensors,):
            raise ValueError(f"orientation must be a scalar or have shape ({self.n_sensors},)")
        n = self.model.dim
        as_finite("x0", self.x0, (n,))
        as_finite("x0_hat", self.x0_hat, (n,))
        _ = self.initial_cov  # validates P0

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
            P0 = as_finite("P0", self.P0)
            n = self.model.dim
            if P0.shape == (n,):
                P0 = np.diag(P0)
            if P0.shape != (n, n):
                raise ValueError(f"P0 must have shape ({n},) or ({n}, {n}), got {P0.shape}")
            self._cache["P0"] = spd("P0", P0)
        return self._cache["P0"].copy()

    def per_sensor(self, name: str) -> FloatArray:
        """Return the per-sensor parameter ``name`` as an (M,) array."""
        allow_zero = name in ("vmax", "rho", "orientation")
        if name == "orientation":
            return np.broadcast_to(np.asarray(self.orientation, float), (self.n_sensors,)).copy()
        return per_sensor(name, getattr(self, name), self.n_sensors, allow_zero=allow_zero)

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


def make_scenario(scenario: str | Scenario = "paper", **overrides: Any) -> Scenario:
    """Return the named preset (or a given scenario) with ``overrides`` applied.

    Per-sensor fields given as a tuple of the preset's length are dropped when only
    ``n_sensors`` changes, so ``make_scenario("paper", n_sensors=5)`` keeps working: the
    first sensor's value is then used for every sensor.
    """
    if isinstance(scenario, Scenario):
        base = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(Scenario) if f.init}
    elif scenario in PRESETS:
        base = {f.name: f.default for f in dataclasses.fields(Scenario) if f.init}
        base.update(PRESETS[scenario])
    else:
        raise ValueError(
            f"scenario must be one of {sorted(PRESETS)} or a Scenario, got {scenario!r}"
        )
    unknown = set(overrides) - set(base)
    if unknown:
        raise ValueError(f"unknown scenario field(s) {sorted(unknown)}; valid: {sorted(base)}")
    m = overrides.get("n_sensors", base["n_sensors"])
    for key in ("sigma_d2", "sigma_theta2", "vmax", "rho", "orientation"):
        val = base[key]
        if key not in overrides and isinstance(val, (tuple, list)) and len(val) != m:
            base[key] = val[0]
    base.update(overrides)
    return Scenario(**base)
