"""The authoring loop: for each function in DAG order → prompt → model → draft → checks →
feedback → repair … → freeze.

Every attempt re-runs all checks; the best draft so far is kept; exhaustion raises
`AuthoringExhausted` with a state that `--resume` continues from (journal.py).

An answer cut off at its output limit (`stop_reason: max_tokens`) is told so — not "no code
block" — and the next attempt of that function asks with twice the `max_tokens`, up to
`MAX_TOKENS_CAP`. A call that fails is journaled (`call_failed`, with the usage the API billed,
if any) before the error ends the run.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from agent.clients.base import STOP_MAX_TOKENS, ImageBlock, ModelClient
from agent.errors import AgentError, AuthoringExhausted, BudgetExceeded, GateFailed
from agent.extract import (
    TRUNCATED_CHECK,
    DraftFormatError,
    extract_draft,
    format_error_report,
    truncated_error,
)
from agent.journal import Journal
from agent.prompt import DomainContext, Feedback, build_request
from agent.report import report_image
from artifacts import provenance
from checks.inputs import case_seed, fresh_seed
from checks.report import sanitise_text
from contracts.functions import authoring_order


class Checker(Protocol):
    """Runs a draft's full check suite; returns a check report (check_report.schema.json)."""

    def check(
        self,
        domain: str,
        function: str,
        source: str,
        *,
        deps: dict[str, str],
        out_dir: Path,
        cases_seed: int,
    ) -> dict: ...

    def markdown(self, report: dict) -> str: ...


class GateOutcome(Protocol):
    """What a trial gate run found (`artifacts.gate.GateResult` is one)."""

    @property
    def passed(self) -> bool: ...

    @property
    def blamed(self) -> str | None: ...

    images: dict[str, list[str]]
    trials: list[dict]

    def markdown(self) -> str: ...


# (frozen sources, seed, folder for its files) → outcome
Gate = Callable[[dict[str, str], int, Path], GateOutcome]
GATE_ROUNDS = 3  # gate runs before an authoring run gives up on a set that keeps failing trials


@dataclass(frozen=True, kw_only=True)
class Attempt:
    function: str
    attempt: int
    passed: bool
    report: dict
    source: str | None


Progress = Callable[[str], None]

DEFAULT_MAX_TOKENS = 16000  # an answer's output limit on a function's first attempt
MAX_TOKENS_CAP = 64000  # the most it grows to, doubling after each answer cut off


def next_max_tokens(current: int, cap: int = MAX_TOKENS_CAP) -> int:
    """The output limit after an answer was cut off at `current`: doubled, at most `cap`."""
    return max(current, min(current * 2, cap))


def _stderr_progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _score(report: dict) -> tuple[int, int]:
    checks = report.get("checks", [])
    return (sum(c["status"] == "passed" for c in checks), -len(checks))


