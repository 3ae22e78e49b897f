"""The policy network (saturated mean) and the single-file policy format."""

from __future__ import annotations

import io
import json
import struct
import subprocess
import sys
import zipfile
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import torch
from gymnasium import spaces

from activetrack.envs import CentralizedTrackingEnv, parallel_env
from activetrack.train.networks import NetConfig, build_policy, mean_action, saturate
from activetrack.train.policy_io import load_policy, save_policy

OBS = spaces.Box(-np.inf, np.inf, (23,), np.float32)
ACT = spaces.Box(-1.0, 1.0, (2,), np.float32)


def test_saturate_is_unit_outside_the_small_ball():
    m = torch.tensor([[3.0, 4.0, 0.001, 0.0], [0.0, -0.5, 0.0, 0.0]])
    s = saturate(m, gain=100.0)
    expect = torch.tensor([[0.6, 0.8, 0.1, 0.0], [0.0, -1.0, 0.0, 0.0]])
    torch.testing.assert_close(s, expect)


@pytest.mark.parametrize("gain", [100.0, None])
def test_deterministic_action_is_the_mean(gain):
    torch.manual_seed(0)
    policy = build_policy(OBS, ACT, NetConfig(hidden=(16, 16), action_gain=gain))
    obs = np.random.default_rng(0).normal(size=(5, 23)).astype(np.float32)
    with torch.no_grad():
        mean = mean_action(policy, torch.as_tensor(obs)).numpy()
        dist_mean = policy.get_distribution(torch.as_tensor(obs)).distribution.mean.numpy()
    np.testing.assert_allclose(mean, dist_mean, rtol=1e-6)
    act, _ = policy.predict(obs, deterministic=True)
    np.testing.assert_allclose(act, np.clip(mean, -1, 1), rtol=1e-6)
    if gain is not None:
        with torch.no_grad():  # the raw linear head, before saturation
            raw = policy.action_net(policy.mlp_extractor.forward_actor(torch.as_tensor(obs)))
        raw_norm = np.linalg.norm(raw.numpy(), axis=1)
        np.testing.assert_allclose(
            np.linalg.norm(act, axis=1), np.minimum(gain * raw_norm, 1), rtol=1e-5
        )


def test_save_load_round_trip(tmp_path):
    torch.manual_seed(1)
    net = NetConfig(hidden=(32, 16), activation="relu", action_gain=None, log_std_init=-0.7)
    policy = build_policy(OBS, ACT, net)
    path = save_policy(
        tmp_path / "sub" / "policy.zip",
        policy,
        net,
        kind="bc",
        scenario={"name": "paper"},
        seed=7,
        train_config={"episodes": 3},
    )
    assert zipfile.ZipFile(path).namelist() == ["meta.json", "policy.pth"]

    def no_constants(name):
        raise AssertionError(f"meta.json holds {name}: not standard JSON")

    meta = json.loads(zipfile.ZipFile(path).read("meta.json"), parse_constant=no_constants)
    assert None in meta["observation_space"]["low"]  # an infinite bound is null
    loaded = load_policy(path)
    assert loaded.policy.observation_space == policy.observation_space
    assert loaded.meta["seed"] == 7 and loaded.meta["kind"] == "bc"
    assert loaded.meta["train_config"] == {"episodes": 3}
    assert NetConfig.from_dict(loaded.meta["net"]) == net
    for (k, a), (k2, b) in zip(
        policy.state_dict().items(), loaded.policy.state_dict().items(), strict=True
    ):
        assert k == k2 and torch.equal(a, b)
    obs = np.random.default_rng(0).normal(size=(4, 23)).astype(np.float32)
    np.testing.assert_array_equal(loaded.predict(obs), policy.predict(obs, deterministic=True)[0])
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as zf:
        zf.writestr("meta.json", '{"format": "other"}')
    with pytest.raises(ValueError, match="not an activetrack policy"):
        load_policy(bad)


def test_act_uses_the_env_observations(tmp_path):
    env = parallel_env("paper")
    obs, _ = env.reset(seed=4)
    for _ in range(3):
        np.testing.assert_array_equal(
            np.stack(list(env.observe().values())), np.stack(list(obs.values()))
        )
        obs, *_ = env.step({a: np.array([0.2, 0.9]) for a in env.agents})
    torch.manual_seed(0)
    net = NetConfig(hidden=(8,))
    policy = build_policy(OBS, ACT, net)
    learned = load_policy(
        save_policy(tmp_path / "p.zip", policy, net, kind="bc", scenario={}, seed=0)
    )
    actions = learned.act(obs)
    assert list(actions) == env.agents
    np.testing.assert_array_equal(
        np.stack(list(actions.values())), learned.predict(np.stack(list(obs.values())))
    )


