"""`--agent "COMMAND"`: any program answers the requests, through files.

For each request RIVET writes a folder (`<run>/agent/<function>-<attempt>/`):

```
prompt.md        the whole request as Markdown: a short header saying how to answer, the system
                 text, then the user content; each image as ![caption](NN-caption.png)
NN-caption.png   the images prompt.md references (relative paths)
request.json     function, attempt, max_tokens, request hash, the image files
```
then runs COMMAND (split like a shell would, not run by one) with the folder as its working
directory and these variables added to the caller's environment (the command is the user's
own program, not a draft: it may need its own credentials):

```
RIVET_REQUEST_DIR    the folder
RIVET_RESPONSE_FILE  <folder>/response.md: where the answer goes
RIVET_FUNCTION       render | perceive | relate | plan
RIVET_ATTEMPT        1, 2, …
RIVET_MAX_TOKENS     the answer's length limit a model client would use
```
The answer is `response.md`, read as the model's answer (it must hold one ```python block).
A non-zero exit, no (or an empty) `response.md`, or running past `timeout_s` (`--agent-timeout`,
default 1800 s; the command's whole process group is killed) is an `AgentCommandFailed`. The
command's stdout and stderr are kept in `agent.stdout` / `agent.stderr` in the folder.

The transcript and manifest name the command as the author: `{"kind": "model", "provider":
"agent", "model": "<command name>"}` (the program's file name; for an interpreter such as
`python3 x.py`, "python3 x.py"); the full command line is not recorded, as it may carry
secrets. RIVET cannot see an agent's token usage, so calls cost $0 and `--max-usd` does not
apply (`--max-calls` does).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import time
from pathlib import Path

from agent.clients import _http
from agent.clients.base import Author, ImageBlock, ModelRequest, ModelResponse, TextBlock, Usage
from agent.clients.pricing import Budget
from agent.errors import AgentCommandFailed
from contracts.errors import UsageError

DEFAULT_TIMEOUT_S = 1800.0
RESPONSE = "response.md"
PROMPT = "prompt.md"
INTERPRETERS = {
    "python",
    "python3",
    "sh",
    "bash",
    "zsh",
    "node",
    "deno",
    "bun",
    "ruby",
    "perl",
    "uv",
    "uvx",
    "npx",
}
_KILL_GRACE_S = 5.0


def command_name(argv: list[str]) -> str:
    """The author name of a command: its program's file name, plus the script for interpreters."""
    prog = os.path.basename(argv[0])
    if re.sub(r"[\d.]+$", "", prog) in INTERPRETERS:
        script = next((a for a in argv[1:] if not a.startswith("-")), None)
        if script is not None and len(argv) > 1 and argv[1] not in ("-c", "-e", "-m"):
            return f"{prog} {os.path.basename(script)}"
    return prog


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:40] or "image"


def prompt_markdown(request: ModelRequest, images: dict[int, str]) -> str:
    """The request as one Markdown document; `images` maps a content index to its file."""
    out = [
        f"# RIVET request: `{request.function}`, attempt {request.attempt}",
        "",
        f"Answer by writing the file `{RESPONSE}` in this folder (its path is also in "
        "`$RIVET_RESPONSE_FILE`): the text you would answer in a chat, holding exactly one "
        f"```python block with the whole module. Keep the answer under about "
        f"{request.max_tokens} tokens. The images are PNG files in this folder, referenced below.",
        "",
        "---",
        "",
        "## System",
        "",
    ]
    out += [b.text.rstrip() + "\n" for b in request.system]
    out += ["---", "", "## Request", ""]
    for i, b in enumerate(request.content):
        if isinstance(b, TextBlock):
            out.append(b.text.rstrip() + "\n")
        elif isinstance(b, ImageBlock):
            out.append(f"![{b.caption or 'image'}]({images[i]})\n")
    return "\n".join(out)


