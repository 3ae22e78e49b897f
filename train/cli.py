"""The training command: ``activetrack train bc|dagger|ppo|rllib-ppo``.

Each method writes ``OUT/policy.zip`` (loadable by ``activetrack evaluate --policy``),
``OUT/config.json`` and TensorBoard logs in ``OUT/tb``; PPO also writes ``model.zip`` and
``checkpoints/``; ``rllib-ppo`` (:mod:`activetrack.train.rllib`, the ``[ray]`` extra, imported
only when that method runs) writes RLlib checkpoints in ``checkpoints/``. Every option's
default is the field default of
:class:`~activetrack.train.imitation.ImitationConfig` (DAgger:
:data:`~activetrack.train.imitation.DAGGER_DEFAULTS`),
:class:`~activetrack.train.ppo.PPOConfig` or :class:`~activetrack.train.networks.NetConfig`:
the parser's defaults are None and only the options given reach the config, which checks
every value. Before training: the configs, ``--threads``, the ``--init`` policy file and
the output folder (one holding results needs ``--overwrite``; one another run is writing
is refused) are checked. The run writes everything, folders included, into the staging
folder ``OUT/.tmp-run-*`` (printed when the run starts: TensorBoard reads its logs there
while it trains) and moves it into place only when it completes; a failed or interrupted
run leaves the previous outputs as they were.
"""

from __future__ import annotations

import argparse
import inspect
from dataclasses import fields
from pathlib import Path
from typing import Any

from activetrack.baselines.cli import add_ray_arguments
from activetrack.baselines.evaluation import check_batched
from activetrack.cli import COMMANDS, add_output_arguments, field_default, seed_int
from activetrack.files import RunOutputs, prepare_output_dir
from activetrack.train import imitation as imitation_module
from activetrack.train.action_targets import TARGETS
from activetrack.train.bench_learn import add_parser as add_bench_learn_parser
from activetrack.train.frames import FRAMES
from activetrack.train.imitation import DAGGER_DEFAULTS, ImitationConfig, train_imitation
from activetrack.train.networks import ACTIVATIONS, NetConfig
from activetrack.train.pathwise_cli import add_pathwise_parser
from activetrack.train.policy_io import VIEWS, load_policy, save_policy
from activetrack.train.ppo import LR_SCHEDULES, OUTPUTS, PPOConfig, check_warm_start, train_ppo
from activetrack.train.selfplay_cli import add_selfplay_parsers
from activetrack.train.set_policy_cli import add_set_policy_parser
from activetrack.train.utils import DEFAULT_THREADS, MAX_THREADS, check_int, configure_torch
from activetrack.world.scenarios import PRESETS

#: CLI option (argparse dest) -> config field, where the names differ.
_RENAMES = {"lr": "learning_rate"}
#: Planners ``train bc|dagger --expert`` can imitate.
EXPERTS = ("gsr", "lookahead")


#: What ``--action-gain none`` parses to (None means "not given").
_LINEAR = "none"


def _action_gain(text: str) -> float | str:
    if text.lower() == _LINEAR:
        return _LINEAR
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number or 'none', got {text!r}") from None


