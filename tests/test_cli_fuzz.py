"""Fuzzing the command line: every input works or is an argparse-style error, never a traceback.

Each example builds a command line from valid, borderline and absurd option values (tiny
runs: one seed, a few steps), runs ``activetrack.cli.main`` in-process and accepts exactly
two outcomes: exit status 0, or status 2 with the last line of stderr
``activetrack <command>: error: <message>``. Any other exception (from numpy, torch,
zipfile...) fails the test. Training itself is replaced by a stub once every check has
passed (the checks are what is fuzzed; training has its own tests).
"""

from __future__ import annotations

import contextlib
import io
import re
import tempfile
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from activetrack.cli import main

NUMBERS = st.sampled_from(
    ["0", "1", "2", "3", "-1", "0.5", "2.5", "1e-300", "1e308", "-1e308", "nan", "inf", "-inf"]
    + ["99999999999999999999", "x", "", "1e3", "0x10"]
)
#: ``--workers`` values that never start Ray (1: serial) or are rejected before it starts.
WORKERS = st.sampled_from(["1", "0", "-1", "x", "1.5", "nan", "", "99999999999999999999"])
ERROR = re.compile(r"^activetrack [a-z]+( [a-z]+)?: error: .+")
SETTINGS = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def run(argv: list[str]) -> tuple[int, str]:
    """Return the exit status and stderr of ``activetrack argv``."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


def check(argv: list[str], code: int, err: str) -> None:
    assert code in (0, 2), (argv, code, err)
    if code == 2:
        last = err.strip().splitlines()[-1] if err.strip() else ""
        assert ERROR.match(last), (argv, err)


def options(pairs: dict[str, st.SearchStrategy]) -> st.SearchStrategy:
    """Return flat argument lists with any subset of the options, each with a drawn value."""
    items = sorted(pairs.items())
    return st.lists(st.sampled_from(items), unique_by=lambda kv: kv[0], max_size=5).flatmap(
        lambda chosen: (
            st.tuples(*[st.tuples(st.just(k), v) for k, v in chosen]).map(
                lambda kvs: [x for k, v in kvs for x in (k, *([v] if isinstance(v, str) else v))]
            )
            if chosen
            else st.just([])
        )
    )


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    (root / "a_file").write_text("")
    (root / "random.zip").write_bytes(bytes(range(256)) * 4)
    (root / "truncated.zip").write_bytes(b"PK\x03\x04" + bytes(30))
    return root


def out_choices(root: Path) -> st.SearchStrategy:
    fresh = st.builds(lambda: tempfile.mkdtemp(dir=root))
    return st.one_of(fresh, st.sampled_from(["/proc/x", str(root / "a_file"), str(root)]))


def test_simulate_fuzz(folders):
    strategy = st.tuples(
        options(
            {
                "--planner": st.sampled_from(["gsr", "gsr-restarts", "gbes", "rm", "nope"]),
                "--gsr-tol": NUMBERS,
                "--gsr-max-sweeps": NUMBERS,
                "--gbes-spacing": st.sampled_from(["0.05", "0.2", "0", "-1", "nan", "inf", "x"]),
                "--seed": NUMBERS,
                "--steps": st.sampled_from(["1", "2", "0", "-1", "x", "1.5"]),
                "--scenario": st.sampled_from(["paper", "homogeneous", "nope"]),
                "--workers": WORKERS,
                "--address": st.just(""),
            }
        ),
        out_choices(folders),
        st.booleans(),
    )

    @SETTINGS
    @given(strategy)
    def inner(drawn):
        opts, out, overwrite = drawn
        if "--steps" not in opts:
            opts = [*opts, "--steps", "2"]
        argv = ["simulate", "--runs", "1", "--no-plot", "--no-progress", "--out", out, *opts]
        argv += ["--overwrite"] if overwrite else []
        code, err = run(argv)
        check(argv, code, err)
        seen.add(code)

    seen: set[int] = set()
    inner()
    assert seen == {0, 2}  # both runs and errors were exercised


def test_evaluate_fuzz(folders):
    policies = st.lists(
        st.sampled_from(
            ["gsr", "rm", "nope", str(folders / "random.zip"), str(folders / "truncated.zip")]
            + [str(folders), str(folders / "missing.zip")]
        ),
        min_size=1,
        max_size=3,
    )
    strategy = st.tuples(
        policies,
        options(
            {
                "--episodes": st.sampled_from(["1", "0", "-1", "x"]),
                "--seed": NUMBERS,
                "--scenario": st.sampled_from(["paper", "homogeneous", "nope"]),
                "--out": out_choices(folders),
                "--workers": WORKERS,
                "--address": st.just(""),
                "--loss-trace": NUMBERS,
                "--pool": st.sampled_from(["a=gsr", "a=gsr,rm", "gsr=rm", "x", "a=", "=gsr"]),
            }
        ),
        st.booleans(),
    )

    @SETTINGS
    @given(strategy)
    def inner(drawn):
        chosen, opts, no_plot = drawn
        argv = ["evaluate", "--no-progress", *[x for p in chosen for x in ("--policy", p)]]
        if "--episodes" not in opts:
            opts = [*opts, "--episodes", "1"]
        argv += [*opts, *(["--no-plot"] if no_plot else []), "--overwrite"]
        code, err = run(argv)
        check(argv, code, err)
        seen.add(code)

    seen: set[int] = set()
    inner()
    assert seen == {0, 2}  # both runs and errors were exercised


class Reached(Exception):
    """Training was reached: every check passed."""


def test_train_fuzz(folders):
    pytest.importorskip("torch")
    import activetrack.train.cli as tcli

    common = {
        "--hidden": st.lists(NUMBERS, min_size=1, max_size=3),
        "--activation": st.sampled_from(["tanh", "relu", "elu", "sigmoid"]),
        "--action-gain": st.one_of(NUMBERS, st.just("none")),
        "--threads": NUMBERS,
        "--seed": NUMBERS,
    }
    imitation = {
        **common,
        "--episodes": NUMBERS,
        "--epochs": NUMBERS,
        "--batch-size": NUMBERS,
        "--lr": NUMBERS,
        "--weight-decay": NUMBERS,
        "--workers": NUMBERS,  # training is stubbed: no Ray starts
        "--address": st.sampled_from(["", "auto", "127.0.0.1:1"]),
    }
    dagger = {**imitation, "--iterations": NUMBERS, "--beta": NUMBERS}
    ppo = {
        **common,
        **{
            o: NUMBERS
            for o in (
                "--total-timesteps --n-copies --n-steps --batch-size --n-epochs --lr --gamma "
                "--gae-lambda --clip-range --ent-coef --target-kl --critic-warmup "
                "--checkpoint-every --eval-every --eval-episodes --log-std-init"
            ).split()
        },
        "--view": st.sampled_from(["shared", "centralized", "both"]),
        "--lr-schedule": st.sampled_from(["constant", "linear", "cosine"]),
        "--init": st.sampled_from([str(folders / "random.zip"), str(folders / "missing.zip")]),
    }
    strategy = st.one_of(
        *[
            st.tuples(st.just(method), options(pairs), out_choices(folders))
            for method, pairs in (("bc", imitation), ("dagger", dagger), ("ppo", ppo))
        ]
    )

    def reached(*args, **kwargs):
        raise Reached

    @SETTINGS
    @given(strategy)
    def inner(drawn):
        method, opts, out = drawn
        argv = ["train", method, "--no-progress", "--overwrite", "--out", out, *opts]
        try:
            code, err = run(argv)
        except Reached:
            seen.add("reached")
            return
        check(argv, code, err)
        assert code == 2, argv  # a stubbed training never returns 0
        seen.add(code)

    seen: set[object] = set()
    with (
        mock.patch.object(tcli, "train_imitation", reached),
        mock.patch.object(tcli, "train_ppo", reached),
        mock.patch.object(tcli, "configure_torch", lambda n: n),
    ):
        inner()
    assert seen == {"reached", 2}


def test_config_fuzz():
    """Any value of any field: the config is built, or a ValueError/TypeError names the field."""
    pytest.importorskip("torch")
    from dataclasses import fields

    from activetrack.train import ImitationConfig, NetConfig, PPOConfig

    values = st.one_of(
        st.integers(-(2**70), 2**70),
        st.floats(allow_nan=True, allow_infinity=True),
        st.booleans(),
        st.none(),
        st.text(max_size=5),
        st.lists(st.integers(-3, 5000), max_size=10),
        st.sampled_from(["tanh", "shared", "linear", "batched", (16, 16)]),
    )
    classes = [ImitationConfig, NetConfig, PPOConfig]
    strategy = st.sampled_from(classes).flatmap(
        lambda cls: st.tuples(st.just(cls), st.sampled_from([f.name for f in fields(cls)]), values)
    )

    @settings(SETTINGS, max_examples=400)
    @given(strategy)
    def inner(drawn):
        cls, name, value = drawn
        try:
            cls(**{name: value})
        except (ValueError, TypeError) as exc:
            assert name in str(exc), (cls.__name__, name, value, str(exc))

    inner()
