"""``--ray [ADDRESS]``: each reproduce unit as a Ray task (see :mod:`warp_critic.reproduce.engine.executors`).

No shared filesystem is assumed: a task gets the files of the stage directories it reads (and of its
own unfinished stage directory, to resume) and returns the files of its stage directory, which the
driver writes into ``--out``. The address is checked before anything starts: it must answer as a
gRPC server does (a Ray head), within seconds. A user error raised inside a task reaches the driver
as that one-line error.
"""

from __future__ import annotations

import os
import socket
import tempfile
import time
from pathlib import Path

from warp_critic.core.errors import FieldError, UserError
from warp_critic.reproduce.engine.executors import (
    UNIT_FAULT_ENV,
    Admit,
    Done,
    Log,
    More,
    Unit,
    _quiet,
    admit_all,
    call_unit,
    no_units,
)


def _read_tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder``, keyed by its path relative to ``folder.parent``."""
    out = {}
    if folder.is_dir():
        for p in sorted(folder.rglob("*")):
            if p.is_file() and not p.name.endswith(".tmp") and p.name != ".lock":
                out[str(p.relative_to(folder.parent))] = p.read_bytes()
    return out


def _write_tree(root: Path, files: dict[str, bytes]) -> None:
    from warp_critic.running.files import atomic_write_bytes

    for rel, data in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, data)


def _ray_unit(
    unit: Unit, inputs: dict[str, bytes], env: dict[str, str]
) -> tuple[dict[str, bytes], dict, float]:
    """A Ray task: run ``unit`` in a private folder holding ``inputs``; return its stage directory's files."""
    os.environ.update(env)
    from warp_critic.core.runtime import init

    init()
    with tempfile.TemporaryDirectory(prefix="warp-critic-unit-") as tmp:
        root = Path(tmp)
        for rel, data in inputs.items():
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            (root / rel).write_bytes(data)
        t = time.perf_counter()
        result = call_unit(_quiet(unit), root)
        seconds = time.perf_counter() - t
        return _read_tree(root / unit.dir_name), result, seconds


#: the client preface of HTTP/2 and an empty SETTINGS frame; a gRPC server (a Ray head) answers
#: with its own SETTINGS frame
H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + b"\x00\x00\x00\x04\x00\x00\x00\x00\x00"


def _speaks_grpc(host: str, port: int, timeout: float = 3.0) -> bool:
    """Whether ``host:port`` answers an HTTP/2 preface with a SETTINGS frame (gRPC does)."""
    with socket.create_connection((host, port), timeout=timeout) as conn:
        conn.settimeout(timeout)
        conn.sendall(H2_PREFACE)
        head = b""
        deadline = time.monotonic() + timeout
        while len(head) < 9 and time.monotonic() < deadline:
            try:
                chunk = conn.recv(9 - len(head))
            except TimeoutError:
                break
            if not chunk:
                break
            head += chunk
    return len(head) == 9 and head[3] == 0x04 and head[5:9] == b"\x00\x00\x00\x00"


def check_ray_address(address: str | None) -> None:
    """A reachable ``HOST:PORT`` that speaks gRPC, as a Ray head does (or ``auto``, or none for a
    local cluster), checked in a few seconds before anything starts."""
    if address in (None, "", "auto", "local"):
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise FieldError(
            "ray",
            f"{address!r}: expected auto, or HOST:PORT of the cluster's head (e.g. 10.0.0.1:6379)",
        )
    try:
        grpc = _speaks_grpc(host.strip("[]"), int(port))
    except (OSError, ValueError, OverflowError) as e:
        raise FieldError("ray", f"{address}: cannot reach the Ray cluster's head ({e})") from None
    if not grpc:
        raise FieldError(
            "ray",
            f"{address}: not a Ray cluster's head (it does not answer as a gRPC server does; "
            "give the address that `ray start --head` printed)",
        )


def unit_failure(name: str, e: BaseException) -> UserError:
    """The one-line error of a unit that failed on Ray: a user error raised inside the task (Ray
    hands it back as the ``cause`` of its wrapper) is that error itself, anything else says so."""
    cause = getattr(e, "cause", None)
    if isinstance(cause, UserError):
        return cause
    if isinstance(e, UserError):
        return e
    return UserError(
        f"reproduce: unit {name} failed on Ray ({type(e).__name__}: "
        f"{' '.join(str(e).split())[:200]}); run again to resume"
    )


class RayExecutor:
    """One Ray task per unit (``address``: ``None`` starts a local cluster, ``auto`` joins the running
    one, ``HOST:PORT`` the head at that address)."""

    name = "ray"

    def __init__(
        self, address: str | None, device: str, num_cpus: int | None = None, retries: int = 3
    ):
        try:
            import ray
        except ImportError:
            raise UserError('--ray needs Ray: pip install -e ".[ray]"') from None
        check_ray_address(address)
        self.ray, self.retries = ray, retries
        kwargs = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
        try:
            if address in (None, "", "local"):  # a cluster of this machine alone, on loopback
                ray.init(
                    num_cpus=num_cpus or os.cpu_count(), _node_ip_address="127.0.0.1", **kwargs
                )
            else:
                ray.init(address=address, **kwargs)
        except Exception as e:  # ConnectionError and Ray's own
            raise FieldError(
                "ray",
                f"{address or 'local'}: cannot start or join a Ray cluster "
                f"({type(e).__name__}: {' '.join(str(e).split())[:160]})",
            ) from None
        self.gpu = str(device).startswith("cuda")
        if self.gpu and not ray.cluster_resources().get("GPU", 0):
            ray.shutdown()
            raise FieldError("device", f"{device}: the Ray cluster has no GPU")

    def run(
        self,
        units: list[Unit],
        root: Path,
        done: Done,
        log: Log,
        more: More = no_units,
        admit: Admit = admit_all,
    ) -> None:
        """Submit each unit once ready (and ``admit``-ted: Ray queues it for a free worker
        itself, so a limit is asked at submission)."""
        ray = self.ray
        env = {
            k: v
            for k, v in os.environ.items()
            if k in (UNIT_FAULT_ENV, "WARP_CRITIC_TORCH_THREADS")
        }
        task = ray.remote(_ray_unit).options(
            max_retries=self.retries,
            retry_exceptions=False,
            num_cpus=0 if self.gpu else 1,
            num_gpus=1 if self.gpu else 0,
        )
        refs = {}

        def submit(u: Unit) -> None:
            inputs = _read_tree(root / u.dir_name)  # an unfinished stage directory resumes
            for d in u.reads:
                inputs.update(_read_tree(root / d))
            log(f"reproduce: {u.name}: submitted to Ray ({u.dir_name}, {len(inputs)} input files)")
            refs[task.remote(u, inputs, env)] = u

        for u in units:
            if admit(u):
                submit(u)
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            u = refs.pop(ready[0])
            try:
                files, result, seconds = ray.get(ready[0])
            except Exception as e:  # the unit failed for good (after Ray's retries)
                raise unit_failure(u.name, e) from None
            stage = root / u.dir_name
            _write_tree(root, files)
            for p in sorted(
                stage.rglob("*"), reverse=True
            ):  # the task returned the whole directory:
                rel = str(
                    p.relative_to(root)
                )  # what it removed (unstarted seeds, merged segments) goes
                if p.is_file() and rel not in files and p.name != ".lock":
                    p.unlink()
            done(u, result, seconds)
            for ready in more():
                if admit(ready):
                    submit(ready)

    def close(self) -> None:
        self.ray.shutdown()


__all__ = ["RayExecutor", "check_ray_address", "unit_failure"]
