"""A reliability study as the paper runs it: N independent authoring runs of one domain, each
run's final programs on the same first K start/goal pairs of a split (paper: 10 runs × 6
pairs), summarised per run and pooled.

A run that did not finish authoring has no programs: it is listed as a failed run with its
reason, never dropped. A run that never started (no model call: its options or credentials
were refused) is no authoring attempt: it is listed apart and counted nowhere. The pooled figures are given twice: over all runs, where each pair of
a failed run counts as a failure (the reliability of authoring and solving together), and
over the finished runs alone (how good the systems are that authoring produced).

The simulator knows nothing of journals: the caller names the runs (`StudyRun`: a name, and
the policy of its final programs or the reason it has none; `artifacts.policy.find_runs`
reads them from a runs folder), and each finished run is evaluated by `run_eval` with its own
policy, so its programs run in a sandbox session of their own.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from artifacts.policy import PolicySpec
from experiments.evaluation import EvalConfig, run_eval

METRICS = (("state", "state_ok"), ("plan", "plan_ok"), ("final", "final_ok"))


@dataclass(frozen=True)
class StudyRun:
    """One authoring run of the study: `policy` is None when the run produced no programs."""

    name: str
    policy: PolicySpec | None
    reason: str | None = None
    started: bool = True  # False: the run never made a call (not counted, listed apart)


def counts(trials: Sequence[dict], *, failed_pairs: int = 0) -> dict[str, Any]:
    """Successes per metric over `trials`, plus `failed_pairs` trials that all failed."""
    n = len(trials) + failed_pairs
    out: dict[str, Any] = {"trials": n}
    for _, key in METRICS:
        k = sum(bool(t[key]) for t in trials)
        out[key] = k
        out[key.replace("_ok", "_rate")] = k / n if n else 0.0
    return out


def run_study(
    config: EvalConfig,
    runs: Sequence[StudyRun],
    instances: Sequence[dict],
    *,
    workers: int = 1,
    ray_address: str | None = None,
    progress: Callable[[str, int], Callable[[dict], None] | None] | None = None,
) -> dict:
    """Evaluate every finished run on `instances` (the K pairs) and summarise the study.

    `progress(run_name, trials)` may return a per-trial callback (e.g. a progress bar)."""
    per_run: list[dict] = []
    for run in runs:
        if not run.started:
            per_run.append({"run": run.name, "reason": run.reason, "summary": None,
                            "started": False})  # fmt: skip
            continue
        summary = None
        if run.policy is not None:
            try:
                summary = run_eval(
                    replace(config, policy=run.policy),
                    instances,
                    workers=workers,
                    ray_address=ray_address,
                    progress=progress(run.name, len(instances)) if progress else None,
                )
            finally:
                _close_in_process_policy()
        per_run.append({"run": run.name, "reason": run.reason, "summary": summary})
    return summarise_study(config, per_run, [i.get("name", "") for i in instances])


def _close_in_process_policy() -> None:
    """End the sandbox session of the run just evaluated in this process (`workers=1`), so a
    study of N runs never holds N sessions; worker processes end theirs when they exit."""
    from experiments import evaluation

    policy = evaluation._WORKER.pop("policy", None)
    close = getattr(policy, "close", None)
    if close is not None:
        close()


def summarise_study(config: EvalConfig, per_run: list[dict], pairs: list[str]) -> dict:
    """The study's JSON: per run (`summary` None for a run with no programs) and pooled."""
    k = len(pairs)
    runs_out: list[dict] = []
    all_trials: list[dict] = []
    finished_trials: list[dict] = []
    failed_pairs = 0
    never_started = [
        {"run": e["run"], "reason": e.get("reason")} for e in per_run if not e.get("started", True)
    ]
    for entry in per_run:
        if not entry.get("started", True):
            continue
        summary = entry["summary"]
        row: dict[str, Any] = {"run": entry["run"], "finished": summary is not None}
        if summary is None:
            row["reason"] = entry.get("reason") or "the run produced no programs"
            row["counts"] = None
            failed_pairs += k
        else:
            trials = summary["per_trial"]
            row["counts"] = counts(trials)
            row["failures"] = summary["failures"]
            row["summary"] = summary
            all_trials += trials
            finished_trials += trials
        runs_out.append(row)
    finished = [r for r in runs_out if r["finished"]]
    per_run_final = [r["counts"]["final_rate"] if r["finished"] else 0.0 for r in runs_out]
    return {
        "study": "reliability",
        "domain": config.domain,
        "split": config.split,
        "view": config.view,
        "protocol": config.protocol.label,
        "pairs": k,
        "pair_names": pairs,
        "total_runs": len(runs_out),
        "finished_runs": len(finished),
        "runs_solving_every_pair": sum(
            r["finished"] and r["counts"]["final_ok"] == k for r in runs_out
        ),
        "pooled": {"runs": len(runs_out), **counts(all_trials, failed_pairs=failed_pairs)},
        "pooled_finished": {"runs": len(finished), **counts(finished_trials)},
        "final_rate_per_run": {
            "mean": statistics.fmean(per_run_final) if per_run_final else None,
            "min": min(per_run_final) if per_run_final else None,
            "max": max(per_run_final) if per_run_final else None,
        },
        "runs": runs_out,
        "never_started": never_started,
    }


