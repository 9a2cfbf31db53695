"""Many trials: the benchmark protocol (20 goals × 3 starts), metrics, attribution, tables.

Trials run in worker processes (`workers`); each worker builds its own domain and policy, so
nothing crosses process boundaries but instance names and JSON results.

Every finished trial is appended to a trial log (`TrialLog`, JSON lines, fsynced) as it
finishes: an interrupted run keeps what it finished, and `resume` continues it, running only
the trials the log does not hold. The log's first line is the evaluation's configuration; a
log of another configuration is refused, never mixed in. Interrupted (Ctrl-C, or SIGTERM to the
command alone, as a cancelled CI job sends), a pool of workers stops at once: the trials not
begun are cancelled, and each worker ends its trial, closes its sandbox and exits (`_stop`).
"""

from __future__ import annotations

import json
import statistics
import sys
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from artifacts import jsonl
from artifacts.policy import PolicySpec
from artifacts.policy import make_policy as policy_of
from sim.trials import HONEST, TrialProtocol

# The paper's figures (Table I: front camera; Table III: final success on two more viewpoints).
PAPER = {
    "cubes": {"state_ac": 1.0, "plan_sr": 1.0, "final_sr": 1.0, "view1": 0.933, "view2": 1.0},
    "tangram": {"state_ac": 0.90, "plan_sr": 0.90, "final_sr": 0.90, "view1": 1.0, "view2": 0.867},
    "assembly": {
        "state_ac": 0.933,
        "plan_sr": 0.867,
        "final_sr": 0.867,
        "view1": 0.80,
        "view2": 0.767,
    },
}


@dataclass(frozen=True, kw_only=True)
class EvalConfig:
    """One evaluation: a domain, a policy, a camera, a protocol.

    Attributes:
        camera: a view name, or a camera dict (e.g. from `sim.observation.load_camera`).
        view: how the camera is named in reports (the view name, or the camera file's stem).
        sandbox: where the policy's programs run ("docker", or "local" for speed).
    """

    domain: str
    policy: PolicySpec
    view: str = "front"
    camera: Any = None
    protocol: TrialProtocol = HONEST
    split: str = "dev"
    sandbox: str = "docker"
    record_root: str | None = None
    loop: str = "open"  # "closed": look again after each transfer and replan (sim.loop)
    faults: tuple[str, ...] = ()  # one fault per trial drawn from these (sim.faults)
    fit: bool = False  # judge each perceived state's fit (artifacts.fit) into the trial JSON


def make_policy(config: EvalConfig) -> Any:
    return policy_of(config.domain, config.policy, sandbox=config.sandbox, fit=config.fit)


_WORKER: dict[str, Any] = {}


def _init_pool_worker(config: EvalConfig) -> None:
    _stop_on_sigterm()
    _init_worker(config)


def _init_worker(config: EvalConfig) -> None:
    import domains
    from sim.trials import prepare

    _WORKER["domain"] = domains.load(config.domain)
    prepare(_WORKER["domain"], record=config.record_root is not None)
    _WORKER["policy"] = make_policy(config)
    _WORKER["config"] = config


