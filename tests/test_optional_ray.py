"""Ray is optional: the core, envs and baselines import and run without it.

A fresh interpreter hides Ray with a meta-path finder that refuses ``ray`` (as if it were
not installed), imports the layers and their command modules, runs a serial study, and
asks for workers, which must fail with the error that names the extra.
"""

from __future__ import annotations

import json
import subprocess
import sys

BLOCK_RAY = """
import sys

class NoRay:
    def find_spec(self, name, path=None, target=None):
        if name == "ray" or name.startswith("ray."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, NoRay())
"""

PROBE = """
import json
import activetrack, activetrack.envs, activetrack.baselines
import activetrack.baselines.cli, activetrack.baselines.distributed
from activetrack import make_scenario
from activetrack.baselines import GSR, run_monte_carlo
from activetrack.baselines.distributed import RayNotInstalledError, check_options

res = run_monte_carlo(make_scenario("paper", n_steps=3), {"gsr": GSR()}, 2, progress=False)
errors = []
for kw in ({"workers": 2}, {"address": "auto"}):
    try:
        check_options(**kw)
    except RayNotInstalledError as exc:
        errors.append([str(exc), isinstance(exc, ImportError), isinstance(exc, ValueError)])
print(json.dumps({"ray_loaded": "ray" in sys.modules, "runs": len(res["gsr"].seeds),
                  "errors": errors}))
"""


def _run(code: str, tmp_path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", BLOCK_RAY + code], capture_output=True, text=True, cwd=tmp_path
    )


def test_layers_import_and_run_serially_without_ray(tmp_path):
    out = _run(PROBE, tmp_path)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["ray_loaded"] is False and got["runs"] == 2
    assert len(got["errors"]) == 2
    for message, is_import_error, is_value_error in got["errors"]:
        assert 'pip install "activetrack[ray]"' in message
        assert is_import_error and is_value_error
    assert "workers=2 runs on Ray" in got["errors"][0][0]


def test_the_blocker_hides_ray(tmp_path):
    # The probe is only meaningful if the finder does hide an installed Ray.
    out = _run("import ray", tmp_path)
    assert out.returncode != 0 and "No module named 'ray'" in out.stderr


def test_simulate_with_workers_without_ray_names_the_extra(tmp_path):
    code = (
        "from activetrack.cli import main\n"
        f"raise SystemExit(main(['simulate', '--workers', '2', '--out', {str(tmp_path / 'o')!r}]))"
    )
    out = _run(code, tmp_path)
    assert out.returncode == 2
    assert 'workers=2 runs on Ray, which is not installed: pip install "activetrack[ray]"' in (
        out.stderr
    )
    assert not (tmp_path / "o").exists()
