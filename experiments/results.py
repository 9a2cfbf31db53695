"""docs/results.md, generated from committed run files.

Each figure of the page comes from one `rivet eval` command listed in `runs()`. The command's
JSON summary, its trials cut to their verdicts (`compact`), is committed as
docs/results/KEY.json with the command, the commit, the date and the wall time that produced it
(`artifacts.provenance`). The page is rendered from those files alone: no figure is typed by
hand, and a test checks that the committed page is what they render.

    python -m experiments.results run [KEY ...]   # run the listed commands whose files are
                                                  # missing (or those named), then compact them
    python -m experiments.results render [--check]  # write docs/results.md (--check: exit 1
                                                  # where the committed page differs)
    python -m experiments.results compact FULL.json KEY  # keep a run made with --json FULL.json

`make results` renders; `make results-runs` runs what is missing (hours on a 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import domains
from artifacts.store import ROOT as ARTIFACTS
from experiments.evaluation import PAPER, wilson
from sim.faults import FAULTS

REPO = Path(__file__).resolve().parents[1]
RUN_FILES = REPO / "docs" / "results"
PAGE = REPO / "docs" / "results.md"
ENVELOPE = tuple(f"envelope-{n}" for n in range(1, 6))  # docs/cameras/envelope-N.json
VIEWS = ("view1", "view2")
REASON_CHARS = 160  # a failure's reason, kept to this length in a run file
Files = Mapping[str, dict | None]  # run files by key; None where a run has not been made


CHECKS_BENCH = ("python", "-m", "benchmarks.checks_bench")


@dataclass(frozen=True)
class Run:
    """One command of the page, kept as docs/results/KEY.json: `rivet eval` with `args`, or
    (`tool="checks"`) the checks' mutation benchmark with `args`."""

    key: str
    args: tuple[str, ...]
    tool: str = "eval"

    @property
    def program(self) -> tuple[str, ...]:
        return ("rivet",) if self.tool == "eval" else CHECKS_BENCH

    @property
    def argv(self) -> list[str]:
        """The command's arguments after its program (the full output goes under runs/results/)."""
        if self.tool == "eval":
            return ["eval", *self.args, "--quiet", "--json", str(self.output)]
        return [*self.args, "--out", str(self.output.parent)]

    @property
    def output(self) -> Path:
        """The command's own output, relative to the repository."""
        if self.tool == "eval":
            return Path("runs/results") / f"{self.key}.json"
        return Path("runs/results") / self.key / "bench_checks.json"

    @property
    def command(self) -> str:
        return shlex.join([*self.program, *self.argv])


def runs(names: Iterable[str] | None = None) -> list[Run]:
    """Every command the page reads, for each registered domain (or `names`)."""
    names = list(domains.names() if names is None else names)
    art = ("--policy", "artifacts")
    test = ("--split", "test")
    first20 = ("--trials", "20", "--workers", "2")
    out: list[Run] = []
    for d in names:
        out.append(Run(f"{d}-dev-front", (d, *art, "--split", "dev", "--workers", "2")))
        out.append(Run(f"{d}-test-front", (d, *art, *test, "--workers", "2")))
    for d in names:
        out.append(Run(f"{d}-test-oracle", (d, "--policy", "oracle", *test, "--workers", "2")))
    for d in names:
        for v in VIEWS:
            out.append(Run(f"{d}-test-{v}", (d, *art, *test, "--view", v, *first20)))
        for c in ENVELOPE:
            camera = ("--camera", f"docs/cameras/{c}.json")
            out.append(Run(f"{d}-test-{c}", (d, *art, *test, *camera, *first20)))
    for d in names:
        closed = ("--loop", "closed")
        out.append(Run(f"{d}-test-front-closed", (d, *art, *test, *closed, "--workers", "2")))
    for d in names:
        for f in FAULTS:
            fault = (*test, "--faults", f)
            out.append(Run(f"{d}-test-{f}-closed", (d, *art, *fault, *closed, *first20)))
            out.append(
                Run(f"{d}-test-{f}-open", (d, *art, *fault, "--trials", "5", "--workers", "2"))
            )
    for d in names:
        for c in ENVELOPE:
            camera = ("--camera", f"docs/cameras/{c}.json")
            out.append(Run(f"{d}-test-{c}-closed", (d, *art, *test, *camera, *closed, *first20)))
    for d in names:
        out.append(Run(f"checks-{d}", ("--domain", d, "--repeats", "10"), tool="checks"))
    return out


