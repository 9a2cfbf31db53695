"""The authoring loop driven by a scripted model through every branch."""

from __future__ import annotations

import json

import pytest

from agent.clients import Budget, ScriptedClient
from agent.errors import AuthoringExhausted, BudgetExceeded
from agent.journal import Journal
from agent.loop import AuthoringRun
from contracts.functions import authoring_order

from .conftest import CONTEXT, bad, good

ORDER = authoring_order()


def run(tmp_path, client, checker, **kw):
    return AuthoringRun(
        ctx=CONTEXT,
        client=client,
        checker=checker,
        journal=Journal(tmp_path / "run"),
        progress=lambda _: None,
        **kw,
    )


def test_dependency_order_is_the_designs():
    assert ORDER == ("render", "perceive", "relate", "plan")


def test_pass_first_time_freezes_all_four(tmp_path, checker):
    client = ScriptedClient([good(f) for f in ORDER])
    frozen = run(tmp_path, client, checker).run()
    assert set(frozen) == set(ORDER)
    assert [r.function for r in client.requests] == list(ORDER)
    # later prompts carry the frozen source of their code dependencies
    relate_prompt = client.requests[2].text()
    assert "## Frozen `render`" in relate_prompt and "def render()" in relate_prompt
    assert "## Frozen `relate`" in client.requests[3].text()


def test_repair_then_pass_feeds_back_draft_and_report(tmp_path, checker):
    client = ScriptedClient(
        [good("render"), bad("perceive"), good("perceive"), good("relate"), good("plan")]
    )
    r = run(tmp_path, client, checker)
    r.run()
    repair = client.requests[2]
    assert repair.function == "perceive" and repair.attempt == 2
    text = repair.text()
    assert "Your previous draft failed its checks (attempt 1 of 4)" in text
    assert "return {'ok': False}" in text
    assert "returns_ok: failed" in text
    assert [a.passed for a in r.history] == [True, False, True, True, True]


def test_every_attempt_reruns_the_checks(tmp_path, checker):
    client = ScriptedClient(
        [bad("render"), bad("render"), good("render")] + [good(f) for f in ORDER[1:]]
    )
    run(tmp_path, client, checker).run()
    assert [f for f, _ in checker.calls] == ["render"] * 3 + list(ORDER[1:])


def test_exhaustion_reports_and_keeps_the_best_draft(tmp_path, checker):
    client = ScriptedClient([good("render")] + [bad("perceive")] * 3)
    with pytest.raises(AuthoringExhausted) as info:
        run(tmp_path, client, checker, max_attempts=3).run()
    assert info.value.function == "perceive"
    assert "--resume" in str(info.value)
    assert (tmp_path / "run" / "drafts" / "perceive-0.py").is_file()
    events = [e["event"] for e in Journal(tmp_path / "run").events()]
    assert events[-1] == "exhausted"


def test_resume_after_exhaustion_continues_without_asking_again(tmp_path, checker):
    first = ScriptedClient([good("render")] + [bad("perceive")] * 2)
    with pytest.raises(AuthoringExhausted):
        run(tmp_path, first, checker, max_attempts=2).run()
    second = ScriptedClient([good("perceive"), good("relate"), good("plan")])
    frozen = run(tmp_path, second, checker, max_attempts=4).run()
    assert set(frozen) == set(ORDER)
    assert [(r.function, r.attempt) for r in second.requests] == [
        ("perceive", 3),
        ("relate", 1),
        ("plan", 1),
    ]


def test_budget_stops_before_an_over_budget_call(tmp_path, checker):
    client = ScriptedClient([good(f) for f in ORDER], budget=Budget(max_usd=0.25), usd_per_call=0.1)
    with pytest.raises(BudgetExceeded, match="max-usd"):
        run(tmp_path, client, checker).run()
    assert len(client.requests) == 2  # the third call was refused before it was made
    assert client.budget.spent_usd == pytest.approx(0.2)


def test_call_budget(tmp_path, checker):
    client = ScriptedClient([good(f) for f in ORDER], budget=Budget(max_calls=1))
    with pytest.raises(BudgetExceeded, match="max-calls 1"):
        run(tmp_path, client, checker).run()


@pytest.mark.parametrize(
    ("reply", "fragment"),
    [
        ("I would write a renderer like this: def render(): ...", "holds no ```python code block"),
        (good("render") + good("render"), "holds 2 code blocks"),
        (
            "```python\ndef draw():\n    return 1\n```",
            "must define a top-level function `render`; it defines: draw",
        ),
        ("```python\ndef render(:\n```", "not valid Python"),
    ],
    ids=["no_code_block", "two_code_blocks", "wrong_function_name", "syntax_error"],
)
def test_malformed_responses_become_feedback(tmp_path, checker, reply, fragment):
    client = ScriptedClient([reply, good("render")] + [good(f) for f in ORDER[1:]])
    r = run(tmp_path, client, checker)
    r.run()
    assert r.history[0].passed is False
    assert r.history[0].report["checks"][0]["name"] == "response_format"
    assert fragment in client.requests[1].text()
    report = json.loads((tmp_path / "run" / "reports" / "render-1.json").read_text())
    from contracts import validate

    validate("check_report", report)


