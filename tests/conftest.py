"""Project-wide test settings: no test can reach a real model API, and rendering is headless."""

from __future__ import annotations

import copy
import os
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest

# Set before anything imports MuJoCo, pyrender or the Anthropic client.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault(
    "MENAGERIE_ROOT", str(Path(__file__).resolve().parents[2] / "shared" / "menagerie")
)
os.environ["RIVET_FORBID_MODEL_API"] = "1"
# A developer's real credentials never reach a test (and `--sandbox local` refuses to run
# beside them: `rivet.commands._options.CREDENTIAL_VARIABLES`).
for _name in ("ANTHROPIC_API_KEY", "ANTHROPIC_AUTH_TOKEN", "OPENAI_API_KEY"):
    os.environ.pop(_name, None)

# [bytes] of drawn check cases a test process keeps (a perceive drawing is about 1 GB)
KEPT_BYTES = 1.5e9


def _frozen_copy(value):
    """`value`'s dicts and lists copied, its arrays shared and made read-only: a check that
    wrote into a kept drawing's image would raise instead of changing the next test's case."""
    if isinstance(value, dict):
        return {k: _frozen_copy(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_frozen_copy(v) for v in value]
    if isinstance(value, tuple):
        return tuple(_frozen_copy(v) for v in value)
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
        return value
    return copy.deepcopy(value)


def _nbytes(value) -> int:
    if isinstance(value, dict):
        return sum(_nbytes(v) for v in value.values())
    if isinstance(value, list | tuple):
        return sum(_nbytes(v) for v in value)
    return value.nbytes if isinstance(value, np.ndarray) else 0


@pytest.fixture(scope="session", autouse=True)
def _drawn_cases_kept():
    """The check cases `checks.run` draws, kept per test process and handed out as copies.

    `build_cases` is a pure function of its domain, function, budget and case seed (tests/
    checks/test_fresh_cases.py calls it directly and says so), and the tests draw from a few
    fixed seeds, so a drawing that took seconds of rendering is made once per process. Each
    caller gets its own copy of the containers (the checks write into their cases:
    `_relate_states`); the images are shared, read-only."""
    import checks.run

    drawn = checks.run.build_cases
    kept: OrderedDict[tuple, tuple[dict, int]] = OrderedDict()

    def build_cases(domain, function, budget, seed):
        key = (id(domain), domain.name, function, repr(budget), int(seed))
        if key not in kept:
            cases = drawn(domain, function, budget, seed)
            kept[key] = (_frozen_copy(cases), _nbytes(cases))
            while len(kept) > 1 and sum(n for _, n in kept.values()) > KEPT_BYTES:
                kept.popitem(last=False)
        kept.move_to_end(key)
        return _frozen_copy(kept[key][0])

    checks.run.build_cases = build_cases
    yield
    checks.run.build_cases = drawn


# The tests that each take minutes (the three authoring replays): `--dist loadfile` would keep
# them in one unit, which `pytest-xdist` sends out last (it starts the files with the most
# tests first), and one core would replay alone at the end. Each is a unit of its own, sent
# first.
LONGEST = ("tests/agent/test_author_replay.py::test_replayed_authoring_",)


@pytest.hookimpl(optionalhook=True)  # pytest-xdist's hook: absent under `-p no:xdist`
def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class LongestFirst(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return nodeid if nodeid.startswith(LONGEST) else super()._split_scope(nodeid)

        def _assign_work_unit(self, node) -> None:
            for scope in [s for s in reversed(self.workqueue) if s.startswith(LONGEST)]:
                self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

    return LongestFirst(config, log)
