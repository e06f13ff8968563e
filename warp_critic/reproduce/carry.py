"""Carry the complete stages of a reproduce output to another machine, without training-only state.

A paper-setting ``reproduce`` takes longer than one sitting on a laptop CPU. Its complete stages
can be saved into a small archive (a folder that can be committed or copied), and restored into an
output folder on another machine, where ``reproduce`` then skips them and runs only what is left.

* :func:`save` copies every complete stage of ``out`` (its ``stage.json`` is present and usable)
  into ``archive/<stage dir>``, without recordings (``*.rrd``) and locks. Meta-training checkpoints
  lose the state that only a resumed training needs (:data:`TRAINING_ONLY`: optimisers, ours' last
  policies, the baselines' target networks and replay buffers); what meta-test, the maps, the
  tables and the report read stays (networks, config, scene identity, metrics); a shipped scene's
  absolute path is written ``scenes/NAME`` (the scene is found by its content hash). A stage already in
  the archive is skipped when its ``stage.json`` is the same, refused when it differs.
* :func:`restore` copies every archived stage that ``out`` lacks into ``out`` (made a reproduce
  output if new; its lock is held while copying). A stage ``out`` already has complete is skipped;
  one that ``out`` holds incomplete (started there) is refused, never overwritten.

* :func:`publish` copies a finished report (``REPORT.md``, ``results.json``, figures, and the
  records of the stages it read) into a folder to commit, such as ``docs/paper``.

Each stage is copied into a temporary sibling directory and renamed into place, so an interrupted
call leaves no half-copied stage behind.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from warp_critic.core.errors import UserError
from warp_critic.reproduce.stages import MARKER, claim_out, read_complete, read_stage
from warp_critic.running.locks import LOCK

#: checkpoint entries only a resumed training reads
TRAINING_ONLY = ("optimizer_state", "policy_params", "agent_state", "buffer")
#: files never carried
SKIPPED_SUFFIXES = (".rrd",)
SKIPPED_NAMES = (LOCK,)


def complete_stages(folder: Path) -> dict[str, dict]:
    """Stage directory name -> ``stage.json`` of every complete stage directly under ``folder``."""
    found = {}
    for d in sorted(Path(folder).iterdir()) if Path(folder).is_dir() else []:
        data = read_stage(d) if d.is_dir() else None
        if data is not None and isinstance(data.get("group"), str):
            read_complete(d, data["group"])  # an edited or damaged stage.json: one line
            found[d.name] = data
    return found


#: the entries of a run's checkpoint and config that name its scene file
SCENE_KEYS = ("scene", "scene_path", "scene_file")


def _portable(record: dict) -> dict:
    """``record`` with a shipped scene's absolute path as ``scenes/NAME``: an archive names no
    machine's folders, and a run's scene is found by its content hash wherever it is
    (:func:`~warp_critic.running.scenefile.find_run_scene`)."""
    from warp_critic.physics.scene import scenes_dir

    shipped = scenes_dir().resolve()
    out = dict(record)
    for key in SCENE_KEYS:
        value = out.get(key)
        if isinstance(value, str) and Path(value).is_absolute():
            path = Path(value).resolve()
            if path.parent == shipped:
                out[key] = f"scenes/{path.name}"
    return out


def _slim_checkpoint(src: Path, dst: Path) -> None:
    from warp_critic.running.rundir import atomic_torch_save, load_checkpoint_file

    ckpt = load_checkpoint_file(src)
    slim = _portable({k: v for k, v in ckpt.items() if k not in TRAINING_ONLY})
    if isinstance(slim.get("config"), dict):
        slim["config"] = _portable(slim["config"])
    atomic_torch_save(slim, dst)


def _portable_config(src: Path, dst: Path) -> None:
    from warp_critic.running.rundir import atomic_write_text

    try:
        config = json.loads(src.read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        shutil.copy2(src, dst)  # not a run's config: carried as it is
        return
    text = json.dumps(_portable(config) if isinstance(config, dict) else config, indent=2)
    atomic_write_text(dst, text + "\n")


def _copy_stage(src: Path, dst_parent: Path, slim: bool) -> None:
    """``src`` -> ``dst_parent/src.name`` through a temporary sibling renamed into place."""
    final = dst_parent / src.name
    tmp = dst_parent / f".carrying-{src.name}"
    if tmp.exists():
        shutil.rmtree(tmp)  # what an interrupted call of ours left; never a stage
    try:
        for path in sorted(src.rglob("*")):
            rel = path.relative_to(src)
            if path.is_dir() or path.name in SKIPPED_NAMES or path.suffix in SKIPPED_SUFFIXES:
                continue
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            if slim and path.name == "checkpoint.pt":
                _slim_checkpoint(path, target)
            elif slim and path.name == "config.json":
                _portable_config(path, target)
            else:
                shutil.copy2(path, target)
        tmp.rename(final)
    except OSError as e:
        shutil.rmtree(tmp, ignore_errors=True)
        raise UserError(f"{final}: cannot write ({e.strerror or e})") from None


def _carry(src: Path, dst: Path, *, slim: bool, started: str) -> list[str]:
    """Copy the complete stages of ``src`` that ``dst`` lacks; an identical stage there is skipped,
    a different or unfinished one refused (``started`` says what an unfinished one is)."""
    have = complete_stages(dst)
    copied = []
    for name, data in complete_stages(src).items():
        if name in have:
            if have[name] != data:
                raise UserError(
                    f"{dst / name}: holds another result of this stage than {src / name}; "
                    "not replacing it"
                )
            continue
        if (dst / name).exists():
            raise UserError(f"{dst / name}: {started}")
        _copy_stage(src / name, dst, slim=slim and data["group"] == "metatrain")
        copied.append(name)
    return copied


def save(out: Path, archive: Path) -> list[str]:
    """Copy the complete stages of ``out`` into ``archive``; returns the names copied."""
    out, archive = Path(out), Path(archive)
    if not (out / MARKER).is_file():
        raise UserError(f"{out}: not a reproduce output (no {MARKER})")
    complete_stages(out)  # an edited stage.json is refused before anything is written
    try:
        archive.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{archive}: cannot create ({e.strerror or e})") from None
    return _carry(
        out, archive, slim=True, started="exists but is not a complete stage; not replacing it"
    )


def restore(archive: Path, out: Path) -> list[str]:
    """Copy the archived stages that ``out`` lacks into ``out``; returns the names copied."""
    archive = Path(archive)
    if not archive.is_dir():
        raise UserError(f"{archive}: no such directory")
    if not complete_stages(archive):
        raise UserError(f"{archive}: holds no complete reproduce stage")
    out, lock = claim_out(Path(out))
    try:
        return _carry(
            archive,
            out,
            slim=False,
            started="this stage was started here and is not complete; remove it to take the "
            "archived one",
        )
    finally:
        lock.release()


#: what :func:`publish` copies of a stage the report read: its record, raw cells and figures
PUBLISHED_SUFFIXES = (".json", ".png")


def _published_record(d: Path) -> bool:
    """Whether ``d`` is what :func:`publish` writes for a stage: a ``stage.json`` and nothing but
    :data:`PUBLISHED_SUFFIXES` files (never a carried stage, which holds its runs)."""
    if not (d / "stage.json").is_file():
        return False
    return all(p.is_dir() or p.suffix in PUBLISHED_SUFFIXES for p in d.rglob("*"))


def publish(out: Path, dest: Path) -> tuple[list[str], list[str]]:
    """Copy the report of ``out`` into ``dest``, for committing: ``REPORT.md``, ``results.json``,
    ``ledger.jsonl`` (where there is one), ``figures/*.png`` and, of each stage the report read (``results.json``'s ``stages``), its
    ``*.json`` and ``*.png`` files outside its runs (``stage.json``, the raw ``errors.json`` cells,
    the landscapes), so every number in the report traces to a file in ``dest``.

    ``dest``'s figures and stage records from an earlier report that this one did not read are
    removed (they no longer match the report beside them); anything else in ``dest`` (a README,
    carried stages, search rows) is left alone. Returns (stage dirs written, stage dirs removed)."""
    from warp_critic.running.rundir import atomic_write_bytes

    out, dest = Path(out), Path(dest)
    if not (out / MARKER).is_file():
        raise UserError(f"{out}: not a reproduce output (no {MARKER})")
    try:
        results = json.loads((out / "results.json").read_text())
        stages = sorted(v["dir"] for v in results["stages"].values())
        report = (out / "REPORT.md").read_bytes()
    except FileNotFoundError as e:
        raise UserError(f"{e.filename}: missing; run reproduce to write its report first") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise UserError(f"{out / 'results.json'}: not a reproduce report's results") from None
    for name in stages:
        if Path(name).name != name or not (out / name / "stage.json").is_file():
            raise UserError(f"{out / 'results.json'}: names stage {name!r}, which {out} lacks")
    try:
        dest.mkdir(parents=True, exist_ok=True)
        figures = sorted((out / "figures").glob("*.png"))
        (dest / "figures").mkdir(exist_ok=True)
        keep = {p.name for p in figures}
        for old in (dest / "figures").glob("*.png"):
            if old.name not in keep:
                old.unlink()
        for png in figures:
            atomic_write_bytes(dest / "figures" / png.name, png.read_bytes())
        for name in stages:
            for path in sorted((out / name).rglob("*")):
                rel = path.relative_to(out / name)
                if rel.parts[0] == "run" or path.is_dir() or path.suffix not in PUBLISHED_SUFFIXES:
                    continue
                (dest / name / rel).parent.mkdir(parents=True, exist_ok=True)
                atomic_write_bytes(dest / name / rel, path.read_bytes())
        pruned = [
            d.name
            for d in sorted(dest.iterdir())
            if d.is_dir() and d.name not in stages and _published_record(d)
        ]
        for name in pruned:
            shutil.rmtree(dest / name)
        if (out / "ledger.jsonl").is_file():  # the calls that made the report, and their times
            atomic_write_bytes(dest / "ledger.jsonl", (out / "ledger.jsonl").read_bytes())
        atomic_write_bytes(dest / "results.json", (out / "results.json").read_bytes())
        atomic_write_bytes(dest / "REPORT.md", report)  # last: a report only beside its files
    except OSError as e:
        raise UserError(f"{dest}: cannot write ({e.strerror or e})") from None
    return stages, pruned


def summary(archive: Path) -> str:
    """One line per archived stage: name, group, seconds (for the tool's listing)."""
    rows = [
        f"{name}: {data['group']}, {float(data.get('seconds', 0.0)):.0f} s"
        for name, data in complete_stages(Path(archive)).items()
    ]
    return "\n".join(rows) if rows else f"{archive}: no complete stage"


__all__ = ["TRAINING_ONLY", "complete_stages", "save", "restore", "publish", "summary"]
