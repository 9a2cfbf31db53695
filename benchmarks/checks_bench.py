"""The checks' mutation benchmark: do the checks reject realistic bugs, and only those?

For a domain's hand-written reference programs (`domains/<domain>/programs/`):
- every correct program is checked `--repeats` times: none may be rejected, and all its
  reports must be identical once timings are left out (no flakiness);
- every mutant of `domains/<domain>/mutants.toml` (a reference program with a planted bug) is
  checked once: it must be rejected; the table says by which check.
Targets (issues 6, 16): in each domain at least 95 % of mutants rejected, zero rejections
of the correct programs.
- every program from the field in `--field DIR` (default ../shared/field, read in place:
  model-written drafts that passed the checks of their day and failed in trials, named
  `<domain>_<function>_<what>.py`) is checked on `--field-draws` fresh draws: the table says
  on how many it was rejected, and a case it got wrong on each.

Usage:
    python -m benchmarks.checks_bench [--domain all|cubes|tangram|assembly] [--repeats 10]
        [--sandbox docker|local] [--only NAME[,NAME…]] [--seed S] [--out DIR]
        [--field DIR] [--field-draws N]
Every mutant's check draws its cases afresh (`checks.inputs`); the repeats of a correct
program share one draw, so that their reports can be compared. `--seed S` draws every check's
cases from S instead; each row records the seed its cases came from (`cases_seed`), so
`--only NAME --seed S` checks a mutant on the same cases again.
Writes DIR/bench_checks.md (the table) and DIR/bench_checks.json — with `--domain all` (the
default) one DIR/<domain>/ of each per domain and the per-domain totals in DIR; exit 0 when
both targets are met in every domain, 1 otherwise, 2 for a broken catalogue.
"""

from __future__ import annotations

import argparse
import ast
import io
import json
import statistics
import sys
import textwrap
import time
import tokenize
import tomllib
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import domains
from artifacts.provenance import run_record
from contracts.functions import FUNCTIONS

REPO = Path(__file__).resolve().parent.parent
TARGET_CAUGHT = 0.95
FIELD = REPO.parent / "shared" / "field"  # programs from the field, read in place


class CatalogueError(Exception):
    """A mutant's replacement does not apply to its reference program."""


@dataclass(frozen=True, kw_only=True)
class Mutant:
    name: str
    function: str
    bug: str
    description: str
    source: str


def programs(domain: str) -> dict[str, str]:
    folder = REPO / "domains" / domain / "programs"
    return {f: (folder / f"{f}.py").read_text() for f in FUNCTIONS}


def field_programs(folder: Path | None, domain: str) -> list[tuple[str, str, Path]]:
    """(name, function, path) of `domain`'s programs from the field in `folder`
    (`<domain>_<function>_<what>.py`); none where the folder is not there."""
    if folder is None or not folder.is_dir():
        return []
    out = []
    for path in sorted(folder.glob(f"{domain}_*.py")):
        function = path.stem[len(domain) + 1 :].split("_", 1)[0]
        if function in FUNCTIONS:
            out.append((path.stem, function, path))
    return out


def catalogue(domain: str) -> Path:
    """The mutant catalogue of a domain (beside its programs)."""
    return REPO / "domains" / domain / "mutants.toml"


def load_mutants(path: Path, references: dict[str, str]) -> list[Mutant]:
    """The catalogue's mutants with their sources (replacements applied and verified)."""
    if not path.is_file():
        known = ", ".join(sorted(p.parent.name for p in (REPO / "domains").glob("*/mutants.toml")))
        raise CatalogueError(f"no mutant catalogue {path}; domains with one: {known}")
    data = tomllib.loads(path.read_text())
    out, names = [], set()
    for m in data["mutant"]:
        if m["name"] in names:
            raise CatalogueError(f"mutant {m['name']!r} is listed twice")
        names.add(m["name"])
        if m["function"] not in references:
            raise CatalogueError(f"{m['name']}: unknown function {m['function']!r}")
        source = references[m["function"]]
        for k, (old, new) in enumerate(m["replace"]):
            try:
                source = replace_once(source, old, new, within=m.get("within"))
            except CatalogueError as e:
                raise CatalogueError(
                    f"{m['name']}: replacement {k} in {m['function']}.py: {e}"
                ) from None
        if source == references[m["function"]]:
            raise CatalogueError(f"{m['name']}: the replacements change nothing")
        out.append(
            Mutant(
                name=m["name"],
                function=m["function"],
                bug=m["bug"],
                description=m["description"],
                source=source,
            )
        )
    return out


