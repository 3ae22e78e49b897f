"""Communication between the robots: who receives whom each step (issue 37).

The paper motivates its decentralized method by "limitations on the robots' processing and
communication resources"; real teams talk over radios of limited range that drop packets
and deliver them late. This module is the communication model as a concept of its own,
chosen per scenario (not yet wired into the world):

- :class:`CommunicationModel`, the public base: :meth:`~CommunicationModel.links` returns
  the step's *link matrix* ``L`` (bool, (..., M, M)) from the sensors' true positions:
  ``L[..., i, j]`` is True iff robot ``i`` receives what robot ``j`` sends this step
  (row: receiver, column: sender); the diagonal is always True (a robot has its own
  measurement). A packet sent at step ``t`` over a link is delivered at step
  ``t + delay`` (:attr:`~CommunicationModel.delay`, whole steps; :class:`DeliveryQueue`).
- :class:`FullCommunication` (today's central team: every link, no delay; it consumes no
  random numbers, so a scenario using it keeps its random streams bit for bit).
- :class:`RangeLimited`: a link within ``range`` (closed disk), optionally only with line
  of sight through the occluders (the segment between the two robots not
  :func:`activetrack.models.occluders.blocked`, tested by
  :func:`~activetrack.models.occluders.line_of_sight`); each packet (each ordered pair
  ``i != j``) then dropped independently with probability ``drop``; delivered ``delay``
  steps later.

And the pieces a decentralized team builds on: :func:`components` (the connected groups
of a link matrix, for distributed planning inside each group), :class:`DeliveryQueue`
(messages released ``delay`` steps after they were sent, in order of their send step, so
a receiver's filter processes measurements in time order) and :func:`measurement_senders`
/ :func:`measurement_mask` (whose measurements each robot's filter uses this step).
"""

from __future__ import annotations

import abc
import heapq
import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from activetrack.models.occluders import Occluders, line_of_sight
from activetrack.validation import (
    ComparedByValue,
    FloatArray,
    as_finite,
    check_bool,
    check_int,
    check_trailing_shape,
)

__all__ = [
    "CommunicationModel", "DelayLine", "DeliveryQueue", "FullCommunication", "RangeLimited",
    "components",
    "measurement_mask", "measurement_senders",
]  # fmt: skip


def _positions(positions: ArrayLike) -> FloatArray:
    """Return the sensors' positions checked: finite float64 (..., M, 2) with M >= 1."""
    p = check_trailing_shape("positions", as_finite("positions", positions), (2,))
    if p.ndim < 2 or p.shape[-2] < 1:
        raise ValueError(f"positions must have shape (..., M, 2) with M >= 1, got {p.shape}")
    return p


def _generator(rng: Any) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    return rng


def _link_matrix(name: str, links: ArrayLike) -> np.ndarray:
    """Return ``links`` checked: a bool array (..., M, M), M >= 1."""
    arr = np.asarray(links)
    if arr.dtype != np.bool_:
        raise ValueError(f"{name} must be a bool array (..., M, M), got dtype {arr.dtype}")
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2] or arr.shape[-1] < 1:
        raise ValueError(f"{name} must have shape (..., M, M) with M >= 1, got {arr.shape}")
    return arr


