"""The world's moves among occluders: sensors' starts outside them, moves that neither
pass through nor end in one (:func:`activetrack.models.occluders.project_move`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.validation import FloatArray


class OccludedMoves:
    """The occluder rules of :class:`activetrack.world.World` (a base class of it)."""

    _occ: Any
    _pose: bool
    params: Any

    def _outside_occluders(self, sensors: FloatArray, rows: np.ndarray, one: bool) -> FloatArray:
        """Return ``sensors`` with each start inside an occluder drawn again (from its copy's
        generator, after the copy's other draws) until it is outside."""
        from activetrack.models import occluders  # noqa: PLC0415 (occluded scenarios only)

        batch = sensors[None] if one else sensors
        # One vectorized test of every start, then the copies with a start inside draw
        # again, each from its own generator (as a loop over all copies would).
        layouts = self._occ if one or not self._occ.batched else self._occ[rows]
        bad_copies = np.flatnonzero(np.any(occluders.inside(batch, layouts), axis=-1))
        for j in bad_copies.tolist():
            i = int(rows[j])
            occ = self._occ if one else self._occ[i]
            for _ in range(1000):
                bad = occluders.inside(batch[j], occ)
                if not bad.any():
                    break
                batch[j][bad] = self._start_positions(self.rng(i).random((int(bad.sum()), 2)))
            else:
                raise ValueError(
                    "occluders cover the sensors' start disk: no start outside them found"
                )
        return batch[0] if one else batch

    def _around_occluders(
        self, sensors: FloatArray, fixes: FloatArray, moved: FloatArray, projected: np.ndarray
    ) -> tuple[FloatArray, np.ndarray]:
        """Return the moves ``moved`` (from the fixes) mended so that each true straight
        move from ``sensors`` neither passes through nor ends in an occluder
        (:func:`activetrack.models.occluders.project_move`, the nearest reachable point), and the
        projected marks including those mended."""
        from activetrack.models import occluders  # noqa: PLC0415 (occluded scenarios only)

        desired = sensors + (moved - fixes) if self._pose else moved
        reached, hit = occluders.project_move(sensors, desired, self._occ, self.params.r)
        if not np.any(hit):
            return moved, projected
        return (fixes + (reached - sensors) if self._pose else reached), projected | hit