_LAYOUT = {
    tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
    tokenize.ENCODING, tokenize.ENDMARKER,
}  # fmt: skip


def _code_tokens(text: str) -> list[tokenize.TokenInfo]:
    """`text`'s tokens without comments, line breaks and indentation (a fragment — half a
    call, a dict entry — is fine)."""
    out = []
    try:
        for t in tokenize.generate_tokens(io.StringIO(textwrap.dedent(text)).readline):
            if t.type not in _LAYOUT:
                out.append(t)
    except (tokenize.TokenError, IndentationError):
        pass  # an unclosed bracket at the end of a fragment: the tokens before it stand
    return out


def _offsets(source: str) -> Callable[[tuple[int, int]], int]:
    """Character offset in `source` of a tokenizer position (row from 1, column)."""
    starts = [0]
    for line in source.splitlines(keepends=True):
        starts.append(starts[-1] + len(line))
    return lambda at: starts[at[0] - 1] + at[1]


def replace_once(source: str, old: str, new: str, *, within: str | None = None) -> str:
    """`source` with `old` replaced by `new`, where `old` occurs exactly once.

    `old` is matched as code, not as text: as its tokens, comments, line breaks and
    indentation aside, so a re-wrapped line, a changed comment or an edit elsewhere in the
    program leaves a mutant applying. `within` names a function (or `Class.method`) to look in
    only. The text `old` spans in `source` is replaced; `new`'s lines after the first take the
    indentation they have relative to `old`'s first line. Raises `CatalogueError` otherwise."""
    lo, hi = 0, len(source)
    if within is not None:
        lo, hi = _function_span(source, within)
    if within is None and source.count(old) == 1:
        return source.replace(old, new)  # written as the program reads
    if old.endswith("\n") and new.endswith("\n"):
        new = new[:-1]  # the span replaced ends at `old`'s last token, before its line break
    want = [(t.type, t.string) for t in _code_tokens(old)]
    if not want:
        raise CatalogueError("the old text has no code in it")
    offset = _offsets(source)
    tokens = [t for t in _code_tokens(source) if lo <= offset(t.start) and offset(t.end) <= hi]
    have = [(t.type, t.string) for t in tokens]
    starts = [i for i in range(len(have) - len(want) + 1) if have[i : i + len(want)] == want]
    if len(starts) != 1:
        where = f" in {within}" if within else ""
        raise CatalogueError(
            f"matches {len(starts)} times{where} (must be exactly once): {old[:80]!r}"
        )
    first, last = tokens[starts[0]], tokens[starts[0] + len(want) - 1]
    begin, end = offset(first.start), offset(last.end)
    line = first.line.splitlines()[0] if first.line else ""
    indent = line[: len(line) - len(line.lstrip())]  # where `old` stands in `source`
    written = old[: len(old) - len(old.lstrip(" "))]  # `old`'s own indentation
    body = [
        row[len(written) :] if row.startswith(written) else row
        for row in new.lstrip(" ").split("\n")
    ]
    text = "\n".join([body[0], *(indent + row if row else row for row in body[1:])])
    return source[:begin] + text + source[end:]


def _function_span(source: str, name: str) -> tuple[int, int]:
    """(start, end) character offsets of the function `name` (`f` or `Class.method`)."""
    tree = ast.parse(source)
    scope: list[ast.stmt] = tree.body
    *outer, leaf = name.split(".")
    for part in outer:
        found = [n for n in scope if isinstance(n, ast.ClassDef) and n.name == part]
        if not found:
            raise CatalogueError(f"no class {part!r}")
        scope = found[0].body
    defs = [
        n for n in scope if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef) and n.name == leaf
    ]
    if len(defs) != 1:
        raise CatalogueError(f"{len(defs)} functions named {name!r}")
    node = defs[0]
    start = node.decorator_list[0].lineno if node.decorator_list else node.lineno
    assert node.end_lineno is not None
    offset = _offsets(source + "\n")
    return offset((start, 0)), offset((node.end_lineno + 1, 0))