class AuthoringRun:
    def __init__(
        self,
        *,
        ctx: DomainContext,
        client: ModelClient,
        checker: Checker,
        journal: Journal,
        max_attempts: int = 4,
        progress: Progress = _stderr_progress,
        max_tokens: int = DEFAULT_MAX_TOKENS,
        max_tokens_cap: int = MAX_TOKENS_CAP,
        cases_seed: int | None = None,
        gate: Gate | None = None,
        gate_rounds: int = GATE_ROUNDS,
    ) -> None:
        self.ctx = ctx
        self.cases_seed: int | None = cases_seed
        self.gate = gate
        self.gate_rounds = gate_rounds
        self.client = client
        self.checker = checker
        self.journal = journal
        self.max_attempts = max_attempts
        self.progress = progress
        self.max_tokens = max_tokens
        self.max_tokens_cap = max(max_tokens_cap, max_tokens)
        self.history: list[Attempt] = []
        self._t0 = time.monotonic()

    def run(self) -> dict[str, str]:
        """Author every function not yet frozen in this run; return the frozen sources."""
        state = self.journal.state()
        frozen = dict(state.frozen)
        self.cases_seed = self._run_cases_seed()
        if not self.journal.events():
            self.journal.event(
                "started",
                config={
                    "domain": self.ctx.domain,
                    "max_attempts": self.max_attempts,
                    "cases_seed": self.cases_seed,
                    "author": _author_of(self.client),
                    "commit": provenance.commit(),
                },
            )
        record = getattr(self.client, "record_cases_seed", None)
        if record is not None:
            record(self.cases_seed)
        for function in authoring_order():
            if function in frozen:
                self.progress(f"[{function}] frozen earlier in this run")
                continue
            frozen[function] = self._author(function, frozen)
        if self.gate is not None:
            frozen = self._gated(frozen)
        self.journal.event("finished")
        return frozen

    @property
    def run_seed(self) -> int:
        """The run's check-case seed (decided when the run starts)."""
        assert self.cases_seed is not None, "the run has not started"
        return self.cases_seed

    def _gated(self, frozen: dict[str, str]) -> dict[str, str]:
        """Run the trial gate on the candidate set; a failure goes back as the feedback of the
        blamed function's next attempt, and the functions after it are checked again (and
        repaired where they now fail), until the gate passes or `gate_rounds` are spent."""
        assert self.gate is not None
        order = authoring_order()
        for rnd in range(1, self.gate_rounds + 1):
            seed = case_seed(self.run_seed, "gate", rnd)
            self._say("gate", rnd, "running the trial gate")
            outcome = self.gate(dict(frozen), seed, self.journal.dir / "gate" / f"round{rnd}")
            self.journal.event(
                "gate",
                round=rnd,
                seed=seed,
                passed=outcome.passed,
                blamed=outcome.blamed,
                trials=outcome.trials,
            )
            if outcome.passed:
                self._say("gate", rnd, "passed")
                return frozen
            blamed = outcome.blamed
            assert blamed is not None
            self._say("gate", rnd, f"failed: held against {blamed}")
            if rnd == self.gate_rounds:
                self.journal.event("gate_failed", rounds=rnd, blamed=blamed)
                raise GateFailed(rnd, blamed, str(self.journal.dir))
            images = _gate_images(outcome, self.journal.dir)
            feedback = Feedback(
                draft=frozen[blamed], report_markdown=outcome.markdown(), images=images
            )
            frozen[blamed] = self._author(
                blamed, frozen, first=self._next_attempt(blamed), feedback=feedback
            )
            for later in order[order.index(blamed) + 1 :]:
                frozen[later] = self._recheck(later, frozen)
        raise AssertionError("unreachable")

    def _next_attempt(self, function: str) -> int:
        return self.journal.state().attempts.get(function, 0) + 1

    def _recheck(self, function: str, frozen: dict[str, str]) -> str:
        """A frozen function checked again against its (changed) dependencies: kept when it
        still passes, repaired from its next attempt when not."""
        attempt = self._next_attempt(function)
        out = self.journal.images_dir(function, attempt) / "recheck"
        deps = {d: src for d, src in frozen.items() if d != function}
        self._say(function, attempt, "checking the frozen version against its new dependencies")
        report = self.checker.check(
            self.ctx.domain,
            function,
            frozen[function],
            deps=deps,
            out_dir=out,
            cases_seed=case_seed(self.run_seed, f"{function}/recheck", attempt),
        )
        self.journal.event("rechecked", function=function, passed=bool(report["passed"]))
        if report["passed"]:
            return frozen[function]
        images, _ = _report_images(report, out)
        feedback = Feedback(
            draft=frozen[function],
            report_markdown=self.checker.markdown(report),
            images=images,
        )
        return self._author(function, frozen, first=attempt, feedback=feedback)

    def _run_cases_seed(self) -> int:
        """The run's check-case seed: the journal's (a resumed run), else the one given (a
        replayed transcript's), else a fresh one. Each attempt draws its cases from
        `checks.inputs.case_seed(run seed, function, attempt)`."""
        for e in self.journal.events():
            if e["event"] == "started":
                seed = (e.get("config") or {}).get("cases_seed")
                if isinstance(seed, int):
                    return seed
        if self.cases_seed is not None:
            return int(self.cases_seed)
        return fresh_seed()

    def _say(self, function: str, attempt: int, what: str) -> None:
        st = self.journal.state()
        self.progress(
            f"[{function} {attempt}/{self.max_attempts}] {what}  "
            f"(calls {st.calls}, in {st.usage.input_tokens + st.usage.cache_read_tokens + st.usage.cache_write_tokens} "
            f"out {st.usage.output_tokens} tok, ${st.spent_usd:.2f}, {time.monotonic() - self._t0:.0f}s)"
        )

    def _author(
        self,
        function: str,
        frozen: dict[str, str],
        *,
        first: int = 1,
        feedback: Feedback | None = None,
    ) -> str:
        """Attempts `first` … `first + max_attempts - 1` of `function` (after the trial gate
        or a re-check, `first` continues the run's numbering with `feedback` to start from)."""
        best: Attempt | None = None
        max_tokens = self.max_tokens
        last = first + self.max_attempts - 1
        for attempt in range(first, last + 1):
            request = build_request(
                self.ctx,
                function,
                attempt,
                frozen=frozen,
                feedback=feedback,
                max_attempts=last,
                max_tokens=max_tokens,
            )
            text = self.journal.saved_response(function, attempt)
            if text is None:
                self._say(function, attempt, "asking the model")
                self.journal.save_request(request)
                self.journal.event(
                    "call", function=function, attempt=attempt, request_hash=request.hash
                )
                try:
                    response = self.client.complete(request)
                except BudgetExceeded as e:  # refused before the call (or before a retry)
                    if e.usage is not None:
                        self.journal.call_failed(function, attempt, request.hash, e, e.usage)
                    else:
                        self.journal.event(
                            "refused", function=function, attempt=attempt, reason=str(e)[:2000]
                        )
                    raise
                except AgentError as e:
                    self.journal.call_failed(
                        function, attempt, request.hash, e, getattr(e, "usage", None)
                    )
                    raise
                self.journal.save_response(
                    function, attempt, response, request.hash, max_tokens=request.max_tokens
                )
                text, truncated = response.text, response.truncated
            else:
                truncated = self.journal.saved_stop_reason(function, attempt) == STOP_MAX_TOKENS
            grown = next_max_tokens(max_tokens, self.max_tokens_cap) if truncated else max_tokens
            if truncated:
                self._say(
                    function,
                    attempt,
                    f"the answer was cut off at max_tokens {max_tokens}; next attempt: {grown}",
                )
            source: str | None
            try:
                source = extract_draft(text, function)
            except DraftFormatError as e:
                source = None
                error, check = e, "response_format"
                if truncated:
                    error = truncated_error(function, max_tokens, grown)
                    check = TRUNCATED_CHECK
                report = format_error_report(self.ctx.domain, function, error, check=check)
                markdown = f"**{check}** failed: {error}"
                self.journal.save_report(function, attempt, report, markdown)
            else:
                self.journal.save_draft(function, attempt, source)
                saved = self.journal.saved_report(function, attempt)
                if saved is None:
                    self._say(function, attempt, "checking the draft")
                    deps = {d: src for d, src in frozen.items() if d != function}
                    report = self.checker.check(
                        self.ctx.domain,
                        function,
                        source,
                        deps=deps,
                        out_dir=self.journal.images_dir(function, attempt),
                        cases_seed=case_seed(self.run_seed, function, attempt),
                    )
                    markdown = self.checker.markdown(report)
                    if truncated and not report["passed"]:
                        markdown += (
                            f"\n\n(Your answer was also cut off at its output limit of "
                            f"{max_tokens} tokens; the next attempt may use up to {grown}.)"
                        )
                    self.journal.save_report(function, attempt, report, markdown)
                else:
                    report = saved
                    markdown = self.journal.saved_markdown(
                        function, attempt
                    ) or self.checker.markdown(report)
            max_tokens = grown
            result = Attempt(
                function=function,
                attempt=attempt,
                passed=bool(report["passed"]),
                report=report,
                source=source,
            )
            self.history.append(result)
            if result.passed and source is not None:
                self.journal.freeze(function, attempt, source)
                self._say(function, attempt, f"passed {len(report['checks'])} checks: frozen")
                return source
            self._say(function, attempt, f"failed: {report.get('first_failure')}")
            if best is None or _score(report) > _score(best.report):
                best = result
            images, refused = _report_images(report, self.journal.images_dir(function, attempt))
            feedback = Feedback(
                draft=source if source is not None else text,
                report_markdown=markdown
                + "".join(f"\n\n(Image refused: {why}.)" for why in refused),
                images=images,
            )
        assert best is not None
        if best.source is not None:
            self.journal.save_draft(function, 0, best.source)  # drafts/<fn>-0.py: the best so far
        self.journal.event(
            "exhausted", function=function, attempts=self.max_attempts, best_attempt=best.attempt
        )
        raise AuthoringExhausted(
            function,
            self.max_attempts,
            str(self.journal.dir),
            f"best attempt: {best.attempt} (first failure: {best.report.get('first_failure')})",
        )


