"""The in-container harness: the fork server, the forked child, the wire format.

Design rule: this package imports only the standard library and numpy, and nothing from the
rest of `sandbox`, because it is copied into the sandbox image on its own (as
`sandbox.harness`, under a stub `sandbox` package) and also runs as the local backend's
subprocess.
"""