def check(
    domain: str,
    function: str,
    source: str,
    refs: dict[str, str],
    executor: Any,
    out: Path,
    seed: int | None = None,
):
    from checks import run_checks

    deps = {d: src for d, src in refs.items() if d != function}
    t0 = time.perf_counter()
    report = run_checks(
        domain, function, source, deps=deps, executor=executor, out_dir=out, cases_seed=seed
    )
    return report, time.perf_counter() - t0


def failing(report: dict) -> list[str]:
    from checks.report import passes

    return [c["name"] for c in report["checks"] if not passes(c)]


# `--domain all`: every registered domain with a mutant catalogue (an optional extra of a
# domain, beside its people-written programs)
DOMAINS = tuple(n for n in domains.names() if (domains.load(n).root / "mutants.toml").is_file())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.checks_bench", description=__doc__)
    parser.add_argument(
        "--domain", default="all", help=f"a domain, or 'all' ({', '.join(DOMAINS)}; the default)"
    )
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--sandbox", choices=("docker", "local"), default="docker")
    parser.add_argument("--only", default="", help="comma-separated mutant names (no repeats)")
    parser.add_argument(
        "--seed", type=int, default=None, help="draw every check's cases from this seed"
    )
    parser.add_argument("--out", type=Path, default=REPO / "runs" / "bench-checks")
    parser.add_argument(
        "--field",
        type=Path,
        default=FIELD,
        help="folder of programs from the field, <domain>_<function>_<what>.py (default "
        "../shared/field; read in place)",
    )
    parser.add_argument(
        "--field-draws", type=int, default=5, help="fresh draws per field program (0: none)"
    )
    args = parser.parse_args(argv)
    if args.repeats < 0 or args.field_draws < 0:
        parser.error("--repeats and --field-draws take a count ≥ 0")
    args.argv = list(sys.argv[1:] if argv is None else argv)  # for each summary's "run"

    import sandbox

    names = list(DOMAINS) if args.domain == "all" else [args.domain]
    loaded: dict[str, tuple[dict[str, str], list[Mutant]]] = {}
    only = {n for n in args.only.split(",") if n}
    for domain in names:
        refs = programs(domain)
        try:
            mutants = load_mutants(catalogue(domain), refs)
        except CatalogueError as e:
            print(f"broken catalogue: {e}", file=sys.stderr)
            return 2
        if only:
            mutants = [m for m in mutants if m.name in only]
        loaded[domain] = (refs, mutants)
    if only:
        unknown = only - {m.name for _, ms in loaded.values() for m in ms}
        if unknown:
            print(f"unknown mutants {sorted(unknown)}", file=sys.stderr)
            return 2
    args.out.mkdir(parents=True, exist_ok=True)
    summaries = []
    ok = True
    with sandbox.open_executor(args.sandbox) as ex:
        for domain, (refs, mutants) in loaded.items():
            if only and not mutants:
                continue
            out = args.out / domain if len(names) > 1 else args.out
            summary, good = bench_domain(domain, refs, mutants, args, ex, out, only=bool(only))
            summaries.append(summary)
            ok = ok and good
    if len(names) > 1:
        (args.out / "bench_checks.json").write_text(json.dumps({"domains": summaries}, indent=1))
        md = render_totals(summaries)
        (args.out / "bench_checks.md").write_text(md)
        print()
        print(md)
    return 0 if ok else 1


