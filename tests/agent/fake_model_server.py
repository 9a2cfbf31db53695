"""A fake model API on 127.0.0.1 (standard library only), for the clients' wire-level tests.

It answers the routes the real SDKs call — Anthropic `POST /v1/messages` (JSON or a server-sent
event stream, as the request asks) and `POST /v1/messages/count_tokens`, OpenAI-compatible
`POST /v1/chat/completions` — from a per-route script of replies, and records every request
(path, headers, JSON body). A script that runs out answers with the default reply.

Replies: `Json(status, body, headers)`, `Sse(events, headers, cut_after=None)` (a chunked event
stream; `cut_after=k` drops the connection after k events, without the closing chunk, as a
broken stream looks), `Close()` (drop the connection without answering), `Slow(seconds,
reply)` (wait, then reply).
"""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

DEFAULT_TEXT = "```python\ndef render():\n    pass\n```"


@dataclass
class Json:
    status: int = 200
    body: Any = None
    headers: dict[str, str] = field(default_factory=dict)


@dataclass
class Sse:
    events: list[tuple[str | None, Any]]
    headers: dict[str, str] = field(default_factory=dict)
    cut_after: int | None = None
    delay_s: float = 0.0  # between events


@dataclass
class Close:
    pass


@dataclass
class Slow:
    seconds: float
    reply: Any


@dataclass
class Recorded:
    method: str
    path: str
    headers: dict[str, str]
    body: Any


def anthropic_error(status: int, kind: str, message: str, headers: dict | None = None) -> Json:
    return Json(
        status, {"type": "error", "error": {"type": kind, "message": message}}, headers or {}
    )


def anthropic_message(
    text: str = DEFAULT_TEXT,
    *,
    model: str = "claude-opus-5",
    stop_reason: str = "end_turn",
    usage: dict | None = None,
) -> dict:
    return {
        "id": "msg_fake",
        "type": "message",
        "role": "assistant",
        "model": model,
        "content": [{"type": "text", "text": text}],
        "stop_reason": stop_reason,
        "stop_sequence": None,
        "usage": usage
        or {
            "input_tokens": 100,
            "output_tokens": 50,
            "cache_creation_input_tokens": 1000,
            "cache_read_input_tokens": 2000,
        },
    }


