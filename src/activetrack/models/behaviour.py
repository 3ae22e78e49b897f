"""How a true target moves: :class:`TargetBehaviour`, the public base, and four behaviours.

The motion model (:mod:`activetrack.models.motion`, eq. 1-3, 39) is what the *filter*
believes; a behaviour is what the *target* does. Until now they were one thing: the target
drew its next state from the filter's own linear Gaussian model (eq. 2), so the estimator
was always right about how it moves. A behaviour advances one target's true state ``x``
(n,) (position first, eq. 1) one step, from the step's random generator and, for a
reactive behaviour, the sensors' true positions:

- :class:`FilterModel`: today's target, eq. (2) with the motion model's own ``(Phi, Qd)``;
- :class:`Maneuvering`: a Markov switch between constant velocity and coordinated turns
  of given rates (the jump Markov linear system an IMM filter assumes, Bar-Shalom, Li and
  Kirubarajan 2001, ch. 11), each mode discretized exactly (:func:`coordinated_turn`);
- :class:`StopAndGo`: moving (eq. 39) and stopped, a two-mode Markov chain;
- :class:`Evasive`: a scripted evader that runs straight away from the nearest sensor at
  its speed limit, optionally only when a sensor is within a detection range;
- :class:`Controlled`: a target moved by an external action each step (its velocity within
  its speed limit), the target of a separate agent (a user, a learning algorithm: the
  two-team ``pursuit`` environment, :mod:`activetrack.envs.pursuit`); without an action
  it moves by its ``fallback`` behaviour.

**Mode.** A behaviour may carry a discrete mode (the maneuvering target's current turn
rate, whether the evader is fleeing); it is part of the target's true state, held by the
caller: :meth:`TargetBehaviour.initial_mode` draws it at the start and
:meth:`TargetBehaviour.step` returns the next one with the next state. Behaviours without
modes return 0. Within a step the mode switches first and the target then moves with the
new mode's dynamics: ``m_k ~ Pi[m_{k-1}, :]``, ``x_k = Phi(m_k) x_{k-1} + w(m_k)``, the
convention of the IMM filter (:mod:`activetrack.estimation.imm`).

A new behaviour subclasses :class:`TargetBehaviour` (in any module), sets ``name`` and
implements :meth:`TargetBehaviour.step`; behaviours compare by value
(:class:`~activetrack.validation.ComparedByValue`), so copies and pickles equal the original.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from activetrack.models import _motion_kernels as mtk
from activetrack.models.motion import LinearMotionModel, from_continuous, from_matrices
from activetrack.validation import (
    ComparedByValue,
    FloatArray,
    as_finite,
    check_float,
    real_scalar,
)

#: Tolerance on a transition matrix's row sums and an initial distribution's sum.
STOCHASTIC_TOL = 1e-9


class TargetBehaviour(ComparedByValue, abc.ABC):
    """How one true target moves, one step at a time (see the module docstring).

    A subclass sets ``name`` and implements :meth:`step`; ``reactive`` says whether
    :meth:`step` reads the sensors' positions (then they must be passed), ``n_modes`` how
    many discrete modes it has (1: none).
    """

    #: A short identifier.
    name: ClassVar[str] = ""
    #: Whether :meth:`step` reads the sensors' true positions.
    reactive: ClassVar[bool] = False

    def __repr__(self) -> str:
        """Return ``Name(field=value, ...)``: the ``_FIELDS`` a behaviour is built from if it
        lists them, else its public attributes (arrays as lists)."""
        keys = getattr(self, "_FIELDS", None) or [k for k in vars(self) if not k.startswith("_")]
        args = (f"{k}={np.asarray(v).tolist() if isinstance(v, np.ndarray) else v!r}"
                for k in keys for v in [getattr(self, k)])  # fmt: skip
        return f"{type(self).__name__}({', '.join(args)})"

    @property
    def n_modes(self) -> int:
        """Return the number of discrete modes (1 for a behaviour without modes)."""
        return 1

    def initial_mode(self, rng: np.random.Generator) -> int:
        """Return the mode at the start of an episode (by default 0; no draw)."""
        return 0

    @abc.abstractmethod
    def step(
        self,
        x: FloatArray,
        rng: np.random.Generator,
        sensors: FloatArray | None = None,
        mode: int = 0,
    ) -> tuple[FloatArray, int]:
        """Return ``(x_next, mode_next)``: the target's true state after one step from
        ``x`` (n,) in ``mode``, drawing from ``rng``; ``sensors`` (M, 2) are the sensors'
        true positions (read by a reactive behaviour only)."""

    def _state(self, x: ArrayLike, n: int | None = None) -> FloatArray:
        """Return ``x`` as a finite (n,) state (position first), else a ValueError."""
        x = as_finite("x", x)
        if x.ndim != 1 or x.shape[0] < 2 or x.shape[0] % 2 or (n is not None and x.shape[0] != n):
            want = f"({n},)" if n is not None else "(n,), n even >= 2"
            raise ValueError(f"x must have shape {want} (position first), got {x.shape}")
        return x


def _motion_model(name: str, value: object) -> LinearMotionModel:
    if not isinstance(value, LinearMotionModel):
        raise ValueError(f"{name} must be an activetrack.LinearMotionModel, got {value!r}")
    return value


class FilterModel(TargetBehaviour):
    """Today's target: eq. (2), ``x(k+1) = Phi x(k) + G w_d(k)``, the filter's own model.

    :meth:`step` is :meth:`LinearMotionModel.sample_next` (bit for bit, the same ``n``
    normals from ``rng``); :meth:`move` is the world's compiled step
    (:func:`activetrack.models._motion_kernels.move_target_rows`, what
    ``activetrack.world.tracking.move_target`` runs) on given normals, bit for bit, so a
    world that keeps drawing its normals from its own noise block keeps its results.
    """

    name = "filter_model"

    def __init__(self, model: LinearMotionModel) -> None:
        self.model = _motion_model("model", model)

    def __eq__(self, other: object) -> bool:  # the model by value (its class compares by id)
        if type(other) is not type(self):
            return False
        a, b = self.model, other.model
        return a.dt == b.dt and all(
            np.array_equal(getattr(a, k), getattr(b, k)) for k in ("Phi", "G", "Qd")
        )

    __hash__ = TargetBehaviour.__hash__

    def step(
        self,
        x: FloatArray,
        rng: np.random.Generator,
        sensors: FloatArray | None = None,
        mode: int = 0,
    ) -> tuple[FloatArray, int]:
        """Return ``(Phi x + F w, 0)`` with ``w`` ``n`` standard normals from ``rng``."""
        return self.model.sample_next(self._state(x, self.model.dim), rng), 0

    def move(self, x: FloatArray, normals: FloatArray) -> FloatArray:
        """Return ``Phi x + F normals`` (rows (..., n)) by the world's compiled kernel."""
        n = self.model.dim
        x = np.asarray(x, np.float64)
        w = np.asarray(normals, np.float64)
        if x.shape[-1:] != (n,) or w.shape != x.shape:
            raise ValueError(
                f"x and normals must have one shape (..., {n}), got {x.shape}, {w.shape}"
            )
        out = np.empty(x.shape)
        mtk.move_target_rows(
            self.model.Phi, np.ascontiguousarray(self.model.noise_factor),
            np.ascontiguousarray(x.reshape(-1, n)), np.ascontiguousarray(w.reshape(-1, n)),
            out.reshape(-1, n),
        )  # fmt: skip
        return out