# -- run files ----------------------------------------------------------------------------------

_SUMMARY_KEYS = (
    "domain",
    "trials",
    "state_ac",
    "plan_sr",
    "final_sr",
    "intervals",
    "final_with_failed_plan",
    "view",
    "split",
    "policy",
    "protocol",
    "loop",
    "faults",
    "failures",
    "timing",
    "precision",
    "set_hash",
    "run",
)


def compact(summary: Mapping) -> dict:
    """A `rivet eval --json` summary of one domain and camera, its trials cut to their verdicts,
    failure, wall time and (closed loop) final status: what the page reads."""
    if "per_trial" not in summary:
        raise ValueError("not the summary of one domain and one camera (no per_trial)")
    if "run" not in summary:
        raise ValueError("the summary names no command, commit or date (an older rivet eval)")
    out = {k: summary[k] for k in _SUMMARY_KEYS if k in summary}
    trials = []
    for t in summary["per_trial"]:
        row: dict = {k: bool(t[k]) for k in ("state_ok", "plan_ok", "final_ok")}
        row = {"name": t["name"], **row, "wall_s": round(t["timings"].get("total", 0.0), 2)}
        if t.get("failure"):
            reason = str(t["failure"]["reason"])
            cut = reason[:REASON_CHARS] + ("…" if len(reason) > REASON_CHARS else "")
            row["failure"] = {"stage": t["failure"]["stage"], "reason": cut}
        if t.get("loop"):
            row["loop"] = {
                k: t["loop"][k] for k in ("status", "reason", "replans") if k in t["loop"]
            }
        if t.get("fault"):
            row["fault"] = {
                k: t["fault"][k] for k in ("name", "step", "happened", "detail") if k in t["fault"]
            }
        trials.append(row)
    out["per_trial"] = trials
    return out


def compact_checks(bench: Mapping) -> dict:
    """A checks benchmark's `bench_checks.json` of one domain, each row cut to its verdict."""
    if "summary" not in bench or "run" not in bench["summary"]:
        raise ValueError("not one domain's bench_checks.json naming its command (an older run)")
    return {
        "summary": dict(bench["summary"]),
        "correct": [
            {k: r[k] for k in ("function", "runs", "rejections", "identical_reports")}
            for r in bench["correct"]
        ],
        "mutants": [
            {k: r[k] for k in ("mutant", "function", "caught", "first_failure", "seconds")}
            for r in bench["mutants"]
        ],
        "field": [
            {k: r[k] for k in ("program", "function", "draws", "rejected", "case")}
            for r in bench.get("field", [])
        ],
    }


def load(key: str, folder: Path = RUN_FILES) -> dict | None:
    path = folder / f"{key}.json"
    return json.loads(path.read_text()) if path.is_file() else None


def write(key: str, output: Mapping, folder: Path = RUN_FILES) -> Path:
    """Keep a command's output (an eval summary, or a checks benchmark's) as KEY.json."""
    kept = compact_checks(output) if "mutants" in output else compact(output)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{key}.json"
    path.write_text(json.dumps(kept, indent=1, ensure_ascii=False) + "\n")
    return path


# -- the page -----------------------------------------------------------------------------------

RATES = (("state_ac", "state accuracy"), ("plan_sr", "plan success"), ("final_sr", "final success"))


def rate(run: Mapping | None, key: str) -> str:
    """A rate and its Wilson 95 % interval: "95.0 % (86.3–98.3)"; "not run" without a file."""
    if run is None:
        return "not run"
    low, high = run["intervals"][key]
    return f"{100 * run[key]:.1f} % ({100 * low:.1f}–{100 * high:.1f})"


def _paper(domain: str, keys: Sequence[str]) -> str:
    """The paper's figures, in percent, without the unit (they have no interval)."""
    p = PAPER.get(domain, {})
    return " / ".join("–" if k not in p else f"{100 * p[k]:.1f}" for k in keys)


