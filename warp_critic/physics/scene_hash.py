"""The content hash of a USD scene: one digest for one content, whatever the file's name or place.

:func:`content_hash` hashes the text export of the FLATTENED stage (sublayers and references
composed in), without the "Generated from Composed Stage of root layer <path>" note that
:meth:`Usd.Stage.Flatten` would add, and with asset paths under the scene's own folder (which
flattening makes absolute) written back relative to it (``@/abs/dir/x.png@`` -> ``@./x.png@``).
So a renamed or moved copy (or the .usdc of the same stage) hashes the same, and any change of what
the simulation reads -- a mass, a limit, the home pose -- changes the hash.

Instanced prims (``instanceable = true``) are expanded in place before flattening: USD numbers
their prototypes in an order that changes from one stage to the next (``Flattened_Prototype_1``
may be any of them), which would give one file a different hash in every process.

The training-default attributes (:data:`~warp_critic.physics.schema.ATTRIBUTES` outside the
``scene`` scope) are left out: a run resolves them into its own config, so a changed default does
not change any run. The text format is the installed USD's: compare hashes made with the same USD
version.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from warp_critic.physics.schema import ATTRIBUTES

__all__ = ["content_hash"]

# root attributes a run copies into its config (not read by the simulation)
_UNHASHED = tuple(a.usd for a in ATTRIBUTES if a.scope != "scene")


def content_hash(path: Path, stage) -> str:
    """sha256 hex digest of ``stage``'s composed content (``path``: its root layer's file)."""
    text = _expanded(stage).Flatten(addSourceFileComment=False).ExportToString()
    text = text.replace(f"@{path.parent.as_posix()}/", "@./")
    names = tuple(f" {attr} " for attr in _UNHASHED) + tuple(f" {attr}=" for attr in _UNHASHED)
    text = "\n".join(line for line in text.splitlines() if not any(n in line for n in names))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _expanded(stage):
    """``stage`` itself when it has no instances, else a second stage on the same layers whose
    session layer turns instancing off for every instance (nested ones included)."""
    if not stage.GetPrototypes():
        return stage
    from pxr import Sdf, Usd

    session = Sdf.Layer.CreateAnonymous(".usda")
    session.TransferContent(stage.GetSessionLayer())
    view = Usd.Stage.Open(
        stage.GetRootLayer(), session, stage.GetPathResolverContext(), Usd.Stage.LoadAll
    )
    view.SetLoadRules(stage.GetLoadRules())
    with Usd.EditContext(view, view.GetSessionLayer()):
        for _ in range(64):  # each pass exposes one more level of nested instances
            if not view.GetPrototypes():
                break
            for prim in Usd.PrimRange.Stage(view, Usd.PrimAllPrimsPredicate):
                if prim.IsInstance():
                    prim.SetInstanceable(False)
    if view.GetPrototypes():
        raise ValueError("instanced prims that cannot be expanded for hashing")
    return view
