"""The command line's exit codes, and what every command shares: its scene (read, then
built), its output folder, its JSON and its closing line on shortfalls.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..scenes.build import SceneObjects
    from ..scenes.spec import Scene
    from ..shortfall import Shortfall

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_SHORTFALL, EXIT_INTERRUPTED, EXIT_PIPE = 0, 1, 2, 3, 130, 141

#: Every exit code of the command line and what it means (shown by ``--help``).
EXIT_CODES = {
    EXIT_OK: "the request was met",
    EXIT_FAILED: "stability: a case of the suite failed",
    EXIT_USAGE: "user error (bad arguments or scene, unreadable scene file, unwritable output; "
                "with --strict, a request known to fall short): one line on stderr, nothing written",
    EXIT_SHORTFALL: "finished but missed the request (simulation stopped early, target projected or "
                    "unreachable, speeds clipped to the limits, schedule unreachable, unverified or "
                    "unchecked, a wall-clock guard fired): outputs written, one 'shortfall:' line on stderr",
    EXIT_INTERRUPTED: "interrupted",
    EXIT_PIPE: "the reader of the standard output stopped reading (a pipe into head): ended quietly",
}


def _print_json(data: Any) -> None:
    from ..scenes.report import to_json
    sys.stdout.write(to_json(data))


def _parsed(args: argparse.Namespace, section: str | None = None, purpose: str = "") -> Scene:
    """Load the SCENE argument (form only); refuse a sweep scene where the command needs
    contacts of its own, and, with ``section``, a scene that does not declare it."""
    from ..errors import SceneError
    from ..scenes.build import planar_scene_error, sweep_scene_error
    from ..scenes.spec import load_scene
    scene = load_scene(args.scene)
    if scene.sweep is not None and args.command not in ("run", "sweep"):
        raise sweep_scene_error(scene, args.command)
    if scene.planar is not None and args.command not in ("run", "precision"):
        raise planar_scene_error(scene, args.command)
    if section is not None and getattr(scene, section) is None:
        raise SceneError(f"The scene {scene.name!r} has no [{section}] section {purpose}.")
    return scene


def _scene(args: argparse.Namespace, section: str | None = None, purpose: str = "") -> SceneObjects:
    """:func:`_parsed`, then built: every value checked (exit 2 on a bad one)."""
    from ..scenes.build import build_scene
    return build_scene(_parsed(args, section, purpose))


def _out_dir(args: argparse.Namespace, scene: Scene) -> Path:
    """``--out``, or ``out/<scene name>``."""
    return Path(args.out) if args.out is not None else Path("out") / scene.name


def _known_shortfalls(objects: SceneObjects, args: argparse.Namespace,
                      stages: tuple[str, ...]) -> list[Shortfall]:
    """The shortfalls of ``stages`` known before any work; with ``--strict`` a refusal (exit 2)."""
    from ..errors import SceneError
    from ..scenes.study import request_shortfalls
    known = [s for s in request_shortfalls(objects) if s.stage in stages]
    if args.strict and known:
        raise SceneError(f"--strict: {known[0]}" + (f" (and {len(known) - 1} more)" if len(known) > 1 else ""))
    return known


def _finish(shortfalls: Sequence[Shortfall]) -> int:
    """Exit 0, or 3 with one line on stderr naming every shortfall."""
    from ..scenes.report import shortfall_line
    if not shortfalls:
        return EXIT_OK
    print(f"active-contacts: {shortfall_line(shortfalls)}", file=sys.stderr)
    return EXIT_SHORTFALL