def _stages(run: Mapping | None) -> str:
    if run is None:
        return "not run"
    counts = Counter(t["failure"]["stage"] for t in run["per_trial"] if "failure" in t)
    return ", ".join(f"{s} {n}" for s, n in counts.most_common()) or "none"


def _failing(named: Sequence[tuple[str, Mapping | None]], limit: int = 6) -> list[str]:
    """The failing trials of each named run (the first `limit` of each; the run file has the
    rest), grouped by run: a table, or a line saying none."""
    rows: list[str] = []
    for label, run in named:
        failed = [t for t in (run or {}).get("per_trial", []) if "failure" in t]
        if failed:
            rows.append(f"| **{label}** ({len(failed)}) | | | |")
        rows += [
            f"| `{t['name']}` | {t['failure']['stage']} | {'yes' if t['final_ok'] else 'no'} | "
            f"{t['failure']['reason'].replace('|', '∣')} |"
            for t in failed[:limit]
        ]
        if len(failed) > limit:
            rows.append(f"| … {len(failed) - limit} more in the run file | | | |")
    if not rows:
        return ["No trial failed in these runs."]
    return ["| trial | stage | final | reason |", "|---|---|---|---|", *rows]


def _meta(found: Mapping) -> Mapping:
    """A run file's provenance (`artifacts.provenance.run_record`) with its wall time."""
    if "run" in found:
        return found["run"]
    return {**found["summary"]["run"], "wall_s": found["summary"]["wall_s"]}


def _committed_set(domain: str) -> str | None:
    """The set hash of the domain's committed frozen set (artifacts/<domain>/manifest.json)."""
    path = ARTIFACTS / domain / "manifest.json"
    return json.loads(path.read_text())["set_hash"] if path.is_file() else None


def _minutes(run: Mapping | None) -> str:
    return "–" if run is None else f"{_meta(run)['wall_s'] / 60:.1f} min"


def _intro() -> list[str]:
    """The page's head: where its figures come from, and what they measure."""
    return [
        "# Results",
        "",
        "<!-- Generated by `make results` (python -m experiments.results render) from the run",
        "     files in docs/results/. Do not edit: change experiments/results.py or re-run. -->",
        "",
        "Every figure on this page is read from a committed run file, docs/results/KEY.json, the",
        "summary of one listed command (`rivet eval`, or the checks' benchmark); the table at the",
        "end gives each run's command, date, commit and wall time. A rate is followed by its",
        "Wilson 95 % interval. `python -m experiments.results run KEY` runs a command again and",
        "`make results` rewrites this page.",
        "",
        "The programs behind `--policy artifacts` are the people-written reference programs",
        "(labelled so in their transcripts and manifests), frozen from `domains/<d>/programs/`; no",
        "model wrote them. Each domain has two splits of 60 trials (20 goals × 3 starts): `dev`,",
        "where programs and prompts are changed, and `test`, reported and never tuned on",
        '(docs/domains.md, "Splits"). Trials run under the honest protocol: realistic images and a',
        "calibration error (docs/observations.md), the programs in the Docker sandbox, and an",
        "executor that acts on the perceived start and its own plan targets, sensing the world only",
        "through its gripper and a wrist-camera in-hand estimate, which also shows it the camera's",
        "calibration offset (docs/executor.md). The machine:",
        "the CPU cores each run records (`cpus` in its file), no GPU, Mesa llvmpipe for rendering,",
        "MuJoCo physics at 2 ms.",
    ]


def _table_i(got: Files, names: Sequence[str]) -> list[str]:
    """Table I: the front camera, dev and test."""
    out: list[str] = [
        "",
        "## Table I — front camera",
        "",
        "| domain | split | trials | state accuracy | plan success | final success | paper, test (%) |",
        "|---|---|---|---|---|---|---|",
    ]
    for d in names:
        for split in ("dev", "test"):
            run = got[f"{d}-{split}-front"]
            cells = " | ".join(rate(run, k) for k, _ in RATES)
            paper = _paper(d, [k for k, _ in RATES]) if split == "test" else ""
            n = "–" if run is None else run["trials"]
            out.append(f"| {d} | {split} | {n} | {cells} | {paper} |")
    out += [
        "",
        'Run files `D-dev-front` and `D-test-front` (table "Runs"). The paper\'s figures are RIVET',
        "with Claude on its own trials, not on these.",
        "",
        'Failing trials ("final": whether the trial still ended at the goal):',
        "",
        *_failing([(f"{d} {sp}", got[f"{d}-{sp}-front"]) for d in names for sp in ("dev", "test")]),
    ]
    return out


