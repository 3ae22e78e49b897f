"""The world: the closed tracking loop, batched over copies (``World``), the
scenarios it runs, one step's kernels, the observation and the planning problem.
"""

from activetrack.world._sizes import WORLD_BYTES_MAX, world_bytes
from activetrack.world.world import DEFAULT_NOISE_BLOCK, StepResult, World

__all__ = ["DEFAULT_NOISE_BLOCK", "WORLD_BYTES_MAX", "StepResult", "World", "world_bytes"]
