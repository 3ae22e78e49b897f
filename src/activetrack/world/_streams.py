"""Each copy's random stream: its generator and its block of step noise.

Copy ``i`` of a :class:`activetrack.world.World` draws from its own generator. With
``noise_block = b > 1`` the step normals are drawn ``b`` steps at a time, never past the
episode's last step; a copy whose episode ends with normals of its block unused has its
generator put back, at its next reset, to where the block began and advanced by the
normals used, so every copy's stream is in the state a single environment's (one step a
call) would be in at every reset (the world's module docstring lists the draws).
:class:`RandomStreams` is that part of the world, its base class; it reads the world's
counters (``_s["k"]``, ``episode_steps``) and owns ``_rngs`` and the ``_noise*`` arrays.
"""

from __future__ import annotations

import numpy as np

from activetrack.validation import FloatArray

_Selection = int | slice | np.ndarray


class RandomStreams:
    """The random streams of :class:`activetrack.world.World` (see the module docstring)."""

    def rng(self, i: int = 0) -> np.random.Generator:
        """Return copy ``i``'s generator (created from fresh entropy if never seeded)."""
        g = self._rngs[i]
        if g is None:
            g = self._rngs[i] = np.random.default_rng()
        return g

    def _draw_noise(self, rows: np.ndarray) -> None:
        """Refill the noise blocks of copies ``rows``, never past their episode's last step."""
        b = self.noise_block
        k = self._s["k"]
        left = np.minimum(b, np.maximum(self.episode_steps - (k if self._one else k[rows]), 1))
        for i, steps in zip(rows.tolist(), np.atleast_1d(left).tolist(), strict=True):
            rng = self.rng(i)
            self._noise_from[i] = rng.bit_generator.state
            self._noise[b - steps :, i] = rng.standard_normal((steps, self._n_noise))
        self._noise_left[rows] = left
        self._noise_drawn[rows] = left

    def _rewind_noise(self, rows: np.ndarray) -> None:
        """Put back the generators of copies ``rows`` that drew normals they did not use:
        to their state before the block, advanced by the normals used (a single
        environment's draws, one step a call, leave the same state)."""
        for i in rows[self._noise_left[rows] > 0].tolist():
            rng = self.rng(i)
            rng.bit_generator.state = self._noise_from[i]
            used = int(self._noise_drawn[i] - self._noise_left[i])
            if used:
                rng.standard_normal((used, self._n_noise))
        self._noise_left[rows] = 0

    def _step_noise(self, sel: _Selection) -> FloatArray:
        """Return the ``n + 2M`` standard normals of this step for the selected copies."""
        if self._noise is None:
            if isinstance(sel, int):
                return (self._rngs[sel] or self.rng(sel)).standard_normal(self._n_noise)
            return np.stack([self.rng(i).standard_normal(self._n_noise) for i in self._rows(sel)])
        rows = self._rows(sel)
        left = self._noise_left[rows]
        if not left.all():
            self._draw_noise(rows[left == 0])
            left = self._noise_left[rows]
        if left.min() == left.max():  # copies in step (the common case): one column
            noise = self._noise[self.noise_block - int(left[0]),
                                sel if isinstance(sel, slice) else rows]  # fmt: skip
        else:
            noise = self._noise[self.noise_block - left, rows]
        self._noise_left[rows] = left - 1
        return noise[0] if isinstance(sel, int) else noise

    def _noise_of(self, sel: _Selection, partial: bool) -> FloatArray:
        """Return the step's standard normals of the copies ``sel`` (all copies' rows, zero
        for those not stepping, when ``partial``)."""
        if self._one and self._noise is None:  # the single env's draw, without a call
            return (self._rngs[0] or self.rng(0)).standard_normal(self._n_noise)
        noise = self._step_noise(sel)
        if partial:
            full = np.zeros((self.num_copies, self._n_noise))
            full[sel] = noise
            noise = full
        return noise

    def _started(self, i: int) -> bool:
        """Return whether copy ``i`` was ever reset."""
        return self._rngs[i] is not None
