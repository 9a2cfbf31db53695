"""Fan work out to a Ray cluster: `--ray ADDRESS` on `rivet eval` and `rivet author --runs N`.

`ADDRESS` is a Ray address (`ray://host:10001`, `host:6379`) or `local` to start a Ray
instance on this machine. The cluster's nodes need this project installed (and, for
authoring, Docker and the sandbox image). Ray is an optional extra: `uv sync --extra ray`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

from contracts.errors import UsageError


def _ray():
    try:
        import ray
    except ImportError:
        raise UsageError(
            "--ray needs the optional extra: uv sync --extra ray (or pip install 'rivet[ray]')"
        ) from None
    return ray


def connect(address: str, *, num_cpus: int | None = None) -> Any:
    ray = _ray()
    if not ray.is_initialized():
        if address == "local":
            ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
    return ray


def map_with_actors(
    address: str,
    init: Callable[[Any], None],
    init_arg: Any,
    work: Callable[[Any], Any],
    items: Sequence[Any],
    *,
    workers: int,
) -> Iterator[tuple[int, Any]]:
    """Run `work(item)` on `workers` Ray actors, each set up once with `init(init_arg)`.

    Yields (index, result) as results arrive.
    """
    ray = connect(address, num_cpus=max(workers, 1) if address == "local" else None)

    @ray.remote
    class _Worker:
        def __init__(self) -> None:
            init(init_arg)

        def run(self, index: int, item: Any) -> tuple[int, Any]:
            return index, work(item)

    actors = [_Worker.remote() for _ in range(max(1, workers))]  # type: ignore[attr-defined]
    pending = [actors[i % len(actors)].run.remote(i, item) for i, item in enumerate(items)]
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        yield ray.get(done[0])


def map_tasks(address: str, fn: Callable[[Any], Any], items: Sequence[Any]) -> list[Any]:
    """Run `fn(item)` as independent Ray tasks; results in the items' order."""
    ray = connect(address)
    remote = ray.remote(fn)
    return ray.get([remote.remote(item) for item in items])