def anthropic_sse(
    text: str = DEFAULT_TEXT,
    *,
    model: str = "claude-opus-5",
    stop_reason: str = "end_turn",
    usage: dict | None = None,
    thinking: str | None = None,
    pieces: int = 3,
    headers: dict | None = None,
    cut_after: int | None = None,
) -> Sse:
    """The event stream of one message: start, (thinking), text in `pieces` deltas, stop."""
    u = usage or {
        "input_tokens": 100,
        "output_tokens": 50,
        "cache_creation_input_tokens": 1000,
        "cache_read_input_tokens": 2000,
    }
    start = anthropic_message(
        "", model=model, stop_reason=stop_reason, usage={**u, "output_tokens": 1}
    )
    start["content"], start["stop_reason"] = [], None
    events: list[tuple[str | None, Any]] = [
        ("message_start", {"type": "message_start", "message": start})
    ]
    index = 0
    if thinking is not None:
        events += [
            (
                "content_block_start",
                {
                    "type": "content_block_start",
                    "index": 0,
                    "content_block": {"type": "thinking", "thinking": "", "signature": ""},
                },
            ),
            (
                "content_block_delta",
                {
                    "type": "content_block_delta",
                    "index": 0,
                    "delta": {"type": "thinking_delta", "thinking": thinking},
                },
            ),
            (
                "content_block_delta",
                {
                    "type": "content_block_delta",
                    "index": 0,
                    "delta": {"type": "signature_delta", "signature": "sig"},
                },
            ),
            ("content_block_stop", {"type": "content_block_stop", "index": 0}),
        ]
        index = 1
    events.append(
        (
            "content_block_start",
            {
                "type": "content_block_start",
                "index": index,
                "content_block": {"type": "text", "text": ""},
            },
        )
    )
    step = max(1, -(-len(text) // pieces))
    for k in range(0, len(text), step):
        events.append(
            (
                "content_block_delta",
                {
                    "type": "content_block_delta",
                    "index": index,
                    "delta": {"type": "text_delta", "text": text[k : k + step]},
                },
            )
        )
    events += [
        ("ping", {"type": "ping"}),
        ("content_block_stop", {"type": "content_block_stop", "index": index}),
        (
            "message_delta",
            {
                "type": "message_delta",
                "delta": {"stop_reason": stop_reason, "stop_sequence": None},
                "usage": {"output_tokens": u["output_tokens"]},
            },
        ),
        ("message_stop", {"type": "message_stop"}),
    ]
    return Sse(events, headers or {}, cut_after=cut_after)


def openai_completion(
    text: str = DEFAULT_TEXT,
    *,
    model: str = "local-vlm",
    finish_reason: str = "stop",
    usage: dict | None = None,
) -> dict:
    return {
        "id": "chatcmpl-fake",
        "object": "chat.completion",
        "created": 1,
        "model": model,
        "choices": [
            {
                "index": 0,
                "message": {"role": "assistant", "content": text},
                "finish_reason": finish_reason,
            }
        ],
        "usage": usage or {"prompt_tokens": 1200, "completion_tokens": 80, "total_tokens": 1280},
    }


def openai_sse(
    text: str = DEFAULT_TEXT,
    *,
    model: str = "local-vlm",
    finish_reason: str = "stop",
    usage: dict | None = None,
    include_usage: bool = True,
    pieces: int = 3,
    cut_after: int | None = None,
    headers: dict | None = None,
) -> Sse:
    def chunk(delta: dict, finish: str | None, **extra: Any) -> dict:
        return {
            "id": "chatcmpl-fake",
            "object": "chat.completion.chunk",
            "created": 1,
            "model": model,
            "choices": [{"index": 0, "delta": delta, "finish_reason": finish}],
            **extra,
        }

    events: list[tuple[str | None, Any]] = [
        (None, chunk({"role": "assistant", "content": ""}, None))
    ]
    step = max(1, -(-len(text) // pieces))
    for k in range(0, len(text), step):
        events.append((None, chunk({"content": text[k : k + step]}, None)))
    events.append((None, chunk({}, finish_reason)))
    if include_usage:
        u = usage or {"prompt_tokens": 1200, "completion_tokens": 80, "total_tokens": 1280}
        events.append(
            (
                None,
                {
                    "id": "chatcmpl-fake",
                    "object": "chat.completion.chunk",
                    "created": 1,
                    "model": model,
                    "choices": [],
                    "usage": u,
                },
            )
        )
    events.append((None, "[DONE]"))
    return Sse(events, headers or {}, cut_after=cut_after)


class _Quiet(ThreadingHTTPServer):
    def handle_error(self, request: Any, client_address: Any) -> None:
        pass  # a client that hangs up (a timeout test, a cut stream) is not an error here


class FakeModelServer:
    """`with FakeModelServer() as server:` … `server.url`, `server.script[route].append(reply)`."""

    ROUTES = ("messages", "count_tokens", "chat")

    def __init__(self, *, count_tokens: int = 3100) -> None:
        self.script: dict[str, list[Any]] = {r: [] for r in self.ROUTES}
        self.requests: list[Recorded] = []
        self.count_tokens = count_tokens
        self.default_text = DEFAULT_TEXT
        self._lock = threading.Lock()
        server = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args: Any) -> None:
                pass

            def do_POST(self) -> None:
                n = int(self.headers.get("content-length") or 0)
                raw = self.rfile.read(n) if n else b""
                try:
                    body = json.loads(raw) if raw else None
                except json.JSONDecodeError:
                    body = raw.decode(errors="replace")
                server._serve(self, body)

            do_GET = do_POST

        self.httpd = _Quiet(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self._thread = threading.Thread(
            target=self.httpd.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True
        )

    # --------------------------------------------------------------------------- lifecycle

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}"

    def __enter__(self) -> FakeModelServer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()

    def calls(self, route: str) -> list[Recorded]:
        return [r for r in self.requests if _route(r.path) == route]

    # --------------------------------------------------------------------------- serving

    def _serve(self, h: BaseHTTPRequestHandler, body: Any) -> None:
        route = _route(h.path)
        with self._lock:
            self.requests.append(
                Recorded(h.command, h.path, {k.lower(): v for k, v in h.headers.items()}, body)
            )
            reply = self.script[route].pop(0) if route and self.script[route] else None
        if reply is None:
            reply = self._default(route, body)
        self._send(h, reply, body)

    def _default(self, route: str | None, body: Any) -> Any:
        streaming = isinstance(body, dict) and bool(body.get("stream"))
        if route == "messages":
            model = (
                body.get("model", "claude-opus-5") if isinstance(body, dict) else "claude-opus-5"
            )
            if streaming:
                return anthropic_sse(self.default_text, model=model)
            return Json(200, anthropic_message(self.default_text, model=model))
        if route == "count_tokens":
            return Json(200, {"input_tokens": self.count_tokens})
        if route == "chat":
            model = body.get("model", "local-vlm") if isinstance(body, dict) else "local-vlm"
            return (
                openai_sse(self.default_text, model=model)
                if streaming
                else Json(200, openai_completion(self.default_text, model=model))
            )
        return Json(
            404, {"type": "error", "error": {"type": "not_found_error", "message": "no such route"}}
        )

    def _send(self, h: BaseHTTPRequestHandler, reply: Any, body: Any) -> None:
        if isinstance(reply, Slow):
            time.sleep(reply.seconds)
            reply = reply.reply
        if callable(reply) and not isinstance(reply, (Json, Sse, Close)):
            reply = reply(body)
        if isinstance(reply, Close):
            h.close_connection = True
            with contextlib.suppress(OSError):
                h.connection.shutdown(socket.SHUT_RDWR)
            return
        if isinstance(reply, Json):
            data = json.dumps(reply.body).encode()
            h.send_response(reply.status)
            h.send_header("content-type", "application/json")
            h.send_header("content-length", str(len(data)))
            for k, v in reply.headers.items():
                h.send_header(k, v)
            h.end_headers()
            h.wfile.write(data)
            h.wfile.flush()
            return
        assert isinstance(reply, Sse), reply
        h.send_response(200)
        h.send_header("content-type", "text/event-stream")
        h.send_header("transfer-encoding", "chunked")
        for k, v in reply.headers.items():
            h.send_header(k, v)
        h.end_headers()
        for i, (event, data) in enumerate(reply.events):
            if reply.cut_after is not None and i >= reply.cut_after:
                h.wfile.flush()
                h.close_connection = True
                with contextlib.suppress(OSError):
                    h.connection.shutdown(socket.SHUT_RDWR)
                return
            payload = data if isinstance(data, str) else json.dumps(data)
            text = (f"event: {event}\n" if event else "") + f"data: {payload}\n\n"
            chunk = text.encode()
            h.wfile.write(f"{len(chunk):x}\r\n".encode() + chunk + b"\r\n")
            h.wfile.flush()
            if reply.delay_s:
                time.sleep(reply.delay_s)
        h.wfile.write(b"0\r\n\r\n")
        h.wfile.flush()


def _route(path: str) -> str | None:
    path = path.split("?", 1)[0]
    if path.endswith("/messages/count_tokens"):
        return "count_tokens"
    if path.endswith("/messages"):
        return "messages"
    if path.endswith("/chat/completions"):
        return "chat"
    return None


def closed_port_url() -> str:
    """A loopback URL where nothing listens: every connect is refused at once."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return f"http://127.0.0.1:{port}"


class Blackhole:
    """A loopback address that accepts no connection: its listen queue (backlog 0) is already
    full, so every further connect waits until it times out."""

    def __enter__(self) -> Blackhole:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(0)
        port = self.sock.getsockname()[1]
        self.filler = socket.create_connection(("127.0.0.1", port), timeout=1)
        self.url = f"http://127.0.0.1:{port}"
        return self

    def __exit__(self, *exc: object) -> None:
        self.filler.close()
        self.sock.close()