class CommunicationModel(ComparedByValue, abc.ABC):
    """Who receives whom each step, and how late (module docstring).

    A subclass implements :meth:`_links` (unchecked: positions and draws already
    validated), may set ``delay`` (an int >= 0, whole steps; 0 by default) and, if it is
    random, :meth:`n_draws`. Its randomness is standard normals, as the world's step noise
    (one block per copy and step, :mod:`activetrack.world._streams`): :meth:`links` draws
    them from a generator, :meth:`links_from_draws` takes them from the caller. Both
    validate their input and force the diagonal True. Equality is by value
    (:class:`ComparedByValue`).
    """

    #: Steps between sending and delivery (0: the same step).
    delay: int = 0

    @property
    def name(self) -> str:
        """Return the model's name (scenario records, messages): its class name."""
        return type(self).__name__

    def n_draws(self, n_robots: int) -> int:
        """Return how many standard normals one step of ``n_robots`` robots uses (0: none)."""
        return 0

    def links(
        self,
        positions: ArrayLike,
        rng: np.random.Generator,
        occluders: Occluders | None = None,
    ) -> np.ndarray:
        """Return the step's link matrix, bool (..., M, M): ``[..., i, j]`` True iff robot
        ``i`` receives what robot ``j`` sends this step (delivered :attr:`delay` steps
        later); the diagonal is True.

        ``positions`` (..., M, 2) the sensors' true positions, ``rng`` the episode's
        stream: one ``rng.standard_normal((..., n_draws(M)))`` if :meth:`n_draws` is not
        0, nothing otherwise; ``occluders`` the layout (a batched set: the first leading
        axis of ``positions`` is its layout axis).
        """
        p = _positions(positions)
        rng = _generator(rng)
        n = self.n_draws(p.shape[-2])
        draws = rng.standard_normal(p.shape[:-2] + (n,)) if n else None
        return self._checked_links(p, draws, occluders)

    def links_from_draws(
        self, positions: ArrayLike, draws: ArrayLike | None, occluders: Occluders | None = None
    ) -> np.ndarray:
        """Return :meth:`links` with the standard normals ``draws`` (..., n_draws(M)) given
        (None when :meth:`n_draws` is 0): for a caller that draws a step's noise in one
        block (the world)."""
        p = _positions(positions)
        n = self.n_draws(p.shape[-2])
        if n == 0:
            if draws is not None:
                raise ValueError(f"draws must be None: {self.name} draws nothing, got an array")
        else:
            draws = as_finite("draws", draws)
            if draws.shape != p.shape[:-2] + (n,):
                raise ValueError(
                    f"draws must have shape {p.shape[:-2] + (n,)} (positions' leading axes, "
                    f"n_draws), got {draws.shape}"
                )
        return self._checked_links(p, draws, occluders)

    def _checked_links(
        self, p: FloatArray, draws: FloatArray | None, occluders: Occluders | None
    ) -> np.ndarray:
        if occluders is not None and not isinstance(occluders, Occluders):
            raise ValueError(
                f"occluders must be an Occluders or None, got {type(occluders).__name__}"
            )
        out = np.array(self._links(p, draws, occluders), dtype=bool)
        m = p.shape[-2]
        out[..., np.arange(m), np.arange(m)] = True
        return out

    @abc.abstractmethod
    def _links(
        self, positions: FloatArray, draws: FloatArray | None, occluders: Occluders | None
    ) -> np.ndarray:
        """Return the link matrix (..., M, M) of checked ``positions`` and ``draws``
        (..., n_draws(M)) or None (the diagonal may be anything)."""

    def check(self, n_steps: int) -> None:
        """Raise ``ValueError`` naming ``delay`` unless a packet sent at the first step of an
        episode of ``n_steps`` steps is delivered within it (``delay < n_steps``): for the
        scenario to refuse a model its episodes cannot use."""
        n = check_int("n_steps", n_steps, 1)
        if self.delay >= n:
            raise ValueError(
                f"delay must be < the episode's n_steps = {n} (a packet would never be "
                f"delivered), got {self.delay}"
            )


class FullCommunication(CommunicationModel):
    """Every robot receives every robot, at once (today's central team). Draws nothing."""

    def _links(self, positions, draws, occluders):
        m = positions.shape[-2]
        return np.ones(positions.shape[:-2] + (m, m), bool)

    def __repr__(self) -> str:
        return "FullCommunication()"