def test_centralized_view_act_concatenates(tmp_path):
    cenv = CentralizedTrackingEnv("paper")
    penv = parallel_env("paper")
    torch.manual_seed(0)
    net = NetConfig(hidden=(8,))
    policy = build_policy(cenv.observation_space, cenv.action_space, net)
    learned = load_policy(
        save_policy(
            tmp_path / "c.zip", policy, net, kind="ppo", scenario={}, seed=0, view="centralized"
        )
    )
    cobs, _ = cenv.reset(seed=9)
    pobs, _ = penv.reset(seed=9)
    joint = policy.predict(cobs, deterministic=True)[0]
    per_agent = learned.act(pobs)
    np.testing.assert_allclose(np.concatenate(list(per_agent.values())), joint, rtol=1e-6)


# Bad policy files: each one a ValueError "<path>: <problem>", before any big allocation. ---
@pytest.fixture(scope="module")
def good_file(tmp_path_factory):
    torch.manual_seed(0)
    net = NetConfig(hidden=(16, 16))
    path = tmp_path_factory.mktemp("good") / "policy.zip"
    save_policy(path, build_policy(OBS, ACT, net), net, kind="bc", scenario={}, seed=0)
    with zipfile.ZipFile(path) as zf:
        members = {name: zf.read(name) for name in zf.namelist()}
    return path, members


def write_zip(path, members):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


def with_meta(members, **changes):
    meta = json.loads(members["meta.json"])
    for dotted, value in changes.items():
        *parents, last = dotted.split("__")
        d = meta
        for key in parents:
            d = d[key]
        d[last] = value
    return {**members, "meta.json": json.dumps(meta)}


