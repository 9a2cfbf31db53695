"""What the API clients share: timeouts, the retry policy, progress while waiting, test guard.

Both SDKs (`anthropic`, `openai`) are built the same way (Stainless), so one classifier reads
both: `APIStatusError` (an HTTP error, or an `error` event inside a stream), `APIConnectionError`
/ `APITimeoutError` (wrapping the `httpx2` exception), and bare `httpx2` errors raised while a
stream is read. The SDKs' own retries are off (`max_retries=0`); `call_with_retries` retries
instead, so that it can cap `retry-after`, bound the time spent on an endpoint that accepts no
connection, re-check the budget before every retry and count a broken stream's usage.
"""

from __future__ import annotations

import contextlib
import email.utils
import ipaddress
import os
import random
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal, TypeVar
from urllib.parse import urlsplit

import httpx2 as httpx

from agent.errors import AgentError

CONNECT_TIMEOUT_S = 5.0  # one TCP/TLS connect
READ_TIMEOUT_S = 600.0  # between two chunks of an answer (streamed: per chunk)
CONNECT_DEADLINE_S = 30.0  # all connect attempts of one call, retries included
RETRY_AFTER_CAP_S = 60.0  # the most a server's retry-after is waited
PROGRESS_EVERY_S = 30.0

T = TypeVar("T")
Say = Callable[[str], None]


def stderr_say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


@dataclass(frozen=True)
class RetryPolicy:
    max_retries: int = 6  # retries of transient failures (429, 5xx, 529, broken streams)
    connect_retries: int = 2  # retries of a failed connect …
    connect_deadline_s: float = CONNECT_DEADLINE_S  # … all within this many seconds
    retry_after_cap_s: float = RETRY_AFTER_CAP_S
    initial_backoff_s: float = 0.5
    max_backoff_s: float = 8.0

    def backoff(self, n: int) -> float:
        delay = min(self.initial_backoff_s * 2.0 ** (n - 1), self.max_backoff_s)
        return delay * (1 - 0.25 * random.random())


@dataclass(frozen=True)
class Failure:
    """One failed attempt, as the retry loop sees it."""

    kind: Literal["connect", "timeout", "network", "status"]
    message: str  # plain words, for people
    retryable: bool
    status: int | None = None
    error_type: str | None = None
    retry_after_s: float | None = None


def parse_retry_after(headers: Any) -> float | None:
    """Seconds from `retry-after-ms`, `retry-after` (seconds or an HTTP date); None if absent."""
    if headers is None:
        return None
    ms = headers.get("retry-after-ms")
    if ms is not None:
        try:
            return float(ms) / 1000
        except ValueError:
            pass
    value = headers.get("retry-after")
    if value is None:
        return None
    try:
        return float(value)
    except ValueError:
        parsed = email.utils.parsedate_tz(value)
        return None if parsed is None else float(email.utils.mktime_tz(parsed) - time.time())


def _error_body(body: Any) -> tuple[str | None, str | None]:
    """(error type, message) from an Anthropic or OpenAI error body."""
    if isinstance(body, dict):
        err = body.get("error", body)
        if isinstance(err, dict):
            kind = err.get("type") or err.get("code")
            return (str(kind) if kind else None), (str(err.get("message") or "") or None)
        if isinstance(err, str):
            return None, err
    if isinstance(body, str) and body.strip():
        return None, body.strip()[:300]
    return None, None


RETRYABLE_ERROR_TYPES = {"overloaded_error", "api_error", "rate_limit_error", "timeout_error"}


def classify(sdk: Any, e: BaseException, url: str, read_timeout_s: float) -> Failure | None:
    """What a failed attempt was, for either SDK; None for an exception that is not the API's."""
    if isinstance(e, sdk.APIStatusError):
        status = e.status_code
        kind, message = _error_body(getattr(e, "body", None))
        headers = e.response.headers if getattr(e, "response", None) is not None else None
        should = headers.get("x-should-retry") if headers is not None else None
        if status == 200:  # an `error` event inside a stream
            retryable = kind in RETRYABLE_ERROR_TYPES
            text = f"the stream from {url} ended with an error: {kind or 'error'}"
        else:
            retryable = status in (408, 409, 429) or status >= 500
            text = f"{url} answered HTTP {status}" + (f" {kind}" if kind else "")
        if should == "true":
            retryable = True
        elif should == "false":
            retryable = False
        if message:
            text += f": {message}"
        return Failure(
            kind="status",
            message=text,
            retryable=retryable,
            status=status,
            error_type=kind,
            retry_after_s=parse_retry_after(headers),
        )
    if isinstance(e, sdk.APIConnectionError):
        cause = e.__cause__
        if isinstance(cause, httpx.ConnectTimeout):
            return Failure(kind="connect", message="the connect timed out", retryable=True)
        if isinstance(cause, (httpx.ConnectError, OSError)):
            return Failure(kind="connect", message=_plain(cause), retryable=True)
        if isinstance(e, sdk.APITimeoutError) or isinstance(cause, httpx.TimeoutException):
            return Failure(
                kind="timeout",
                message=f"no data from {url} for {read_timeout_s:.0f} s",
                retryable=True,
            )
        detail = _plain(cause) if cause is not None else str(e)
        return Failure(
            kind="network", message=f"the connection to {url} broke: {detail}", retryable=True
        )
    if isinstance(e, sdk.APIError):  # an error inside an OpenAI-style stream
        kind, message = _error_body(getattr(e, "body", None))
        text = f"the stream from {url} ended with an error" + (f": {kind}" if kind else "")
        return Failure(
            kind="status",
            message=text + (f": {message or e.message}" if (message or e.message) else ""),
            retryable=kind in RETRYABLE_ERROR_TYPES or kind == "server_error",
            error_type=kind,
        )
    if isinstance(e, httpx.TimeoutException):  # while a stream is read
        return Failure(
            kind="timeout", message=f"no data from {url} for {read_timeout_s:.0f} s", retryable=True
        )
    if isinstance(e, httpx.HTTPError):  # a stream cut off mid-way
        return Failure(
            kind="network", message=f"the stream from {url} broke: {_plain(e)}", retryable=True
        )
    return None


