"""Input checks shared by the public API.

Every public function validates its arguments here so that a user's typo raises a
``ValueError`` naming the parameter and the allowed range, instead of failing deep
inside numpy. Hot loops call the unchecked private kernels directly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
SYMMETRY_TOL = 1e-9  # |p12 - p21| of a 2x2 SPD matrix, relative to its largest entry


class UnexpectedKeywordError(TypeError, ValueError):
    """An unknown keyword argument, worded like Python's own ``TypeError``.

    It subclasses :class:`ValueError` too, so callers that catch either keep working (and
    wrappers such as TorchRL's ``GymEnv``, which probe optional keywords and fall back on
    ``TypeError: ... unexpected keyword argument``, recognize it).
    """


def as_finite(name: str, value: ArrayLike, shape: Sequence[int | None] | None = None) -> FloatArray:
    """Return ``value`` as a float64 array, checking that it is finite and of ``shape``.

    ``shape`` may contain ``None`` for a free dimension; a leading ``...`` is not supported,
    use :func:`check_trailing_shape` for batched inputs.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:  # 10**400: too large a float
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    if shape is not None:
        if arr.ndim != len(shape) or any(
            s is not None and s != a for s, a in zip(shape, arr.shape, strict=True)
        ):
            want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN or inf), got {value!r}")
    return arr


def _reject_non_real(name: str, value: object) -> None:
    """Raise ``ValueError`` if ``value`` holds anything but real numbers (bools and strings too)."""
    if isinstance(value, (list, tuple)):
        for v in value:
            _reject_non_real(name, v)
    elif isinstance(value, (bool, np.bool_, str, bytes)) or value is None:
        raise ValueError(f"{name} must hold real numbers, got {value!r}")


def real_array(name: str, value: object, *, finite: bool = True) -> FloatArray:
    """Return ``value`` as a float64 array of real (and, with ``finite``, finite) numbers.

    Strings, bools, ``None``, complex numbers, ragged nestings and object arrays raise a
    ``ValueError`` naming ``name``, so a value is converted once here instead of failing
    later (``np.asarray("0.1", float)`` would silently parse a string, and a complex
    action would lose its imaginary part). ``finite=False`` leaves NaN and inf to the
    caller, for a message that says where they are.
    """
    _reject_non_real(name, value)
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be real numbers, got {value!r}") from exc
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be real numbers, got {value!r}")
    arr = arr.astype(np.float64, copy=False)
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN or inf), got {value!r}")
    return arr


def check_trailing_shape(name: str, arr: FloatArray, trailing: tuple[int, ...]) -> FloatArray:
    """Return ``arr`` after checking that its last dimensions equal ``trailing``."""
    if arr.ndim < len(trailing) or arr.shape[arr.ndim - len(trailing) :] != trailing:
        raise ValueError(
            f"{name} must have shape (..., {', '.join(map(str, trailing))}), got {arr.shape}"
        )
    return arr


def positive(name: str, value: ArrayLike, *, allow_zero: bool = False) -> FloatArray:
    """Return ``value`` as a finite float64 array whose entries are > 0 (or >= 0)."""
    arr = as_finite(name, value)
    bad = arr < 0 if allow_zero else arr <= 0
    if np.any(bad):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be {bound}, got {value!r}")
    return arr


def per_sensor(name: str, value: ArrayLike, n: int, *, allow_zero: bool = False) -> FloatArray:
    """Return a positive per-sensor parameter broadcast to shape ``(n,)``."""
    arr = positive(name, value, allow_zero=allow_zero)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have shape ({n},), got {arr.shape}")
    return arr


def spd(name: str, value: ArrayLike, *, rtol: float = 1e-9) -> FloatArray:
    """Return ``value`` checked to be a finite, symmetric, positive definite matrix (batched ok)."""
    arr = as_finite(name, value)
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
        raise ValueError(f"{name} must be a square matrix (..., n, n), got shape {arr.shape}")
    scale = np.max(np.abs(arr), axis=(-2, -1), keepdims=True)
    asym = np.abs(arr - np.swapaxes(arr, -1, -2))
    if np.any(asym > rtol * np.maximum(scale, 1e-300)):
        raise ValueError(f"{name} must be symmetric")
    try:
        np.linalg.cholesky(0.5 * (arr + np.swapaxes(arr, -1, -2)))
    except np.linalg.LinAlgError as exc:
        raise ValueError(f"{name} must be positive definite") from exc
    return arr


