"""The Docker backend (the default): one warm, locked-down container per executor.

The container runs the fork-server harness as PID 1; the host talks to it over the container's
attached stdin/stdout (no `docker exec`, no network, no writable mount). Job files are staged in
a host directory mounted read-only at /in. Hardening, all by default: no network, read-only root
file system, size-capped tmpfs /tmp (noexec) and /dev/shm, uid 10001, every capability dropped,
no-new-privileges, the project's own seccomp profile (`sandbox.seccomp`: Docker's denials and
more — io_uring, System V and POSIX IPC, sockets other than unix/inet/inet6, namespaces),
pids/memory (swap = memory)/CPU limits, no host environment variables, a private IPC namespace,
no core dumps, no logging of the channel, the cgroup's high-water marks and limit-hit counts
masked (`MASKED_PATHS`: they would carry what one job used to the next). Containers
carry the label ``rivet.sandbox=1`` and their owner; leftovers whose owner is gone are reaped
whenever an executor starts.

What it does NOT isolate: the host kernel is shared (a kernel exploit is an escape; seccomp and
dropped capabilities narrow the surface, nothing more); timing and cache side channels; what
/proc and /sys show about the host (kernel version, CPU model, load, uptime); disk and memory
bandwidth. Inside the container, a program can read everything in the image (the harness,
`contracts`, `geometry`, `toolbox`: public anyway) and its own inputs; nothing that judges it
runs there.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import struct
import uuid
from pathlib import Path
from typing import Any

from sandbox import seccomp
from sandbox._session import Channel, ChannelClosed, HarnessExecutor
from sandbox.errors import BadJob, SandboxUnavailable
from sandbox.image import LABEL, docker_client, has_image, image_tag

_MUX = struct.Struct(">BxxxI")  # Docker's attach stream header: stream id, payload size
HARNESS_MB = 1024  # [MiB] kept for the warm harness (about 400 MiB resident) and the job's slack
# A container's masked paths replace the engine's default list, so that list comes first
# (Docker 20.10-27's, the last entry from 25 on). Then the cgroup files (v1 and v2) that hold a
# high-water mark or a count of limit hits over the container's life: a job could read there
# what an earlier job used (a few bits a job, from one to the next). Masked, each reads as
# empty (/dev/null bound over it); the harness reads none of them (it reads `memory.stat`,
# `cpu.stat` / `cpuacct.usage` and the OOM-kill count; docs/sandbox.md lists what those carry).
MASKED_PATHS = (
    "/proc/asound",
    "/proc/acpi",
    "/proc/kcore",
    "/proc/keys",
    "/proc/latency_stats",
    "/proc/timer_list",
    "/proc/timer_stats",
    "/proc/sched_debug",
    "/proc/scsi",
    "/sys/firmware",
    "/sys/devices/virtual/powercap",
    *(
        f"/sys/fs/cgroup/memory/memory.{kind}{what}"
        for kind in ("", "memsw.", "kmem.", "kmem.tcp.")
        for what in ("max_usage_in_bytes", "failcnt")
    ),
    "/sys/fs/cgroup/pids/pids.events",
    "/sys/fs/cgroup/memory.peak",
    "/sys/fs/cgroup/memory.swap.peak",
    "/sys/fs/cgroup/pids.peak",
    "/sys/fs/cgroup/pids.events",
)


class _AttachChannel(Channel):
    """The container's stdin/stdout over Docker's attach socket (stdout/stderr multiplexed)."""

    def __init__(self, sock: Any) -> None:
        self.wrapper = sock  # a SocketIO over the raw socket: the fd closes once both are closed
        self.sock = getattr(sock, "_sock", sock)
        self.sock.setblocking(True)
        self.buf = bytearray()
        self.stderr = bytearray()

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def recv(self, timeout: float) -> bytes:
        while True:
            out = self._take()
            if out:
                return out
            if not select.select([self.sock], [], [], max(0.0, timeout))[0]:
                raise TimeoutError(f"no data within {timeout:.1f} s")
            data = self.sock.recv(1 << 20)
            if not data:
                raise ChannelClosed("the container's output stream ended")
            self.buf += data

    def _take(self) -> bytes:
        out = bytearray()
        while len(self.buf) >= _MUX.size:
            stream, size = _MUX.unpack_from(self.buf)
            if len(self.buf) < _MUX.size + size:
                break
            payload = self.buf[_MUX.size : _MUX.size + size]
            del self.buf[: _MUX.size + size]
            if stream == 2:
                self.stderr += payload
                del self.stderr[:-8192]
            else:
                out += payload
        return bytes(out)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.wrapper.close()
        self.sock.close()


class DockerExecutor(HarnessExecutor):
    """Runs each job in a fresh forked child inside one warm, hardened container.

    Args:
        image: image tag (default: the tag of the current repository state; it must exist:
            `make sandbox-image`).
        cpus: CPU limit of the container [CPUs].
        memory_mb: memory limit of the container, harness included; swap is off [MiB]. A job
            may ask for at most this minus `HARNESS_MB`.
        pids_limit: most processes and threads in the container at once.
        tmpfs_mb: size of the /tmp tmpfs [MiB].
        preload: heavy modules the harness imports up front ("default", "none" or a,b,c).
        output_limit_mb: cap on a job's output [MiB].
    """

    name = "docker"

    def __init__(
        self,
        *,
        image: str | None = None,
        cpus: float = 1.0,
        memory_mb: int = 6144,
        pids_limit: int = 256,
        tmpfs_mb: int = 256,
        preload: str = "default",
        client: Any = None,
        output_limit_mb: float = 64,
        tail_bytes: int = 8192,
    ) -> None:
        self._own_client = client is None
        self.client = client or docker_client()
        self.image = image or image_tag()
        if not has_image(self.client, self.image):
            if self._own_client:
                self.client.close()
            raise SandboxUnavailable(
                f"the sandbox image {self.image} is missing (the image tag follows its inputs): "
                "build it with `make sandbox-image` (works offline)"
            )
        super().__init__(output_limit_mb=output_limit_mb, tail_bytes=tail_bytes)
        self.limits = {
            "cpus": cpus,
            "memory_mb": memory_mb,
            "pids_limit": pids_limit,
            "tmpfs_mb": tmpfs_mb,
        }
        self.preload = preload
        self.container: Any = None
        # labels every container this executor creates, so that one whose creation a signal
        # interrupted (the engine made it, its id never came back) is still removed
        self.token = uuid.uuid4().hex
        self.reaped = reap_leftovers(self.client)

    def container_options(self) -> dict[str, Any]:
        """The `containers.create` keyword arguments: every hardening setting in one place."""
        from docker.types import LogConfig, Ulimit

        lim = self.limits
        return {
            "command": ["python", "-m", "sandbox.harness.server", "--preload", self.preload],
            "stdin_open": True,
            "tty": False,
            "network_mode": "none",
            "read_only": True,
            "user": "10001:10001",
            "cap_drop": ["ALL"],
            "security_opt": ["no-new-privileges:true", f"seccomp={seccomp.profile_json()}"],
            "pids_limit": lim["pids_limit"],
            "mem_limit": f"{lim['memory_mb']}m",
            "memswap_limit": f"{lim['memory_mb']}m",
            "nano_cpus": int(lim["cpus"] * 1e9),
            "tmpfs": {"/tmp": f"rw,nosuid,nodev,noexec,size={lim['tmpfs_mb']}m,mode=1777"},
            "shm_size": "64m",
            "ipc_mode": "private",
            "environment": {},  # none of the host's; the image sets the few the harness keeps
            "volumes": {str(self.stage_root): {"bind": "/in", "mode": "ro"}},
            "working_dir": "/tmp",
            "hostname": "sandbox",
            "ulimits": [
                Ulimit(name="core", soft=0, hard=0),
                Ulimit(name="nofile", soft=1024, hard=1024),
            ],
            "log_config": LogConfig(type="none"),
            "labels": {LABEL: "1", f"{LABEL}.owner": _owner(), f"{LABEL}.executor": self.token},
        }

    def _open(self) -> Channel:
        import docker

        try:
            self.container = self._create()
            sock = self.container.attach_socket(
                params={"stdin": 1, "stdout": 1, "stderr": 1, "stream": 1}
            )
            self.container.start()
        except docker.errors.DockerException as e:
            self._kill()
            raise SandboxUnavailable(
                f"cannot start a sandbox container from {self.image}: {e}"
            ) from None
        return _AttachChannel(sock)

    def _create(self) -> Any:
        """`containers.create` with the masked paths added (the client library has no option
        for them; the engine's API has since 1.39): the same steps the library takes."""
        try:
            from docker.models.containers import _create_container_args
        except ImportError as e:  # a docker SDK that changed its insides
            raise SandboxUnavailable(
                f"this docker SDK cannot create the sandbox container ({e}); install the "
                "version uv.lock pins (uv sync)"
            ) from None
        kwargs = {
            **self.container_options(),
            "image": self.image,
            "version": self.client.api.api_version,
        }
        create = _create_container_args(kwargs)
        create["host_config"]["MaskedPaths"] = list(MASKED_PATHS)
        made = self.client.api.create_container(**create)
        return self.client.containers.get(made["Id"])

    def _harness_path(self, staged: Path) -> str:
        return f"/in/{staged.name}"

    def _check(self, memory_mb: int) -> None:
        room = self.limits["memory_mb"] - HARNESS_MB
        if memory_mb > room:
            raise BadJob(
                f"the program asks for {memory_mb} MiB but this executor's container leaves "
                f"{room} MiB for programs; open it with memory_mb={memory_mb + HARNESS_MB} or more"
            )

    def close(self) -> None:
        super().close()
        if self._own_client:
            self.client.close()

    def _kill(self) -> None:
        """Remove this executor's container, and any other it created: a SIGTERM or Ctrl-C
        can land between the engine creating one and its id reaching `self.container`."""
        import docker

        with contextlib.suppress(docker.errors.DockerException):
            if self.container is not None:
                self.container.remove(force=True)
            for c in self.client.containers.list(
                all=True, filters={"label": f"{LABEL}.executor={self.token}"}
            ):
                c.remove(force=True)
        self.container = None

    def _death(self) -> tuple[str, str]:
        import docker

        try:
            self.container.wait(timeout=10)
            self.container.reload()
            state = self.container.attrs["State"]
        except (docker.errors.DockerException, OSError, AttributeError) as e:
            return "crashed", f"the sandbox container died ({type(e).__name__}); restarted"
        if state.get("OOMKilled"):
            return "oom", "the container ran out of memory and was killed; restarted"
        return (
            "crashed",
            f"the sandbox container died (exit code {state.get('ExitCode')}); restarted",
        )

    def _diagnostics(self) -> str:
        channel = self._channel
        if isinstance(channel, _AttachChannel) and channel.stderr:
            return "harness stderr: " + channel.stderr.decode(errors="replace")[-2000:]
        return ""


def reap_leftovers(client: Any) -> int:
    """Remove labelled sandbox containers that stopped or whose owner process is gone."""
    import docker

    n = 0
    try:
        containers = client.containers.list(all=True, filters={"label": f"{LABEL}=1"})
    except docker.errors.DockerException:
        return 0
    for c in containers:
        owner = c.labels.get(f"{LABEL}.owner", "")
        if c.status == "running" and _owner_alive(owner):
            continue
        with contextlib.suppress(docker.errors.DockerException):
            c.remove(force=True)
            n += 1
    return n


def _owner() -> str:
    return f"{socket.gethostname()}:{os.getpid()}:{_start_time(os.getpid())}"


def _owner_alive(owner: str) -> bool:
    """Whether the process named by an owner label still runs (unknown hosts count as alive)."""
    host, _, rest = owner.partition(":")
    pid, _, start = rest.partition(":")
    if host != socket.gethostname():
        return bool(owner)
    return pid.isdigit() and _start_time(int(pid)) == start


def _start_time(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return ""