def bench_domain(
    domain: str,
    refs: dict[str, str],
    mutants: list[Mutant],
    args: argparse.Namespace,
    ex: Any,
    out: Path,
    *,
    only: bool,
) -> tuple[dict[str, Any], bool]:
    """One domain's benchmark: its correct programs `args.repeats` times, each mutant once;
    writes OUT/bench_checks.{md,json}; (summary, both targets met)."""
    from checks import comparable
    from checks.inputs import fresh_seed

    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    times: list[float] = []
    correct_rows: list[dict[str, Any]] = []
    mutant_rows: list[dict[str, Any]] = []
    repeats = 0 if only else args.repeats
    for fn in FUNCTIONS if repeats else ():
        seed = fresh_seed() if args.seed is None else args.seed  # one draw for the repeats
        reports = []
        for k in range(repeats):
            report, dt = check(domain, fn, refs[fn], refs, ex, out / "images" / fn, seed)
            times.append(dt)
            reports.append(report)
            print(
                f"{domain} {fn} run {k + 1}/{repeats}: "
                f"{'pass' if report['passed'] else 'REJECTED'} {failing(report)} ({dt:.1f} s)",
                flush=True,
            )
        identical = all(comparable(r) == comparable(reports[0]) for r in reports)
        correct_rows.append(
            {
                "function": fn,
                "runs": repeats,
                "rejections": sum(not r["passed"] for r in reports),
                "identical_reports": identical,
                "rejected_by": sorted({n for r in reports for n in failing(r)}),
                "cases_seed": seed,
            }
        )
    for m in mutants:
        report, dt = check(
            domain, m.function, m.source, refs, ex, out / "images" / m.name, args.seed
        )
        times.append(dt)
        fails = failing(report)
        mutant_rows.append(
            {
                "mutant": m.name,
                "function": m.function,
                "bug": m.bug,
                "caught": not report["passed"],
                "first_failure": report["first_failure"],
                "failing": fails,
                # each failing check's [cases failed, cases checked]: a mutant that fails only
                # where the correct program fails too (same seed) is not caught
                "failures": {
                    c["name"]: [c.get("failures"), c.get("examples")]
                    for c in report["checks"]
                    if c["name"] in fails
                },
                "seconds": round(dt, 1),
                "cases_seed": report.get("cases_seed"),
            }
        )
        print(
            f"{domain} {m.name}: "
            f"{'caught by ' + str(report['first_failure']) if fails else 'MISSED'} ({dt:.1f} s, "
            f"cases seed {report.get('cases_seed')})",
            flush=True,
        )
    field_rows = [] if only else bench_field(domain, refs, args, ex, out, times)
    caught = sum(r["caught"] for r in mutant_rows)
    rate = caught / len(mutant_rows) if mutant_rows else 1.0
    false_rejections = sum(r["rejections"] for r in correct_rows)
    first = Counter(r["first_failure"] for r in mutant_rows if r["caught"])
    summary = {
        "domain": domain,
        "mutants": len(mutant_rows),
        "caught": caught,
        "caught_rate": round(rate, 4),
        "caught_by_first": dict(sorted(first.items(), key=lambda kv: (-kv[1], kv[0]))),
        "mutants_per_function": dict(Counter(r["function"] for r in mutant_rows)),
        "correct_runs": sum(r["runs"] for r in correct_rows),
        "false_rejections": false_rejections,
        "all_reports_identical": all(r["identical_reports"] for r in correct_rows),
        "field": [
            {k: r[k] for k in ("program", "function", "draws", "rejected")} for r in field_rows
        ],
        "seconds_per_check_median": round(statistics.median(times), 1) if times else None,
        "seconds_per_check_max": round(max(times), 1) if times else None,
        "wall_s": round(time.perf_counter() - t_start, 1),
        "sandbox": args.sandbox,
        "run": run_record(args.argv, program=("python", "-m", "benchmarks.checks_bench")),
    }
    (out / "bench_checks.json").write_text(
        json.dumps(
            {
                "summary": summary,
                "correct": correct_rows,
                "mutants": mutant_rows,
                "field": field_rows,
            },
            indent=1,
        )
    )
    md = render_markdown(summary, correct_rows, mutant_rows, field_rows)
    (out / "bench_checks.md").write_text(md)
    print()
    print(md)
    good = rate >= TARGET_CAUGHT and false_rejections == 0 and summary["all_reports_identical"]
    return summary, good