def bad_files(good_path, members, folder):
    """Return (name, path, expected message) of broken variants of a good policy file."""
    raw = good_path.read_bytes()
    state = torch.load(io.BytesIO(members["policy.pth"]), weights_only=True)
    nan_state = {k: v.clone() for k, v in state.items()}
    nan_state["action_net.bias"][0] = float("nan")
    nan_buf = io.BytesIO()
    torch.save(nan_state, nan_buf)
    tiny_std = {k: v.clone() for k, v in state.items()}
    tiny_std["log_std"][:] = -200.0  # finite, but exp(-200) is 0 in float32
    sparse = {**state, "action_net.weight": state["action_net.weight"].to_sparse()}
    on_meta = {**state, "action_net.weight": state["action_net.weight"].to("meta")}
    huge_low = json.loads(members["meta.json"])["observation_space"]["low"]
    huge_low[0] = 10**400  # valid JSON, too large for any float
    wide = build_policy(OBS, ACT, NetConfig(hidden=(32, 16)))
    wide_buf = io.BytesIO()
    torch.save(wide.state_dict(), wide_buf)
    cases = {
        "truncated": (raw[: len(raw) // 2], "not a readable zip file"),
        "random bytes": (np.random.default_rng(0).bytes(5000), "not a readable zip file"),
        "empty": (b"", "not a readable zip file"),
        "bad deflate": (_bad_deflate(members), "member 'policy.pth' is corrupt"),
        "missing member": ({"meta.json": members["meta.json"]}, "missing member 'policy.pth'"),
        "no meta": ({"policy.pth": members["policy.pth"]}, "missing member 'meta.json'"),
        "meta not json": ({**members, "meta.json": b"{nope"}, "not valid JSON"),
        "meta a list": ({**members, "meta.json": b"[1, 2]"}, "must hold a JSON object"),
        "hidden a string": (with_meta(members, net__hidden="16"), "hidden"),
        "hidden floats": (with_meta(members, net__hidden=[16.5, 16]), "hidden"),
        "huge hidden": (with_meta(members, net__hidden=[20000, 20000]), "hidden"),
        "too many parameters": (with_meta(members, net__hidden=[4096] * 8), "parameters"),
        "unknown net field": (with_meta(members, net__width=3), "unknown network"),
        "net a list": (with_meta(members, net=[16, 16]), "net"),
        "bad activation": (with_meta(members, net__activation=3), "activation"),
        "zero gain": (with_meta(members, net__action_gain=0), "action_gain"),
        "shape a string": (with_meta(members, observation_space__shape="23"), "shape"),
        "huge shape": (with_meta(members, observation_space__shape=[10**9]), "shape"),
        "low strings": (with_meta(members, observation_space__low=["a"] * 23), "low"),
        "low too short": (with_meta(members, action_space__low=[0.0]), "low"),
        "low too large": (
            with_meta(members, observation_space__low=huge_low),
            "low is out of range",
        ),
        "bad dtype": (with_meta(members, action_space__dtype="int8"), "dtype"),
        "bad view": (with_meta(members, view=3), "view"),
        "scenario a list": (with_meta(members, scenario=[1]), "scenario"),
        "pth garbage": ({**members, "policy.pth": b"not a pickle"}, "not a torch state dict"),
        "pth other net": ({**members, "policy.pth": wide_buf.getvalue()}, "has shape"),
        "pth a list": ({**members, "policy.pth": _saved([1, 2])}, "must hold a state dict"),
        "pth nan": ({**members, "policy.pth": nan_buf.getvalue()}, "NaN"),
        "pth log_std": ({**members, "policy.pth": _saved(tiny_std)}, "log_std must be in"),
        "pth sparse": ({**members, "policy.pth": _saved(sparse)}, "must be a dense CPU tensor"),
        "pth meta": ({**members, "policy.pth": _saved(on_meta)}, "must be a dense CPU tensor"),
        "pth a class": ({**members, "policy.pth": _saved(Fraction(1, 3))}, "Unsupported global"),
        # A zip bomb: 50 MB of zeros declared for a 1000-parameter network.
        "pth too large": ({**members, "policy.pth": bytes(50_000_000)}, "bytes, more than"),
    }
    out = []
    for i, (name, (content, message)) in enumerate(cases.items()):
        path = folder / f"bad{i}.zip"
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            write_zip(path, content)
        out.append((name, path, message))
    return out


def _bad_deflate(members):
    """Return a zip whose policy.pth deflate stream starts with a reserved block type."""
    buf = io.BytesIO()
    write_zip(buf, members)
    raw = bytearray(buf.getvalue())
    with zipfile.ZipFile(io.BytesIO(bytes(raw))) as zf:
        info = zf.getinfo("policy.pth")
    # Local header: 30 bytes, then the name and the extra field (sizes at 26 and 28).
    h = info.header_offset
    name_len, extra_len = struct.unpack("<HH", raw[h + 26 : h + 30])
    start = h + 30 + name_len + extra_len
    raw[start] = 0b111  # BFINAL=1, BTYPE=11: reserved, an invalid block for zlib
    return bytes(raw)


def _saved(obj):
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def test_bad_policy_files_give_a_clean_error(good_file, tmp_path):
    path, members = good_file
    assert load_policy(path).meta["net"]["hidden"] == [16, 16]  # the variants' source is good
    for name, bad, message in bad_files(path, members, tmp_path):
        with pytest.raises(ValueError) as err:
            load_policy(bad)
        text = str(err.value)
        assert text.startswith(f"{bad}: "), (name, text)
        assert message in text, (name, text)
        assert "\n" not in text and "weights_only" not in text, (name, text)
    with pytest.raises(ValueError, match="no such file"):
        load_policy(tmp_path / "missing.zip")
    with pytest.raises(ValueError, match="no such file"):
        load_policy(tmp_path)  # a folder


def test_bad_policy_files_allocate_nothing_big(good_file, tmp_path):
    """Under an address-space limit of the current size + 300 MB, every bad file still gives
    its ValueError: nothing is allocated for the sizes a file merely declares."""
    path, members = good_file
    cases = bad_files(path, members, tmp_path)
    code = f"""
import resource, sys
from activetrack.train.policy_io import load_policy
vm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmSize"))
resource.setrlimit(resource.RLIMIT_AS, (vm * 1024 + 300 * 2**20, resource.RLIM_INFINITY))
for name, path, message in {[(n, str(p), m) for n, p, m in cases]!r}:
    try:
        load_policy(path)
    except ValueError as exc:
        assert message in str(exc), (name, str(exc))
    else:
        raise AssertionError(name)
print("ok")
"""
    if not Path("/proc/self/status").exists():
        pytest.skip("needs /proc")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr[-2000:]


def test_state_shapes_are_computed_without_building(good_file):
    """The shapes checked before building equal those of the network built."""
    for net, obs, act in [
        (NetConfig(hidden=(16, 16)), 23, 2),
        (NetConfig(hidden=(7,), activation="relu", action_gain=None), 5, 3),
        (NetConfig(hidden=()), 9, 4),
        (NetConfig(hidden=(3, 4, 5)), 69, 6),
    ]:
        o = spaces.Box(-np.inf, np.inf, (obs,), np.float32)
        a = spaces.Box(-1.0, 1.0, (act,), np.float32)
        built = {k: tuple(v.shape) for k, v in build_policy(o, a, net).state_dict().items()}
        assert net.expected_state_shapes(obs, act) == built


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"hidden": (0,)}, "hidden"),
        ({"hidden": (5000,)}, "hidden"),
        ({"hidden": (8,) * 9}, "hidden"),
        ({"hidden": "16"}, "hidden"),
        ({"activation": "sigmoid"}, "activation"),
        ({"log_std_init": float("nan")}, "log_std_init"),
        ({"action_gain": 0.0}, "action_gain"),
        ({"action_gain": -5}, "action_gain"),
        ({"action_gain": float("inf")}, "action_gain"),
        ({"ortho_init": "yes"}, "ortho_init"),
    ],
)
def test_net_config_validates_every_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        NetConfig(**kwargs)


def test_net_config_converts_types():
    net = NetConfig(hidden=[np.int64(8), 4.0], action_gain=np.float32(50), log_std_init=-1)
    assert net.hidden == (8, 4) and all(type(h) is int for h in net.hidden)
    assert type(net.action_gain) is float and type(net.log_std_init) is float
    assert NetConfig.from_dict(net.to_dict()) == net