def psd(name: str, value: ArrayLike, *, rtol: float = 1e-9) -> FloatArray:
    """Return ``value`` checked to be a finite, symmetric, positive semidefinite matrix."""
    arr = as_finite(name, value)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {arr.shape}")
    scale = max(float(np.max(np.abs(arr))), 1e-300)
    if np.any(np.abs(arr - arr.T) > rtol * scale):
        raise ValueError(f"{name} must be symmetric")
    if np.min(np.linalg.eigvalsh(arr)) < -1e-10 * scale:
        raise ValueError(f"{name} must be positive semidefinite")
    return arr


def real_scalar(name: str, value: ArrayLike, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a float, checking that it is a finite scalar > 0 (or >= 0).

    Python and NumPy floats take a fast path (no array is made).
    """
    if type(value) is float or isinstance(value, np.floating):
        v = float(value)
    else:
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError, OverflowError) as exc:  # 10**400: too large a float
            raise ValueError(f"{name} must be a real number, got {value!r}") from exc
        if arr.ndim != 0:
            raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
        v = float(arr)
    if not (v >= 0.0 if allow_zero else v > 0.0) or v == np.inf:  # NaN fails both
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value!r}")
    return v


def spd2_entries(
    name: str, p11: float, p12: float, p21: float, p22: float, max_abs: float = 1e150
) -> None:
    """Raise unless ``[[p11, p12], [p21, p22]]`` (floats) is finite, symmetric and SPD.

    The one-matrix, float-only form of :func:`spd` for 2x2 matrices (symmetry to a
    relative ``1e-9``; positive definite: ``p11 > 0`` and ``det > 0``). Entries must not
    exceed ``max_abs`` in magnitude (the determinant must not overflow).
    """
    if not (
        math.isfinite(p11) and math.isfinite(p12) and math.isfinite(p21) and math.isfinite(p22)
    ):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    scale = max(abs(p11), abs(p22), abs(p12))
    if scale > max_abs or abs(p21) > max_abs:
        raise ValueError(f"{name}: entries must be within [-{max_abs:g}, {max_abs:g}]")
    if abs(p12 - p21) > SYMMETRY_TOL * max(scale, 1e-300):
        raise ValueError(f"{name} must be symmetric")
    if p11 <= 0.0 or p11 * p22 - p12 * p21 <= 0.0:
        raise ValueError(f"{name} must be positive definite (eigenvalues > 0)")


def spd2_stack(name: str, arr: FloatArray, *, max_abs: float = 1e150) -> None:
    """Raise unless every matrix of ``arr`` (..., 2, 2) is finite, symmetric and SPD.

    The stacked form of :func:`spd2_entries` (same rule, vectorized).
    """
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    if arr.size and np.max(np.abs(arr)) > max_abs:
        raise ValueError(f"{name}: entries must be within [-{max_abs:g}, {max_abs:g}]")
    p11, p12, p21, p22 = arr[..., 0, 0], arr[..., 0, 1], arr[..., 1, 0], arr[..., 1, 1]
    scale = np.maximum(np.maximum(np.abs(p11), np.abs(p22)), np.abs(p12))
    if np.any(np.abs(p12 - p21) > SYMMETRY_TOL * np.maximum(scale, 1e-300)):
        raise ValueError(f"{name} must be symmetric")
    if np.any(p11 <= 0.0) or np.any(p11 * p22 - p12 * p21 <= 0.0):
        raise ValueError(f"{name} must be positive definite (eigenvalues > 0)")


def within(name: str, value: ArrayLike, low: float, high: float, *, what: str = "") -> None:
    """Raise unless every nonzero ``value`` lies in ``[low, high]`` (zeros pass).

    ``what`` names the quantity when it is not ``name`` itself (e.g. ``"||c|| / r"``).
    Python floats take a fast path (no array is made).
    """
    if type(value) is float:
        if value == 0.0 or low <= value <= high:
            return
        got = value
    else:
        arr = np.asarray(value, dtype=np.float64)
        bad = (arr != 0.0) & ~((arr >= low) & (arr <= high))
        if not np.any(bad):
            return
        got = float(arr[bad].flat[0])
    bound = f"<= {high:g}" if low == 0.0 else f"0 or within [{low:g}, {high:g}]"
    raise ValueError(f"{name}: {what or name} must be {bound}, got {got:g}")


# Field checks of configuration dataclasses (the planners' and the training settings): each
# returns the value converted to its type or raises a ValueError naming the field and range.
def check_int(name: str, value: Any, low: int, high: int | None = None) -> int:
    """Return ``value`` as an int in ``[low, high]`` (integral floats accepted, bools not)."""
    bound = f">= {low}" if high is None else f"in [{low}, {high}]"
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if isinstance(value, (float, np.floating)) and math.isfinite(value) and value == int(value):
        ok, value = True, int(value)
    if not ok or value < low or (high is not None and value > high):
        raise ValueError(f"{name} must be an integer {bound}, got {value!r}")
    return int(value)


def check_float(
    name: str,
    value: Any,
    low: float = -math.inf,
    high: float = math.inf,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Return ``value`` as a finite float in the interval from ``low`` to ``high``.

    ``low_open``/``high_open`` exclude the bound itself (e.g. ``> 0``).
    """
    if math.isinf(low) and math.isinf(high):
        bound = "finite"
    elif math.isinf(high):
        bound = f"finite and {'>' if low_open else '>='} {low:g}"
    elif math.isinf(low):
        bound = f"finite and {'<' if high_open else '<='} {high:g}"
    else:
        bound = f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )
    if ok:
        value = float(value)
        ok = math.isfinite(value) and (value > low if low_open else value >= low)
        ok = ok and (value < high if high_open else value <= high)
    if not ok:
        raise ValueError(f"{name} must be a number {bound}, got {value!r}")
    return value


