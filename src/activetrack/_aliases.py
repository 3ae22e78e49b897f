"""Deprecated module paths of the flat layout (``activetrack.scenarios`` and the like).

The core's modules live in sub-packages named for their concepts (``activetrack.models``,
``activetrack.kinematics``, ``activetrack.estimation``, ``activetrack.solvers``,
``activetrack.world``; see ``docs/architecture.md``). Importing a module by its old flat
path still works and warns with a :class:`DeprecationWarning` naming the new path; the
module you get forwards every attribute to the new module. The aliases go in a later
release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings
from typing import Any

#: Old flat module path -> its module in the concept layout.
MOVED = {
    f"activetrack.{old}": f"activetrack.{new}"
    for old, new in {
        "motion": "models.motion",
        "measurement": "models.measurement",
        "sensor_models": "models.sensor_models",
        "objective": "models.objective",
        "occluders": "models.occluders",
        "occluder_kernels": "models._occluder_kernels",
        "sensor_motion": "kinematics.sensor_motion",
        "motion_kernels": "kinematics._kernels",
        "geometry": "kinematics.geometry",
        "feasible_set": "kinematics.feasible_set",
        "ekf": "estimation.ekf",
        "ekf_kernels": "estimation._kernels",
        "solver": "solvers.analytic",
        "solver_scalar": "solvers._scalar",
        "solver_steps": "solvers._steps",
        "solver_batch": "solvers._batch",
        "solver_inputs": "solvers._inputs",
        "solver_results": "solvers.results",
        "solver_numeric": "solvers.numeric",
        "companion": "solvers.companion",
        "hessenberg_qr": "solvers.hessenberg_qr",
        "_coefficients": "solvers._coefficients",
        "scenarios": "world.scenarios",
        "observation": "world.observation",
        "observation_kernels": "world._observation_kernels",
        "tracking": "world.tracking",
        "loop_kernels": "world._loop_kernels",
        "problem": "world.problem",
    }.items()
}


class _Forward(types.ModuleType):
    """A module that reads and writes its attributes on the module it stands for."""

    def __init__(self, name: str, target: types.ModuleType) -> None:
        super().__init__(name, target.__doc__)
        object.__setattr__(self, "_target", target)

    def __getattr__(self, attr: str) -> Any:
        return getattr(object.__getattribute__(self, "_target"), attr)

    def __setattr__(self, attr: str, value: Any) -> None:
        if attr.startswith("__") and attr.endswith("__"):  # the import system's own
            object.__setattr__(self, attr, value)
        else:
            setattr(object.__getattribute__(self, "_target"), attr, value)

    def __dir__(self) -> list[str]:
        return dir(object.__getattribute__(self, "_target"))


class _Loader(importlib.abc.Loader):
    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        new = MOVED[spec.name]
        warnings.warn(
            f"{spec.name} moved to {new}; the old path goes in a later release",
            DeprecationWarning,
            stacklevel=3,
        )
        return _Forward(spec.name, importlib.import_module(new))

    def exec_module(self, module: types.ModuleType) -> None:
        return None


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname: str, path: Any = None, target: Any = None):
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Loader())


def install() -> None:
    """Put the finder of the old paths on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())