def _stop_on_sigterm() -> None:
    """A pool worker's SIGTERM (what `run_eval` sends each worker when it is interrupted) ends
    the worker now: a trial under way unwinds as on Ctrl-C, the worker's sandbox session closes
    (its container removed), and the process exits. Only the first SIGTERM counts."""
    import signal

    def on_sigterm(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if _WORKER.get("busy"):
            raise _Stopped  # `_run_one` closes the policy and exits
        _exit_worker()

    signal.signal(signal.SIGTERM, on_sigterm)


class _Stopped(BaseException):
    """A trial worker told to stop (SIGTERM) in the middle of a trial."""


def _exit_worker() -> None:
    import os

    policy = _WORKER.get("policy")
    try:
        if policy is not None and callable(getattr(policy, "close", None)):
            policy.close()
    finally:
        os._exit(143)


def _run_one(instance_json: dict) -> dict:
    _WORKER["busy"] = True
    try:
        return _trial(instance_json)
    except _Stopped:
        _exit_worker()
        raise  # not reached
    finally:
        _WORKER["busy"] = False


def _trial(instance_json: dict) -> dict:
    from domains.instance import Instance
    from sim.trials import run_trial

    cfg: EvalConfig = _WORKER["config"]
    instance = Instance.from_dict(instance_json)
    record = Path(cfg.record_root) / instance.name if cfg.record_root else None
    try:
        result = run_trial(
            _WORKER["domain"],
            instance,
            _WORKER["policy"],
            camera=cfg.camera if cfg.camera is not None else cfg.view,
            protocol=cfg.protocol,
            record_dir=record,
            loop=cfg.loop,  # type: ignore[arg-type]
            faults=cfg.faults,
        ).to_dict()
    except Exception as e:  # a broken trial must not stop the run
        import traceback

        result = {
            "name": instance.name,
            "state_ok": False,
            "plan_ok": False,
            "final_ok": False,
            "failure": {
                "stage": "harness",
                "reason": f"{type(e).__name__}: {e}",
                "traceback": traceback.format_exc(limit=-4),
            },
            "timings": {},
            "steps": [],
            "object_errors": [],
        }
    return result


class TrialLog:
    """One evaluation's trial results as JSON lines: a header with its configuration, then
    one line per finished trial, each on disk (fsynced) before the next one counts.

    Args:
        path: the log file.
        header: what identifies the evaluation (configuration, set hash, trial names).
        resume: keep the trials an earlier log of the same evaluation holds; else start anew.
    Raises:
        UsageError: resuming a log of another evaluation.
    """

    def __init__(self, path: Path, header: dict, *, resume: bool) -> None:
        from contracts import to_jsonable
        from contracts.errors import UsageError

        self.path = path
        self.header = json.loads(json.dumps(to_jsonable(header)))
        self.kept: dict[str, dict] = {}
        if resume and path.is_file():
            lines = jsonl.read(path)
            if not lines or lines[0].get("evaluation") != self.header:
                raise UsageError(
                    f"--resume: {path} is the log of another evaluation (another policy, "
                    "set, camera, split, protocol, loop, faults or trial list); run without "
                    "--resume to start anew"
                )
            self.kept = {r["name"]: r for r in lines[1:] if "name" in r}
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.unlink(missing_ok=True)
            jsonl.append(path, {"evaluation": self.header})

    def earlier(self) -> int:
        """Trials an earlier, unfinished log at this path holds (0: none)."""
        return len(self.kept)

    def add(self, result: dict) -> None:
        jsonl.append(self.path, result)


def run_eval(
    config: EvalConfig,
    instances: Sequence[dict],
    *,
    workers: int = 1,
    progress: Callable[[dict], None] | None = None,
    ray_address: str | None = None,
    log: TrialLog | None = None,
) -> dict:
    """Run every instance (JSON dicts) and summarise; results keep the instances' order.

    `ray_address` fans the trials out to Ray actors (see `experiments.scaleout`) instead of local
    processes. `log`: each finished trial is appended to it, and the trials it already holds
    (a resumed run) are not run again.
    """
    results: dict[int, dict] = {}
    todo: list[tuple[int, dict]] = []
    for i, inst in enumerate(instances):
        kept = log.kept.get(inst.get("name", "")) if log is not None else None
        if kept is not None:
            results[i] = kept
            if progress:
                progress(kept)
        else:
            todo.append((i, inst))

    def done(i: int, result: dict) -> None:
        results[i] = result
        if log is not None:
            log.add(result)
        if progress:
            progress(result)

    if not todo:
        pass
    elif ray_address is not None:
        from experiments.scaleout import map_with_actors

        order = [i for i, _ in todo]
        for k, result in map_with_actors(
            ray_address, _init_worker, config, _run_one, [inst for _, inst in todo], workers=workers
        ):
            done(order[k], result)
    elif workers <= 1:
        _init_worker(config)
        for i, inst in todo:
            done(i, _run_one(inst))
    else:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")  # a fresh GL context per worker; no forked EGL state
        pool = ProcessPoolExecutor(
            workers, mp_context=ctx, initializer=_init_pool_worker, initargs=(config,)
        )
        try:
            futures = {pool.submit(_run_one, inst): i for i, inst in todo}
            for fut in as_completed(futures):
                done(futures[fut], fut.result())
        except BaseException:  # Ctrl-C, SIGTERM (the CLI's), a failing callback
            _stop(pool)
            raise
        pool.shutdown(wait=True)
    per_trial = [results[i] for i in range(len(instances))]
    return summarise(config, per_trial)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Stop an interrupted pool now, not after its running trials: cancel the trials not begun,
    send each worker SIGTERM (`_stop_on_sigterm`: its trial unwinds, its sandbox closes, it
    exits), and wait for them. The finished trials are in the log already."""
    import contextlib
    import os
    import signal

    processes = list((getattr(pool, "_processes", None) or {}).values())  # the pool's own
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        with contextlib.suppress(OSError, AttributeError):
            os.kill(process.pid, signal.SIGTERM)
    for process in processes:
        with contextlib.suppress(AttributeError, ValueError, AssertionError):
            process.join(timeout=60)


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float] | None:
    """The Wilson score interval (95 % by default) of a rate of `successes` in `n` trials;
    None for no trials."""
    if n == 0:
        return None
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    low = 0.0 if successes == 0 else max(0.0, float(centre - half))
    high = 1.0 if successes == n else min(1.0, float(centre + half))
    return low, high


def summarise(config: EvalConfig, per_trial: list[dict]) -> dict:
    n = len(per_trial)
    rate = lambda key: (sum(t[key] for t in per_trial) / n) if n else 0.0  # noqa: E731
    pos = [
        s["position_error"]
        for t in per_trial
        for s in t["steps"]
        if s.get("position_error") is not None
    ]
    yaw = [s["yaw_error"] for t in per_trial for s in t["steps"] if s.get("yaw_error") is not None]
    latency = [t["timings"]["policy"] for t in per_trial if "policy" in t["timings"]]
    cpu = [
        t["timings"]["policy_cpu_total"] for t in per_trial if "policy_cpu_total" in t["timings"]
    ]
    wall = [t["timings"]["total"] for t in per_trial if "total" in t["timings"]]
    sim_t = sum(t["timings"].get("execute_sim", 0.0) for t in per_trial)
    exec_wall = sum(t["timings"].get("execute_wall", 0.0) for t in per_trial)
    return {
        "domain": config.domain,
        "trials": n,
        "state_ac": rate("state_ok"),
        "plan_sr": rate("plan_ok"),
        "final_sr": rate("final_ok"),
        "intervals": {  # Wilson 95 % of each rate
            key: wilson(sum(bool(t[ok]) for t in per_trial), n)
            for key, ok in (
                ("state_ac", "state_ok"),
                ("plan_sr", "plan_ok"),
                ("final_sr", "final_ok"),
            )
        },
        "final_with_failed_plan": sum(t["final_ok"] and not t["plan_ok"] for t in per_trial),
        "view": config.view,
        "split": config.split,
        "policy": " ".join(p for p in config.policy if p),
        "protocol": config.protocol.label,
        "protocol_settings": {
            "realism": config.protocol.realism,
            "in_hand": config.protocol.in_hand,
            "track_objects": config.protocol.track_objects,
            "weld_assist": config.protocol.weld_assist,
        },
        "failures": dict(Counter(t["failure"]["stage"] for t in per_trial if t["failure"])),
        "loop": config.loop,
        **({"faults": fault_table(per_trial)} if config.faults else {}),
        "timing": {
            "median_policy_latency_s": statistics.median(latency) if latency else None,
            "median_policy_cpu_s": statistics.median(cpu) if cpu else None,
            "median_trial_wall_s": statistics.median(wall) if wall else None,
            "realtime_factor": sim_t / exec_wall if exec_wall > 0 else None,
        },
        "precision": {
            "median_position_error_mm": 1000 * float(np.median(pos)) if pos else None,
            "median_yaw_error_deg": float(np.degrees(np.median(yaw))) if yaw else None,
            "placements": len(pos),
        },
        "per_trial": per_trial,
    }


def fault_table(per_trial: list[dict]) -> dict[str, dict]:
    """Per fault: trials it happened in, and how they ended — recovered (final success), gave
    up (the closed loop stopped, saying why) or wrong (ended otherwise off the goal). Apart:
    `toppled`, the trials not recovered in which the fault left a part on another face
    (`sim.faults`: no transfer from above can right it), and the recovery rate of the rest
    (`recoverable_interval`)."""
    out: dict[str, dict] = {}
    for t in per_trial:
        f = t.get("fault")
        if not f:
            continue
        row = out.setdefault(f["name"], {"drawn": 0, "happened": 0, "recovered": 0, "gave_up": 0,
                                         "wrong": 0, "toppled": 0})  # fmt: skip
        row["drawn"] += 1
        if not f.get("happened"):
            continue
        row["happened"] += 1
        if t["final_ok"]:
            row["recovered"] += 1
            continue
        if (t.get("loop") or {}).get("status") == "gave_up":
            row["gave_up"] += 1
        else:
            row["wrong"] += 1
        if f.get("toppled"):
            row["toppled"] += 1
    for row in out.values():
        row["interval"] = wilson(row["recovered"], row["happened"])
        row["recoverable_interval"] = wilson(row["recovered"], row["happened"] - row["toppled"])
    return out


def table(summary: dict) -> str:
    """The terminal table: metrics, paper figures where known, and every failure."""
    d = summary["domain"]
    paper = PAPER.get(d, {})
    pct = lambda v: "   –  " if v is None else f"{100 * v:5.1f}%"  # noqa: E731
    lines = [
        f"{d} · policy {summary['policy']} · view {summary['view']} · split "
        f"{summary.get('split', 'dev')} · {summary['trials']} trials",
        f"  protocol: {summary.get('protocol', '')}"
        + (", closed loop" if summary.get("loop") == "closed" else ""),
        f"  {'metric':<10} {'ours':>7} {'95 % interval':>15} {'paper':>7}",
    ]
    spans = summary.get("intervals", {})
    span = lambda k: (  # noqa: E731
        "" if spans.get(k) is None else f"{100 * spans[k][0]:.1f}–{100 * spans[k][1]:.1f}%"
    )
    for key in ("state_ac", "plan_sr", "final_sr"):
        ref = (
            paper.get(key)
            if summary["view"] == "front"
            else paper.get(summary["view"])
            if key == "final_sr"
            else None
        )
        lines.append(f"  {key:<10} {pct(summary[key]):>7} {span(key):>15} {pct(ref):>7}")
    if summary.get("final_with_failed_plan"):
        lines.append(f"  final successes with a failed plan: {summary['final_with_failed_plan']}")
    t, p = summary["timing"], summary["precision"]
    if t["median_policy_latency_s"] is not None:
        cpu = t.get("median_policy_cpu_s")
        lines.append(
            f"  median policy latency {t['median_policy_latency_s'] * 1000:.0f} ms"
            + ("" if cpu is None else f" ({cpu * 1000:.0f} ms of CPU in the programs)")
        )
    if t["median_trial_wall_s"] is not None:
        lines.append(
            f"  median trial wall time {t['median_trial_wall_s']:.1f} s"
            + (
                f", simulation {t['realtime_factor']:.1f}× real time"
                if t["realtime_factor"]
                else ""
            )
        )
    if p["median_position_error_mm"] is not None:
        lines.append(
            f"  placement: median position error {p['median_position_error_mm']:.2f} mm, "
            f"median yaw error {p['median_yaw_error_deg']:.2f}° over {p['placements']} placements"
        )
    if summary.get("faults"):
        lines.append(
            f"  {'fault':<6} {'happened':>8} {'recovered':>9} {'gave up':>7} {'wrong':>5} "
            f"{'toppled':>7}"
        )
        for name, row in summary["faults"].items():
            lines.append(
                f"  {name:<6} {row['happened']:>4}/{row['drawn']:<3} {row['recovered']:>9} "
                f"{row['gave_up']:>7} {row['wrong']:>5} {row.get('toppled', 0):>7}"
            )
    failed = [tr for tr in summary["per_trial"] if tr["failure"]]
    if failed:
        lines.append(f"  failures ({len(failed)}):")
        for tr in failed:
            lines.append(f"    {tr['name']}: [{tr['failure']['stage']}] {tr['failure']['reason']}")
    return "\n".join(lines)


def write_json(summary: dict, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(summary, indent=1) + "\n")


def progress_bar(total: int, desc: str):
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="trial", file=sys.stderr, dynamic_ncols=True)
    counts: Counter[str] = Counter()

    def update(result: dict) -> None:
        counts["final"] += bool(result["final_ok"])
        bar.update(1)
        bar.set_postfix_str(f"final {counts['final']}/{bar.n}")
        if bar.n == total:
            bar.close()

    return update
