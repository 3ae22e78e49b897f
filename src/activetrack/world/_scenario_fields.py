"""The :class:`activetrack.world.scenarios.Scenario` fields' accepted ranges and their
conversion: each function checks one field (or kind of field) and returns it converted, or
raises a ``ValueError`` naming the field and its accepted range.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from activetrack.models.measurement import INFORMATION_RATIO_MAX as _INFORMATION_RATIO_MAX
from activetrack.models.motion import MODELS, LinearMotionModel
from activetrack.models.objective import OBJECTIVES, Objective
from activetrack.models.sensor import as_sensor_model, checked
from activetrack.validation import FloatArray, real_array, spd

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
N_TARGETS_MAX = 100
POSE_COV_MAX = 1e8
N_STEPS_MAX = 10**9
REWARD_SCALE_RANGE = (1e-12, 1e12)
MAX_TRACE_RANGE = (1e-300, 1e300)
#: Largest accepted ratio of the first predicted position variance to the smallest range
#: variance: how much one update may shrink the position covariance. The position block
#: of the posterior then keeps a condition number that float64 represents over long runs.
#: (The bearing's information, which grows as a sensor nears the target, is bounded by the
#: same ratio in the EKF itself: its near-distance rule.)
INFORMATION_RATIO_MAX = _INFORMATION_RATIO_MAX

_PER_SENSOR = ("sigma_d2", "sigma_theta2", "vmax", "rho", "orientation")
#: Sensor model names (:class:`activetrack.models.sensor_models.SensorModel`, lower case).
SENSOR_MODELS = ("range_bearing", "range", "bearing")
#: Objective names (:data:`activetrack.models.objective.OBJECTIVES`).
OBJECTIVE_NAMES = ("trace", "worst_trace", "logdet")


class Bounds(NamedTuple):
    """A numeric field's accepted values, for each of its entries (every sensor's, every
    coordinate's): ``lo <= x <= hi``, also ``0`` when ``zero``; only integers when
    ``integer``."""

    lo: float
    hi: float
    zero: bool = False
    integer: bool = False

    def __str__(self) -> str:
        """Return the range as the fields' error messages word it."""
        if self.integer:
            return f"an integer in [{int(self.lo)}, {int(self.hi)}]"
        span = f"[{self.lo:g}, {self.hi:g}]"
        return f"0 or {span}" if self.zero and self.lo > 0 else span


#: Every numeric :class:`~activetrack.world.scenarios.Scenario` field's accepted values
#: (per entry of a vector or per-sensor field; ``P0`` and ``pose_cov``: their diagonal's
#: entries), the one place the checks read them from.
BOUNDS: dict[str, Bounds] = {
    "n_sensors": Bounds(1, N_SENSORS_MAX, integer=True),
    "n_steps": Bounds(1, N_STEPS_MAX, integer=True),
    "n_targets": Bounds(1, N_TARGETS_MAX, integer=True),
    "random_occluders": Bounds(0, 100, integer=True),
    "filter_iterations": Bounds(1, 100, integer=True),
    "dt": Bounds(*DT_RANGE),
    "sensor_radius": Bounds(0.0, LENGTH_MAX),
    "reward_scale": Bounds(*REWARD_SCALE_RANGE),
    "max_trace": Bounds(*MAX_TRACE_RANGE),
    "q": Bounds(0.0, Q_MAX, zero=True),
    "sigma_d2": Bounds(*SIGMA_D2_RANGE),
    "sigma_theta2": Bounds(*SIGMA_THETA2_RANGE),
    "vmax": Bounds(0.0, SPEED_MAX, zero=True),
    "rho": Bounds(0.0, LENGTH_MAX, zero=True),
    "orientation": Bounds(-ORIENTATION_MAX, ORIENTATION_MAX, zero=True),
    "max_range": Bounds(1e-6, LENGTH_MAX),
    "p_detect": Bounds(0.0, 1.0, zero=True),
    "x0": Bounds(-STATE_MAX, STATE_MAX, zero=True),
    "x0_hat": Bounds(-STATE_MAX, STATE_MAX, zero=True),
    "P0": Bounds(*P0_RANGE),
    "pose_cov": Bounds(0.0, POSE_COV_MAX, zero=True),
    "sensor_center": Bounds(-LENGTH_MAX, LENGTH_MAX, zero=True),
    "occluder_bounds": Bounds(-LENGTH_MAX, LENGTH_MAX, zero=True),
    "occluder_size": Bounds(1e-6, LENGTH_MAX),
}

