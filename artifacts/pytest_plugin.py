"""pytest plugin: `pytest --rivet-artifacts artifacts/` runs every frozen program's full check
suite (in the sandbox) and the manifest hash checks, one test item each.

Registered through the `pytest11` entry point, so any project with RIVET installed can run its
committed artifacts' property suites in CI.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any, ClassVar

import pytest

from contracts.functions import authoring_order

PLUGIN_SEED = 1  # the case seed of a set whose manifest records none


def _seed(config: pytest.Config, manifest: dict, function: str) -> int | None:
    """The seed of the cases to check on: the one the frozen version passed on (its
    manifest's), unless `--rivet-seed` names one or asks for fresh cases."""
    text = config.getoption("--rivet-seed")
    if text == "fresh":
        return None
    if text == "frozen":
        seed = manifest["functions"][function].get("cases_seed")
        return PLUGIN_SEED if seed is None else int(seed)
    try:
        return int(text)
    except ValueError:
        raise pytest.UsageError(f"--rivet-seed {text}: an integer or 'fresh'") from None


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("rivet")
    group.addoption(
        "--rivet-artifacts",
        metavar="DIR",
        default=None,
        help="check the frozen programs under DIR/<domain>/ (hashes and full check suites)",
    )
    group.addoption(
        "--rivet-seed",
        metavar="S|frozen|fresh",
        default="frozen",
        help="the seed the check cases are drawn from: 'frozen' (default) the cases each "
        "program passed on when it was frozen (its manifest's), so that CI repeats; 'fresh' "
        "new cases each run (a failure names their seed); or a number",
    )
    group.addoption(
        "--rivet-images",
        metavar="DIR",
        default="rivet-check-images",
        help="where a failing suite's case images go, DIR/<domain>/<function>/ (overlays of the "
        "cases it got wrong, for a CI job to upload); a passing suite leaves none "
        "(default: rivet-check-images/)",
    )
    group.addoption(
        "--rivet-sandbox",
        choices=("docker", "local"),
        default="docker",
        help="where the check suites run (default docker; local isolates nothing)",
    )


def pytest_configure(config: pytest.Config) -> None:
    root = config.getoption("--rivet-artifacts")
    if root:
        path = Path(root)
        if not path.is_dir():
            raise pytest.UsageError(f"--rivet-artifacts {root}: not a directory")
        if config.args_source != pytest.Config.ArgsSource.ARGS:  # no paths given
            config.args[:] = [str(path)]  # only the suites it was pointed at
        else:
            config.args.append(str(path))  # beside the paths given (`pytest tests --rivet-…`)


def pytest_collect_file(parent: pytest.Collector, file_path: Path):
    root = parent.config.getoption("--rivet-artifacts")
    if (
        root
        and file_path.name == "manifest.json"
        and file_path.parent.parent.resolve() == Path(root).resolve()
    ):
        return ArtifactSet.from_parent(parent, path=file_path)
    return None


class ArtifactSet(pytest.File):
    def collect(self):
        domain = self.path.parent.name
        yield IntegrityItem.from_parent(self, name=f"{domain}::integrity", domain=domain)
        for function in authoring_order():
            yield CheckItem.from_parent(
                self, name=f"{domain}::{function}", domain=domain, function=function
            )


class IntegrityItem(pytest.Item):
    def __init__(self, *, domain: str, **kw) -> None:
        super().__init__(**kw)
        self.domain = domain

    def runtest(self) -> None:
        from artifacts.store import verify

        verify(self.domain, self.path.parent.parent)

    def repr_failure(self, excinfo, style=None):
        from artifacts.errors import ArtifactError

        if isinstance(excinfo.value, ArtifactError):  # one readable line, no traceback
            return f"{self.domain}: {excinfo.value}"
        return super().repr_failure(excinfo, style=style)

    def reportinfo(self):
        return self.path, None, f"{self.domain}: manifest and file hashes"


class CheckFailed(Exception):
    pass


class CheckItem(pytest.Item):
    _executors: ClassVar[dict[str, Any]] = {}

    def __init__(self, *, domain: str, function: str, **kw) -> None:
        super().__init__(**kw)
        self.domain = domain
        # not `self.function`: pytest's keyword matching (-k) takes that for a test function
        self.program = function

    def runtest(self) -> None:
        from artifacts.store import verify
        from checks import report_markdown, run_checks

        manifest, sources = verify(self.domain, self.path.parent.parent)
        backend = self.config.getoption("--rivet-sandbox")
        if backend not in self._executors:
            import sandbox

            self._executors[backend] = sandbox.open_executor(backend)
        deps = {d: src for d, src in sources.items() if d != self.program}
        images = Path(self.config.getoption("--rivet-images")) / self.domain / self.program
        shutil.rmtree(images, ignore_errors=True)  # what an earlier run left is not this one's
        report = run_checks(
            self.domain,
            self.program,
            sources[self.program],
            deps=deps,
            executor=self._executors[backend],
            cases_seed=_seed(self.config, manifest, self.program),
            out_dir=images,
        )
        if report["passed"]:
            shutil.rmtree(images, ignore_errors=True)
            return
        pictures = sorted(images.rglob("*.png")) if images.is_dir() else []
        raise CheckFailed(
            report_markdown(report)
            + f"\n\n(cases drawn from seed {report['cases_seed']})"
            + (
                f"\n\nimages of the failing cases ({len(pictures)}), under {images}/:\n"
                + "\n".join(f"  {p}" for p in pictures[:20])
                if pictures
                else ""
            )
        )

    def repr_failure(self, excinfo, style=None):
        from artifacts.errors import ArtifactError

        if isinstance(excinfo.value, CheckFailed):
            return str(excinfo.value)
        if isinstance(excinfo.value, ArtifactError):
            return f"{self.domain}: {excinfo.value}"
        return super().repr_failure(excinfo, style=style)

    def reportinfo(self):
        return self.path, None, f"{self.domain}: {self.program} check suite"


def pytest_sessionfinish(session: pytest.Session) -> None:
    for ex in CheckItem._executors.values():
        ex.close()  # type: ignore[attr-defined]
    CheckItem._executors.clear()