def _plain(e: BaseException) -> str:
    text = str(e) or type(e).__name__
    return text.replace("[Errno 111] ", "").replace("[Errno -2] ", "").replace("[Errno -3] ", "")


def call_with_retries(
    attempt: Callable[[], T],
    *,
    classify: Callable[[BaseException], Failure | None],
    give_up: Callable[[Failure, int, float, BaseException], BaseException],
    policy: RetryPolicy,
    say: Say,
    connect_timeout_s: float,
    started: float | None = None,
    before_retry: Callable[[], None] = lambda: None,
) -> T:
    """`attempt()` until it succeeds, a failure is not retryable, or the retries are spent.

    Connect failures are retried at most `policy.connect_retries` times and never past
    `policy.connect_deadline_s` after `started`; they are retried silently (the one message is
    `give_up`'s). A server's retry-after is honoured up to `policy.retry_after_cap_s`.
    `before_retry` runs before each retry (the budget check) and may raise.
    """
    t0 = time.monotonic() if started is None else started
    tries = 0
    connects = 0
    while True:
        tries += 1
        try:
            return attempt()
        except Exception as e:
            failure = classify(e)
            if failure is None:
                raise
            elapsed = time.monotonic() - t0
            retries = tries - 1
            if failure.retry_after_s is not None and failure.retry_after_s > 0:
                delay = min(failure.retry_after_s, policy.retry_after_cap_s)
            else:
                delay = policy.backoff(tries)
            stop = not failure.retryable or retries >= policy.max_retries
            if failure.kind == "connect":
                connects += 1
                late = elapsed + delay + connect_timeout_s > policy.connect_deadline_s
                stop = stop or connects > policy.connect_retries or late
            if stop:
                raise give_up(failure, tries, elapsed, e) from e
            if failure.kind != "connect":
                waited = ""
                if failure.retry_after_s is not None and failure.retry_after_s > delay:
                    waited = (
                        f" (the server asked for {failure.retry_after_s:.0f} s; waiting at most "
                        f"{policy.retry_after_cap_s:g} s)"
                    )
                say(
                    f"  {failure.message}; retry {tries}/{policy.max_retries} in {delay:.1f} s{waited}"
                )
            before_retry()
            time.sleep(delay)


class Ticker:
    """Calls `say(line(elapsed_s))` every `every_s` seconds while a call is in flight."""

    def __init__(self, say: Say, every_s: float, line: Callable[[float], str]) -> None:
        self.say, self.every_s, self.line = say, every_s, line
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.t0 = time.monotonic()

    def __enter__(self) -> Ticker:
        self.t0 = time.monotonic()
        if self.every_s > 0:
            self._thread = threading.Thread(target=self._run, name="rivet-progress", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.every_s):
            with contextlib.suppress(Exception):  # progress must never break a call
                self.say(self.line(time.monotonic() - self.t0))

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)


def is_loopback(url: str) -> bool:
    host = (urlsplit(url).hostname or "").strip("[]").lower()
    if host == "localhost" or host.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def forbid_real_api(url: str, *, injected: bool) -> None:
    """Under `RIVET_FORBID_MODEL_API=1` (the test suite), only an injected HTTP client or a
    loopback address (a local fake server) may be used."""
    if os.environ.get("RIVET_FORBID_MODEL_API") == "1" and not injected and not is_loopback(url):
        raise AgentError(
            f"real model API calls are forbidden here (RIVET_FORBID_MODEL_API=1): {url}; "
            "inject an http_client or use a local (127.0.0.1) base URL"
        )


def timeout(read_s: float, connect_s: float) -> httpx.Timeout:
    return httpx.Timeout(read_s, connect=connect_s)


_CONTEXT_WORDS = ("prompt is too long", "context window", "context length", "too many tokens")


def is_context_error(f: Failure) -> bool:
    text = (f.message or "").lower()
    return f.status == 400 and (
        f.error_type == "context_length_exceeded" or any(w in text for w in _CONTEXT_WORDS)
    )


def failure_error(
    f: Failure,
    tries: int,
    elapsed: float,
    usage: Any,
    *,
    api: str,
    base_url: str,
    what: str,
    model: str,
    credentials: str,
    base_url_env: str,
) -> Exception:
    """The one clear error a call ends with once `call_with_retries` gives up."""
    from agent.errors import ApiUnreachable, ContextWindowExceeded, ModelCallFailed

    if f.kind == "connect":
        return ApiUnreachable(
            f"cannot reach the {api} at {base_url}: {f.message} ({tries} tries in "
            f"{elapsed:.0f} s). Check the network, or the address (--base-url, {base_url_env}).",
            usage=usage,
        )
    if is_context_error(f):
        return ContextWindowExceeded(
            f"the prompt for {what} does not fit {model}'s context window: {f.message}",
            usage=usage,
        )
    if f.status in (401, 403):
        return ModelCallFailed(
            f"{f.message}. The credentials come from {credentials}.", usage=usage
        )
    tail = f" (after {tries} tries in {elapsed:.0f} s)" if tries > 1 else ""
    return ModelCallFailed(f"{what}: {f.message}{tail}", usage=usage)
