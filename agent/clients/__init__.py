"""Model clients behind one interface (`ModelClient.complete(request) -> response`)."""

from agent.clients.agent_command import AgentCommandClient
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
from agent.clients.openai_client import OpenAIClient
from agent.clients.pricing import PRICES, Budget, cost_usd, price_of
from agent.clients.replay import RecordingClient, ReplayClient
from agent.clients.scripted import ScriptedClient

__all__ = [
    "DEFAULT_MODEL",
    "PRICES",
    "AgentCommandClient",
    "AnthropicClient",
    "Author",
    "Budget",
    "ImageBlock",
    "ModelClient",
    "ModelRequest",
    "ModelResponse",
    "OpenAIClient",
    "RecordingClient",
    "ReplayClient",
    "ScriptedClient",
    "TextBlock",
    "Usage",
    "cost_usd",
    "price_of",
]
