"""The loop kernel's pieces (:mod:`activetrack.world.tracking`) against longhand computations."""

import math

import numpy as np
import pytest

from activetrack.world import tracking
from activetrack.world.scenarios import make_scenario


@pytest.mark.parametrize("preset", ["paper", "two_targets", "mixed"])
def test_measure_every_target_in_one_call_matches_longhand(preset):
    sc = make_scenario(preset, orientation=0.3)
    p = tracking.LoopParams.from_scenario(sc)
    rng = np.random.default_rng(1)
    m, k = sc.n_sensors, sc.n_targets
    for batch in ((), (3,)):
        targets = rng.normal(size=batch + (k, 2)) * 5
        sensors = rng.normal(size=batch + (m, 2)) * 5
        noise = rng.standard_normal(batch + (2 * m * k,))
        z = tracking.measure(p, targets if k > 1 else targets[..., 0, :], sensors, noise)
        z = z if k > 1 else z[..., None, :, :]
        assert z.shape == batch + (k, m, 2)
        for idx in np.ndindex(*batch):
            for t in range(k):
                for i in range(m):
                    dx, dy = (
                        targets[idx + (t, 0)] - sensors[idx + (i, 0)],
                        targets[idx + (t, 1)] - sensors[idx + (i, 1)],
                    )
                    e = noise[idx + (2 * m * t + 2 * i,)], noise[idx + (2 * m * t + 2 * i + 1,)]
                    dist = math.hypot(dx, dy) + math.sqrt(sc.per_sensor("sigma_d2")[i]) * e[0]
                    bearing = math.atan2(dy, dx) - 0.3
                    bearing += math.sqrt(sc.per_sensor("sigma_theta2")[i]) * e[1]
                    bearing = (bearing + math.pi) % (2 * math.pi) - math.pi
                    model = sc.sensor_models[i] if sc.sensor_models is not None else 0
                    want = (
                        dist if model in (0, 1) else 0.0,
                        bearing if model in (0, 2) else 0.0,
                    )
                    np.testing.assert_allclose(z[idx + (t, i)], want, rtol=1e-12, atol=1e-12)


def test_move_target_is_eq_2():
    sc = make_scenario("two_targets")
    p = tracking.LoopParams.from_scenario(sc)
    rng = np.random.default_rng(2)
    for tp in p.targets:
        x, w = rng.normal(size=tp.dim), rng.standard_normal(tp.dim)
        want = [
            sum(tp.Phi[r, c] * x[c] for c in range(tp.dim))
            + sum(tp.noise_factor[r, c] * w[c] for c in range(tp.dim))
            for r in range(tp.dim)
        ]
        np.testing.assert_allclose(tracking.move_target(tp, x, w), want, rtol=1e-12, atol=1e-12)
