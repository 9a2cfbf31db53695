"""Model clients behind one interface (`ModelClient.complete(request) -> response`)."""

from agent.clients.anthropic_client import DEFAULT_MODEL, AnthropicClient
from agent.clients.base import (
    Author,
    ImageBlock,
    ModelClient,
    ModelRequest,
    ModelResponse,
    TextBlock,
    Usage,
)
from agent.clients.pricing import PRICES, Budget, cost_usd
from agent.clients.replay import RecordingClient, ReplayClient
from agent.clients.scripted import ScriptedClient

__all__ = [
    "DEFAULT_MODEL",
    "PRICES",
    "AnthropicClient",
    "Author",
    "Budget",
    "ImageBlock",
    "ModelClient",
    "ModelRequest",
    "ModelResponse",
    "RecordingClient",
    "ReplayClient",
    "ScriptedClient",
    "TextBlock",
    "Usage",
    "cost_usd",
]
