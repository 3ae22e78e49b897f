"""Which copies of a :class:`activetrack.world.World` a call reads or advances: a mask,
indices or None (all), turned into the selection the world indexes its arrays with."""

from __future__ import annotations

from typing import Any

import numpy as np

_Selection = int | slice | np.ndarray


class CopySelection:
    """The copy selections of :class:`activetrack.world.World` (its base class; it reads
    ``num_copies``)."""

    def _rows(self, sel: _Selection) -> np.ndarray:
        """Return the copy indices of a selection."""
        return np.arange(self.num_copies)[sel] if isinstance(sel, slice) else np.atleast_1d(sel)

    def _select(self, indices: Any) -> _Selection | None:
        """Return the selection of ``indices`` (None: all copies); None if it is empty.

        A world of one copy selects with the integer 0, so a step runs on unbatched arrays.
        """
        N = self.num_copies
        if indices is None:
            return 0 if N == 1 else slice(None)
        idx = np.asarray(indices)
        if idx.dtype == np.bool_:
            if idx.shape != (N,):
                raise ValueError(f"a copy mask must have shape ({N},), got {idx.shape}")
            idx = np.flatnonzero(idx)
        elif idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
            raise ValueError(f"copy indices must be a 1-d integer array, got {indices!r}")
        idx = idx.astype(np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= N or np.unique(idx).size != idx.size):
            raise ValueError(f"copy indices must be distinct and in [0, {N - 1}], got {indices!r}")
        if idx.size == 0:
            return None
        if idx.size == N:
            return 0 if N == 1 else slice(None)
        return idx
