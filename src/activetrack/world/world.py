"""The closed tracking loop of Section V, written once: N independent copies in one object.

:class:`World` holds, for every copy, the true target state, the EKF posterior and its
prediction, the sensors' positions and the episode's counters. One :meth:`World.step`
follows the paper's timeline:

1. **move**: the sensors go to their next positions within reach and outside the ``rho``
   disks around the predicted target (eq. 13-16, :mod:`activetrack.kinematics.sensor_motion`), from
   a planner's absolute positions (:meth:`World.step`) or from actions in units of the reach
   (:meth:`World.step_actions`);
2. **advance**: the true target moves (eq. 2; or by its behaviour,
   :mod:`activetrack.world.behaviours`), every sensor measures distance and bearing
   (eq. 4) and the EKF updates (eq. 11): :func:`activetrack.world.tracking.advance`;
3. **score**: the trace of the posterior position covariance (eq. 12, 17); the reward is
   ``-reward_scale`` times it;
4. **episode end**: truncation after ``n_steps`` steps, termination when the score
   exceeds ``max_trace``;
5. **predict** (eq. 3): ``x_hat(k+1|k), P(k+1|k)``, what the next plan and the next
   observation are made from (:meth:`World.planning_problem`, :meth:`World.observe`).

Environments, the simulation runner and the expert policies are adapters over this loop;
none of them repeats a step of it.

Beyond the paper (:mod:`activetrack.models.sensor_models`, ``docs/tasks.md``) the same loop runs K
targets, each with its own model and EKF (known data association; every sensor keeps
``rho`` from every predicted target; the score is the scenario's objective over the
targets), sensors of any measurement model, and sensors whose position is known only
through a fix ``p_S + e``, ``e ~ N(0, Sigma_i)`` drawn afresh every step: the world moves
and measures from the true positions (``sensors``), the filter, the planners and the
observations use the fixes (``fixes``).

Randomness: copy ``i`` draws from its own ``np.random.default_rng(seed_i)``: at reset ``2M``
uniforms for the sensors' start (uniform by area in the start disk), then ``n_k`` normals
per target if they start from ``N(x0_hat, P0)``, then ``2M`` normals for the first fixes
when poses are uncertain; at every step ``n + 2M`` standard normals in the paper (``n``
process noise, then ``2M`` measurement noise, sensor-major), in general every target's
process noise, then every target's ``2M`` measurement noise, then ``2M`` for the new fixes. With
``noise_block = b > 1`` the step normals are drawn ``b`` steps at a time, never past the
episode's last step; a copy whose episode ends with normals of its block unused (terminated
on ``max_trace``, or reset mid-episode) has its generator put back, at its next reset, to
where the block began and advanced by the normals used, so every copy's stream is in the
state a single environment's (one step a call) would be in at every reset
(:mod:`activetrack.world._streams`). A world of one copy runs the same code on unbatched
arrays (no leading axis inside a step), which is what makes a single environment fast.

Which compiled fast path a world takes is decided once, from the scenario's
:attr:`~activetrack.world.scenarios.Scenario.capabilities`: with ``fused_step`` (one
target, known sensor positions, every sensor measures, the EKF of eq. 11) a whole step is
one compiled call, and with one copy also the observation (:mod:`activetrack.world._fast`
holds that code). What adapters read (state, planning problem, observation, errors) is
:mod:`activetrack.world._readers`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from activetrack.kinematics import sensor_motion
from activetrack.kinematics.separation import Separation, pair_distances
from activetrack.kinematics.team import TeamMotion
from activetrack.models.motion import predict, psd_factor
from activetrack.models.objective import TRACE, as_objective, combined
from activetrack.validation import FloatArray, as_generator, check_int
from activetrack.world import _fast, observation, tracking
from activetrack.world._motion_state import MotionState
from activetrack.world._occluded import OccludedMoves
from activetrack.world._readers import _TARGET_FIELDS, WorldReaders
from activetrack.world._selection import CopySelection
from activetrack.world._sizes import WORLD_BYTES_MAX, world_bytes
from activetrack.world._streams import RandomStreams
from activetrack.world.behaviours import TargetMotion
from activetrack.world.imm_tracking import IMMTracking
from activetrack.world.scenarios import Scenario, make_scenario
from activetrack.world.team_filters import TeamTracking
from activetrack.world.track_management import TrackManagement

#: Steps of noise a copy draws per generator call in a world of several copies.
DEFAULT_NOISE_BLOCK = 64


_Selection = int | slice | np.ndarray


class StepResult(NamedTuple):
    """What one step returns for the copies it advanced (NumPy scalars for one copy).

    Attributes:
        reward: ``-reward_scale`` times the objective (by default ``tr P(k+1|k+1)_11``).
        terminated: the trace exceeded ``max_trace``.
        truncated: the episode reached ``n_steps``.
    """

    reward: Any
    terminated: Any
    truncated: Any


class World(  # (the mixins: world/_selection.py, _streams.py, ..., imm_tracking.py)
    CopySelection, RandomStreams, WorldReaders, OccludedMoves, TargetMotion, MotionState,
    IMMTracking, TeamTracking, TrackManagement,
):  # fmt: skip
    """``num_copies`` independent tracking episodes of one scenario, stepped together.

    Args:
        scenario: a preset name or a :class:`~activetrack.Scenario`; ``**overrides`` are
            scenario fields (as in :func:`activetrack.make_scenario`).
        num_copies: N >= 1.
        noise_block: steps of noise a copy draws per generator call (default 1 for one
            copy, :data:`DEFAULT_NOISE_BLOCK` otherwise; see the module docstring).
        max_steps: truncate episodes after ``min(scenario.n_steps, max_steps)`` steps
            (Gymnasium's ``max_episode_steps``; None: ``n_steps``); the observations' time
            feature still counts in ``n_steps``.

    State (leading axis N, read-only for users): ``x_true`` (N, n), ``x_hat``/``P`` the
    posterior, ``x_pred``/``P_pred`` the prediction, ``sensors`` (N, M, 2), ``k`` steps
    taken, ``trace`` the posterior trace, ``projected`` (N, M) this step's moves pushed
    out of a ``rho`` disk, ``n_projected`` their count in the episode, ``terminated`` and
    ``truncated``.
    """

    def __init__(
        self,
        scenario: str | Scenario = "paper",
        num_copies: int = 1,
        *,
        noise_block: int | None = None,
        max_steps: int | None = None,
        **overrides: Any,
    ) -> None:
        if isinstance(num_copies, bool) or not isinstance(num_copies, (int, np.integer)):
            raise ValueError(f"num_copies must be an integer >= 1, got {num_copies!r}")
        if num_copies < 1:
            raise ValueError(f"num_copies must be an integer >= 1, got {num_copies!r}")
        if noise_block is None:
            noise_block = 1 if num_copies == 1 else DEFAULT_NOISE_BLOCK
        if (
            isinstance(noise_block, bool)
            or not isinstance(noise_block, (int, np.integer))
            or noise_block < 1
        ):
            raise ValueError(f"noise_block must be an integer >= 1, got {noise_block!r}")
        sc = make_scenario(scenario, **overrides)
        need = world_bytes(int(num_copies), int(noise_block), sc.n_sensors, sc.n_targets,
                           max(mdl.dim for mdl in sc.target_models))  # fmt: skip
        if need > WORLD_BYTES_MAX:
            raise ValueError(
                f"num_copies (num_envs) x noise_block x n_sensors x n_targets: the world's "
                f"arrays would take about {need / 2**30:.3g} GiB (num_copies={num_copies}, "
                f"noise_block={noise_block}, n_sensors={sc.n_sensors}, "
                f"n_targets={sc.n_targets}), more than {WORLD_BYTES_MAX / 2**30:g} GiB "
                "(WORLD_BYTES_MAX); lower some of them"
            )
        self.scenario = sc
        self.params = p = tracking.LoopParams.from_scenario(sc)
        self.num_copies = N = int(num_copies)
        self.noise_block = int(noise_block)
        self.n_sensors = m = sc.n_sensors
        #: K, the number of targets.
        self.n_targets = K = sc.n_targets
        self._n_noise = p.n_noise
        self._n_steps = int(sc.n_steps)
        #: Steps after which an episode is truncated (``n_steps`` unless ``max_steps`` is less).
        self.episode_steps = self._n_steps
        if max_steps is not None:
            self.episode_steps = min(self._n_steps, check_int("max_steps", max_steps, 1))
        self._max_trace = np.inf if sc.max_trace is None else float(sc.max_trace)
        self._scale = float(sc.reward_scale)
        #: The score of a configuration (eq. 12, 17); the reward is minus it at the posterior.
        self.objective = as_objective(sc.objective)  # a name, or a new objective itself
        #: Which fast paths apply (:class:`activetrack.world.capabilities.Capabilities`).
        self.capabilities = caps = sc.capabilities
        # The trace objective (the paper's; with K targets their sum): the score is the trace.
        self._plain = caps.trace_objective
        self._pose = not caps.known_poses
        if self._pose:  # a square root of each sensor's (PSD) fix covariance
            self._pose_factor = psd_factor(p.pose_cov)
        self._dt = float(sc.dt)
        self._x0s = sc.target_states("x0")
        self._x0_hats = sc.target_states("x0_hat")
        self._P0s = sc.initial_covs
        self._chol0s = [np.linalg.cholesky(P0) for P0 in self._P0s]
        # Offsets of each target's process and measurement noise in a step's normals.
        dims = [t.dim for t in p.targets]
        proc = np.cumsum([0, *dims])
        self._noise_slices = [
            (slice(int(proc[k]), int(proc[k + 1])),
             slice(int(proc[-1]) + 2 * m * k, int(proc[-1]) + 2 * m * (k + 1)))
            for k in range(K)
        ]  # fmt: skip
        end = int(proc[-1]) + 2 * m * K
        self._pose_slice = slice(end, end + 2 * m)
        # Every target's measurement normals, contiguous (target-major).
        self._meas_slice = slice(int(proc[-1]), end)
        # The detection draws (p_detect < 1), M per target, last.
        self._detect_slice = slice(p.n_noise - m * K, p.n_noise)
        self._limited = not caps.unlimited_sensing
        # One target, known sensor positions, every sensor measures, no occluders: the whole
        # step is one compiled call (activetrack.world._loop_kernels.advance_rows).
        ekf = sc.estimator == "ekf"  # else an IMM: stage by stage (world/imm_tracking.py)
        self._fused = caps.fused_step and ekf
        # One target, every sensor measures, the EKF of eq. (11): the advance is one call per
        # step (activetrack.world.tracking.advance_target), else stage by stage.
        self._per_target = caps.per_target_update and ekf
        # A sensor whose kinematics is not a built-in Disk: every move asks its kinematics.
        self._team = None if caps.disk_kinematics else TeamMotion(sc.kinematics_models)
        # A minimum separation between sensors: every move goes through its rule (d_sep > 0).
        self._sep = None if caps.no_separation else Separation(pair_distances(sc.d_sep, m))
        if N > 1:  # the step's normals are (copies, n_noise) then; one copy's are (n_noise,)
            self._noise_slices = [
                ((slice(None), a), (slice(None), b)) for a, b in self._noise_slices
            ]
            self._meas_slice = (slice(None), self._meas_slice)
            self._detect_slice = (slice(None), self._detect_slice)
        self._center = np.asarray(sc.sensor_center, dtype=np.float64)
        # The occluders in force: the scenario's fixed set, or with random layouts each
        # copy's own (batched over copies; a placeholder until a copy's first reset).
        self._random_layouts = sc.random_occluders > 0
        self._occ = p.occluders
        if self._random_layouts:
            first = sc.draw_occluders(np.random.default_rng(0))
            self._occ = first if N == 1 else type(first).stack([first] * N)
        # Observation constants (activetrack.world.observation).
        self.length_scale = observation.length_scale(sc)
        self.layout = observation.layout_of(sc)
        self._extended = self.layout.extended
        self._constants = self.layout.sensor_constants(sc, self.length_scale)
        self._order = observation.cyclic_order(m)
        self._obs_shape = (m, self.layout.obs_dim)
        self._obs_cache: np.ndarray | None = None  # the observation a one-copy step made
        if self._fused:  # the compiled step's and observation's constant arguments
            _fast.prepare(self)

        self._rngs: list[np.random.Generator | None] = [None] * N
        self._noise = (
            np.zeros((self.noise_block, N, self._n_noise)) if self.noise_block > 1 else None
        )
        self._noise_left = np.zeros(N, dtype=np.int64)
        # Each copy's generator state before its last block and that block's steps: what
        # puts a generator back when its episode ends before the block is used up.
        self._noise_from: list[dict[str, Any] | None] = [None] * N
        self._noise_drawn = np.zeros(N, dtype=np.int64)
        # Copies not yet reset hold a valid placeholder (the prior, sensors one length scale
        # away), since whole-batch steps compute them too before discarding the result.
        # One copy keeps its state unbatched (Python numbers for the counters): a step then
        # stores by rebinding, with no NumPy indexing, which costs microseconds per call.
        self._one = N == 1
        # What a step computes: every copy (a subset is computed with all, see _step); with
        # one copy its unbatched arrays (a view of each whole array).
        self._every = ... if self._one else slice(None)
        targets = []
        for tp, x0_hat, P0 in zip(p.targets, self._x0_hats, self._P0s, strict=True):
            x_pred, P_pred = predict(x0_hat, P0, tp.Phi, tp.Q)
            targets.append(
                {
                    "x_true": x0_hat.copy(),
                    "x_hat": x0_hat.copy(),
                    "P": P0.copy(),
                    "x_pred": x_pred,
                    "P_pred": P_pred,
                }
            )
        sensors = np.broadcast_to(
            self._x0_hats[0][:2] + np.array([self.length_scale, 0.0]), (m, 2)
        ).copy()
        state = {
            "sensors": sensors,
            "fixes": sensors.copy(),
            "k": 0,
            "trace": 0.0,
            "score": 0.0,
            "projected": np.zeros(m, dtype=bool),
            "n_projected": np.zeros(m, dtype=np.int64),
            "terminated": False,
            "truncated": False,
            "ended": True,  # not started, or its episode is over
        }
        if self._limited:  # which sensor detected which target at the last step
            state["detected"] = np.zeros((K, m), dtype=bool)
        self._motion_setup(state)  # a heading, a velocity: _motion_state
        if not self._one:
            state = {k: np.broadcast_to(v, (N, *np.shape(v))).copy() for k, v in state.items()}
            targets = [
                {k: np.broadcast_to(v, (N, *np.shape(v))).copy() for k, v in t.items()}
                for t in targets
            ]
        self._s: dict[str, Any] = state
        #: Per-target state: x_true, x_hat, P, x_pred, P_pred of each target.
        self._t: list[dict[str, Any]] = targets
        self._init_behaviours()  # the true targets' behaviours (activetrack.world.behaviours)
        self._init_imm()  # an IMM estimator's state (activetrack.world.imm_tracking)
        self._init_team()  # a filter per robot (activetrack.world.team_filters)
        self._init_tracks()  # births, departures, tracks (activetrack.world.track_management)

    # Reset ------------------------------------------------------------------------------
    def reset(
        self, indices: Sequence[int] | np.ndarray | None = None, seeds: Sequence[Any] | None = None
    ) -> None:
        """Start new episodes for copies ``indices`` (a mask or indices; None: all).

        ``seeds`` gives one seed (an int, anything ``default_rng`` takes, or None) per
        selected copy; a copy without a seed continues its generator.
        """
        sel = self._select(indices)
        if sel is None:
            return
        self._obs_cache = None  # the state changes
        rows = self._rows(sel)
        if self._noise is not None:
            self._rewind_noise(rows)
        if seeds is not None:
            seeds = list(seeds)
            if len(seeds) != rows.size:
                raise ValueError(f"seeds must hold one seed per reset copy ({rows.size})")
            for j, (i, s) in enumerate(zip(rows.tolist(), seeds, strict=True)):
                if s is not None:
                    self._rngs[i] = as_generator(f"seeds[{j}]", s)
        m, p = self.n_sensors, self.params
        gaussian = self.scenario.target_init == "gaussian"
        u = np.empty((rows.size, m, 2))
        g = [np.empty((rows.size, t.dim)) for t in p.targets] if gaussian else None
        e = np.empty((rows.size, m, 2)) if self._pose else None
        for j, i in enumerate(rows.tolist()):
            rng = self.rng(i)
            u[j] = rng.random((m, 2))
            if gaussian:
                for gk in g:
                    gk[j] = rng.standard_normal(gk.shape[1])
            if self._pose:
                e[j] = rng.standard_normal((m, 2))
        one = isinstance(sel, int)
        if one:  # one copy: unbatched arrays, as in the step
            u = u[0]
            g = None if g is None else [gk[0] for gk in g]
            e = None if e is None else e[0]
        sensors = self._start_positions(u)
        if self._random_layouts:  # each episode's own layout, drawn after the other draws
            layouts = self.scenario.draw_occluder_batch([self.rng(i) for i in rows.tolist()])
            self._occ = layouts[0] if self._one else self._occ.replaced(rows, layouts)
        if self._occ is not None:  # no sensor starts inside an occluder: draw again
            sensors = self._outside_occluders(sensors, rows, one=isinstance(sel, int))
        if self._sep is not None:  # each sensor drawn again while too close to another
            sensors = self._separated_starts(sensors, rows, one=isinstance(sel, int))
        batch = u.shape[:-2]
        trace = 0.0
        score = []
        for k, tp in enumerate(p.targets):
            x0_hat, P0 = self._x0_hats[k], self._P0s[k]
            x_hat = np.broadcast_to(x0_hat, (*batch, tp.dim)).copy()
            P = np.broadcast_to(P0, (*batch, *P0.shape)).copy()
            x_pred, P_pred = predict(x_hat, P, tp.Phi, tp.Q)
            new_t = {
                "x_true": x0_hat + g[k] @ self._chol0s[k].T if gaussian else self._x0s[k].copy(),
                "x_hat": x_hat,
                "P": P,
                "x_pred": x_pred,
                "P_pred": P_pred,
            }
            if self._one:
                self._t[k].update(new_t)
            else:
                for key, value in new_t.items():
                    self._t[k][key][sel] = value
            trace += float(TRACE.of_covariance(P0))
            score.append(float(self.objective.of_covariance(P0)))
        new = {
            "sensors": sensors,
            "fixes": self._fix(sensors, e) if self._pose else sensors,
            "k": 0,
            "trace": trace,
            "score": trace if self._plain else float(combined(self.objective, np.array(score))),
            "projected": False,
            "n_projected": 0,
            "terminated": False,
            "truncated": False,
            "ended": False,
        }
        if self._limited:
            new["detected"] = False
        self._motion_start(new, sensors)
        if self._one:
            new["projected"] = np.zeros(self.n_sensors, dtype=bool)
            new["n_projected"] = np.zeros(self.n_sensors, dtype=np.int64)
            if self._limited:
                new["detected"] = np.zeros((self.n_targets, self.n_sensors), dtype=bool)
            self._s.update(new)
        else:
            for key, value in new.items():
                self._s[key][sel] = value
        self._reset_behaviours(rows)  # (spawned generators: the copies' streams do not move)
        self._reset_imm(sel)
        self._reset_team(rows)  # (after the behaviours': its own spawned generators)
        self._reset_tracks(rows)
        self._noise_left[sel] = 0
        if self._noise is not None:
            self._draw_noise(rows)

    def _start_positions(self, u: FloatArray) -> FloatArray:
        """Return start positions uniform (by area) in the sensors' disk from uniforms ``u``
        (..., M, 2)."""
        radius = self.scenario.sensor_radius * np.sqrt(u[..., 0])
        angle = 2.0 * np.pi * u[..., 1]
        return self._center + radius[..., None] * np.stack([np.cos(angle), np.sin(angle)], -1)

    def _fix(self, sensors: FloatArray, normals: FloatArray) -> FloatArray:
        """Return the position fixes ``p_S + e``, ``e ~ N(0, Sigma_i)`` from standard normals."""
        return sensors + np.einsum("...ij,...j->...i", self._pose_factor, normals)

    # Step -------------------------------------------------------------------------------
    def step(self, positions: FloatArray, live: Any = None) -> StepResult | None:
        """Advance the copies ``live`` (None: all) with the sensors' proposed next positions.

        ``positions`` (N, M, 2) are absolute (a world of one copy also takes (M, 2)); a move
        beyond reach or into a ``rho`` disk is mended by
        :func:`activetrack.kinematics.sensor_motion.move_to` (a planner's feasible positions pass
        unchanged). Returns the advanced copies' :class:`StepResult` (None if none).
        """
        return self._step(sensor_motion.move_to, positions, live)

    def step_actions(self, actions: FloatArray, live: Any = None) -> StepResult | None:
        """As :meth:`step`, with actions (N, M, 2) in units of the reach (eq. 13).

        :func:`activetrack.kinematics.sensor_motion.apply_actions` gives the positions.
        """
        return self._step(sensor_motion.apply_actions, actions, live)

    def _step(self, move: Any, moves: FloatArray, live: Any) -> StepResult | None:
        """Move the sensors of the copies ``live`` by ``move`` and advance them (steps 1-5)."""
        absolute = move is sensor_motion.move_to
        name = "positions" if absolute else "actions"
        if self._one and self._fused:  # the single env: the short way
            if live is not None and self._select(live) is None:
                return None
            return StepResult(*_fast.step_one(self, absolute, moves, name))
        sel = 0 if live is None and self._one else self._select(live)
        if sel is None:
            return None
        st = self._s
        if st["ended"] if self._one else st["ended"][sel].any():
            self._not_running(sel)
        mv = self._moves_array(moves, name, sel)
        if isinstance(sel, np.ndarray):  # the others are computed, not used: zero moves
            given, mv = mv, np.zeros_like(mv)
            mv[sel] = given[sel]
        # A subset of several copies is computed with all of them and written back alone:
        # stacked matrix products round a row differently with another number of rows, and
        # a copy's numbers must not depend on which other copies step with it.
        partial = isinstance(sel, np.ndarray)
        calc = self._every
        if self._fused:
            noise = self._noise_of(sel, partial)
            sensors, projected, target = _fast.advance_fused(self, mv, absolute, noise, calc)
            fixes, detected, results = sensors, None, [target]
            trace = target[-1][sel] if partial else target[-1]
        else:
            sensors, fixes, projected, detected, results = self._advance(move, mv, sel, calc)
            trace = None
        scores = []
        for t, (x_true, x_post, P_post, x_next, P_next, *tr) in zip(self._t, results, strict=True):
            if partial:
                x_true, x_post, P_post, x_next, P_next = (
                    a[sel] for a in (x_true, x_post, P_post, x_next, P_next)
                )
                for key, value in zip(
                    _TARGET_FIELDS, (x_true, x_post, P_post, x_next, P_next), strict=True
                ):
                    t[key][sel] = value
            else:  # the fresh arrays become the state (no copies)
                t["x_true"], t["x_hat"], t["P"], t["x_pred"], t["P_pred"] = (
                    x_true, x_post, P_post, x_next, P_next)  # fmt: skip
            if not tr:
                tr = TRACE.of_covariance(P_post)  # its position block
                trace = tr if trace is None else trace + tr
            if not self._plain:
                scores.append(self.objective.of_covariance(P_post))
        if partial:
            sensors, fixes, projected = sensors[sel], fixes[sel], projected[sel]
            if detected is not None:
                detected = detected[sel]
        score = trace if self._plain else combined(self.objective, np.stack(scores, -1))
        if self._births is not None:  # over the tracks held, plus the search term
            trace, score = self._track_score(sel)
        terminated = trace > self._max_trace  # never when max_trace is None (inf)
        new = {
            "sensors": sensors,
            "fixes": fixes,
            "projected": projected,
            "trace": trace,
            "score": score,
            "terminated": terminated,
        }
        if detected is not None:
            new["detected"] = detected
        self._motion_store(new, sel, partial)
        if self._one:
            truncated = _fast.store_one(self, new, bool(np.count_nonzero(projected)))
        else:
            k = st["k"][sel] + 1
            truncated = k >= self.episode_steps
            if np.count_nonzero(projected):  # rare; the mixed-type add costs microseconds
                st["n_projected"][sel] += projected
            if partial:
                for key, value in new.items():
                    st[key][sel] = value
            else:  # every copy: the step's fresh arrays become the state (no copies)
                st.update(new)
            st["k"][sel], st["truncated"][sel] = k, truncated
            st["ended"][sel] = terminated | truncated
        return StepResult(-self._scale * score, terminated, truncated)

    def _moves_array(self, moves: Any, name: str, sel: _Selection) -> FloatArray:
        """Return the proposed moves as C-contiguous float64 (M, 2) for a world of one copy
        (which also takes (1, M, 2)) or (N, M, 2), those of the copies ``sel`` finite (the
        others are not used); or raise ValueError naming ``name``."""
        m = self.n_sensors
        a = moves if type(moves) is np.ndarray else np.asarray(moves)
        if a.dtype != np.float64:
            if a.dtype.kind not in "iuf":
                raise ValueError(f"{name} must be real numbers, got dtype {a.dtype}")
            a = a.astype(np.float64)
        if self._one:
            if a.shape == (1, m, 2):
                a = a[0]
            if a.shape != (m, 2):
                raise ValueError(f"{name} must have shape ({m}, 2) or (1, {m}, 2), got {a.shape}")
            # (on the single env's few numbers, cheaper than np.isfinite)
            if not all(map(math.isfinite, a.ravel().tolist())):
                raise ValueError(f"{name} must be finite (no NaN or inf), got {a.tolist()}")
            # one kernel signature: a read-only or strided array would compile another
            flags = a.flags
            return a if flags.c_contiguous and flags.writeable else a.copy()
        if a.shape != (self.num_copies, m, 2):
            raise ValueError(f"{name} must have shape ({self.num_copies}, {m}, 2), got {a.shape}")
        if not np.isfinite(a[sel]).all():  # (one reduction; the copies only to say them)
            finite = np.isfinite(a[sel]).all(axis=(-2, -1))
            bad = self._rows(sel)[~np.atleast_1d(finite)][:10].tolist()
            raise ValueError(f"{name} must be finite (no NaN or inf); copies {bad}")
        return a

    def _not_running(self, sel: _Selection) -> None:
        """Raise the RuntimeError of a step of copies ``sel`` without a running episode."""
        rows = self._rows(sel)
        bad = [i for i in rows.tolist() if self.get("terminated", i) or self.get("truncated", i)
               or not self._started(i)]  # fmt: skip
        raise RuntimeError(
            f"copies {bad[:10]} have no running episode (never reset, or ended): reset them"
            " before stepping"
        )

    def _advance(
        self, move: Any, moves: FloatArray, sel: _Selection, calc: _Selection
    ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray | None, list[tuple]]:
        """Return ``(sensors, fixes, projected, detected, results)`` of one step of the
        copies ``calc``, stage by stage: ``results`` holds every target's ``(x_true,
        x_post, P_post, x_pred, P_pred)``."""
        st, p, K, tgt = self._s, self.params, self.n_targets, self._t
        # (One target without a comprehension: on Python 3.11 each one is a function call.)
        sensors = st["sensors"][calc]
        fixes = st["fixes"][calc] if self._pose else sensors
        x_preds = [tgt[0]["x_pred"][calc]] if K == 1 else [t["x_pred"][calc] for t in tgt]
        # Sensors move from where they believe they are, out of every target's rho disk.
        if K == 1:
            where = x_preds[0][..., :2]
        else:  # (..., K, 2), filled row by row (cheaper than np.stack on small arrays)
            where = np.empty(x_preds[0].shape[:-1] + (K, 2))
            for k, x in enumerate(x_preds):
                where[..., k, :] = x[..., :2]
        moved, projected = self._move_sensors(move, moves, sensors, fixes, where, calc)
        noise = self._noise_of(sel, isinstance(sel, np.ndarray))
        if self._pose:  # the true sensor makes the believed displacement; a new fix
            sensors = sensors + (moved - fixes)
            fixes = self._fix(
                sensors, noise[..., self._pose_slice].reshape(*noise.shape[:-1], -1, 2)
            )
        else:
            sensors = fixes = moved
        general = not self._per_target
        detected = None
        if general:  # every target moves, then all are measured in one call
            moved_t = [
                tracking.move_target(tp, t["x_true"][calc], noise[proc])
                for t, tp, (proc, _) in zip(tgt, p.targets, self._noise_slices, strict=True)
            ] if self._behaviours is None else self._move_targets(sel, calc, noise)  # fmt: skip
            if self._births is not None:  # departures and births
                moved_t = self._arrivals(moved_t, sel, calc)
            true_pos = np.empty(moved_t[0].shape[:-1] + (K, 2))
            for k, x in enumerate(moved_t):
                true_pos[..., k, :] = x[..., :2]
            z_all = tracking.measure(p, true_pos, sensors, noise[self._meas_slice])
            if self._limited:
                draws = noise[self._detect_slice] if p.p_detect is not None else None
                detected = tracking.detections(p, true_pos, sensors, draws, self._occ)
                detected = detected if self._births is None else self._mask_absent(detected)
        results = []
        for k, (t, tp, x_pred, (proc, meas)) in enumerate(
            zip(tgt, p.targets, x_preds, self._noise_slices, strict=True)
        ):
            P_pred = t["P_pred"][calc]
            if not general:
                x_true = t["x_true"][calc]
                x_true, _, x_post, P_post = tracking.advance_target(
                    p, tp, x_true, x_pred, P_pred, sensors, fixes, noise[proc], noise[meas]
                )
            else:
                x_true = moved_t[k]
                z = z_all[..., k, :, :]
                seen = None if detected is None else detected[..., k, :]
                if self._imm is not None:
                    results.append((x_true, *self._imm_step(k, z, fixes, seen, sel, calc)))
                    continue
                x_post, P_post = tracking.filter_update(p, x_pred, P_pred, z, fixes, seen)
            results.append((x_true, x_post, P_post, *predict(x_post, P_post, tp.Phi, tp.Q)))
        if general and self._comm is not None:  # each robot's filters (no random draws here)
            self._team_step(z_all, fixes, detected, sensors, sel)
        if self._births is not None:  # initiation, deletion, search points
            self._manage_tracks(results, z_all, sensors, fixes, detected, sel)
        return sensors, fixes, projected, detected, results
