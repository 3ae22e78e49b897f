"""The true targets' behaviours in the world: the scenario field ``target_behaviour`` and
the world's part that moves a target by its :class:`~activetrack.TargetBehaviour`.

``target_behaviour`` is None (every target follows its filter's own model, eq. 2, by the
world's compiled step: the world is what it always was), one behaviour for every target,
or a tuple of K (:func:`converted`). With a behaviour, each copy's true target ``k`` moves
by ``behaviour.step(x_true, rng, sensors, mode)``:

- ``rng`` is the copy's own generator for target ``k``, made at each reset by
  :meth:`numpy.random.Generator.spawn` from the copy's stream (spawning does not advance
  the stream, so every other draw of the copy is what it was);
- ``sensors`` are the sensors' true positions at the start of the step (the target and
  the sensors move at once, each from where the other was);
- ``mode`` is the target's discrete mode, carried per copy and target, drawn at reset by
  :meth:`~activetrack.TargetBehaviour.initial_mode`.

The step's process-noise normals are still drawn from the copy's stream (unused), so the
measurement noise a copy draws is the same whatever the behaviour: runs against two
behaviours from the same seeds are paired. A :class:`~activetrack.FilterModel` is the
exception: it moves by :meth:`~activetrack.FilterModel.move` on those very normals (the
world's compiled kernel, bit for bit). A copy's behaviour draws only from its own
generators, so its numbers do not depend on the other copies.

A :class:`~activetrack.Controlled` target is moved by an agent: :meth:`TargetMotion.
set_target_actions` gives the actions of the copies' next step (consumed by it); a
copy stepped without them moves its controlled targets by their fallback.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from activetrack.models.behaviour import Controlled, FilterModel, TargetBehaviour
from activetrack.validation import FloatArray, as_finite

_WHAT = "target_behaviour must be None, an activetrack.TargetBehaviour or a tuple of one per target"


def converted(value: object, sc: Any) -> Any:
    """Return the scenario field ``target_behaviour`` checked: None, one behaviour (for
    every target) or a tuple of K (one behaviour when all K are equal).

    ``sc`` is the scenario, its other fields converted. Each behaviour is probed once from
    its target's ``x0`` with every sensor at ``sensor_center``: a state of another
    dimension than the target's model, a failing step, a non-finite next state or a
    behaviour's own time step (its ``dt``, a :class:`~activetrack.FilterModel`'s model's)
    other than the scenario's ``dt`` raises a ValueError naming the field.
    """
    if value is None:
        return None
    models, x0s, dt = sc.target_models, sc.target_states("x0"), sc.dt
    sensors = np.broadcast_to(np.asarray(sc.sensor_center, np.float64), (sc.n_sensors, 2))
    kk = len(models)
    if isinstance(value, TargetBehaviour):
        each = (value,) * kk
    elif isinstance(value, (tuple, list)) and all(isinstance(v, TargetBehaviour) for v in value):
        if len(value) != kk:
            raise ValueError(f"{_WHAT} ({kk}), got {len(value)} entries")
        each = tuple(value)
    else:
        raise ValueError(f"{_WHAT}, got {value!r}")
    for k, (b, model, x0) in enumerate(zip(each, models, x0s, strict=True)):
        name = f"target_behaviour (target {k})"
        step = b.model.dt if isinstance(b, FilterModel) else getattr(b, "dt", None)
        if step is not None and not math.isclose(float(step), dt, rel_tol=1e-12):
            raise ValueError(
                f"{name}: its time step {float(step):g} must be the scenario's dt ({dt:g}); "
                f"build the behaviour with dt={dt:g}"
            )
        _probe(b, name, model.dim, x0, sensors)
    return each[0] if all(b == each[0] for b in each) else each


def _probe(b: TargetBehaviour, name: str, n: int, x0: FloatArray, sensors: FloatArray) -> None:
    """Raise ValueError naming ``name`` unless ``b`` steps ``x0`` (n,) to a finite (n,) state
    and a mode in ``[0, n_modes)``."""
    if isinstance(b, FilterModel) and b.model.dim != n:  # (its step would only say "x")
        raise ValueError(
            f"{name}: FilterModel's model has state dimension {b.model.dim}, the target's "
            f"motion model {n}"
        )
    rng = np.random.default_rng(0)
    try:
        mode = b.initial_mode(rng)
        nxt, mode = b.step(np.array(x0, dtype=np.float64), rng, np.array(sensors), mode)
    except Exception as exc:  # a user's code: report it against the field
        raise ValueError(
            f"{name}: {b!r} cannot move the target's state of dimension {n} (its motion "
            f"model's): {exc}"
        ) from exc
    nxt = np.asarray(nxt)
    if nxt.shape != (n,) or not np.all(np.isfinite(nxt)):
        raise ValueError(f"{name}: {b!r} must return a finite state of shape ({n},), got {nxt!r}")
    if not (isinstance(mode, (int, np.integer)) and 0 <= mode < b.n_modes):
        raise ValueError(f"{name}: {b!r} must return a mode in [0, {b.n_modes - 1}], got {mode!r}")


def per_target(value: Any, kk: int) -> tuple[TargetBehaviour, ...] | None:
    """Return the field ``target_behaviour`` as K behaviours, or None."""
    if value is None or isinstance(value, tuple):
        return value
    return (value,) * kk


def record(value: Any) -> Any:
    """Return the field's JSON-friendly record: which behaviour (name and class) for one,
    a list of them for a tuple."""
    if isinstance(value, tuple):
        return [record(v) for v in value]
    cls = type(value)
    return {"name": value.name, "class": f"{cls.__module__}.{cls.__qualname__}"}


class TargetMotion:
    """The part of :class:`activetrack.world.World` that moves the true targets by their
    behaviours (see the module docstring); it reads the world's ``scenario``, ``_s``,
    ``_t``, ``_noise_slices`` and generators."""

    def _init_behaviours(self) -> None:
        """Set up the behaviours' generators and modes (None without a behaviour)."""
        self._behaviours = per_target(self.scenario.target_behaviour, self.n_targets)
        self._controlled = tuple(
            k for k, b in enumerate(self._behaviours or ()) if isinstance(b, Controlled)
        )
        if self._behaviours is not None:
            self._behaviour_rngs: list[list[np.random.Generator] | None] = [None] * self.num_copies
            self._modes = np.zeros((self.num_copies, self.n_targets), dtype=np.int64)
            self._target_actions = np.zeros((self.num_copies, len(self._controlled), 2))
            self._acted = np.zeros(self.num_copies, dtype=bool)

    @property
    def controlled_targets(self) -> tuple[int, ...]:
        """Return the indices of the targets moved by an agent (:class:`~activetrack.
        Controlled`), in target order; empty when none is."""
        return self._controlled

    def set_target_actions(self, actions: Any, copies: Any = None) -> None:
        """Set the actions of the controlled targets for the next step of some copies.

        ``actions`` is (N, C, 2) for every copy, or (C, 2) for a world of one copy (C the
        number of :attr:`controlled_targets`, in their order): each a target's velocity over
        its speed (:meth:`activetrack.Controlled.act`; longer than 1: scaled onto the unit
        disk); ``copies`` (indices or a mask) limits them to those copies. They hold for
        the copies' next step only (a reset drops them). Raises ValueError naming
        ``target_actions`` for another shape or a value that is not finite, and when the
        scenario has no controlled target.
        """
        c = len(self._controlled)
        if not c:
            raise ValueError(
                "target_actions: no target of this scenario is controlled (give it the "
                "target_behaviour activetrack.Controlled)"
            )
        a = as_finite("target_actions", actions)
        if self.num_copies == 1 and a.shape == (c, 2):
            a = a[None]
        if a.shape != (self.num_copies, c, 2):
            one = f"({c}, 2) or " if self.num_copies == 1 else ""
            raise ValueError(
                f"target_actions must have shape {one}({self.num_copies}, {c}, 2), got {a.shape}"
            )
        sel = self._select(copies)
        if sel is None:  # no copy selected
            return
        rows = self._rows(sel)
        self._target_actions[rows] = a[rows]
        self._acted[rows] = True

    @property
    def target_modes(self) -> np.ndarray | None:
        """Return every copy's targets' current modes (N, K) int64 (a copy; a behaviour
        without modes is in mode 0), or None when the targets follow their filter's model."""
        return None if self._behaviours is None else self._modes.copy()

    def _reset_behaviours(self, rows: np.ndarray) -> None:
        """Give the copies ``rows`` new generators (spawned from their streams) and modes."""
        if self._behaviours is None:
            return
        for i in rows.tolist():
            self._acted[i] = False
            gens = self.rng(i).spawn(self.n_targets)
            self._behaviour_rngs[i] = gens
            pairs = zip(self._behaviours, gens, strict=True)
            self._modes[i] = [b.initial_mode(g) for b, g in pairs]

    def _move_targets(self, sel: Any, calc: Any, noise: FloatArray) -> list[FloatArray]:
        """Return every target's next true state for the copies ``calc`` (those not in
        ``sel`` keep theirs: they are computed, not used), each moved by its behaviour."""
        sensors = self._s["sensors"]  # the true positions at the step's start
        rows = [0] if self._one else self._rows(sel).tolist()
        out = []
        for k, (t, b, (proc, _)) in enumerate(
            zip(self._t, self._behaviours, self._noise_slices, strict=True)
        ):
            x = t["x_true"][calc]
            if isinstance(b, FilterModel):  # the world's own normals, its compiled kernel
                out.append(b.move(x, noise[proc]))
                continue
            nxt = np.array(x, dtype=np.float64)
            c = self._controlled.index(k) if k in self._controlled else -1
            for i in rows:
                at = ... if self._one else i
                if c >= 0 and self._acted[i]:  # the agent's action (the mode stays)
                    nxt[at] = b.act(x[at], self._target_actions[i, c])
                    continue
                mode = int(self._modes[i, k])
                nxt[at], self._modes[i, k] = b.step(
                    x[at], self._behaviour_rngs[i][k], sensors[at], mode
                )
            if not np.all(np.isfinite(nxt)):
                raise ValueError(f"target_behaviour {b!r} moved target {k} to a non-finite state")
            out.append(nxt)
        self._acted[rows] = False  # an action holds for one step
        return out
