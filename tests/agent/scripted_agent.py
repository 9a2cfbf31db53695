"""A scripted `--agent` program for the tests: it answers each request from files.

Usage: python scripted_agent.py ANSWERS_DIR

For a request (RIVET_FUNCTION, RIVET_ATTEMPT) it looks in ANSWERS_DIR for, in order:
  <function>-<attempt>.exit   exit with the status it holds (after writing to stderr)
  <function>-<attempt>.hang   sleep until killed
  <function>-<attempt>.md     the answer: copied to RIVET_RESPONSE_FILE
  <function>.md               the answer for any attempt
and exits 0 without writing a response when none is there. Every request is logged to
ANSWERS_DIR/log.jsonl: function, attempt, working directory, the environment variables, and
whether prompt.md and every image it references are present.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
import time
from pathlib import Path


def main() -> int:
    answers = Path(sys.argv[1])
    function, attempt = os.environ["RIVET_FUNCTION"], os.environ["RIVET_ATTEMPT"]
    here = Path.cwd()
    prompt = here / "prompt.md"
    text = prompt.read_text() if prompt.is_file() else ""
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    entry = {
        "function": function,
        "attempt": int(attempt),
        "cwd": str(here),
        "request_dir": os.environ.get("RIVET_REQUEST_DIR"),
        "response_file": os.environ.get("RIVET_RESPONSE_FILE"),
        "max_tokens": os.environ.get("RIVET_MAX_TOKENS"),
        "prompt_chars": len(text),
        "images": images,
        "images_present": all((here / p).is_file() for p in images),
        "has_api_key": "ANTHROPIC_API_KEY" in os.environ,
    }
    with open(answers / "log.jsonl", "a") as log:
        log.write(json.dumps(entry) + "\n")
    stem = f"{function}-{attempt}"
    if (answers / f"{stem}.exit").is_file():
        print(f"scripted agent: failing {stem} on purpose", file=sys.stderr)
        return int((answers / f"{stem}.exit").read_text().strip() or 1)
    if (answers / f"{stem}.hang").is_file():
        print("scripted agent: hanging", file=sys.stderr, flush=True)
        while True:
            time.sleep(1)
    for name in (f"{stem}.md", f"{function}.md"):
        if (answers / name).is_file():
            shutil.copy(answers / name, os.environ["RIVET_RESPONSE_FILE"])
            return 0
    return 0  # no answer: exits 0 without a response file


if __name__ == "__main__":
    sys.exit(main())