def _help(text: str, cls: type, name: str, default: Any = None) -> str:
    """Return ``text`` with the default of ``cls.name`` (or ``default``) appended."""
    value = field_default(cls, name) if default is None else default
    if isinstance(value, tuple):
        value = " ".join(map(str, value))
    return f"{text} (default {value})".lstrip()


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Add ``train bc|dagger|ppo`` to the ``activetrack`` subparsers ``sub``."""
    p = sub.add_parser(
        "train",
        help=COMMANDS["train"][1],
        description="Train a policy and write OUT/policy.zip, which 'activetrack evaluate "
        "--policy OUT/policy.zip' loads. See the README for commands and budgets.",
    )
    p.set_defaults(parser=p)
    methods = p.add_subparsers(dest="method", metavar="METHOD", required=True)
    signature = inspect.signature(imitation_module.train_imitation).parameters
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--scenario",
        default=signature["scenario"].default,
        choices=sorted(PRESETS),
        help="preset (default %(default)s)",
    )
    common.add_argument(
        "--seed",
        type=seed_int,
        default=signature["seed"].default,
        help="training seed (default %(default)s)",
    )
    add_output_arguments(common, None, required=True)
    common.add_argument(
        "--hidden",
        type=int,
        nargs="+",
        default=None,
        help=_help("MLP hidden sizes", NetConfig, "hidden"),
    )
    common.add_argument(
        "--activation",
        choices=sorted(ACTIVATIONS),
        default=None,
        help=_help("", NetConfig, "activation"),
    )
    common.add_argument(
        "--action-gain",
        type=_action_gain,
        default=None,
        help=_help(
            "saturation gain of the mean action (per sensor, m / max(|m|, 1/K)); "
            "'none' for SB3's linear mean",
            NetConfig,
            "action_gain",
        ),
    )
    common.add_argument(
        "--frame",
        choices=FRAMES,
        default=None,
        help=_help(
            "the network's frame: 'sight' is each agent's line-of-sight frame (rotation-"
            "equivariant; the paper's observation layout)",
            NetConfig,
            "frame",
        ),
    )
    common.add_argument(
        "--threads",
        type=int,
        default=DEFAULT_THREADS,
        help=f"torch threads, 1 to {MAX_THREADS} (default %(default)s)",
    )
    common.add_argument("--no-progress", action="store_true", help="hide the progress bar")

    def imitation(name: str, help_text: str, own: dict[str, Any]) -> None:
        def default(field_name: str) -> Any:
            return own.get(field_name, field_default(ImitationConfig, field_name))

        q = methods.add_parser(name, parents=[common], help=help_text, description=help_text)
        q.add_argument(
            "--episodes",
            type=int,
            default=None,
            help="expert-labelled episodes in total: the label budget "
            f"(default {default('episodes')})",
        )
        q.add_argument(
            "--epochs",
            type=int,
            default=None,
            help=f"passes over the data (per DAgger round) (default {default('epochs')})",
        )
        q.add_argument(
            "--batch-size", type=int, default=None, help=f"(default {default('batch_size')})"
        )
        q.add_argument("--lr", type=float, default=None, help=f"Adam (default {default('lr')})")
        q.add_argument(
            "--weight-decay",
            type=float,
            default=None,
            help=f"Adam (default {default('weight_decay')})",
        )
        if name == "dagger":
            q.add_argument(
                "--iterations",
                type=int,
                default=None,
                help=f"rounds; the episodes are split over them (default {default('iterations')})",
            )
            q.add_argument(
                "--beta",
                type=float,
                default=None,
                help="round i executes the expert with probability beta**i "
                f"(default {default('beta')})",
            )
        q.add_argument(
            "--target",
            choices=TARGETS,
            default=None,
            help="what the network predicts: position, the expert's next position in the "
            "sensor's heading frame over its reach, turned into the command by the "
            "kinematics; or command, the env's action (the same on the paper's disks) "
            f"(default {default('target')})",
        )
        q.add_argument(
            "--expert",
            choices=EXPERTS,
            default="gsr",
            help="the planner to imitate: gsr, or lookahead (the receding-horizon planner "
            "of activetrack.baselines.lookahead) (default %(default)s)",
        )
        q.add_argument(
            "--batched",
            action="store_true",
            help="label all of a round's episodes at once in a batched world (far faster "
            "with --expert lookahead; the labels equal the serial ones to the planner's "
            "tolerance)",
        )
        add_ray_arguments(q, "expert-labelled episodes")
        q.set_defaults(func=run_train, parser=q, method_defaults=own)

    imitation("bc", "behaviour cloning of an expert (--expert)", {"iterations": 1})
    imitation("dagger", "DAgger with an expert's labels (--expert)", DAGGER_DEFAULTS)

    q = methods.add_parser(
        "ppo",
        parents=[common],
        help="PPO (stable-baselines3), from scratch or from --init PATH/policy.zip",
        description="PPO with parameter sharing over the PettingZoo env (default) or on the "
        "centralized Gymnasium view; TensorBoard logs in OUT/tb, checkpoints in "
        "OUT/checkpoints.",
    )

    def ppo(option: str, text: str = "", type_: Any = int, **kw: Any) -> None:
        name = _RENAMES.get(option[2:].replace("-", "_"), option[2:].replace("-", "_"))
        q.add_argument(option, type=type_, default=None, help=_help(text, PPOConfig, name), **kw)

    ppo("--total-timesteps")
    q.add_argument("--init", type=Path, default=None, help="warm start from a policy.zip")
    ppo("--critic-warmup", "timesteps of critic-only training after --init")
    q.add_argument(
        "--log-std-init",
        type=float,
        default=None,
        help="initial log std (default: the network's, "
        f"{field_default(NetConfig, 'log_std_init')}; of --init: unchanged)",
    )
    q.add_argument("--view", choices=VIEWS, default=None, help=_help("", PPOConfig, "view"))
    ppo("--n-copies", "environment copies")
    ppo("--n-steps", "rollout length per slot")
    ppo("--batch-size")
    ppo("--n-epochs")
    ppo("--lr", "learning rate", float)
    q.add_argument(
        "--lr-schedule",
        choices=LR_SCHEDULES,
        default=None,
        help=_help("linear: decay to 0 over the run", PPOConfig, "lr_schedule"),
    )
    ppo("--gamma", "discount, in (0, 1]", float)
    ppo("--gae-lambda", "in [0, 1]", float)
    ppo("--clip-range", "> 0", float)
    ppo("--ent-coef", ">= 0", float)
    q.add_argument(
        "--target-kl", type=float, default=None, help="> 0 (default: none, no early stop)"
    )
    q.add_argument(
        "--no-normalize-reward",
        action="store_true",
        help="train on the raw reward instead of VecNormalize's scaled one",
    )
    ppo("--checkpoint-every", "timesteps (0: none)")
    ppo("--eval-every", "validate the deterministic policy every N timesteps (0: never)")
    ppo("--eval-episodes", "validation episodes")
    q.add_argument(
        "--keep-best", action="store_true", help="save the best validated policy, not the last"
    )
    q.set_defaults(func=run_train, parser=q)
    _add_rllib_parser(methods, common)
    add_selfplay_parsers(methods)  # (the two-team game: activetrack.train.selfplay_cli)
    add_pathwise_parser(methods)  # (gradients through the filter: activetrack.train.pathwise_cli)
    add_set_policy_parser(methods)  # (decentralized teams: activetrack.train.set_policy_cli)
    # `activetrack bench-learn`, a command of its own (BenchMARL: activetrack.train.bench_learn)
    add_bench_learn_parser(sub, COMMANDS["bench-learn"][1])


#: ``train rllib-ppo`` option -> :class:`~activetrack.train.rllib.RLlibPPOConfig` field. The
#: defaults are repeated here only for the help text (the parser's defaults are None, so
#: the config's own defaults apply); a test checks that they agree.
_RLLIB_OPTIONS: dict[str, tuple[str, Any, str]] = {
    "--num-env-runners": ("num_env_runners", int, "Ray actors that sample, >= 0 (0: the driver)"),
    "--envs-per-runner": ("num_envs_per_env_runner", int, "env copies per runner, >= 1"),
    "--train-batch-size": ("train_batch_size", int, "env steps per iteration"),
    "--minibatch-size": ("minibatch_size", int, "agent-steps per SGD minibatch"),
    "--num-epochs": ("num_epochs", int, "SGD passes per iteration"),
    "--lr": ("lr", float, "Adam learning rate, in (0, 1]"),
    "--gamma": ("gamma", float, "discount, in (0, 1]"),
    "--lambda": ("lambda_", float, "GAE lambda, in [0, 1]"),
    "--clip-param": ("clip_param", float, "PPO clip, > 0"),
    "--entropy-coeff": ("entropy_coeff", float, ">= 0"),
    "--reward-scale": ("reward_scale", float, "the env's reward_scale while training, > 0"),
    "--checkpoint-every": ("checkpoint_every", int, "iterations between checkpoints (0: last)"),
}
_RLLIB_DEFAULTS = {
    "num_env_runners": 1,
    "num_envs_per_env_runner": 4,
    "train_batch_size": 2048,
    "minibatch_size": 512,
    "num_epochs": 10,
    "lr": 3e-4,
    "gamma": 0.99,
    "lambda_": 0.95,
    "clip_param": 0.2,
    "entropy_coeff": 0.0,
    "reward_scale": 0.05,
    "checkpoint_every": 10,
}
#: Default of ``train rllib-ppo --iterations``.
RLLIB_ITERATIONS = 10


def _add_rllib_parser(methods: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Add ``train rllib-ppo`` (RLlib PPO with one shared module; needs the [ray] extra)."""
    q = methods.add_parser(
        "rllib-ppo",
        parents=[common],
        help='RLlib PPO on Ray, one policy shared by the sensors (pip install "activetrack[ray]")',
        description="Multi-agent PPO with RLlib (new API stack, torch): every sensor maps to "
        "one shared module, the network of the SB3 path. Runs on a local Ray, or on the "
        "cluster at --address. Writes OUT/policy.zip (for 'activetrack evaluate --policy'), "
        "OUT/config.json, RLlib checkpoints in OUT/checkpoints and TensorBoard logs in OUT/tb.",
    )
    q.add_argument(
        "--iterations",
        metavar="N",
        type=int,
        default=RLLIB_ITERATIONS,
        help="training iterations, >= 1 (default %(default)s)",
    )
    q.add_argument(
        "--address",
        metavar="ADDR",
        default=None,
        help="a running Ray cluster ('auto', HOST:PORT or ray://HOST:PORT; default: start a "
        "local Ray for the run)",
    )
    for option, (name, type_, text) in _RLLIB_OPTIONS.items():
        q.add_argument(
            option,
            dest=f"rllib_{name}",
            metavar="N" if type_ is int else "X",
            type=type_,
            default=None,
            help=f"{text} (default {_RLLIB_DEFAULTS[name]})",
        )
    q.set_defaults(func=run_rllib, parser=q)