def coordinated_turn(omega: float, q: float, dt: float) -> LinearMotionModel:
    """Return the coordinated-turn model of known rate ``omega`` (rad/s, > 0
    counterclockwise; 0 is eq. 39's constant velocity), discretized exactly.

    State ``[x, y, x_dot, y_dot]``; ``d/dt [p, v] = [v, omega J v] + [0, w]`` with ``J`` the
    90 degree rotation and white acceleration noise ``w`` of intensity ``q`` (as eq. 39):
    linear for a known rate, so Van Loan's method (:func:`activetrack.from_continuous`)
    gives its exact ``Phi`` (the rotation of the velocity by ``omega dt``, and the arcs
    ``sin(omega dt) / omega``, ``(1 - cos(omega dt)) / omega`` of the position) and ``Qd``.
    """
    omega = check_float("omega", omega)
    F = np.zeros((4, 4))
    F[0, 2] = F[1, 3] = 1.0
    F[2, 3], F[3, 2] = -omega, omega
    L = np.zeros((4, 2))
    L[2:, :] = np.eye(2)
    return from_continuous(F, L, q, dt, name=f"coordinated_turn({omega:g})")


def stochastic_matrix(name: str, value: ArrayLike, r: int) -> FloatArray:
    """Return ``value`` checked to be an (r, r) row-stochastic matrix (finite entries in
    [0, 1], each row summing to 1 within :data:`STOCHASTIC_TOL`), else a ValueError naming
    ``name``."""
    P = as_finite(name, value)
    if P.shape != (r, r):
        raise ValueError(f"{name} must have shape ({r}, {r}) (one row per mode), got {P.shape}")
    if np.any(P < 0.0) or np.any(P > 1.0):
        raise ValueError(f"{name} must have entries in [0, 1] (probabilities), got {P.tolist()}")
    sums = P.sum(axis=1)
    if np.any(np.abs(sums - 1.0) > STOCHASTIC_TOL):
        raise ValueError(
            f"{name} must be row-stochastic (each row sums to 1), got row sums {sums.tolist()}"
        )
    return P