class RangeLimited(CommunicationModel):
    """A radio of limited range that drops and delays packets.

    ``range`` (>= 0, ``math.inf`` allowed): robots ``i`` and ``j`` are in contact iff
    ``|p_i - p_j| <= range`` and, with ``line_of_sight`` and occluders, the segment
    ``[p_i, p_j]`` is not blocked (a symmetric relation: the segment is tested once, for
    ``i < j``). ``drop`` in [0, 1]: each packet (each ordered pair ``i != j`` in contact)
    is lost independently with that probability. ``delay`` (int >= 0): packets arrive that
    many whole steps later.

    Random numbers: with ``drop > 0``, ``M * M`` standard normals per step
    (:meth:`n_draws`), read row-major as (M, M): entry ``[i, j]`` below
    ``Phi^{-1}(drop)`` loses the packet from ``j`` to ``i`` (probability ``drop``; the
    world's rule for its detection draws); the diagonal's are drawn and unused, so the
    number of draws does not depend on the positions. With ``drop == 0`` none.
    """

    def __init__(
        self, range: float, drop: float = 0.0, delay: int = 0, line_of_sight: bool = False
    ) -> None:
        r = _real("range", range)
        if not r >= 0.0:
            raise ValueError(f"range must be >= 0 (math.inf allowed), got {range!r}")
        d = _real("drop", drop)
        if not 0.0 <= d <= 1.0:
            raise ValueError(f"drop must be a probability in [0, 1], got {drop!r}")
        self.range = r
        self.drop = d
        self.delay = check_int("delay", delay, 0)
        self.line_of_sight = check_bool("line_of_sight", line_of_sight)

    def __repr__(self) -> str:
        return (
            f"RangeLimited(range={self.range!r}, drop={self.drop!r}, delay={self.delay!r}, "
            f"line_of_sight={self.line_of_sight!r})"
        )

    def in_contact(self, positions: FloatArray, occluders: Occluders | None) -> np.ndarray:
        """Return the symmetric contact matrix (..., M, M) before drops (unchecked input):
        within ``range`` and, if asked, in line of sight; diagonal True."""
        x, y = positions[..., 0], positions[..., 1]
        dx = x[..., :, None] - x[..., None, :]
        dy = y[..., :, None] - y[..., None, :]
        near = np.sqrt(dx * dx + dy * dy) <= self.range  # symmetric: (-d)^2 == d^2
        if self.line_of_sight and occluders is not None and occluders.n_edges:
            # Each segment once (i < j) and only within range: line_of_sight's ``where``
            # leaves the other pairs untested (False), then the relation is mirrored.
            m = positions.shape[-2]
            ask = near & np.triu(np.ones((m, m), bool), 1)
            seen = line_of_sight(positions, positions, occluders, where=ask)
            near = seen | np.swapaxes(seen, -1, -2)
        m = positions.shape[-2]
        near[..., np.arange(m), np.arange(m)] = True
        return near

    def n_draws(self, n_robots: int) -> int:
        """Return ``n_robots ** 2`` with drops, else 0 (the class docstring)."""
        return n_robots * n_robots if self.drop > 0.0 else 0

    def _links(self, positions, draws, occluders):
        out = self.in_contact(positions, occluders)
        if draws is not None:
            from scipy.special import ndtri  # (only with drops)

            # Phi^{-1}(1) = inf: every packet is lost (normal draws are finite).
            out &= ~(draws.reshape(out.shape) < ndtri(self.drop))
        return out


def _real(name: str, value: Any) -> float:
    """Return ``value`` as a float (a real number, not NaN; inf allowed) or raise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    v = float(value)
    if math.isnan(v):
        raise ValueError(f"{name} must not be NaN, got {value!r}")
    return v


def components(links: ArrayLike, connection: str = "weak") -> tuple[np.ndarray, np.ndarray]:
    """Return ``(n, labels)``: the connected groups of link matrices ``links`` (..., M, M).

    ``n`` (...) the number of groups, ``labels`` (..., M) int the group of each robot,
    numbered ``0 .. n - 1`` in order of their lowest robot index (robot 0 is in group 0).
    ``connection`` is scipy's: ``"weak"`` (a link in either direction joins two robots)
    or ``"strong"`` (each must reach the other along received links). Computed by
    :func:`scipy.sparse.csgraph.connected_components` on the block-diagonal graph of all
    the leading axes at once (an edge ``i -> j`` for ``links[..., i, j]``: for strong
    groups the direction does not matter, the reversed graph has the same ones).
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    if connection not in ("weak", "strong"):
        raise ValueError(f"connection must be one of ['weak', 'strong'], got {connection!r}")
    arr = _link_matrix("links", links)
    lead, m = arr.shape[:-2], arr.shape[-1]
    flat = arr.reshape(-1, m, m)
    b = flat.shape[0]
    if b == 0:
        return np.zeros(lead, np.intp), np.zeros(lead + (m,), np.intp)
    # One graph of b * m nodes, copy c's robots at c * m + (0 .. m - 1): block diagonal.
    c, i, j = np.nonzero(flat)
    graph = csr_matrix((np.ones(len(c), np.int8), (c * m + i, c * m + j)), shape=(b * m, b * m))
    _, glob = connected_components(graph, directed=True, connection=connection)
    glob = glob.reshape(b, m)
    # Canonical numbering: each robot's group is named by its lowest member ...
    lowest = np.full(int(glob.max()) + 1, np.iinfo(np.intp).max, np.intp)
    np.minimum.at(lowest, glob.ravel(), np.tile(np.arange(m), b))
    low = lowest[glob]  # (b, m)
    # ... then numbered by the rank of that member among the groups' lowest members.
    root = low == np.arange(m)
    rank = np.cumsum(root, axis=1) - 1
    labels = np.take_along_axis(rank, low, axis=1)
    return root.sum(axis=1).reshape(lead), labels.reshape(lead + (m,))