def run_rllib(args: argparse.Namespace) -> int:
    """Run ``activetrack train rllib-ppo``; return the exit code.

    Checks the configuration, ``--iterations``, ``--address``, ``--threads`` and the output
    folder before Ray starts. Without Ray installed it prints how to install it (exit 2).
    """
    try:
        from activetrack.train import rllib
    except ImportError as exc:
        args.parser.print_usage()
        print(f"{args.parser.prog}: error: {exc}")
        return 2
    given = {}
    for name, _, _ in _RLLIB_OPTIONS.values():
        value = getattr(args, f"rllib_{name}")
        if value is not None:
            given[name] = value
    cfg = rllib.RLlibPPOConfig(**given, net=_net_config(args))
    iterations = check_int("iterations", args.iterations, 1, rllib.MAX_ITERATIONS)
    threads = check_int("threads", args.threads, 1, MAX_THREADS)
    address = rllib.check_address(args.address)
    with prepare_output_dir(args.out, rllib.OUTPUTS, args.overwrite) as outputs:
        _say_where_logs_are(outputs)
        result = rllib.train_rllib_ppo(
            args.scenario,
            seed=args.seed,
            iterations=iterations,
            config=cfg,
            out_dir=outputs,
            address=address,
            progress=not args.no_progress,
            threads=threads,
        )
    print(
        f"rllib-ppo: {iterations} iterations, {result.env_steps} env steps "
        f"({result.agent_steps} agent-steps), {result.seconds:.1f} s, "
        f"{_last_return(result.history)} -> {result.policy_path}"
    )
    return 0


