"""Process set-up, in one place: Warp start, torch threads, seeding and RNG state.

Everything that starts a run (the CLI, the tools, the tests) calls :func:`init` once. Library code
never changes torch's thread count or reseeds global random state; code that needs Warp (the
simulator) starts it only through :func:`init_warp`, which does so once, quietly.
"""

from __future__ import annotations

import os
import random
import sys

import numpy as np
import torch

from warp_critic.core.errors import FieldError, UserError

THREADS_ENV = "WARP_CRITIC_TORCH_THREADS"
GRAPHS_ENV = "WARP_CRITIC_GRAPHS"
MAX_SEED = 2**32 - 1  # numpy's legacy seeding takes 32 bits; torch takes 64: the common range
#: the most seeds one process trains at once (``--seeds``; ``reproduce --seeds``): each gets a run
#: directory and its share of one simulator
MAX_SEEDS = 100


_warp_started = False


#: The file descriptor of the process's stderr: 2, or a copy of it while Warp starts with 2 silenced.
_stderr = 2


def stderr_fd() -> int:
    """Where a line for the user goes now (file descriptor 2 is /dev/null while Warp starts)."""
    return _stderr


def init_warp(quiet: bool = True) -> None:
    """Initialise Warp once (later calls return at once), without its banner and without the native
    CUDA-driver warning on GPU-less machines (printed unconditionally to file descriptor 2;
    ``device="cuda"`` on such a machine gets our own one-line error instead)."""
    global _warp_started
    if _warp_started:
        return
    import warp as wp

    if quiet:
        wp.config.quiet = True
        if hasattr(wp, "LOG_WARNING"):
            wp.config.log_level = wp.LOG_WARNING
        sys.stderr.flush()
        global _stderr
        saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
        try:
            _stderr = saved  # a signal's one line still reaches the user (cli/signals.py)
            os.dup2(devnull, 2)
            wp.init()
        finally:
            os.dup2(saved, 2)
            _stderr = 2
            os.close(saved)
            os.close(devnull)
    else:
        wp.init()
    _warp_started = True


def check_threads(n: int, name: str = "cpu_threads") -> int:
    """A torch thread count: 0 = torch's default, else 1 .. 4 x the cores (more only thrashes)."""
    limit = 4 * (os.cpu_count() or 1)
    if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= limit:
        raise FieldError(
            name,
            f"must be an integer in 0..{limit} (0 = torch's default; this machine has "
            f"{os.cpu_count()} cores), got {n!r}",
        )
    return n


def threads_from_env() -> int:
    """``$WARP_CRITIC_TORCH_THREADS`` (default 1), validated."""
    text = os.environ.get(THREADS_ENV, "1").strip()
    try:
        n = int(text)
    except ValueError:
        raise UserError(
            f"${THREADS_ENV}={text!r}: expected an integer number of torch threads"
        ) from None
    if n < 1:
        raise UserError(f"${THREADS_ENV}={text!r}: must be >= 1")
    try:
        return check_threads(n)
    except FieldError as e:
        raise UserError(f"${THREADS_ENV}={text!r}: {e.problem}") from None


def graphs_from_env() -> bool:
    """``$WARP_CRITIC_GRAPHS`` (default ``1``): replay captured Warp graphs in the simulator.

    ``0`` issues every Warp launch from Python: the same numbers bit for bit, slower; for debugging
    and for measuring the replay side by side (``bench/bench_speed.py``).
    """
    text = os.environ.get(GRAPHS_ENV, "1").strip()
    if text not in ("0", "1"):
        raise UserError(f"${GRAPHS_ENV}={text!r}: expected 0 or 1")
    return text == "1"


def set_threads(n: int) -> None:
    """Set torch's intra-op thread count (``0`` keeps torch's default)."""
    if check_threads(n):
        torch.set_num_threads(n)


def init(threads: int | None = None, quiet: bool = True) -> None:
    """Start a process: Warp (quietly) and torch threads (default ``$WARP_CRITIC_TORCH_THREADS`` or 1).

    The networks are small and Warp's CPU kernels are single-threaded: one torch thread avoids
    oversubscription stalls on a busy machine.
    """
    set_threads(threads_from_env() if threads is None else threads)
    graphs_from_env()  # a bad value is reported at start, not at the first simulator
    init_warp(quiet)


# ------------------------------------------------------------------------------------------------
# seeding and RNG state
# ------------------------------------------------------------------------------------------------


def check_device(device, name: str = "device") -> str:
    """``device`` when it names a device the project can run on (``auto``, ``cpu``, ``cuda`` or
    ``cuda:N``), else a :class:`FieldError` for the flag or field ``name``. Only the name is checked
    (pure: nothing is imported or started); whether that GPU exists is
    :func:`warp_critic.physics.simulator.resolve_device`'s question."""
    d = device if isinstance(device, str) else None
    if d in ("auto", "cpu", "cuda") or (d is not None and d[:5] == "cuda:" and d[5:].isdigit()):
        return d
    raise FieldError(name, f"must be auto, cpu, cuda or cuda:N (got {device!r})")


def check_seed(seed, name: str = "seed") -> int:
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise FieldError(name, f"must be an integer in 0..{MAX_SEED} (got {seed!r})")
    return seed


def seed_everything(seed: int) -> torch.Generator:
    """Seed Python, numpy and torch; returns the run's own generator (everything a run draws)."""
    check_seed(seed)
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    return torch.Generator().manual_seed(seed)


def rng_state(gen: torch.Generator) -> dict:
    """Random-number state to store in a checkpoint (our generator and torch's global one)."""
    return {"rng_state": gen.get_state(), "torch_rng_state": torch.get_rng_state()}


def restore_rng(gen: torch.Generator, ckpt: dict) -> None:
    """Inverse of :func:`rng_state`: a resumed run draws the same numbers as an uninterrupted one."""
    gen.set_state(ckpt["rng_state"])
    torch.set_rng_state(ckpt["torch_rng_state"])
