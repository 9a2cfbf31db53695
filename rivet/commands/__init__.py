"""Command groups of the rivet CLI; each module exposes `register(subparsers)`."""