def distribution(name: str, value: ArrayLike, r: int) -> FloatArray:
    """Return ``value`` checked to be a probability vector of length ``r``."""
    p = as_finite(name, value)
    if p.shape != (r,) or np.any(p < 0.0) or abs(p.sum() - 1.0) > STOCHASTIC_TOL:
        raise ValueError(
            f"{name} must be {r} probabilities >= 0 summing to 1 (one per mode), got {value!r}"
        )
    return p


class Maneuvering(TargetBehaviour):
    """A target switching, as a Markov chain, between constant velocity and coordinated
    turns of given rates.

    ``turn_rates`` (r,) are the modes' rates in rad/s (0: constant velocity, eq. 39;
    negative: clockwise), ``transition`` the (r, r) row-stochastic matrix
    ``Pi[i, j] = P(m_k = j | m_{k-1} = i)``, ``q`` the white acceleration noise intensity of
    every mode, ``dt`` the step, ``initial`` the distribution of the first mode (default:
    mode 0). Each mode is :func:`coordinated_turn` (exact). :attr:`models` are the modes'
    :class:`~activetrack.LinearMotionModel`, the mode set an IMM filter of the same
    parameters uses (:class:`activetrack.IMMFilter` with ``models=behaviour.models``).
    """

    name = "maneuvering"

    def __init__(
        self,
        turn_rates: ArrayLike,
        transition: ArrayLike,
        q: float,
        dt: float,
        initial: ArrayLike | None = None,
    ) -> None:
        rates = as_finite("turn_rates", turn_rates)
        if rates.ndim != 1 or rates.size == 0:
            raise ValueError(
                f"turn_rates must be a non-empty sequence of turn rates (rad/s), got {turn_rates!r}"
            )
        r = rates.size
        self.turn_rates = rates
        self.transition = stochastic_matrix("transition", transition, r)
        self.q = real_scalar("q", q, allow_zero=True)
        self.dt = real_scalar("dt", dt)
        first = np.eye(r)[0] if initial is None else initial
        self.initial = distribution("initial", first, r)
        self.models = tuple(coordinated_turn(w, self.q, self.dt) for w in rates)

    _FIELDS = ("turn_rates", "transition", "q", "dt", "initial")

    def __eq__(self, other: object) -> bool:  # by the parameters (``models`` derive from them)
        return type(other) is type(self) and all(
            np.array_equal(getattr(self, k), getattr(other, k)) for k in self._FIELDS
        )

    __hash__ = TargetBehaviour.__hash__

    @property
    def n_modes(self) -> int:
        """Return the number of modes r."""
        return int(self.turn_rates.size)

    def initial_mode(self, rng: np.random.Generator) -> int:
        """Return the first mode, drawn from ``initial`` (one uniform from ``rng``)."""
        return _draw(self.initial, rng)

    def step(
        self,
        x: FloatArray,
        rng: np.random.Generator,
        sensors: FloatArray | None = None,
        mode: int = 0,
    ) -> tuple[FloatArray, int]:
        """Return ``(x_next, m_next)``: the mode switches (``m_next ~ transition[mode]``, one
        uniform) and the target moves with that mode's model (four standard normals)."""
        if not (0 <= int(mode) < self.n_modes):
            raise ValueError(f"mode must be in [0, {self.n_modes - 1}], got {mode!r}")
        j = _draw(self.transition[int(mode)], rng)
        return self.models[j].sample_next(self._state(x, 4), rng), j


