"""The check suites that decide whether a draft is frozen (work in progress)."""