def _table_iii(got: Files, names: Sequence[str]) -> list[str]:
    """Final success by camera: the named views and the envelope cameras."""
    out: list[str] = [
        "",
        "## Table III — final success by camera (test split)",
        "",
        "The named views, the first 20 test trials each, and five cameras drawn from the",
        "envelope around them (docs/cameras/envelope-N.json, none of the named views;",
        "docs/cameras/README.md). Run files `D-test-CAMERA`.",
        "",
        "| domain | front (60) | "
        + " | ".join(f"{v} (20)" for v in VIEWS)
        + " | paper view1 / view2 (%) |",
        "|---|---|---|---|---|",
    ]
    for d in names:
        cells = " | ".join(rate(got[f"{d}-test-{v}"], "final_sr") for v in ("front", *VIEWS))
        out.append(f"| {d} | {cells} | {_paper(d, VIEWS)} |")
    out += [
        "",
        "Through the envelope cameras, open loop and closed loop (`--loop closed`, run files",
        "`D-test-CAMERA-closed`):",
        "",
        "| domain | loop | " + " | ".join(ENVELOPE) + " |",
        "|---|---|" + "---|" * len(ENVELOPE),
    ]
    for d in names:
        for loop, suffix in (("open", ""), ("closed", "-closed")):
            cells = " | ".join(rate(got[f"{d}-test-{c}{suffix}"], "final_sr") for c in ENVELOPE)
            out.append(f"| {d} | {loop} | {cells} |")
    out += [
        "",
        "Failures by stage:",
        "",
        "| domain | " + " | ".join(VIEWS) + " | " + " | ".join(ENVELOPE) + " |",
        "|---|" + "---|" * (len(VIEWS) + len(ENVELOPE)),
    ]
    for d in names:
        out.append(
            f"| {d} | "
            + " | ".join(_stages(got[f"{d}-test-{c}"]) for c in (*VIEWS, *ENVELOPE))
            + " |"
        )
    return out


def _executor_alone(got: Files, names: Sequence[str]) -> list[str]:
    """The oracle policy: execution alone."""
    out: list[str] = [
        "",
        "## The executor alone (test split)",
        "",
        "`--policy oracle`: the ground-truth states and a reference construction order, executed",
        "by the same robot and executor; what remains is execution (docs/executor.md). Run",
        "files `D-test-oracle`.",
        "",
        "| domain | trials | plan success | final success | placement error, median | failures |",
        "|---|---|---|---|---|---|",
    ]
    for d in names:
        run = got[f"{d}-test-oracle"]
        if run is None:
            out.append(f"| {d} | – | not run | not run | – | – |")
            continue
        p = run["precision"]
        placed = (
            "–"
            if p["median_position_error_mm"] is None
            else f"{p['median_position_error_mm']:.2f} mm, {p['median_yaw_error_deg']:.2f}°"
        )
        out.append(
            f"| {d} | {run['trials']} | {rate(run, 'plan_sr')} | {rate(run, 'final_sr')}"
            f" | {placed} | {_stages(run)} |"
        )
    return out


def _closed_loop(got: Files, names: Sequence[str]) -> list[str]:
    """The closed loop against the open one, without faults."""
    out: list[str] = [
        "",
        "## Closed loop (test split, front camera, no faults)",
        "",
        "`--loop closed`: after each transfer the robot looks again and, where the scene is not",
        'what it believed, plans again with the same frozen programs (docs/executor.md, "Closed',
        'loop and faults"). Beside it, the open loop of Table I. Run files',
        "`D-test-front-closed`.",
        "",
        "| domain | open loop: final | closed loop: final | trial wall, median: open / closed |",
        "|---|---|---|---|",
    ]
    for d in names:
        o, c = got[f"{d}-test-front"], got[f"{d}-test-front-closed"]
        walls = " / ".join(
            "–" if r is None else f"{r['timing']['median_trial_wall_s']:.1f} s" for r in (o, c)
        )
        out.append(f"| {d} | {rate(o, 'final_sr')} | {rate(c, 'final_sr')} | {walls} |")
    out += [
        "",
        "Failing closed-loop trials:",
        "",
        *_failing([(d, got[f"{d}-test-front-closed"]) for d in names], limit=4),
    ]
    return out