class StopAndGo(TargetBehaviour):
    """A target that stops and goes: a two-mode Markov chain, moving (mode 0, eq. 2 with
    eq. 39's constant velocity of intensity ``q``) and stopped (mode 1: it stays where it
    is, velocity 0).

    ``p_stop`` is the probability of stopping at a step while moving, ``p_go`` of moving
    off at a step while stopped (a stop then lasts a geometric number of steps, mean
    ``1 / p_go``). Moving off, the target starts at ``speed`` in a direction drawn
    uniformly (a stopped target has no heading), then moves on in the same step. As a
    linear model the stopped mode is :attr:`stopped_model` (``Phi = diag(1, 1, 0, 0)``, no
    noise; :attr:`moving_model` the moving one), so an IMM can carry both (the move-off
    is a jump no linear mode describes).
    """

    name = "stop_and_go"

    def __init__(self, speed: float, p_stop: float, p_go: float, q: float, dt: float) -> None:
        self.speed = real_scalar("speed", speed)
        self.p_stop = check_float("p_stop", p_stop, 0.0, 1.0)
        self.p_go = check_float("p_go", p_go, 0.0, 1.0)
        self.q = real_scalar("q", q, allow_zero=True)
        self.dt = real_scalar("dt", dt)
        self.moving_model = coordinated_turn(0.0, self.q, self.dt)
        self.stopped_model = from_matrices(
            np.diag([1.0, 1.0, 0.0, 0.0]), np.eye(4), np.zeros((4, 4)), self.dt, "stopped"
        )

    _FIELDS = ("speed", "p_stop", "p_go", "q", "dt")

    def __eq__(self, other: object) -> bool:  # by the parameters (the models derive from them)
        return type(other) is type(self) and all(
            getattr(self, k) == getattr(other, k) for k in self._FIELDS
        )

    __hash__ = TargetBehaviour.__hash__

    @property
    def n_modes(self) -> int:
        """Return 2: moving (0) and stopped (1)."""
        return 2

    @property
    def transition(self) -> FloatArray:
        """Return the mode chain's matrix ``[[1 - p_stop, p_stop], [p_go, 1 - p_go]]``."""
        return np.array([[1.0 - self.p_stop, self.p_stop], [self.p_go, 1.0 - self.p_go]])

    def step(
        self,
        x: FloatArray,
        rng: np.random.Generator,
        sensors: FloatArray | None = None,
        mode: int = 0,
    ) -> tuple[FloatArray, int]:
        """Return ``(x_next, m_next)``: the mode switches (one uniform), then a stopped
        target stays (velocity 0), a moving one moves with eq. (2) (four normals), after
        drawing a heading (one uniform) if it has just moved off."""
        if mode not in (0, 1):
            raise ValueError(f"mode must be 0 (moving) or 1 (stopped), got {mode!r}")
        x = self._state(x, 4)
        j = _draw(self.transition[mode], rng)
        if j == 1:
            out = x.copy()
            out[2:] = 0.0
            return out, 1
        if mode == 1:
            a = 2.0 * np.pi * rng.random()
            x = x.copy()
            x[2:] = self.speed * np.array([np.cos(a), np.sin(a)])
        return self.moving_model.sample_next(x, rng), 0