def check_bool(name: str, value: Any) -> bool:
    """Return ``value`` if it is a bool (numpy's included) or raise a ValueError."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    """Return ``value`` if it is one of ``choices`` or raise a ValueError listing them."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value


def check_seed(name: str, value: Any) -> int | None:
    """Return an environment's seed: None, or an integer >= 0 (Gymnasium's rule, numpy
    integers included, bools not)."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{name} must be None or an integer >= 0, got {value!r}")
    return int(value)


def as_generator(name: str, seed: Any) -> np.random.Generator:
    """Return ``np.random.default_rng(seed)`` or raise a ValueError naming ``name``."""
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError):
        raise ValueError(
            f"{name} must be an integer >= 0 (or a SeedSequence, BitGenerator or Generator), "
            f"got {seed!r}"
        ) from None


def same_attributes(a: object, b: object) -> bool:
    """Return whether ``a`` and ``b`` are of the same class with equal instance attributes
    (arrays compared by value): the equality of a user's model, kinematics or objective,
    so that a copy, a pickle (Ray ships them to workers) or a twin built the same way
    equals the original."""
    if type(a) is not type(b):
        return False
    da, db = getattr(a, "__dict__", {}), getattr(b, "__dict__", {})
    if da.keys() != db.keys():
        return False
    for k, x in da.items():
        y = db[k]
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not np.array_equal(x, y):
                return False
        elif not bool(x == y):
            return False
    return True


class ComparedByValue:
    """Equality by value for the concept objects a user subclasses (a sensor model, a
    kinematics, an objective): same class and equal attributes (:func:`same_attributes`),
    so scenarios and planning problems built from copies, pickles or twins compare equal."""

    def __eq__(self, other: object) -> bool:
        return same_attributes(self, other)

    def __hash__(self) -> int:
        # By class only: equal objects hash equal whatever their attributes (arrays too).
        return hash(type(self))