def measurement_mask(links: ArrayLike) -> np.ndarray:
    """Return whose measurements each robot uses this step, bool (..., M, M): ``[..., i, j]``
    True iff robot ``i``'s filter updates with robot ``j``'s measurement; its own
    (the diagonal) always.

    With no delay this is the step's link matrix: robot ``i`` applies, in one update, the
    measurements of the senders ``j`` of row ``i`` (the measurement-sharing filter; with
    :class:`FullCommunication` every row is all True and each robot's update is today's
    central one). With a delay, a robot updates with its own measurement at once and with
    its neighbours' when :class:`DeliveryQueue` releases them (retrodiction, documented
    where the filters are wired).
    """
    arr = _link_matrix("links", links).copy()
    m = arr.shape[-1]
    arr[..., np.arange(m), np.arange(m)] = True
    return arr


def measurement_senders(links: ArrayLike) -> list[np.ndarray]:
    """Return, for each robot ``i`` of one step's link matrix (M, M), the sorted int array of
    the robots whose measurements it uses this step (:func:`measurement_mask`'s row ``i``;
    ``i`` itself always included)."""
    arr = measurement_mask(links)
    if arr.ndim != 2:
        raise ValueError(f"links must have shape (M, M) (one step), got {arr.shape}")
    return [np.flatnonzero(row) for row in arr]


class DeliveryQueue:
    """Messages in flight between ``n_robots`` robots, released ``delay`` steps after sent.

    :meth:`send` posts, at a step, each sender's payload (any object) to every receiver of
    its column of the link matrix (not to itself: its own data it has at once);
    :meth:`deliver` returns what each receiver gets at a step: the messages due by then,
    as ``(send_step, sender, payload)`` tuples sorted by send step, then sender (so a
    receiver's filter processes measurements in time order), each delivered once.
    """

    def __init__(self, n_robots: int, delay: int = 0) -> None:
        self.n_robots = check_int("n_robots", n_robots, 1)
        self.delay = check_int("delay", delay, 0)
        self._heap: list[tuple[int, int, int, int, int, Any]] = []
        self._order = itertools.count()  # ties (same step, receiver, sender): posting order

    def __len__(self) -> int:
        """Return the number of messages not yet delivered."""
        return len(self._heap)

    def send(
        self, step: int, links: ArrayLike, payloads: Sequence[Any], delay: int | None = None
    ) -> None:
        """Post, at ``step``, ``payloads[j]`` from each robot ``j`` to each ``i != j`` with
        ``links[i, j]`` (an (M, M) bool link matrix), due at ``step + delay`` (this
        queue's delay by default)."""
        step = check_int("step", step, 0)
        d = self.delay if delay is None else check_int("delay", delay, 0)
        arr = _link_matrix("links", links)
        m = self.n_robots
        if arr.shape != (m, m):
            raise ValueError(f"links must have shape ({m}, {m}), got {arr.shape}")
        if len(payloads) != m:
            raise ValueError(
                f"payloads must hold {m} entries (one per sender), got {len(payloads)}"
            )
        for i, j in zip(*np.nonzero(arr), strict=True):
            if i != j:
                entry = (step + d, step, int(j), int(i), next(self._order), payloads[j])
                heapq.heappush(self._heap, entry)

    def deliver(self, step: int) -> list[list[tuple[int, int, Any]]]:
        """Return, for each receiver, its messages due at or before ``step`` (removed from
        the queue): ``(send_step, sender, payload)`` sorted by send step, then sender."""
        step = check_int("step", step, 0)
        out: list[list[tuple[int, int, Any]]] = [[] for _ in range(self.n_robots)]
        due = []
        while self._heap and self._heap[0][0] <= step:
            due.append(heapq.heappop(self._heap))
        for _, sent, sender, receiver, _n, payload in sorted(due, key=lambda e: (e[1], e[2], e[4])):
            out[receiver].append((sent, sender, payload))
        return out


