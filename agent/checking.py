"""The checker the authoring loop uses: the full check suites, run in the sandbox.

A thin adapter over `checks.run_checks` (the judge, in this process; each draft in a sandbox
session of the chosen backend); it exists so the loop depends on the small `Checker`
protocol only.
"""

from __future__ import annotations

from pathlib import Path


class SuiteChecker:
    """Runs `checks.run_checks` with the chosen sandbox backend."""

    def __init__(self, *, sandbox: str = "docker", thorough: bool = False) -> None:
        self.sandbox = sandbox
        self.thorough = thorough
        self._executor = None

    def _get_executor(self):
        if self._executor is None:
            import sandbox

            self._executor = sandbox.open_executor(self.sandbox)
        return self._executor

    def check(
        self,
        domain: str,
        function: str,
        source: str,
        *,
        deps: dict[str, str],
        out_dir: Path,
        cases_seed: int | None = None,
    ) -> dict:
        from checks import run_checks

        return run_checks(
            domain,
            function,
            source,
            deps=deps,
            thorough=self.thorough,
            executor=self._get_executor(),
            out_dir=out_dir,
            cases_seed=cases_seed,
        )

    def close(self) -> None:
        if self._executor is not None:
            self._executor.close()
            self._executor = None

    def markdown(self, report: dict) -> str:
        from checks import report_markdown

        return report_markdown(report)