class AgentCommandClient:
    def __init__(
        self,
        command: str,
        *,
        work_dir: Path,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        budget: Budget | None = None,
        progress: _http.Say | None = None,
        progress_every_s: float = _http.PROGRESS_EVERY_S,
    ) -> None:
        try:
            self.argv = shlex.split(command)
        except ValueError as e:
            raise UsageError(f"--agent {command!r}: {e}") from None
        if not self.argv:
            raise UsageError("--agent: the command is empty")
        prog = self.argv[0]
        found = (
            shutil.which(prog)
            if os.sep not in prog
            else (prog if os.access(prog, os.X_OK) else None)
        )
        if found is None:
            raise UsageError(f"--agent: cannot run {prog!r}: not found or not executable")
        self.executable = os.path.abspath(found)
        if timeout_s <= 0:
            raise UsageError(f"--agent-timeout {timeout_s}: must be positive")
        self.name = command_name(self.argv)
        self.work_dir = Path(work_dir)
        self.timeout_s = timeout_s
        self.budget = budget or Budget()
        self.say = progress or _http.stderr_say
        self.progress_every_s = progress_every_s

    @property
    def author(self) -> Author:
        return Author(
            kind="model",
            provider="agent",
            model=self.name,
            note=f"answers written by the agent command `{self.name}` through RIVET's file "
            "protocol (prompt.md → response.md)",
        )

    def write_request(self, request: ModelRequest) -> Path:
        folder = self.work_dir / f"{request.function}-{request.attempt}"
        if folder.exists():
            shutil.rmtree(folder)  # a fresh folder: never read an older response.md
        folder.mkdir(parents=True)
        images: dict[int, str] = {}
        n = 0
        for i, b in enumerate(request.content):
            if isinstance(b, ImageBlock):
                n += 1
                name = f"{n:02d}-{_slug(b.caption)}.png"
                (folder / name).write_bytes(b.png)
                images[i] = name
        (folder / PROMPT).write_text(prompt_markdown(request, images))
        meta = {
            "function": request.function,
            "attempt": request.attempt,
            "max_tokens": request.max_tokens,
            "request_hash": request.hash,
            "images": list(images.values()),
            "response_file": RESPONSE,
        }
        (folder / "request.json").write_text(json.dumps(meta, indent=2) + "\n")
        return folder

    def complete(self, request: ModelRequest) -> ModelResponse:
        self.budget.reserve(0.0)  # --max-calls
        folder = self.write_request(request)
        response = folder / RESPONSE
        env = {
            **os.environ,
            "RIVET_REQUEST_DIR": str(folder.resolve()),
            "RIVET_RESPONSE_FILE": str(response.resolve()),
            "RIVET_FUNCTION": request.function,
            "RIVET_ATTEMPT": str(request.attempt),
            "RIVET_MAX_TOKENS": str(request.max_tokens),
        }
        what = f"the agent command `{self.name}` ({request.function} attempt {request.attempt})"
        t0 = time.monotonic()
        with (
            open(folder / "agent.stdout", "wb") as out,
            open(folder / "agent.stderr", "wb") as err,
            _http.Ticker(
                self.say,
                self.progress_every_s,
                lambda s: f"  … {what} running, {s:.0f} s",
            ),
        ):
            try:
                proc = subprocess.Popen(
                    [self.executable, *self.argv[1:]],
                    cwd=folder,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=err,
                    start_new_session=True,
                )
            except OSError as e:
                raise AgentCommandFailed(f"{what} could not start: {e}") from None
            try:
                code = proc.wait(timeout=self.timeout_s)
            except subprocess.TimeoutExpired:
                _kill_group(proc)
                raise AgentCommandFailed(
                    f"{what} did not finish within {self.timeout_s:.0f} s (--agent-timeout) and "
                    f"was killed; its files are in {folder}{self._tail(folder)}"
                ) from None
            finally:
                _kill_group(proc)  # whatever it left running in its process group
        elapsed = time.monotonic() - t0
        if code != 0:
            how = f"was killed by signal {-code}" if code < 0 else f"exited with status {code}"
            raise AgentCommandFailed(
                f"{what} {how} after {elapsed:.0f} s; its files are in {folder}{self._tail(folder)}"
            )
        if not response.is_file():
            raise AgentCommandFailed(
                f"{what} exited 0 but wrote no {RESPONSE} (RIVET_RESPONSE_FILE={response})"
                f"{self._tail(folder)}"
            )
        text = response.read_text(errors="replace")
        if not text.strip():
            raise AgentCommandFailed(f"{what} wrote an empty {RESPONSE} ({response})")
        self.budget.spend(0.0)
        return ModelResponse(text=text, model=self.name, usage=Usage(), stop_reason=None)

    @staticmethod
    def _tail(folder: Path) -> str:
        try:
            tail = (folder / "agent.stderr").read_text(errors="replace").strip()[-800:]
        except OSError:
            return ""
        return f"\nits stderr ends:\n{tail}" if tail else ""


def _kill_group(proc: subprocess.Popen) -> None:
    """End the command's process group: SIGTERM while the command runs (SIGKILL after a grace
    period), then SIGKILL for anything it left behind in the group."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError, subprocess.TimeoutExpired):
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=_KILL_GRACE_S)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


__all__ = ["DEFAULT_TIMEOUT_S", "AgentCommandClient", "command_name", "prompt_markdown"]