def test_failure_images_reach_the_model_and_the_html_report(tmp_path, checker, monkeypatch):
    from PIL import Image

    from agent.clients.base import ImageBlock
    from agent.report import write_report

    monkeypatch.chdir(tmp_path)
    plain = checker.check

    def with_image(domain, function, source, *, deps, out_dir, cases_seed=None):
        report = plain(domain, function, source, deps=deps, out_dir=out_dir)
        png = out_dir / "overlay.png"
        Image.new("RGB", (8, 8), (255, 0, 0)).save(png)
        # paths as the checks write them: relative to the working directory
        report["checks"][0]["images"] = [
            {"path": str(png.relative_to(tmp_path)), "caption": "overlay"}
        ]
        return report

    monkeypatch.setattr(checker, "check", with_image)
    client = ScriptedClient(
        [good("render"), bad("perceive"), good("perceive"), good("relate"), good("plan")]
    )
    r = run(tmp_path, client, checker)
    r.run()
    repair = client.requests[2]
    assert any(isinstance(b, ImageBlock) for b in repair.content)
    html = write_report(r.journal, "toy").read_text()
    assert html.count("data:image/png;base64") >= 2


# -- the trial gate ----------------------------------------------------------------------------


class ToyGate:
    """A real, tiny gate: it runs the candidate set's `perceive` and `plan` in a subprocess on
    a 'task' (the round's seed) and holds a failure against the function whose answer is not
    right for it — `perceive` must pass the toy check and say it sees the task."""

    def __init__(self, checker) -> None:
        self.checker = checker
        self.rounds: list[dict[str, str]] = []

    def __call__(self, sources, seed, out):
        from dataclasses import dataclass, field

        self.rounds.append(dict(sources))
        report = self.checker.check("toy", "perceive", sources["perceive"], deps={}, out_dir=out)
        seen = "# sees the task" in sources["perceive"]
        blamed = None if (report["passed"] and seen) else "perceive"

        @dataclass
        class Outcome:
            passed: bool
            blamed: str | None
            trials: list = field(default_factory=list)
            images: dict = field(default_factory=dict)

            def markdown(self) -> str:
                return f"**trial gate**: task {seed}: " + (
                    "passed" if self.passed else "perceive saw nothing"
                )

        trial = {"name": "trial01/toy", "blamed": blamed, "final_ok": blamed is None}
        return Outcome(passed=blamed is None, blamed=blamed, trials=[trial])


def good_seen(function: str) -> str:
    return f"```python\ndef {function}():  # sees the task\n    return {{'ok': True}}\n```\n"


def test_a_gate_failure_goes_back_to_the_blamed_function_and_later_ones_are_rechecked(
    tmp_path, checker
):
    """The four pass their checks; the gate holds the set against `perceive`; its next attempt
    (attempt 2) is asked with the gate's report as feedback, `relate` and `plan` are checked
    again against it (no new answers: they still pass), and the gate then passes."""
    from checks.inputs import case_seed

    gate = ToyGate(checker)
    client = ScriptedClient([*(good(f) for f in ORDER), good_seen("perceive")])
    r = run(tmp_path, client, checker, gate=gate, cases_seed=11)
    frozen = r.run()
    assert "# sees the task" in frozen["perceive"] and len(gate.rounds) == 2
    repair = client.requests[-1]
    assert (repair.function, repair.attempt) == ("perceive", 2)
    assert "perceive saw nothing" in repair.text() and "return {'ok': True}" in repair.text()
    events = Journal(tmp_path / "run").events()
    gates = [e for e in events if e["event"] == "gate"]
    assert [g["passed"] for g in gates] == [False, True] and gates[0]["blamed"] == "perceive"
    assert gates[0]["seed"] == case_seed(11, "gate", 1)
    assert [e["function"] for e in events if e["event"] == "rechecked"] == ["relate", "plan"]
    # gate 1 (its perceive), the repair, the two re-checks, gate 2
    assert [f for f, _ in checker.calls][-5:] == [
        "perceive",
        "perceive",
        "relate",
        "plan",
        "perceive",
    ]


def test_a_gate_that_keeps_failing_ends_the_run_with_a_clear_status(tmp_path, checker):
    gate = ToyGate(checker)
    client = ScriptedClient([*(good(f) for f in ORDER), good("perceive"), good("perceive")])
    from agent.errors import GateFailed

    with pytest.raises(
        GateFailed, match=r"failed the trial gate in 2 rounds, the last held against 'perceive'"
    ):
        run(tmp_path, client, checker, gate=gate, gate_rounds=2).run()
    assert not any(e["event"] == "finished" for e in Journal(tmp_path / "run").events())