def _last_return(history: list[dict[str, float]]) -> str:
    """Return the phrase for the last mean episode return of an RLlib run's ``history``
    (RLlib reports one only once an episode has finished)."""
    done = [
        (i, h["episode_return_mean"])
        for i, h in enumerate(history, 1)
        if "episode_return_mean" in h
    ]
    if not done:
        return "no episode finished in training (no mean return)"
    it, ret = done[-1]
    when = "" if it == len(history) else f" at iteration {it}"
    return f"last mean episode return (all sensors, scaled) {ret:.3f}{when}"


def _net_config(args: argparse.Namespace) -> NetConfig:
    kw: dict[str, Any] = {}
    if args.hidden is not None:
        kw["hidden"] = tuple(args.hidden)
    if args.activation is not None:
        kw["activation"] = args.activation
    if args.action_gain is not None:
        kw["action_gain"] = None if args.action_gain == _LINEAR else args.action_gain
    if getattr(args, "log_std_init", None) is not None:
        kw["log_std_init"] = args.log_std_init
    if args.frame is not None:
        kw["frame"] = args.frame
    return NetConfig(**kw)


def _given(args: argparse.Namespace, cls: type, renames: dict[str, str]) -> dict[str, Any]:
    """Return the config fields of ``cls`` that were given on the command line."""
    names = {f.name for f in fields(cls)} - {"net"}
    out = {}
    for key, value in vars(args).items():
        field_name = renames.get(key, key)
        if field_name in names and value is not None:
            out[field_name] = value
    return out


