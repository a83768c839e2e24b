"""Replanner subclasses for tests/test_background.py, in a module the worker process imports
(it gets the parent's sys.path, on which conftest.py puts this directory)."""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

from avp.errors import AvpError, ConfigError
from avp.replan import Replanner


class GatedReplanner(Replanner):
    """Steps only once the file ``gate`` exists (so a test holds the worker busy as long as it
    wants, without timing), and says in the reason which estimate it was given."""

    def __init__(self, *args, gate: str, **kw) -> None:
        super().__init__(*args, **kw)
        self.gate = gate

    def step(self, t, odometry, target_estimate=None):
        if self.trajectory is not None:  # the first plan is not held
            while not Path(self.gate).exists():
                time.sleep(0.005)
        out = super().step(t, odometry, target_estimate)
        got = "none" if target_estimate is None else f"{target_estimate.point[1]:.3f}"
        return dataclasses.replace(out, reason=f"{out.reason} | estimate y {got}")


class Unreadable(Exception):  # noqa: N818 - pickles, but does not unpickle (two arguments)
    def __init__(self, code: int, detail: str) -> None:
        super().__init__(f"{code}: {detail}")


class UnreadableAvpError(AvpError):
    """An AvpError that pickles but does not unpickle (two arguments)."""

    def __init__(self, code: int, detail: str) -> None:
        super().__init__(f"{code}: {detail}")


class FailingReplanner(Replanner):
    """Its first replan fails: ``kind`` "config" raises a ConfigError, "runtime" a RuntimeError,
    "unreadable" an exception that does not unpickle in the parent, "unreadable_avp" such an
    AvpError, "answer" returns a step that does not pickle (after committing its plan here)."""

    def __init__(self, *args, kind: str, **kw) -> None:
        super().__init__(*args, **kw)
        self.kind = kind
        self.seen: list[object] = []

    def step(self, t, odometry, target_estimate=None):
        if self.trajectory is None:
            return super().step(t, odometry, target_estimate)
        self.seen.append(None if target_estimate is None else float(target_estimate.point[1]))
        if len(self.seen) == 1:
            if self.kind == "config":
                raise ConfigError("replanner.kind", "a planned failure")
            if self.kind == "runtime":
                raise RuntimeError("a planned failure")
            if self.kind == "unreadable_avp":
                raise UnreadableAvpError(7, "a planned failure")
            if self.kind == "answer":
                out = super().step(t, odometry, target_estimate)
                return dataclasses.replace(out, reason=lambda: "does not pickle")
            raise Unreadable(7, "a planned failure")
        out = super().step(t, odometry, target_estimate)
        return dataclasses.replace(out, reason=f"{out.reason} | seen {self.seen}")


class FlagsReplanner(Replanner):
    """Says in its steps' reasons the worker's ``sys.flags.optimize``."""

    def step(self, t, odometry, target_estimate=None):
        out = super().step(t, odometry, target_estimate)
        return dataclasses.replace(out, reason=f"optimize={sys.flags.optimize}")