def _cell(c: dict | None, key: str) -> str:
    if c is None:
        return "–"
    n, ok = c["trials"], c[key]
    return f"{ok}/{n} {100 * ok / n:5.1f}%" if n else "0/0"


def study_table(study: dict) -> str:
    """The terminal tables: one row per run (with its trial failures), then the pooled rows."""
    names = [r["run"] for r in study["runs"]]
    pooled_all = f"pooled, all {study['total_runs']} runs *"
    pooled_fin = f"pooled, {study['finished_runs']} finished runs"
    w = max(len(s) for s in [*names, pooled_all, pooled_fin, "run"])
    col = 14
    head = f"  {'run':<{w}}  {'authoring':<9}" + "".join(f"  {m:>{col}}" for m, _ in METRICS)
    lines = [
        f"{study['domain']} · reliability study · {study['total_runs']} runs × "
        f"{study['pairs']} pairs · split {study['split']} · view {study['view']}",
        f"  protocol: {study['protocol']}",
        f"  pairs: {', '.join(study['pair_names'])}",
        head,
    ]
    for r in study["runs"]:
        c = r["counts"]
        row = f"  {r['run']:<{w}}  {'finished' if r['finished'] else 'FAILED':<9}"
        row += "".join(f"  {_cell(c, key):>{col}}" for _, key in METRICS)
        if r["finished"] and r["failures"]:
            row += "  " + ", ".join(f"{s} ×{n}" for s, n in sorted(r["failures"].items()))
        lines.append(row)
        if not r["finished"]:
            lines.append(f"  {'':<{w}}    {r['reason']}")
        else:
            for t in r["summary"]["per_trial"]:
                if t["failure"]:
                    reason = str(t["failure"]["reason"])[:200]
                    lines.append(f"  {'':<{w}}    {t['name']}: [{t['failure']['stage']}] {reason}")
    lines.append("  " + "-" * (len(head) - 2))
    for label, c in ((pooled_all, study["pooled"]), (pooled_fin, study["pooled_finished"])):
        lines.append(
            f"  {label:<{w}}  {'':<9}" + "".join(f"  {_cell(c, key):>{col}}" for _, key in METRICS)
        )
    spread = study["final_rate_per_run"]
    lines.append(
        f"  {study['finished_runs']}/{study['total_runs']} runs finished authoring; "
        f"{study['runs_solving_every_pair']}/{study['total_runs']} solved every pair"
        + (
            ""
            if spread["mean"] is None
            else f"; final success per run: mean {100 * spread['mean']:.1f}%, "
            f"min {100 * spread['min']:.1f}%, max {100 * spread['max']:.1f}%"
        )
    )
    lines.append("  * a run that did not finish authoring counts each of its pairs as failed")
    if study.get("never_started"):
        lines.append(
            f"  not counted: {len(study['never_started'])} folder(s) of runs that never started "
            "(no model call)"
        )
        lines += [f"    {r['run']}: {r['reason']}" for r in study["never_started"]]
    return "\n".join(lines)
