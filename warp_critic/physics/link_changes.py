"""Link changes: the text form ``LINK.WHAT OP VALUE[@POINT][:MODE]`` of a dynamics change of any link.

A :class:`~warp_critic.physics.variants.Variant` carries a tuple of :class:`LinkChange`, applied in
order to one robot copy. ``LINK`` is a body name of the scene (``iiwa_link_7``, ``arm1``) or ``ee``
(the end-effector link). Several changes are joined with ``;``. What each one does (SI units):

==========================  =====================================================================
``L.mass=V``                SET the link's mass to ``V`` kg (>= 0; 0 is stored as 1e-6 kg, which
                            keeps the link's rotational inertia); its centre of mass (COM) stays
``L.mass+=V``               ADD ``V`` kg at the COM (the new mass must stay >= 0)
``L.mass*=V``               SCALE the mass by ``V`` (>= 0)
  ``:keep`` (default)       ... the inertia tensor about the COM is kept
  ``:scale``                ... the inertia about the COM is scaled by new mass / old mass
``L.point-mass+=V@x,y,z``   ADD a point mass ``V`` kg (>= 0) at ``(x, y, z)`` m in the link frame
                            (``@tip``, the default: the link's end, see below); mass, COM and
                            inertia follow by the parallel-axis theorem
``L.offset=V`` / ``+=`` /   a KINEMATIC length change: the link's end moves along its direction to
``*=``                      length ``V`` / ``L+V`` / ``L*V`` m; mass, COM and inertia unchanged
``L.stretch=V`` / ``+=`` /  a STRETCHED link of that length: its mass distribution, child joints and
``*=``                      visual shapes are stretched along the link at constant mass
==========================  =====================================================================

A link's *end* is the end-effector tip (``warp_critic:tipOffset``) for the end-effector link, else
the origin of its one child joint; its *length* is the end's distance from the link frame. Changing
the length of a link with a child (reacher ``arm1``) therefore moves the child joint, and with it the
rest of the chain. Every mistake raises :class:`~warp_critic.core.errors.FieldError` on the field
``variant`` with a one-line message.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import cast

from warp_critic.core.errors import FieldError

__all__ = ["LinkChange", "parse_changes", "format_changes", "WHATS", "OPS", "MODES"]

WHATS = ("mass", "point-mass", "offset", "stretch")
OPS = ("=", "+=", "*=")
#: allowed modes per WHAT; the first is the default
MODES = {"mass": ("keep", "scale"), "point-mass": ("",), "offset": ("",), "stretch": ("",)}
FIELD = "variant"

_PATTERN = re.compile(
    r"^\s*(?P<link>[^.\s]+)\s*\.\s*(?P<what>[a-z-]+)\s*(?P<op>\+=|\*=|=)\s*(?P<value>[^@:]+?)\s*"
    r"(?:@\s*(?P<point>[^:]+?)\s*)?(?::\s*(?P<mode>[a-z-]+)\s*)?$"
)


@dataclass(frozen=True)
class LinkChange:
    """One change of one link (module docstring). ``point`` is ``None`` (the link's end) or metres
    in the link frame; ``mode`` is ``keep``/``scale`` for a mass change, else ``""``."""

    link: str
    what: str
    op: str
    value: float
    point: tuple[float, float, float] | None = None
    mode: str = ""

    def validate(self) -> None:
        def bad(problem: str) -> FieldError:
            return FieldError(FIELD, f"{self.text()!r}: {problem}")

        if not isinstance(self.link, str) or not self.link:
            raise bad("needs a link name (a body of the scene, or ee)")
        if self.what not in WHATS:
            raise bad(f"unknown change {self.what!r} (known: {', '.join(WHATS)})")
        if self.op not in OPS:
            raise bad(f"unknown operation {self.op!r} (known: {', '.join(OPS)})")
        if not _finite(self.value):
            raise bad(f"the value must be a finite number (got {self.value!r})")
        if self.mode not in MODES[self.what]:
            modes = [m for m in MODES[self.what] if m]
            raise bad(
                f"mode {self.mode!r} does not apply to {self.what}"
                + (f" (modes: {', '.join(modes)})" if modes else " (it takes no mode)")
            )
        if self.point is not None and (
            self.what != "point-mass"
            or len(self.point) != 3
            or not all(_finite(x) for x in self.point)
        ):
            raise bad("@POINT is x,y,z in metres, and only for point-mass")
        if self.point is not None:  # the bound import puts on a tip: farther is a typing mistake
            from warp_critic.physics.model_checks import TIP_OFFSET_MAX

            distance = math.sqrt(sum(float(x) ** 2 for x in self.point))
            if distance > TIP_OFFSET_MAX:
                raise bad(
                    f"@POINT is {distance:g} m from the link; a point is at most "
                    f"{TIP_OFFSET_MAX:g} m from it"
                )
        value = float(self.value)
        if self.what == "point-mass" and (self.op != "+=" or value < 0):
            raise bad("a point mass is added: point-mass+=KG with KG >= 0")
        if self.what == "mass" and self.op != "+=" and value < 0:
            raise bad(f"must be >= 0 (got {value})")
        if self.what in ("offset", "stretch") and self.op != "+=" and value <= 0:
            raise bad(f"must be > 0 (got {value})")

    def text(self) -> str:
        """The change in its text form (round-trips through :func:`parse_changes`)."""
        point = "" if self.point is None else "@" + ",".join(f"{x:g}" for x in self.point)
        mode = f":{self.mode}" if self.mode else ""
        return f"{self.link}.{self.what}{self.op}{self.value:g}{point}{mode}"


def _finite(x) -> bool:
    try:
        return not isinstance(x, bool) and math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def parse_changes(text: str | None) -> tuple[LinkChange, ...]:
    """``'iiwa_link_7.mass=5; ee.offset+=0.4'`` -> a tuple of validated :class:`LinkChange`
    (``None`` or blank -> ``()``). Raises a one-line :class:`FieldError` on ``variant``."""
    if text is None:
        return ()
    if not isinstance(text, str):
        raise FieldError(FIELD, f"must be text like 'ee.mass+=1' (got {text!r})")
    out = []
    for item in (part.strip() for part in text.split(";")):
        if not item:
            continue
        m = _PATTERN.match(item)
        if m is None:
            raise FieldError(
                FIELD,
                f"{item!r}: expected LINK.WHAT=VALUE, +=VALUE or *=VALUE, e.g. ee.mass+=1, "
                "iiwa_link_7.mass=5:keep, ee.point-mass+=2@tip, arm1.offset=1.5, ee.stretch*=2",
            )
        try:
            value = float(m["value"])
        except ValueError:
            raise FieldError(FIELD, f"{item!r}: {m['value']!r} is not a number") from None
        point: tuple[float, float, float] | None = None
        if m["point"] is not None and m["point"] != "tip":
            try:
                xyz = tuple(float(x) for x in m["point"].split(","))
            except ValueError:
                raise FieldError(FIELD, f"{item!r}: @{m['point']} is not x,y,z or tip") from None
            point = cast("tuple[float, float, float]", xyz)  # validate() refuses another length
        what = m["what"]
        mode = m["mode"] if m["mode"] is not None else MODES.get(what, ("",))[0]
        change = LinkChange(m["link"], what, m["op"], value, point, mode)
        change.validate()
        out.append(change)
    return tuple(out)


def format_changes(changes: tuple[LinkChange, ...]) -> str:
    """The text form of ``changes`` (``''`` for none)."""
    return "; ".join(c.text() for c in changes)