def _faults(got: Files, names: Sequence[str]) -> list[str]:
    """Recovery per injected fault."""
    out: list[str] = [
        "",
        "## Faults (test split, front camera)",
        "",
        '`--faults F`: one fault per trial at a seeded moment (docs/executor.md, "Closed loop and',
        'faults"): `slip` (the hand lets go during a transfer), `push` (a placed part pushed',
        "20–40 mm), `move` (a person moves a part), `bias` (a start part believed 15 mm off),",
        "`skip` (a transfer silently skipped). The closed loop on the first 20 test trials, the",
        'open loop on the first 5, the same fault at the same moment in both. "Happened": the',
        'fault took place (a trial whose plan was refused draws none); "recovered": final',
        'success; "gave up": the loop stopped within its budget, saying why; "wrong": it',
        'ended done off the goal. "Toppled": of the trials not recovered, those in which the',
        "fault left a part on another face (the world's truth, judged once the parts came to",
        "rest): a hand that picks from above and turns parts only about the vertical cannot",
        "right it, so the last column is the recovery rate of the rest. Run files",
        "`D-test-FAULT-closed` and `D-test-FAULT-open`.",
        "",
        "| domain | fault | open loop: final | closed: happened | recovered | gave up | wrong |"
        " toppled | recovered, 95 % interval | recovered of the rest |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def rate(k: int, n: int, span) -> str:
        return "–" if span is None else f"{k}/{n}: {100 * span[0]:.1f}–{100 * span[1]:.1f}"

    for d in names:
        for f in FAULTS:
            o, c = got[f"{d}-test-{f}-open"], got[f"{d}-test-{f}-closed"]
            opened = (
                "not run"
                if o is None
                else (f"{sum(t['final_ok'] for t in o['per_trial'])}/{o['trials']}")
            )
            row = None if c is None else c.get("faults", {}).get(f)
            if row is None:
                out.append(f"| {d} | {f} | {opened} | not run | | | | | | |")
                continue
            k, n = row["recovered"], row["happened"]
            # a run made before topples were recorded: none to count when every trial recovered
            toppled = row.get("toppled", 0 if k == n else None)
            rest = (
                "not recorded"
                if toppled is None
                else rate(k, n - toppled, row.get("recoverable_interval", row["interval"]))
            )
            out.append(
                f"| {d} | {f} | {opened} | {n}/{row['drawn']} | {k} | {row['gave_up']}"
                f" | {row['wrong']} | {'–' if toppled is None else toppled}"
                f" | {rate(k, n, row['interval'])} | {rest} |"
            )
    return out


def _timings(got: Files, names: Sequence[str]) -> list[str]:
    """Table I's runs: latency, the programs' CPU, wall times."""
    out: list[str] = [
        "",
        "## Timings (front camera, `--workers 2`)",
        "",
        "Policy latency is the wall time of a trial's five program calls (perceive ×2, relate ×2,",
        "plan) through the sandbox; CPU is the programs' own. Table I's runs.",
        "",
        "| domain | split | policy latency, median | CPU in the programs, median |"
        " trial wall, median | 60 trials |",
        "|---|---|---|---|---|---|",
    ]
    for d in names:
        for split in ("dev", "test"):
            run = got[f"{d}-{split}-front"]
            if run is None:
                out.append(f"| {d} | {split} | – | – | – | – |")
                continue
            t = run["timing"]
            out.append(
                f"| {d} | {split} | {1000 * t['median_policy_latency_s']:.0f} ms | "
                f"{1000 * t['median_policy_cpu_s']:.0f} ms | {t['median_trial_wall_s']:.1f} s | "
                f"{_minutes(run)} |"
            )
    return out


def _checks_benchmark(got: Files, names: Sequence[str]) -> list[str]:
    """The checks' mutation benchmark."""
    out: list[str] = [
        "",
        "## The checks' mutation benchmark",
        "",
        "Each reference program checked 10 times on one fresh draw (none may be rejected, the",
        "reports must be identical) and each mutant of the domain's catalogue, a realistic bug",
        'planted in a reference program, checked once on fresh draws (docs/checks.md, "Mutation',
        'benchmark"). A program from the field (a model-written draft that passed the checks',
        "of its day and failed in trials, ../shared/field) is checked on 5 fresh draws. Run",
        "files `checks-D`.",
        "",
        "| domain | mutants rejected | correct programs rejected | identical reports |"
        " one check, median / max | missed | from the field: rejected draws |",
        "|---|---|---|---|---|---|---|",
    ]
    for d in names:
        bench = got[f"checks-{d}"]
        if bench is None:
            out.append(f"| {d} | not run | | | | | |")
            continue
        b = bench["summary"]
        low, high = wilson(b["caught"], b["mutants"]) or (0.0, 1.0)
        rejected = (
            f"{b['caught']}/{b['mutants']}: {100 * b['caught_rate']:.1f} % "
            f"({100 * low:.1f}–{100 * high:.1f})"
        )
        missed = ", ".join(f"`{m['mutant']}`" for m in bench["mutants"] if not m["caught"])
        out.append(
            f"| {d} | {rejected} | {b['false_rejections']} of {b['correct_runs']} runs | "
            f"{'yes' if b['all_reports_identical'] else 'no'} | {b['seconds_per_check_median']} / "
            f"{b['seconds_per_check_max']} s | {missed or 'none'} | "
            + (
                "; ".join(
                    f"`{f['program']}` {f['rejected']} of {f['draws']}"
                    for f in bench.get("field", [])
                )
                or "none"
            )
            + " |"
        )
    cases = [
        f"- `{f['program']}`: {f['case']}"
        for d in names
        for f in (got[f"checks-{d}"] or {}).get("field", [])
        if f.get("case")
    ]
    if cases:
        out += ["", "A case each program from the field got wrong:", "", *cases]
    return out


def _runs_table(got: Files, all_runs: Sequence[Run]) -> list[str]:
    """Every run: command, date, commit, set, wall time."""
    out: list[str] = [
        "",
        "## Runs",
        "",
        "Each run's command (run from the repository root), the UTC date it finished, the commit",
        'it ran on ("+" where tracked files differed from it), the evaluated set (marked where',
        "it is not the set committed in artifacts/ now: such a run is to be made again) and the",
        "run's wall time, on a 2-core machine that other work may have shared: compare wall",
        "times within a run, not across runs.",
        "",
        "| run file | command | date | commit | set | wall |",
        "|---|---|---|---|---|---|",
    ]
    for spec in all_runs:
        found = got[spec.key]
        if found is None:
            out.append(f"| {spec.key} | `{spec.command}` | not run | | | |")
            continue
        meta = _meta(found)
        commit = (meta.get("commit") or "?") + ("+" if meta.get("dirty") else "")
        set_hash = (found.get("set_hash") or "")[:8] or "–"
        if found.get("set_hash") and found["set_hash"] != _committed_set(found["domain"]):
            set_hash += " (not the committed set)"
        out.append(
            f"| {spec.key} | `{meta['command']}` | {meta['date'][:16].replace('T', ' ')} | "
            f"{commit} | {set_hash} | {_minutes(found)} |"
        )
    return out


def _caveats() -> list[str]:
    """What the figures do not say."""
    return [
        "",
        "## Caveats",
        "",
        "- The dev split is where the programs were written and fixed: its rows are not held out.",
        "- Some test figures are not blind: the cubes programs' (walled-in goal places were first",
        "  reported from test trials, then found by a property test over the task text and fixed:",
        '  docs/domains.md, "Splits"), the executor alone on assembly (a change built for the',
        "  failure a test trial named, once a dev trial showed it), and the closed loop's on the",
        "  envelope cameras (its doubting a look before giving up was built for an assembly trial",
        "  through envelope-3 that the open loop finished).",
        "- The rows of 20 trials are the first 20 of the test split; their intervals are wide.",
        "- The wrist-camera in-hand estimate is a noise model on the true pose (0.3 mm, 0.3°) of the",
        "  object in the hand or between the open jaws, a stand-in for an image pipeline.",
        "- Each row names the commit it ran on. The oracle rows ran before 409fbf1, without the",
        "  executor's camera-offset estimate; `rivet eval --no-camera-offset` runs without it.",
        "- Other measurements live with what they measure: the perceive draws and the check and",
        "  gate times in docs/checks.md, the sandbox's overheads in docs/sandbox.md, the executor's",
        "  own sweeps and a trial worker's memory in docs/executor.md; each names its command.",
        "",
    ]


def render(folder: Path = RUN_FILES, names: Sequence[str] | None = None) -> str:
    """The page, from the run files in `folder`."""
    names = list(domains.names() if names is None else names)
    all_runs = runs(names)
    got = {r.key: load(r.key, folder) for r in all_runs}
    sections = (
        _table_i,
        _table_iii,
        _executor_alone,
        _closed_loop,
        _faults,
        _timings,
        _checks_benchmark,
    )
    out = _intro()
    for section in sections:
        out += section(got, names)
    out += _runs_table(got, all_runs) + _caveats()
    return "\n".join(out)


# -- the command line ---------------------------------------------------------------------------


def _run(keys: Sequence[str]) -> int:
    import os

    known = {r.key: r for r in runs()}
    if unknown := [k for k in keys if k not in known]:
        print(f"unknown run {', '.join(unknown)}; known: {', '.join(known)}", file=sys.stderr)
        return 2
    todo = [known[k] for k in keys] if keys else [r for r in known.values() if load(r.key) is None]
    this_venv = {  # the programs of this interpreter's environment
        "eval": [str(Path(sys.executable).parent / "rivet")],
        "checks": [sys.executable, *CHECKS_BENCH[1:]],
    }
    failed: list[str] = []
    for k, r in enumerate(todo, 1):
        print(f"[{k}/{len(todo)}] {r.command}", file=sys.stderr, flush=True)
        full = REPO / r.output
        full.unlink(missing_ok=True)
        proc = subprocess.run(
            [*this_venv[r.tool], *r.argv], cwd=REPO, env=os.environ.copy(), check=False
        )
        if proc.returncode in (130, 143):  # interrupted or terminated: stop here
            print(
                f"{r.key}: stopped (exit {proc.returncode}); the runs before it are kept",
                file=sys.stderr,
            )
            return proc.returncode
        if not full.is_file():  # a run that fails goes on to the next (hours of them)
            print(f"{r.key}: no summary written (exit {proc.returncode})", file=sys.stderr)
            failed.append(r.key)
            continue
        kept = write(r.key, json.loads(full.read_text()))
        print(f"  → {kept.relative_to(REPO)}", file=sys.stderr)
    if failed:
        print(
            f"{len(failed)} of {len(todo)} runs wrote no summary: {', '.join(failed)}",
            file=sys.stderr,
        )
    return 1 if failed else 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m experiments.results",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="what", required=True)
    p_run = sub.add_parser("run", help="run the commands whose run files are missing, or KEYs")
    p_run.add_argument("keys", nargs="*", metavar="KEY")
    p_render = sub.add_parser("render", help="write docs/results.md from docs/results/")
    p_render.add_argument("--check", action="store_true", help="exit 1 if the page differs")
    p_compact = sub.add_parser("compact", help="keep a run made with `rivet eval --json FULL`")
    p_compact.add_argument("full", type=Path)
    p_compact.add_argument("key")
    args = parser.parse_args(argv)
    if args.what == "run":
        return _run(args.keys)
    if args.what == "compact":
        if args.key not in {r.key for r in runs()}:
            print(f"unknown run {args.key}", file=sys.stderr)
            return 2
        try:
            print(write(args.key, json.loads(args.full.read_text())))
        except (OSError, ValueError) as e:
            print(f"{args.full}: {e}", file=sys.stderr)
            return 2
        return 0
    page = render()
    if args.check:
        same = PAGE.is_file() and PAGE.read_text() == page
        if not same:
            print(
                f"{PAGE.relative_to(REPO)} is not what docs/results/ renders: make results",
                file=sys.stderr,
            )
        return 0 if same else 1
    PAGE.write_text(page)
    print(PAGE.relative_to(REPO))
    return 0


if __name__ == "__main__":
    sys.exit(main())
