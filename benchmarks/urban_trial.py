"""A trial urban layout for the limited-sensing work (issue 13; not yet a named task).

Five 4 m blocks around the paper's target slowed to 5 m/s, four range-and-bearing sensors
(1 m^2, 0.05 rad^2) starting around (8, 0), ``max_range=20``, ``p_detect=0.9``; GSR and
random motion over 30 episodes from seed 1000, with the fraction of steps without a
measurement and the mean NEES. Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/urban_trial.py    # about 2 minutes
"""

from __future__ import annotations

from activetrack.baselines.evaluation import evaluate, format_table

LAYOUT = dict(
    n_sensors=4, target_init="gaussian", P0=(4.0, 4.0, 25.0, 25.0), sigma_d2=1.0,
    sigma_theta2=0.05, x0=(0.0, 0.0, -4.0, 3.0), x0_hat=(0.0, 0.0, -4.0, 3.0),
    max_range=20.0, p_detect=0.9, sensor_center=(8.0, 0.0), sensor_radius=4.0,
    occluders=[
        [(3.0, -8.0), (6.0, -8.0), (6.0, -4.5), (3.0, -4.5)],
        [(2.0, 4.5), (6.0, 4.5), (6.0, 8.0), (2.0, 8.0)],
        [(-9.0, 2.0), (-5.0, 2.0), (-5.0, 5.5), (-9.0, 5.5)],
        [(-16.0, 6.0), (-12.0, 6.0), (-12.0, 10.0), (-16.0, 10.0)],
        [(-10.0, 12.0), (-6.0, 12.0), (-6.0, 16.0), (-10.0, 16.0)],
    ],
)  # fmt: skip


def main() -> None:
    """Print GSR and RM on the trial layout."""
    rows = evaluate(["gsr", "rm"], "paper", episodes=30, seed=1000, progress=False, **LAYOUT)
    print(format_table([r.summary(rows[0]) for r in rows]))


if __name__ == "__main__":
    main()
