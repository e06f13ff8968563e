"""One stage of a plan: its name, kind, settings, inputs, hash and what it produces (a frozen record).

The engine reads ``name``, ``kind``, ``settings``, ``depends`` and ``hash``: the stage's directory is
``<name>-<hash>`` (:func:`dir_name`), complete once its ``stage.json`` is written, and a stage starts
once every stage it ``depends`` on is complete. ``outputs`` is the plan's own description of what
the stage produces (for the experiments that run it and the report that reads it); the engine
passes it along unread.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

#: a stage's folder of resumable progress (``<stage dir>/progress``): what a stage keeps so that a
#: killed call goes on where it was (a long meta-test's batches); the runner removes it once the
#: stage is complete, and a carried or published stage never holds it
PROGRESS = "progress"


def dir_name(name: str, h: str) -> str:
    """The directory of the stage ``name`` whose settings hash to ``h``."""
    return f"{name}-{h}"


def stage_of_dir(directory: str) -> str:
    """The stage name of a :func:`dir_name` (``maps-heldout-1010-a0bbedb7fc`` -> ``maps-heldout-1010``);
    a name without a hash as it is."""
    name, _, h = directory.rpartition("-")
    return (
        name if name and len(h) == 10 and all(ch in "0123456789abcdef" for ch in h) else directory
    )


@dataclass(frozen=True)
class Stage:
    """One stage (sub-stage) of a plan."""

    name: str  # unique in the plan, e.g. metatrain-kuka-ours
    kind: str  # the function that runs it and the keys of its result (its ``stage.json`` group)
    settings: Any  # plain JSON: what the stage computes depends on these and on ``depends`` only
    depends: Mapping[str, str]  # the stages it reads: name -> directory name (in the hash)
    hash: str  # of the settings and the inputs' directories: names the directory
    outputs: Any = None  # what the stage produces, as the plan describes it (read by its owner)

    @property
    def dir_name(self) -> str:
        return dir_name(self.name, self.hash)


__all__ = ["PROGRESS", "Stage", "dir_name"]
