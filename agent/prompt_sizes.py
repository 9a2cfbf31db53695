"""`python -m agent.prompt_sizes --sizes`: the first-attempt prompt of every function of every
domain, measured (characters, images, estimated tokens)."""

from __future__ import annotations

from agent.context import build_context, reference_observations
from agent.prompt import build_request, request_size
from contracts.functions import SIGNATURES


def sizes(domain_names: list[str] | None = None, *, images: bool = True) -> list[dict]:
    """The first-attempt prompt of every function of every domain, measured (`request_size`).
    The frozen dependencies a prompt carries are the people-written reference programs
    (`domains/<d>/programs/`), standing in for what a model would have written."""
    import domains
    from toolbox.docs import toolbox_docs

    docs = toolbox_docs()
    out = []
    for name in domain_names or domains.names():
        domain = domains.load(name)
        observations = reference_observations(domain) if images else ()
        ctx = build_context(domain, observations, docs)
        frozen = {
            f: (domain.root / "programs" / f"{f}.py").read_text()
            for f in SIGNATURES
            if (domain.root / "programs" / f"{f}.py").is_file()
        }
        for function in SIGNATURES:
            request = build_request(ctx, function, 1, frozen=frozen)
            rules = ctx.rules.get(function, "")
            out.append(
                {
                    "domain": name,
                    "function": function,
                    **request_size(request),
                    "rules_chars": len(rules),
                    "facts_chars": len(ctx.facts),
                }
            )
    return out


def _main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m agent.prompt_sizes",
        description="Measure the prompts the authoring loop sends (first attempt, no repair).",
    )
    parser.add_argument("--sizes", action="store_true", help="print each prompt's size")
    parser.add_argument("--domain", action="append", help="only this domain (repeatable)")
    parser.add_argument("--no-images", action="store_true", help="skip the reference images")
    args = parser.parse_args(argv)
    if not args.sizes:
        parser.print_help()
        return 2
    rows = sizes(args.domain, images=not args.no_images)
    print(
        "Tokens are estimated as the clients do without a token count: characters / 3.5 for "
        "text,\nwidth × height / 750 (at most 1600) per image, plus 50 per request.\n"
    )
    head = (
        "| domain | function | system chars | user chars | of which rules | total chars "
        "| text tokens | images | image tokens | tokens |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for r in rows:
        print(
            f"| {r['domain']} | {r['function']} | {r['system_chars']} | {r['user_chars']} "
            f"| {r['rules_chars']} | {r['chars']} | {r['text_tokens']} | {r['images']} "
            f"| {r['image_tokens']} | {r['tokens']} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
