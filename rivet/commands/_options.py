"""Options several commands share, defined once."""

from __future__ import annotations

import argparse
import os
from typing import Any

from sandbox import BACKENDS

# The credentials the model clients read from the environment (`agent.clients`: Anthropic's
# key or token, an OpenAI-compatible endpoint's key). `tests/rivet/test_local_refusal.py`
# holds this list to every variable those clients read.
CREDENTIAL_VARIABLES = ("ANTHROPIC_API_KEY", "ANTHROPIC_AUTH_TOKEN", "OPENAI_API_KEY")


def credentials_in_environment() -> list[str]:
    """The credential variables set (non-empty) in this process's environment."""
    return [name for name in CREDENTIAL_VARIABLES if os.environ.get(name)]


def local_refusal(held: list[str]) -> str:
    """Why `--sandbox local` does not run with `held` credentials in the environment."""
    return (
        f"--sandbox local refuses to run while {', '.join(held)} "
        f"{'is' if len(held) == 1 else 'are'} set: the local backend isolates nothing, and a "
        "draft running as you can read the environment of this process and of every process "
        f"it starts (/proc/PID/environ). Unset {'it' if len(held) == 1 else 'them'} for this "
        "command (env -u NAME rivet ...) or use the docker backend (the default)"
    )


class _SandboxChoice(argparse.Action):
    """Stores the backend; `local` is refused (bad usage, exit 2) while a model credential
    is in the environment."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        if values == "local":
            held = credentials_in_environment()
            if held:
                parser.error(local_refusal(held))
        setattr(namespace, self.dest, values)


def add_sandbox_option(parser: argparse.ArgumentParser, *, what: str = "the programs") -> None:
    """`--sandbox docker|local`: where model-written code runs. Docker is the default; the
    local backend isolates nothing (it says so), is only ever used when named, and refuses to
    run while a model credential is in the environment (`CREDENTIAL_VARIABLES`)."""
    parser.add_argument(
        "--sandbox",
        choices=BACKENDS,
        default="docker",
        action=_SandboxChoice,
        help=f"where {what} run: docker (default) or local (faster, isolates nothing; refused "
        f"while {', '.join(CREDENTIAL_VARIABLES)} is set)",
    )


def int_at_least(low: int):
    """An argparse type: an integer of at least `low` (usage error otherwise)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, got {value}")
        return value

    return parse