def _author_of(client: object) -> dict | None:
    """Who answers this run's calls (provider and model, an agent, or people), as journaled."""
    author = getattr(client, "author", None)
    return author.to_dict() if author is not None else None


def _gate_images(outcome: GateOutcome, run_dir: Path, limit: int = 4) -> tuple[ImageBlock, ...]:
    """The blamed trials' observations, read only from the run's own folder."""
    out: list[ImageBlock] = []
    for trial in outcome.trials:
        if not trial.get("blamed"):
            continue
        for path in outcome.images.get(trial["name"], []):
            data, _ = report_image(path, run_dir)
            if data is not None and len(out) < limit:
                caption = f"trial gate, {trial['name']}: the {Path(path).stem} observation"
                out.append(ImageBlock(png=data, caption=sanitise_text(caption)))
    return tuple(out)


def _report_images(
    report: dict, images_dir: Path, limit: int = 4
) -> tuple[tuple[ImageBlock, ...], list[str]]:
    """The images of the failing checks, read only from the check run's own folder
    (`agent.report.report_image`), and why any other was refused (never read)."""
    out: list[ImageBlock] = []
    refused: list[str] = []
    for check in report.get("checks", []):
        if check.get("status") not in ("failed", "error"):
            continue
        for image in check.get("images", []):
            if len(out) >= limit or not isinstance(image, dict):
                continue
            data, why = report_image(image.get("path"), images_dir)
            if data is None:
                refused.append(f"{sanitise_text(str(check.get('name')))[:100]}: {why}")
                continue
            caption = image.get("caption", Path(str(image.get("path"))).name)
            out.append(
                ImageBlock(png=data, caption=sanitise_text(f"{check.get('name')}: {caption}")[:300])
            )
    return tuple(out), refused