#: The named values of the fields that take names (or an object of their kind instead,
#: :data:`CHOICE_KINDS`).
CHOICES: dict[str, tuple[Any, ...]] = {
    "target_init": ("fixed", "gaussian"),
    "motion": tuple(sorted(MODELS)),
    "sensor_model": SENSOR_MODELS,
    "objective": OBJECTIVE_NAMES,
    "account_pose": (True, False),
    "route_observation": (False, True),
    "team_fusion": ("measurements", "covariance_intersection"),
    "team_observation": (False, True),
}
#: What a field of :data:`CHOICES` takes besides its names (one per sensor or target where
#: the field is per sensor or per target).
CHOICE_KINDS: dict[str, str] = {
    "motion": "activetrack.models.motion.LinearMotionModel",
    "sensor_model": "activetrack.SensorModel",
    "objective": "activetrack.Objective",
}


#: How the fields of :data:`BOUNDS` that are more than one number are given (the bounds
#: hold for each entry).
FORMS: dict[str, str] = {
    **dict.fromkeys(_PER_SENSOR, "per sensor (one for all, or a tuple of M), each"),
    "max_range": "None (unlimited), or per sensor (one for all, or a tuple of M), each",
    "p_detect": "per sensor (one for all, or a tuple of M), each",
    "max_trace": "None (no termination), or",
    "q": "one for all targets (or a tuple of K with n_targets > 1),",
    "x0": "the target state (n entries; K rows with n_targets > 1), each entry",
    "x0_hat": "the target state (n entries; K rows with n_targets > 1), each entry",
    "P0": "its diagonal (n entries) or an n x n symmetric positive definite matrix (shared, "
    "or one per target with n_targets > 1), each diagonal entry",
    "pose_cov": "a variance, M variances, a 2x2 matrix or M 2x2 matrices (symmetric "
    "positive semidefinite), each variance",
    "sensor_center": "(x, y), each",
    "occluder_bounds": "(xmin, ymin, xmax, ymax) with min < max, each",
    "occluder_size": "(lo, hi) with lo <= hi, each",
}


def accepted(name: str) -> str:
    """Return the accepted values of the Scenario field ``name`` in words: its
    :data:`FORMS` and :data:`BOUNDS`, or its :data:`CHOICES` (the polygons, kinematics and
    label otherwise)."""
    if name in BOUNDS:
        return f"{FORMS[name]} in {BOUNDS[name]}" if name in FORMS else str(BOUNDS[name])
    if name in CHOICES:
        named = " or ".join(repr(c) for c in CHOICES[name])
        if name in CHOICE_KINDS:
            named += f", or an {CHOICE_KINDS[name]}"
        return (
            f"per sensor (one for all, or a tuple of M): {named}"
            if name == "sensor_model"
            else named
        )
    from activetrack.models.occluders import MAX_VERTICES  # noqa: PLC0415 (occluded scenarios)

    return {
        "occluders": f"simple polygons of >= 3 (x, y) vertices, at most {MAX_VERTICES} "
        "vertices in all (random rectangles' included), coordinates at most "
        f"{LENGTH_MAX:g} in magnitude",
        "kinematics": "None (a disk of radius vmax dt), an activetrack.Kinematics, or a tuple of M",
        "target_behaviour": "None (the filter's own motion model), an activetrack.TargetBehaviour "
        "for every target, or a tuple of K (one per target)",
        "name": "a string",
        "estimator": "'ekf', 'imm' (the target_behaviour's mode set), or an "
        "activetrack.IMMSpec (modes of the targets' state and dt, a row-stochastic transition)",
        "communication": "None (one central filter) or an activetrack.CommunicationModel "
        "(FullCommunication, or RangeLimited: range >= 0, drop in [0, 1], delay an integer "
        "< n_steps, line_of_sight) or its record",
        "d_sep": "0 (none), a distance in [0, 1e9] every pair keeps, or M radii in [0, 1e9] "
        "(a pair keeps d_i + d_j); it must fit the start disk",
        "births": "None (every target present throughout), or an activetrack.BirthProcess "
        "(targets that appear and leave; needs limited sensing, the EKF, range_bearing sensors)",
    }[name]


