"""The sandbox's seccomp profile: what a program may not ask the kernel, whatever its uid.

Design rule: the profile replaces Docker's default one, so it must deny at least what that one
denies to an unprivileged container, and it denies more: everything the drafts never need that
widens the kernel surface or outlives a session. The list is ours (written from the syscall
table, not copied): a denied call fails with EPERM (ENOSYS for `clone3`, so that the C library
falls back to `clone`, whose flags can be inspected). Only the machine's native architecture
is allowed, so 32-bit or x32 entry points cannot go around the list.

- kernel and system state: modules, kexec, reboot, swap, clocks, quotas, accounting, syslog,
  mounts and file-system contexts, pivot_root/chroot, personality (ASLR off, exec stacks);
- other processes and namespaces: ptrace, process_vm_*, pidfd_getfd, kcmp, setns, unshare,
  clone with any CLONE_NEW* flag;
- attack surface drafts never use: bpf, perf_event_open, userfaultfd, keyrings, io_uring,
  open_by_handle_at, fanotify;
- state that would outlive a session in a warm container: System V shared memory, message
  queues and semaphores, POSIX message queues;
- sockets of any family but AF_UNIX, AF_INET and AF_INET6 (no AF_NETLINK, AF_PACKET,
  AF_VSOCK, AF_ALG, …; `--network none` leaves only loopback for the last two).

`rivet sandbox doctor` tries each group live.
"""

from __future__ import annotations

import json
import platform
from typing import Any

EPERM = 1
ENOSYS = 38

DENIED: dict[str, tuple[str, ...]] = {
    "kernel and system state": (
        "acct", "adjtimex", "clock_adjtime", "clock_settime", "create_module", "delete_module",
        "finit_module", "get_kernel_syms", "init_module", "ioperm", "iopl", "kexec_file_load",
        "kexec_load", "nfsservctl", "query_module", "quotactl", "quotactl_fd", "reboot",
        "settimeofday", "swapoff", "swapon", "syslog", "sysfs", "_sysctl", "uselib", "ustat",
        "vhangup", "vm86", "vm86old", "lookup_dcookie", "personality",
    ),
    "mounts": (
        "mount", "umount", "umount2", "pivot_root", "chroot", "fsopen", "fsconfig", "fsmount",
        "fspick", "move_mount", "open_tree", "mount_setattr",
    ),
    "other processes and namespaces": (
        "ptrace", "process_vm_readv", "process_vm_writev", "pidfd_getfd", "kcmp", "setns",
        "unshare", "process_madvise",
    ),
    "unused attack surface": (
        "bpf", "perf_event_open", "userfaultfd", "add_key", "keyctl", "request_key",
        "io_uring_setup", "io_uring_enter", "io_uring_register", "name_to_handle_at",
        "open_by_handle_at", "fanotify_init",
    ),
    "IPC that outlives a session": (
        "shmget", "shmat", "shmdt", "shmctl", "msgget", "msgsnd", "msgrcv", "msgctl",
        "semget", "semop", "semtimedop", "semctl", "mq_open", "mq_unlink", "mq_timedsend",
        "mq_timedreceive", "mq_notify", "mq_getsetattr",
    ),
}  # fmt: skip
ALLOWED_SOCKET_FAMILIES = (1, 2, 10)  # AF_UNIX, AF_INET, AF_INET6
CLONE_NAMESPACE_FLAGS = {
    "CLONE_NEWTIME": 0x00000080,
    "CLONE_NEWNS": 0x00020000,
    "CLONE_NEWCGROUP": 0x02000000,
    "CLONE_NEWUTS": 0x04000000,
    "CLONE_NEWIPC": 0x08000000,
    "CLONE_NEWUSER": 0x10000000,
    "CLONE_NEWPID": 0x20000000,
    "CLONE_NEWNET": 0x40000000,
}
_ARCH = {"x86_64": "SCMP_ARCH_X86_64", "amd64": "SCMP_ARCH_X86_64", "aarch64": "SCMP_ARCH_AARCH64",
         "arm64": "SCMP_ARCH_AARCH64"}  # fmt: skip


def _deny(names: list[str] | tuple[str, ...], errno: int = EPERM, **extra: Any) -> dict[str, Any]:
    return {"names": list(names), "action": "SCMP_ACT_ERRNO", "errnoRet": errno, **extra}


def _arg(index: int, value: int, op: str, value_two: int = 0) -> dict[str, Any]:
    return {"index": index, "value": value, "valueTwo": value_two, "op": op}


def profile(machine: str | None = None) -> dict[str, Any]:
    """The profile as Docker's JSON format expects it (`--security-opt seccomp=<json>`)."""
    arch = _ARCH.get((machine or platform.machine()).lower())
    if arch is None:
        raise ValueError(f"no seccomp architecture known for {machine or platform.machine()!r}")
    rules = [_deny(sorted(n for group in DENIED.values() for n in group))]
    rules.append(_deny(["clone3"], ENOSYS))
    for flag in CLONE_NAMESPACE_FLAGS.values():  # any namespace flag set → refused
        rules.append(_deny(["clone"], args=[_arg(0, flag, "SCMP_CMP_MASKED_EQ", flag)]))
    highest = max(ALLOWED_SOCKET_FAMILIES)
    rules.append(_deny(["socket"], args=[_arg(0, highest, "SCMP_CMP_GT")]))
    for family in range(0, highest):
        if family not in ALLOWED_SOCKET_FAMILIES:
            rules.append(_deny(["socket"], args=[_arg(0, family, "SCMP_CMP_EQ")]))
    return {"defaultAction": "SCMP_ACT_ALLOW", "architectures": [arch], "syscalls": rules}


def profile_json(machine: str | None = None) -> str:
    return json.dumps(profile(machine), separators=(",", ":"), sort_keys=True)
