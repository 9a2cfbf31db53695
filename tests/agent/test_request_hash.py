"""A request's hash: what strict replay matches a recorded response by."""

from types import SimpleNamespace

from agent.clients.base import ModelRequest, TextBlock
from checks.context import check_fast_enough
from checks.report import build_report, report_markdown
from checks.timing import CallTiming, TimingLog


def _slow_report(times: list[float], *, budget: float = 0.6, wall: float = 0.0) -> str:
    """The feedback Markdown of a draft that fails `interface.fast_enough` (the real check):
    CPU times `times`, or, with `wall`, little CPU and `wall` more seconds of wall time."""
    cases = ["seed1/start/front", "seed2/goal/view1", "seed3/start/view2"]
    calls = [
        CallTiming(
            label=cases[i % 3],
            cpu_s=t / 100 if wall else t,
            wall_s=t + wall,
            key=str(i),
            first=True,
        )
        for i, t in enumerate(times)
    ]
    draft = SimpleNamespace(timings=TimingLog(calls=calls))
    check = check_fast_enough("perceive", draft, budget)
    assert check.failing
    return report_markdown(
        build_report(domain="cubes", function="perceive", source="x = 1", checks=[check])
    )


def _request(text: str) -> ModelRequest:
    return ModelRequest(
        function="perceive",
        attempt=2,
        system=(TextBlock(text="sys"),),
        content=(TextBlock(text=text),),
    )


def test_measured_timings_do_not_change_the_hash():
    here = _slow_report([1.674, 1.75, 1.6, 1.7, 1.1, 1.3, 1.69])
    there = _slow_report([2.031, 2.4, 2.2, 1.9, 3.1, 2.0, 2.1])
    assert here != there  # the model reads what was measured ...
    assert _request(here).hash == _request(there).hash  # ... the hash leaves it out


def test_measured_wall_times_do_not_change_the_hash():
    here = _slow_report([1.674, 1.75, 1.6, 1.7, 1.1, 1.3, 1.69], wall=8.0)
    there = _slow_report([2.031, 2.4, 2.2, 1.9, 3.1, 2.0, 2.1], wall=8.5)
    assert "wall time" in here and here != there
    assert _request(here).hash == _request(there).hash


def test_everything_else_does():
    times = [1.674, 1.75, 1.6, 1.7, 1.1, 1.3, 1.69]
    base = _request(_slow_report(times)).hash
    assert _request(_slow_report(times, budget=0.5)).hash != base  # the budget
    assert _request(_slow_report(times[:6])).hash != base  # how many calls
    assert (
        _request("the plan moves 'red' by 1.674 s").hash
        != _request("the plan moves 'red' by 2.5 s").hash
    )
