"""The single-sensor solver for a batch of problems (Section IV-A): the compiled kernel
:func:`activetrack.solvers._scalar.solve_point` run over the rows in compiled code
(:func:`~activetrack.solvers._scalar.solve_rows`), so a row's answer is exactly the one-problem
answer whatever the batch. Inputs are validated by the caller
(:func:`activetrack.solvers.analytic.solve_single_sensor_batch`).
"""

from __future__ import annotations

import numpy as np

from activetrack.solvers._scalar import solve_rows
from activetrack.solvers.results import BatchSolution
from activetrack.validation import FloatArray


def solve_batch(
    P: FloatArray,
    c: FloatArray,
    r: FloatArray,
    rho: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
) -> BatchSolution:
    """Return the batched solution for validated float64 arrays of shapes (B, 2, 2), (B, 2),
    (B,) x 4."""
    n = P.shape[0]
    s = np.empty((n, 2))
    value = np.empty(n)
    case = np.empty(n, dtype=np.int64)
    feasible = np.empty(n, dtype=bool)
    solve_rows(
        np.ascontiguousarray(P, dtype=np.float64),
        np.ascontiguousarray(c, dtype=np.float64),
        *(np.ascontiguousarray(q, dtype=np.float64) for q in (r, rho, sigma_d2, sigma_theta2)),
        s, value, case, feasible,
    )  # fmt: skip
    return BatchSolution(s=s, value=value, case=case, feasible=feasible)
