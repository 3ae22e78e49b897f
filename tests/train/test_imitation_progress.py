"""The progress of ``train bc``/``train dagger``: labelling in steps, training in epochs.

Issue 35: a bar over the rounds only (``imitation rounds 0/1`` for the whole run) told
nothing. A stand-in for tqdm records every bar's total and updates; the expected counts
come from the configuration (episodes x steps per episode, rounds x epochs).
"""

from __future__ import annotations

import pytest

from activetrack.train.imitation import ImitationConfig, train_imitation
from activetrack.train.networks import NetConfig


class _Bar:
    made: list = []

    def __init__(self, *args, total=None, desc="", disable=False, **kwargs):
        self.total, self.desc, self.disable, self.n, self.updates = total, desc, disable, 0, []
        _Bar.made.append(self)

    def update(self, k=1):
        self.n += k
        self.updates.append(k)

    def set_postfix_str(self, *args, **kwargs):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


@pytest.mark.parametrize("batched", [False, True])
def test_labelling_advances_per_step_and_training_per_epoch(batched, monkeypatch):
    import tqdm.auto

    monkeypatch.setattr(tqdm.auto, "tqdm", _Bar)
    _Bar.made = []
    episodes, steps, epochs, rounds = 4, 5, 3, 2
    cfg = ImitationConfig(
        episodes=episodes, epochs=epochs, iterations=rounds, net=NetConfig(hidden=(8,))
    )
    train_imitation("paper", seed=1, config=cfg, progress=True, batched=batched, n_steps=steps)
    bars = {b.desc: b for b in _Bar.made}
    assert set(bars) == {"labelling", "training"} and not any(b.disable for b in _Bar.made)
    label, train = bars["labelling"], bars["training"]
    assert label.total == label.n == episodes * steps
    # Every step is reported as it happens: one update per step (per copy batched: the
    # round's episodes at once), not one per round.
    per_step = [k for k in label.updates if k > 0]
    assert len(per_step) == (rounds * steps if batched else episodes * steps)
    assert train.total == train.n == rounds * epochs and train.updates == [1] * (rounds * epochs)