def configs(args: argparse.Namespace) -> tuple[Any, NetConfig]:
    """Return the method's config and the network config of parsed arguments (checked)."""
    net = _net_config(args)
    if args.method in ("bc", "dagger"):
        given = {**args.method_defaults, **_given(args, ImitationConfig, {})}
        if args.method == "bc":
            given["iterations"] = 1
        return ImitationConfig(**given, net=net), net
    if args.method == "ppo":
        given = _given(args, PPOConfig, _RENAMES)
        given.pop("log_std_init", None)  # part of the network config here
        if "critic_warmup" in given and getattr(args, "init", None) is None:
            raise ValueError("--critic-warmup trains the critic of a warm start: give --init")
        if args.no_normalize_reward:
            given["normalize_reward"] = False
        if args.keep_best:
            given["keep_best"] = True
        return PPOConfig(**given, net=net, log_std_init=args.log_std_init), net
    raise ValueError(f"unknown method {args.method!r}")


def run_train(args: argparse.Namespace) -> int:
    """Run ``activetrack train <method>`` from parsed arguments; return the exit code.

    Checks everything first (configs, threads, ``--init``, the output folder), then trains.
    """
    cfg, net = configs(args)
    threads = check_int("threads", args.threads, 1, MAX_THREADS)
    init = getattr(args, "init", None)
    if init is not None:
        check_warm_start(load_policy(init), init)  # a bad file fails now, with its problem
    if args.method in ("bc", "dagger"):
        check_batched(args.batched, args.workers, args.address)  # Ray if asked for
    with prepare_output_dir(args.out, OUTPUTS, args.overwrite) as outputs:
        _say_where_logs_are(outputs)
        configure_torch(threads)
        progress = not args.no_progress
        if args.method in ("bc", "dagger"):
            return _run_imitation(args, cfg, net, outputs, threads, progress)
        result = train_ppo(
            args.scenario,
            seed=args.seed,
            config=cfg,
            out_dir=outputs,
            init=init,
            progress=progress,
            threads=threads,
        )
    best = ""
    if result.validation:
        best = f", validation mean trace {min(t for _, t in result.validation):.4f} (best)"
    print(
        f"ppo: {cfg.total_timesteps} timesteps, {result.seconds:.1f} s{best} -> "
        f"{result.policy_path}"
    )
    return 0


def _say_where_logs_are(outputs: RunOutputs) -> None:
    """Print where the run's TensorBoard logs are while it trains (its staging folder)."""
    print(
        f"TensorBoard logs while training: {outputs.staged('tb/')} (moved to "
        f"{outputs.path('tb/')} with the other outputs when the run completes)",
        flush=True,
    )


def _run_imitation(
    args: argparse.Namespace,
    cfg: ImitationConfig,
    net: NetConfig,
    outputs: RunOutputs,
    threads: int,
    progress: bool,
) -> int:
    from activetrack.world.scenarios import make_scenario

    expert = None
    if args.expert == "lookahead":
        from activetrack.baselines.policies import LookaheadPolicy

        expert = LookaheadPolicy(scenario=args.scenario)
    result = train_imitation(
        args.scenario,
        seed=args.seed,
        config=cfg,
        tensorboard_dir=str(outputs.staged("tb/")),
        progress=progress,
        expert=expert,
        threads=threads,
        workers=args.workers,
        address=args.address,
        batched=args.batched,
    )
    train_config = {
        "algo": args.method,
        "expert": args.expert,
        "batched_labels": args.batched,
        **cfg.to_dict(),
        "labels": len(result.data),
        "final_mse": result.losses,
        "rollout_mean_trace": result.rollout_traces,
        "seconds": result.seconds,
    }
    with outputs:
        save_policy(
            outputs.staged("policy.zip"),
            result.policy,
            net,
            kind=args.method,
            scenario=make_scenario(args.scenario).to_dict(),
            seed=args.seed,
            train_config=train_config,
            head=result.head,
        )
        outputs.write_json(
            "config.json", {"seed": args.seed, "scenario": args.scenario, **train_config}
        )
        path = outputs.commit()["policy.zip"]
    print(
        f"{args.method}: {len(result.data)} expert labels, final MSE {result.losses[-1]:.4f}, "
        f"{result.seconds:.1f} s -> {path}"
    )
    return 0
