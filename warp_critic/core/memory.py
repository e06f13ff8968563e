"""How much memory a run may use, and the one check that refuses settings that cannot fit.

Host memory comes from ``psutil``. In a container ``psutil`` reports the host's ``/proc/meminfo``,
not the container's cgroup limit, so a cgroup limit (v2 ``memory.max`` or v1
``memory.limit_in_bytes``), minus what the cgroup already uses, caps it where it is lower.
"""

from __future__ import annotations

from pathlib import Path

import psutil

from warp_critic.core.errors import FieldError

#: A run may plan to use at most this fraction of the available memory.
FRACTION = 0.8
# (limit, usage) files of cgroup v2 and v1
_CGROUP_FILES = (
    ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
    ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
)


def _read_int(path: str) -> int | None:
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None  # "max" = no limit


def _cgroup_free() -> int | None:
    """Bytes the cgroup may still allocate (its limit minus its usage), or ``None`` without a limit."""
    for limit_file, usage_file in _CGROUP_FILES:
        limit = _read_int(limit_file)
        if limit is not None:
            return max(0, limit - (_read_int(usage_file) or 0))
    return None


def available_memory(device: str = "cpu") -> int | None:
    """Bytes of memory free for a new allocation on ``device``: host RAM for the CPU (psutil's
    ``available``, capped by the cgroup), the GPU's free memory for ``cuda``; ``None`` when unknown."""
    if str(device).startswith("cuda"):
        import torch

        try:
            return int(torch.cuda.mem_get_info(torch.device(device))[0])
        except Exception:  # noqa: BLE001 - no driver: the run reports the device itself
            return None
    free = int(psutil.virtual_memory().available)
    cgroup = _cgroup_free()
    return free if cgroup is None else min(free, cgroup)


def check_fits(field: str, what: str, need: int) -> None:
    """Refuse a setting whose estimated peak memory ``need`` (bytes) exceeds :data:`FRACTION` of the
    available host memory: one :class:`FieldError` naming ``field``, saying ``what`` needs it."""
    have = available_memory()
    if have is not None and need > FRACTION * have:
        raise FieldError(
            field,
            f"{what} need about {need / 2**30:.1f} GiB, more than {FRACTION:.0%} of the "
            f"{have / 2**30:.1f} GiB available",
        )
