"""QP back-ends (avp.solve): the one table of back-end facts drives warm starts and iteration caps,
and a missing back-end is a typed SolverError."""

from __future__ import annotations

import dataclasses

import pytest
from scenarios import standard

import avp
from avp import perception, solve
from avp.config import PlannerConfig


def test_backend_table_drives_warm_starts_and_the_fov_iteration_cap() -> None:
    for name, b in solve.BACKENDS.items():
        cfg = dataclasses.replace(PlannerConfig(), solver=name)
        capped = dict(perception._fov_config(cfg).solver_options)
        assert ("max_iter" in capped) == b.iterative, name
        assert (name in solve.WARM_START_SOLVERS) == b.warm_start
        assert solve.SOLVER_DEFAULTS.get(name, {}) == dict(b.defaults)
    assert solve.backend("no-such-backend") == solve.Backend("no-such-backend")
    assert not solve.backend("daqp").warm_start and not solve.backend("daqp").iterative
    assert solve.backend("osqp").max_iter == 200_000


def test_unknown_solver_is_a_solver_error() -> None:
    sc = standard(90, 3.5)
    with pytest.raises(avp.SolverError, match="not installed"):
        avp.plan(sc.state, sc.target, avp.PlannerConfig(solver="no_such_solver"))
