"""Which joints an imported robot trains: the arm chain the file or ``--joints`` chooses, with a
gripper (tendon, equality-coupled or linkage) and a single chain's jaw locked at home; closed loops
and undriven joints among the trained ones refused in one line (:mod:`.robot` builds the scene on
the choice)."""

from __future__ import annotations

from pathlib import Path

from warp_critic.physics.actuation import arm_chains
from warp_critic.physics.importers import (
    fail,
    short,
)
from warp_critic.physics.mjcf_file import GRIPPER_NAME

__all__ = ["check_loops", "trained_joints"]


def check_loops(path: Path, builder, loops, trained: set[int]) -> None:
    """Refuse an MJCF ``connect``/``weld`` equality that closes a loop through a trained joint (one
    whose bodies a locked gripper holds rigid is no concern)."""
    by_name = {short(label): b for b, label in enumerate(builder.body_label)}
    joint_of = {c: j for j, c in enumerate(builder.joint_child)}

    def up(body: int) -> list[int]:
        out: list[int] = []
        while body >= 0 and body in joint_of and len(out) <= len(joint_of):
            out.append(joint_of[body])
            body = builder.joint_parent[joint_of[body]]
        return out

    for kind, b1, b2 in loops:
        a = up(by_name.get(b1, -1))
        b = up(by_name.get(b2, -1))
        through = [j for j in set(a) ^ set(b) if j in trained]
        if through:
            raise fail(
                path,
                f"closed kinematic loop: an <equality><{kind}> joins bodies {b1 or 'world'!r} and "
                f"{b2 or 'world'!r} across the trained joint {short(builder.joint_label[through[0]])!r}; "
                "warp-critic trains open-chain (tree) robots (--joints NAME,.. trains others and "
                "locks the rest at home)",
            )


def trained_joints(
    path: Path, builder, names: list[str], jointed: list[int], actuation, options
) -> tuple[set[int], int | None, str | None]:
    """The joints to train (the others are locked at home) and, for an arm with a hand or a jaw,
    the body that holds it (the default end effector) and the note that says so: ``--joints``,
    else the arm chain of an arm with a hand, else a single chain less its jaw, else every joint;
    each trained joint then needs an actuator (:func:`_check_actuated`). ``options``: the import's
    :class:`~warp_critic.physics.robot.RobotOptions` (its ``joints`` is read)."""
    if options.joints is not None:
        by_name = {names[j]: j for j in jointed}
        unknown = [n for n in options.joints if n not in by_name]
        if unknown or not options.joints:
            raise fail(
                path,
                f"joints: {unknown[0] if unknown else '(none)'!r} is not a movable joint of the "
                f"robot (movable: {', '.join(names[j] for j in jointed)})",
            )
        return {by_name[n] for n in options.joints}, None, None
    arms = arm_chains(builder, set(jointed))
    if len(arms) > 1:
        which = " and ".join(f"{names[a[0]]}..{names[a[-1]]}" for a, _ in arms)
        raise fail(
            path,
            f"{len(arms)} arms ({which}): warp-critic trains one end effector; --joints NAME,.. "
            "trains the joints of one arm and locks the others at home",
        )
    trained, body, kind = set(jointed), None, ""
    if arms:
        trained, body, kind = set(arms[0][0]), arms[0][1], "an arm with a hand"
    elif jaw := _jaw(builder, names, jointed):
        trained, body, kind = trained - set(jaw), builder.joint_parent[jaw[0]], "an arm with a jaw"
    _check_actuated(path, names, sorted(trained), actuation)
    if body is None:
        return trained, None, None
    locked = [names[j] for j in jointed if j not in trained]
    arm = sorted(trained)
    note = (
        f"{path}: {kind}: training the {len(arm)} joints of the arm chain "
        f"{names[arm[0]]}..{names[arm[-1]]} (end effector {short(builder.body_label[body])}); "
        f"the {len(locked)} joints beyond it ({', '.join(locked[:4])}{', ..' * (len(locked) > 4)}) "
        "are locked at home (--joints NAME,.. picks others)"
    )
    return trained, body, note


def _jaw(builder, names: list[str], jointed: list[int]) -> list[int]:
    """A single chain's last joints named as a gripper's (:data:`mjcf_file.GRIPPER_NAME`), first
    to last; none where the joints do not form one chain or no other joint would be left."""
    joint_of = {c: j for j, c in enumerate(builder.joint_child)}
    movable = set(jointed)
    chains = []
    for j in jointed:  # each joint's movable joints from the world down to it
        out: list[int] = []
        body = builder.joint_child[j]
        while body >= 0 and body in joint_of and len(out) <= len(joint_of):
            k = joint_of[body]
            out += [k] if k in movable else []
            body = builder.joint_parent[k]
        chains.append(out[::-1])
    longest = max(chains, key=len)
    if len(longest) != len(jointed):
        return []  # not one chain
    tail: list[int] = []
    for j in reversed(longest):
        if not GRIPPER_NAME.search(names[j]):
            break
        tail.insert(0, j)
    return tail if len(tail) < len(longest) else []


def _check_actuated(path: Path, names: list[str], trained: list[int], actuation) -> None:
    """Refuse a trained joint that the file's actuators do not drive (a file that names no
    actuator drives every joint)."""
    if actuation.actuated is None or not (actuation.actuated or actuation.tendons):
        return  # the file says nothing drives any joint: every one is driven
    idle = [j for j in trained if names[j] not in actuation.actuated]
    if not idle:
        return
    name = names[idle[0]]
    what = {"actuators": "<actuator>", "effort": "<transmission> or non-zero effort"}
    tendon = actuation.tendons.get(name)
    coupled = _coupled_to(actuation.root, name)
    if tendon:
        why = f"an <actuator> drives it only through tendon {tendon!r}, not modelled"
    elif coupled:
        why = f"it follows joint {coupled!r} through an <equality> coupling"
    elif actuation.spatial:
        pulled = ", ".join(actuation.spatial[:2]) + (", .." if len(actuation.spatial) > 2 else "")
        why = (
            "no <actuator> drives it directly; the file's actuators pull spatial tendons "
            f"({pulled}), not modelled"
        )
    else:
        why = f"no {what.get(actuation.source, 'actuator')} drives it"
    raise fail(
        path,
        f"underactuated: joint {name!r} has no actuator ({why}); --joints NAME,.. trains the "
        "joints named and locks the others at home",
    )


def _coupled_to(root, joint: str) -> str | None:
    """The joint an MJCF ``<equality><joint>`` couples ``joint`` to, if any."""
    if root is None:
        return None
    for eq in root.iter("equality"):
        for e in eq.findall("joint"):
            pair = (e.get("joint1"), e.get("joint2"))
            if joint in pair and None not in pair:
                return str(pair[1] if pair[0] == joint else pair[0])
    return None