class DelayLine:
    """A fixed delay of whole steps for batched arrays: what a constant ``delay`` delivers.

    The vectorized counterpart of :class:`DeliveryQueue` for a world of ``N`` copies (a
    heap of Python messages per copy would cost ``N M^2`` pushes a step): each step the
    caller pushes the stepped copies' arrays (leading axis ``N``: their link matrices,
    measurements, detections...) and gets back, for each of them, what it pushed ``delay``
    of its own pushes earlier, with a mask ``valid`` (N,): True for a stepped copy that has
    pushed more than ``delay`` times since its :meth:`reset` (its delayed rows are of the
    current episode), False otherwise (those rows are zeros or stale: to be ignored).
    ``delay == 0`` returns what was pushed. Each copy keeps its own count, so copies that
    step at different times (a world's ``live`` subsets) or reset at different times are
    delayed exactly by their own steps.
    """

    def __init__(self, num_copies: int, delay: int) -> None:
        self.num_copies = check_int("num_copies", num_copies, 1)
        self.delay = check_int("delay", delay, 0)
        self._count = np.zeros(self.num_copies, np.int64)  # pushes since each copy's reset
        self._buffer: tuple[np.ndarray, ...] | None = None  # each (delay, N, ...)

    def _rows(self, rows: ArrayLike | None) -> np.ndarray:
        """Return the copies ``rows`` (None: all; int indices or a bool mask) as a bool mask."""
        mask = np.zeros(self.num_copies, bool)
        try:
            mask[slice(None) if rows is None else np.asarray(rows)] = True
        except IndexError as exc:
            raise ValueError(f"rows must index the {self.num_copies} copies: {exc}") from None
        return mask

    def reset(self, rows: ArrayLike | None = None) -> None:
        """Start a new episode for the copies ``rows`` (int indices or a bool mask; None:
        all): nothing they pushed before is returned as valid."""
        self._count[self._rows(rows)] = 0

    def push(
        self, arrays: Sequence[ArrayLike], rows: ArrayLike | None = None
    ) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
        """Return ``(delayed, valid)`` and store ``arrays`` for the copies ``rows`` (None:
        all): ``delayed`` the arrays (N, ...) with, in each row of ``rows``, what that copy
        pushed ``delay`` of its pushes ago, ``valid`` (N,) bool (class docstring; False
        outside ``rows``). ``arrays`` each have the leading axis N (only the rows of
        ``rows`` are read) and the same shapes at every push."""
        arrs = tuple(np.asarray(a) for a in arrays)
        for k, a in enumerate(arrs):
            if a.ndim < 1 or a.shape[0] != self.num_copies:
                raise ValueError(
                    f"arrays[{k}] must have a leading axis of {self.num_copies} copies, "
                    f"got shape {a.shape}"
                )
        sel = self._rows(rows)
        if self.delay == 0:
            return tuple(np.where(_column(sel, a), a, 0) for a in arrs), sel.copy()
        if self._buffer is None:
            self._buffer = tuple(np.zeros((self.delay,) + a.shape, a.dtype) for a in arrs)
        if [a.shape for a in arrs] != [b.shape[1:] for b in self._buffer]:
            raise ValueError("arrays must have the same shapes (and number) at every push")
        idx = np.flatnonzero(sel)
        slot = self._count[idx] % self.delay
        out = tuple(np.zeros_like(a) for a in arrs)
        for o, b, a in zip(out, self._buffer, arrs, strict=True):
            o[idx] = b[slot, idx]
            b[slot, idx] = a[idx]
        valid = np.zeros(self.num_copies, bool)
        valid[idx] = self._count[idx] >= self.delay
        self._count[idx] += 1
        return out, valid


def _column(mask: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Return the (N,) ``mask`` shaped to broadcast against ``a`` (N, ...)."""
    return mask.reshape(mask.shape + (1,) * (a.ndim - 1))
