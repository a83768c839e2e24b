"""Time allocation: the initial segment durations of a plan (rule in
:class:`~avp.config.TimeAllocation`) and validation of user-given durations."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _validate as v
from ._typing import Array
from .config import PlannerConfig
from .errors import ConfigError
from .types import PerchTarget, State


def initial_durations(state: State, target: PerchTarget, config: PlannerConfig) -> Array:
    """Equal segments summing to ``config.time_allocation.total(distance, speed)``."""
    distance = float(np.linalg.norm(target.point - state.position))
    speed = float(np.linalg.norm(state.velocity))
    total = config.time_allocation.total(distance, speed)
    return np.full(config.n_segments, total / config.n_segments)


def check_durations(durations: Any, config: PlannerConfig) -> Array:
    """User-given durations as a float array of length ``n_segments``, all finite and > 0."""
    if v.holds_booleans(durations):
        raise ConfigError("durations", f"expected {config.n_segments} numbers (s), got booleans {durations!r}")
    shape = np.shape(durations if isinstance(durations, np.ndarray) else np.asarray(durations, dtype=object))
    if len(shape) > 1:
        raise ConfigError("durations", f"expected a flat sequence of {config.n_segments} numbers, got shape {shape}")
    T = v.float_array("durations", durations, f"{config.n_segments} numbers").reshape(-1)
    if T.shape != (config.n_segments,):
        raise ConfigError("durations", f"expected {config.n_segments} values (config.n_segments), got {T.size}")
    if not np.isfinite(T).all() or (T <= 0.0).any():
        raise ConfigError("durations", f"every segment duration must be finite and > 0 s, got {T.tolist()}")
    v.within("durations", T, "duration")
    return T