def bench_field(
    domain: str, refs: dict[str, str], args: argparse.Namespace, ex: Any, out: Path, times: list
) -> list[dict[str, Any]]:
    """Each of `domain`'s programs from the field (`field_programs`) checked on
    `args.field_draws` draws (fresh ones, or `--seed S`, S+1, …): one row per program."""
    from checks.inputs import fresh_seed

    rows = []
    for name, function, path in field_programs(args.field, domain):
        draws = []
        for k in range(args.field_draws):
            seed = fresh_seed() if args.seed is None else args.seed + k
            report, dt = check(
                domain, function, path.read_text(), refs, ex, out / "images" / name, seed
            )
            times.append(dt)
            draws.append(
                {
                    "cases_seed": seed,
                    "rejected": not report["passed"],
                    "first_failure": report["first_failure"],
                    "case": _first_case(report),
                    "seconds": round(dt, 1),
                }
            )
            print(
                f"{domain} field {name} draw {k + 1}/{args.field_draws}: "
                f"{'REJECTED by ' + str(report['first_failure']) if not report['passed'] else 'pass'}"
                f" ({dt:.1f} s, cases seed {seed})",
                flush=True,
            )
        rows.append(
            {
                "program": name,
                "function": function,
                "path": str(path),
                "draws": len(draws),
                "rejected": sum(d["rejected"] for d in draws),
                "case": next((d["case"] for d in draws if d["case"]), None),
                "draw_rows": draws,
            }
        )
    return rows


def _first_case(report: dict) -> str | None:
    """The first line of what the first failing check found: it names the case."""
    for c in report["checks"]:
        if c["name"] == report["first_failure"] and c.get("message"):
            return str(c["message"]).splitlines()[0][:300]
    return None


def render_totals(summaries: list[dict]) -> str:
    """The per-domain figures in one table."""
    lines = [
        "# Checks mutation benchmark: every domain",
        "",
        "| domain | mutants | rejected | correct runs | false rejections | identical reports "
        "| wall time | caught first by | from the field: rejected draws |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summaries:
        by = ", ".join(f"`{k}` {v}" for k, v in s["caught_by_first"].items())
        field = "; ".join(f"{f['program']} {f['rejected']}/{f['draws']}" for f in s["field"])
        lines.append(
            f"| {s['domain']} | {s['mutants']} | {s['caught']} ({100 * s['caught_rate']:.1f} %) "
            f"| {s['correct_runs']} | {s['false_rejections']} | {s['all_reports_identical']} "
            f"| {s['wall_s']:.0f} s | {by} | {field or '–'} |"
        )
    return "\n".join(lines) + "\n"


def render_markdown(
    summary: dict, correct: list[dict], mutants: list[dict], field: list[dict] | None = None
) -> str:
    lines = [
        f"# Checks mutation benchmark ({summary['domain']}, sandbox {summary['sandbox']})",
        "",
        f"- mutants rejected: **{summary['caught']}/{summary['mutants']} "
        f"({100 * summary['caught_rate']:.1f} %)** (target ≥ {100 * TARGET_CAUGHT:.0f} %)",
        f"- correct programs rejected: **{summary['false_rejections']} of "
        f"{summary['correct_runs']} runs** (target 0); identical reports on repeats: "
        f"{summary['all_reports_identical']}",
        f"- time per full check: median {summary['seconds_per_check_median']} s, max "
        f"{summary['seconds_per_check_max']} s; wall time {summary['wall_s']:.0f} s",
        "- caught first by: "
        + (", ".join(f"`{k}` {v}" for k, v in summary["caught_by_first"].items()) or "(none)"),
        "",
    ]
    if correct:
        lines += [
            "| correct program | runs | rejections | identical reports |",
            "|---|---|---|---|",
        ]
        lines += [
            f"| {r['function']} | {r['runs']} | {r['rejections']} | {r['identical_reports']} |"
            for r in correct
        ]
        lines.append("")
    lines += [
        "| mutant | function | bug | caught by (first) | all failing checks |",
        "|---|---|---|---|---|",
    ]
    for r in mutants:
        first = f"`{r['first_failure']}`" if r["caught"] else "**missed**"
        lines.append(
            f"| {r['mutant']} | {r['function']} | {r['bug']} | {first} | "
            f"{', '.join(r['failing'])} |"
        )
    if field:
        lines += [
            "",
            "| program from the field | function | rejected draws | a case it got wrong |",
            "|---|---|---|---|",
        ]
        lines += [
            f"| {r['program']} | {r['function']} | {r['rejected']} of {r['draws']} "
            f"| {r['case'] or '–'} |"
            for r in field
        ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