def _draw(p: FloatArray, rng: np.random.Generator) -> int:
    """Return an index drawn with probabilities ``p`` from one uniform of ``rng``."""
    u = rng.random()
    c = np.cumsum(p)
    return int(min(np.searchsorted(c, u * c[-1], side="right"), p.size - 1))


class Evasive(TargetBehaviour):
    """A scripted evader: it runs straight away from the nearest sensor at ``speed``.

    Each step, if the nearest sensor (by the true positions) is within ``detection_range``
    (None: always), the target sets its velocity to ``speed`` along the direction from that
    sensor to itself and moves ``speed dt`` along it (mode 1); its distance to that
    sensor grows by exactly ``speed dt``. Otherwise (mode 0) it moves with ``idle``, a
    behaviour, or with ``idle=None`` coasts at its own velocity clipped to ``speed``.
    State ``[x, y, x_dot, y_dot, ...]`` (n >= 4; the entries after the velocity, e.g. an
    acceleration, are set to 0 when it flees). A sensor exactly on the target gives no
    direction: it then flees along its velocity (or +x if it has none). Deterministic
    unless ``idle`` draws.
    """

    name = "evasive"
    reactive = True

    def __init__(
        self,
        speed: float,
        dt: float,
        detection_range: float | None = None,
        idle: TargetBehaviour | None = None,
    ) -> None:
        self.speed = real_scalar("speed", speed)
        self.dt = real_scalar("dt", dt)
        self.detection_range = (
            None if detection_range is None else real_scalar("detection_range", detection_range)
        )
        if idle is not None and not isinstance(idle, TargetBehaviour):
            raise ValueError(f"idle must be a TargetBehaviour or None, got {idle!r}")
        self.idle = idle

    @property
    def n_modes(self) -> int:
        """Return 2: idle (0) and fleeing (1)."""
        return 2

    def step(
        self,
        x: FloatArray,
        rng: np.random.Generator,
        sensors: FloatArray | None = None,
        mode: int = 0,
    ) -> tuple[FloatArray, int]:
        """Return ``(x_next, 1)`` when fleeing, else the idle motion and 0."""
        x = self._state(x)
        if x.shape[0] < 4:
            raise ValueError(f"x must hold a position and a velocity (n >= 4), got {x.shape}")
        if sensors is None:
            raise ValueError("sensors must be given (M, 2): an evader reacts to the sensors")
        s = as_finite("sensors", sensors)
        if s.ndim != 2 or s.shape[1] != 2 or s.shape[0] == 0:
            raise ValueError(f"sensors must have shape (M, 2), M >= 1, got {s.shape}")
        rel = x[:2] - s
        d = np.hypot(rel[:, 0], rel[:, 1])
        i = int(np.argmin(d))
        if self.detection_range is not None and d[i] > self.detection_range:
            if self.idle is not None:
                nxt, _ = self.idle.step(x, rng, sensors, 0)
                return nxt, 0
            v = x[2:4]
            sp = float(np.hypot(v[0], v[1]))
            v = v * (self.speed / sp) if sp > self.speed else v
            out = x.copy()
            out[2:4] = v
            out[:2] = x[:2] + self.dt * v
            return out, 0
        u = _direction(rel[i], x[2:4])
        out = np.zeros_like(x)
        out[2:4] = self.speed * u
        out[:2] = x[:2] + self.dt * out[2:4]
        return out, 1


def _direction(away: FloatArray, velocity: FloatArray) -> FloatArray:
    """Return the unit vector along ``away``, else along ``velocity``, else +x."""
    for v in (away, velocity):
        n = float(np.hypot(v[0], v[1]))
        if n > 0.0:
            return v / n
    return np.array([1.0, 0.0])