def _count_field(name: str, value: object) -> int:
    """Return the integer field ``name`` checked against its :data:`BOUNDS`."""
    b = BOUNDS[name]
    return _count(name, value, int(b.hi), lo=int(b.lo))


def _real_field(name: str, value: object) -> float:
    """Return the real scalar field ``name`` checked against its :data:`BOUNDS`."""
    b = BOUNDS[name]
    return _real(name, value, b.lo, b.hi, zero=b.zero)


def _sensor_field(name: str, value: object, m: int) -> float | tuple[float, ...]:
    """Return the per-sensor field ``name`` checked against its :data:`BOUNDS`."""
    b = BOUNDS[name]
    return _sensor_values(name, value, m, b.lo, b.hi, zero=b.zero)


def _vector_field(name: str, value: object, n: int, why: str = "") -> tuple:
    """Return the vector field ``name`` (``n`` entries) checked against its :data:`BOUNDS`."""
    b = BOUNDS[name.split("[")[0]]
    return _vector(name, value, n, b.lo, b.hi, zero=b.zero, why=why)


def _count(name: str, value: object, hi: int, lo: int = 1) -> int:
    """Return ``value`` as an ``int`` in ``[lo, hi]`` (bools, floats and strings rejected)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    if not lo <= value <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
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


def _converted_objective(v: object) -> str | Objective:
    """Return ``objective`` checked: a built-in's name (its instance too), or a new
    objective's instance (its own ``name``, a non-empty string, not a built-in's)."""
    if isinstance(v, Objective):
        builtin = OBJECTIVES.get(v.name) if isinstance(v.name, str) else None
        if builtin is not None and type(v) is type(builtin):
            return v.name
        if not isinstance(v.name, str) or not v.name or builtin is not None:
            raise ValueError(
                f"objective {v!r} must have a name of its own (a non-empty string other "
                f"than {list(OBJECTIVE_NAMES)}), got name {v.name!r}"
            )
        _probe_objective(v)
        return v
    if isinstance(v, str) and v in OBJECTIVE_NAMES:
        return v
    raise ValueError(
        f"objective must be one of {list(OBJECTIVE_NAMES)} or an activetrack.Objective "
        f"instance, got {v!r}"
    )


def _converted_motion(motion: object, kk: int) -> Any:
    """Return ``motion`` checked: one model, or (K > 1) a tuple of K models."""

    def one(v: object) -> str | LinearMotionModel:
        if isinstance(v, LinearMotionModel) or (isinstance(v, str) and v in MODELS):
            return v
        raise ValueError(
            f"motion must be one of {sorted(MODELS)} or a LinearMotionModel "
            f"(or, with n_targets > 1, a tuple of one per target), got {motion!r}"
        )

    if kk > 1 and isinstance(motion, (tuple, list)):
        if len(motion) != kk:
            raise ValueError(f"motion must name one model per target ({kk}), got {len(motion)}")
        return tuple(one(v) for v in motion)
    return one(motion)


def _converted_models(sensor_model: object, m: int) -> object:
    """Return ``sensor_model`` as one entry or a tuple of M: a built-in by its name (its
    instance too: ``RangeOnly()`` is ``"range"``), a model of one's own as itself
    (:func:`activetrack.models.sensor.as_sensor_model`)."""

    def one(v: object) -> object:
        if isinstance(v, str) and v in SENSOR_MODELS:
            return v
        try:
            model = as_sensor_model(v)
        except ValueError as err:
            raise ValueError(
                f"sensor_model must be one of {list(SENSOR_MODELS)}, an activetrack.SensorModel"
                f" or a tuple of {m} of them (one per sensor), got {sensor_model!r} ({err})"
            ) from None
        return model.name if model.builtin else checked(model)

    v = sensor_model
    if isinstance(v, (tuple, list, np.ndarray)):
        if len(v) != m:
            raise ValueError(f"sensor_model must name one model per sensor ({m}), got {len(v)}")
        names = tuple(one(x) for x in v)
        return names[0] if all(n == names[0] for n in names) else names
    return one(v)


def _converted_pose_cov(value: object, m: int) -> float | tuple:
    """Return ``pose_cov`` checked (PSD, in range) in the form it was given."""
    arr = real_array("pose_cov", value)
    if arr.shape not in ((), (m,), (2, 2), (m, 2, 2)):
        raise ValueError(
            f"pose_cov must be a variance, {m} variances (one per sensor), a 2x2 matrix "
            f"or {m} 2x2 matrices, got shape {arr.shape}"
        )
    if arr.ndim <= 1:
        _in_range("pose_cov", arr, 0.0, POSE_COV_MAX, zero=True)
        return float(arr) if arr.ndim == 0 else tuple(float(v) for v in arr)
    mats = arr.reshape(-1, 2, 2)
    _in_range("pose_cov diagonal", mats[:, [0, 1], [0, 1]], 0.0, POSE_COV_MAX, zero=True)
    det = mats[:, 0, 0] * mats[:, 1, 1] - mats[:, 0, 1] ** 2
    if np.any(mats[:, 0, 1] != mats[:, 1, 0]) or np.any(det < 0.0):
        raise ValueError(f"pose_cov must be symmetric positive semidefinite, got {arr.tolist()!r}")
    return (
        tuple(tuple(tuple(float(v) for v in row) for row in mat) for mat in mats)
        if arr.ndim == 3
        else tuple(tuple(float(v) for v in row) for row in arr)
    )


def _per_target_states(key: str, value: object, dims: list[int]) -> tuple:
    """Return K state vectors (one per target, each of its model's dimension)."""
    kk = len(dims)
    rows = value if isinstance(value, (tuple, list, np.ndarray)) else None
    if (
        rows is None
        or len(rows) != kk
        or not all(isinstance(r, (tuple, list, np.ndarray)) for r in rows)
    ):
        raise ValueError(
            f"{key} must hold one state per target ({kk} rows of {dims} entries) when "
            f"n_targets > 1, got {value!r}"
        )
    return tuple(
        _vector_field(f"{key}[{k}]", r, n) for k, (r, n) in enumerate(zip(rows, dims, strict=True))
    )


def _per_target_p0(P0: Any, dims: list[int]) -> tuple:
    """Return P0 for K targets: a shared diagonal, or K diagonals or matrices."""
    kk = len(dims)
    flat = np.asarray(P0, dtype=object)
    shared = (
        flat.ndim == 1
        and len(P0) == dims[0]
        and len(set(dims)) == 1
        and not any(isinstance(v, (tuple, list, np.ndarray)) for v in P0)
    )
    if shared:
        arr = real_array("P0", P0)
        _in_range("P0 diagonal", arr, *P0_RANGE, zero=False)
        return tuple(float(v) for v in arr)
    if not isinstance(P0, (tuple, list)) or len(P0) != kk:
        raise ValueError(
            f"P0 must be a shared diagonal ({dims[0]} entries) or one diagonal or matrix "
            f"per target ({kk}) when n_targets > 1, got {P0!r}"
        )
    out = []
    for k, (pk, n) in enumerate(zip(P0, dims, strict=True)):
        arr = real_array(f"P0[{k}]", pk)
        if arr.shape not in ((n,), (n, n)):
            raise ValueError(f"P0[{k}] must have shape ({n},) or ({n}, {n}), got {arr.shape}")
        _in_range(f"P0[{k}] diagonal", np.diag(arr) if arr.ndim == 2 else arr, *P0_RANGE,
                  zero=False)  # fmt: skip
        if arr.ndim == 2:
            spd(f"P0[{k}]", arr)
            out.append(tuple(tuple(float(v) for v in row) for row in arr))
        else:
            out.append(tuple(float(v) for v in arr))
    return tuple(out)


def _converted_p0(value: object, n: int, motion: object) -> tuple:
    """Return P0 converted (a tuple, or a tuple of tuples), checked SPD and in range."""
    P0 = real_array("P0", value)
    if P0.shape not in ((n,), (n, n)):
        raise ValueError(
            f"P0 must have shape ({n},) or ({n}, {n}) (the state of "
            f"motion={getattr(motion, 'name', motion)!r}), got {P0.shape}"
        )
    _in_range("P0 diagonal", np.diag(P0) if P0.ndim == 2 else P0, *P0_RANGE, zero=False)
    if P0.ndim == 1:
        return tuple(float(v) for v in P0)
    spd("P0", P0)
    return tuple(tuple(float(v) for v in row) for row in P0)


def _converted_occluders(raw: object) -> tuple[tuple, Any]:
    """Return ``occluders`` checked, as tuples of (x, y) float tuples, and their
    :class:`activetrack.models.occluders.Occluders` (None when there are none)."""
    from activetrack.models.occluders import Occluders  # noqa: PLC0415 (occluded scenarios)

    if not isinstance(raw, (tuple, list)):
        raise ValueError(
            f"occluders must be a sequence of polygons (each >= 3 (x, y) vertices), got {raw!r}"
        )
    if not raw:
        return (), None
    try:
        occ = Occluders.from_polygons(list(raw))
    except ValueError as exc:  # name the scenario's field
        raise ValueError(str(exc).replace("polygons", "occluders")) from None
    if occ.scale > LENGTH_MAX:
        raise ValueError(f"occluders coordinates must be at most {LENGTH_MAX:g} in magnitude")
    return tuple(tuple((float(x), float(y)) for x, y in poly) for poly in occ.polygons), occ


def _converted_random_occluders(
    random_occluders: object, occluders: tuple, occluder_bounds: object, occluder_size: object
) -> tuple[int, tuple, tuple]:
    """Return ``random_occluders``, ``occluder_bounds`` and ``occluder_size`` checked (the
    fixed ``occluders`` given converted)."""
    random_occluders = _count_field("random_occluders", random_occluders)
    from activetrack.models.occluders import MAX_VERTICES  # noqa: PLC0415 (occluded scenarios)

    fixed = sum(len(poly) for poly in occluders)
    if fixed + 4 * random_occluders > MAX_VERTICES:
        raise ValueError(
            f"occluders and random_occluders must have at most {MAX_VERTICES} vertices in "
            f"all (4 a random rectangle), got {fixed} + 4 x {random_occluders}"
        )
    b = _vector_field("occluder_bounds", occluder_bounds, 4)
    if not (b[0] < b[2] and b[1] < b[3]):
        raise ValueError(
            f"occluder_bounds must be (xmin, ymin, xmax, ymax) with xmin < xmax and "
            f"ymin < ymax, got {occluder_bounds!r}"
        )
    size = _vector_field("occluder_size", occluder_size, 2)
    if size[0] > size[1]:
        raise ValueError(f"occluder_size must be (lo, hi) with lo <= hi, got {size!r}")
    least = 1e-6 * max(1.0, max(abs(v) for v in b))  # random_layout's smallest side
    if size[0] < least:
        raise ValueError(
            f"occluder_size must be (lo, hi) with lo >= {least:g} (1e-06 times the "
            f"occluder_bounds' scale), got {size!r}"
        )
    return random_occluders, b, size


def _probe_objective(objective: Objective) -> None:
    """Raise ValueError naming ``objective`` unless it scores two configurations of two
    targets (information entries of positive definite matrices) and two covariances as
    one finite value each: a new objective is checked here, not deep in a planner."""
    a = np.array([[2.0, 1.0], [1.0, 4.0]])
    b = np.array([[0.5, 0.0], [-0.2, 1.0]])
    c = np.array([[1.0, 3.0], [0.5, 1.0]])
    P = np.array([[[2.0, 0.3], [0.3, 1.0]], [[1.0, 0.0], [0.0, 5.0]]])
    try:
        with np.errstate(all="ignore"):  # a non-finite value is reported below
            got = [
                np.asarray(objective.of_targets(a, b, c)),
                np.asarray(objective.of_covariances(P)),
            ]
    except Exception as exc:  # a user's code: report it against the field
        raise ValueError(f"objective {objective!r} failed on a valid input: {exc!r}") from exc
    for what, value, shape in (("of_targets", got[0], (2,)), ("of_covariances", got[1], ())):
        if value.shape != shape or not np.all(np.isfinite(value)):
            raise ValueError(
                f"objective {objective!r}: {what} must return finite values of shape {shape} "
                f"on this check's positive definite inputs, got {value!r}"
            )