class Controlled(TargetBehaviour):
    """A target moved by an agent: each step its velocity is an external action.

    The action ``a`` (2,) is the velocity as a fraction of ``speed``: a vector longer than
    1 is scaled onto the unit disk, so the target moves at most ``speed`` (m/s). With an
    action, :meth:`act` sets the velocity to ``speed a`` and moves ``speed a dt`` along it
    (the entries after the velocity, e.g. an acceleration, are set to 0), as
    :class:`Evasive` does when it flees. The world takes the actions before a step
    (:meth:`activetrack.world.World.set_target_actions`); a step without one moves the
    target by :meth:`step`, the ``fallback`` behaviour (its modes are this behaviour's), or
    with ``fallback=None`` it coasts at its own velocity clipped to ``speed``.
    Deterministic given the actions (unless ``fallback`` draws).
    """

    name = "controlled"
    reactive = True

    def __init__(self, speed: float, dt: float, fallback: TargetBehaviour | None = None) -> None:
        self.speed = real_scalar("speed", speed)
        self.dt = real_scalar("dt", dt)
        if fallback is not None and not isinstance(fallback, TargetBehaviour):
            raise ValueError(f"fallback must be a TargetBehaviour or None, got {fallback!r}")
        if isinstance(fallback, Controlled):
            raise ValueError("fallback must not be Controlled itself (it moves without actions)")
        fdt = getattr(fallback, "dt", None)
        if fdt is not None and not np.isclose(float(fdt), self.dt, rtol=1e-12, atol=0.0):
            raise ValueError(f"fallback's dt ({float(fdt):g}) must be dt ({self.dt:g})")
        self.fallback = fallback

    @property
    def n_modes(self) -> int:
        """Return the fallback's number of modes (1 without a fallback)."""
        return 1 if self.fallback is None else self.fallback.n_modes

    def initial_mode(self, rng: np.random.Generator) -> int:
        """Return the fallback's first mode (0 without one, no draw)."""
        return 0 if self.fallback is None else self.fallback.initial_mode(rng)

    def step(
        self,
        x: FloatArray,
        rng: np.random.Generator,
        sensors: FloatArray | None = None,
        mode: int = 0,
    ) -> tuple[FloatArray, int]:
        """Return ``(x_next, mode_next)`` of a step without an action: the fallback's, or
        coasting at the own velocity clipped to ``speed`` (mode 0)."""
        if self.fallback is not None:
            return self.fallback.step(x, rng, sensors, mode)
        x = _with_velocity(self._state(x))
        v = x[2:4]
        sp = float(np.hypot(v[0], v[1]))
        out = x.copy()
        out[2:4] = v * (self.speed / sp) if sp > self.speed else v
        out[:2] = x[:2] + self.dt * out[2:4]
        return out, 0

    def act(self, x: FloatArray, action: FloatArray) -> FloatArray:
        """Return the state after a step with ``action`` (2,): velocity ``speed a`` (``a``
        scaled onto the unit disk), the position moved by ``dt`` times it, the entries after
        the velocity 0."""
        x = _with_velocity(self._state(x))
        a = unit_disk_action("action", action)
        out = np.zeros_like(x)
        out[2:4] = self.speed * a
        out[:2] = x[:2] + self.dt * out[2:4]
        return out


def unit_disk_action(name: str, value: ArrayLike) -> FloatArray:
    """Return ``value`` as a finite (2,) float64 scaled onto the unit disk when longer than
    1, else a ValueError naming ``name``."""
    a = as_finite(name, value)
    if a.shape != (2,):
        raise ValueError(f"{name} must have shape (2,) (a velocity over the speed), got {a.shape}")
    n = float(np.hypot(a[0], a[1]))
    return a / n if n > 1.0 else a


def _with_velocity(x: FloatArray) -> FloatArray:
    """Return ``x`` if it holds a position and a velocity (n >= 4), else a ValueError."""
    if x.shape[0] < 4:
        raise ValueError(f"x must hold a position and a velocity (n >= 4), got {x.shape}")
    return x
