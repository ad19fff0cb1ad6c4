"""Time two versions of paroct against each other, alternating, on the same models.

    python bench/ab_time.py OLD_REV [NEW_REV] [--divisions 40 80] [--models bunny ...] [--rounds 4]

OLD_REV and NEW_REV are git revisions of this repository (NEW_REV default: the working
tree).  Each is checked out into a temporary worktree (the working tree is used as it is),
and a child process per round and version imports that version's paroct (PYTHONPATH), loads
its kernels (compare.warm_up_paroct, its numba cache filled by a first child) and times
mesh() warm on every model and size, fastest of ``repeat`` calls.  The rounds alternate old
and new, each round the other first, so that neither always runs right after the other, and
what the machine does meanwhile weighs on both alike: between compare.py
runs an hour apart TetGen's median time per model moved by 19 % and paroct's small parts by
10 % (session 50), more than most changes gain.  Prints per model the fastest of all rounds
for each version and new / old, then the median of new / old per size.  The tets must be
the same or the row says so: a change meant to keep the meshes is checked on the way.
Calibrate on a noisy day with the same code twice (two names of one commit): in session 51
such runs gave new / old 0.86-0.92 over armadillo and bunny, 4 rounds of 2 calls, and one
child's bunny at diag/80 took 36-56 ms; a change smaller than that spread needs more rounds.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from timing import CORPUS, surface_files

ROOT = Path(__file__).resolve().parent.parent


def _child(models: list[str], folder: str, divisions: list[float], repeat: int) -> None:
    """In a child: warm up, then one JSON line of {model/divisions: [seconds, tets]}."""
    import time

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from compare import warm_up_paroct

    import paroct

    warm_up_paroct()
    out = {}
    for name in models:
        for d in divisions:
            best, tets = float("inf"), -1
            for _ in range(repeat):
                t = time.perf_counter()
                result = paroct.mesh(Path(folder) / name, divisions=d)  # from the file, as compare.py's children
                best = min(best, time.perf_counter() - t)
                tets = int(result.mesh.tets.shape[0])
            out[f"{Path(name).stem}/{d:g}"] = [best, tets]
    print(json.dumps(out))


def _source(rev: str | None, tmp: Path) -> Path:
    """The src folder of revision rev (a fresh worktree under tmp), or of the working tree."""
    if rev is None:
        return ROOT / "src"
    tree = tmp / rev.replace("/", "_")
    done = subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(tree), rev],
                          capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"ab_time.py: cannot check out {rev!r}: {_last_line(done.stderr)}")
    return tree / "src"


def _last_line(text: str) -> str:
    lines = text.strip().splitlines()
    return lines[-1] if lines else "(no message)"


def _run(src: Path, folder: str, divisions: list[float], repeat: int, models: list[str]) -> dict:
    """A child's timings (_child) of the paroct in src."""
    env = dict(os.environ, PYTHONPATH=str(src))
    command = [sys.executable, __file__, "--child", "--folder", folder, "--repeat", str(repeat),
               "--divisions", *map(str, divisions), "--models", *models]
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"ab_time.py: the child timing {src} failed: {_last_line(done.stderr)}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", nargs="?", help="git revision timed first in each round")
    parser.add_argument("new", nargs="?", default=None, help="git revision (default: the working tree)")
    parser.add_argument("--folder", default=str(CORPUS))
    parser.add_argument("--models", nargs="+", default=None, help="file names in folder (default: all)")
    parser.add_argument("--divisions", nargs="+", type=float, default=[40.0, 80.0])
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--repeat", type=int, default=3, help="calls per model and size in a child")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    files = {p.stem: p.name for p in surface_files(args.folder)}
    unknown = [m for m in args.models or [] if Path(m).stem not in files]
    if unknown:
        parser.error(f"not in {args.folder}: {', '.join(unknown)}")
    models = [files[Path(m).stem] for m in args.models] if args.models else list(files.values())
    if args.child:
        _child(models, args.folder, args.divisions, args.repeat)
        return 0
    if args.old is None:
        parser.error("give the old revision")
    with tempfile.TemporaryDirectory() as tmp:
        sources: dict[str, Path] = {}
        try:
            sources["old"] = _source(args.old, Path(tmp))
            sources["new"] = _source(args.new, Path(tmp))
            # Fill each version's numba cache outside the timed rounds, on a mesh the rounds make
            # (at diag/10 a thin part, round_rod, is thinner than any size it may refine to).
            for src in sources.values():
                _run(src, args.folder, args.divisions[:1], 1, models[:1])
            best: dict[str, dict] = {"old": {}, "new": {}}
            for round_ in range(args.rounds):
                # Each round swaps which version goes first.
                for version in ("old", "new") if round_ % 2 == 0 else ("new", "old"):
                    src = sources[version]
                    for key, (seconds, tets) in _run(src, args.folder, args.divisions, args.repeat, models).items():
                        previous = best[version].get(key)
                        best[version][key] = [min(seconds, previous[0]) if previous else seconds, tets]
        finally:  # the worktrees made (the working tree's src is not one)
            for src in sources.values():
                if src != ROOT / "src":
                    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(src.parent)],
                                   capture_output=True)
    print(f"{'model':24s} {'old ms':>9s} {'new ms':>9s} {'new/old':>8s}")
    ratios: dict[str, list[float]] = {}
    for key in best["old"]:
        old, new = best["old"][key], best["new"][key]
        same = "" if old[1] == new[1] else f"  tets {old[1]} -> {new[1]}"
        ratio = new[0] / old[0]
        ratios.setdefault(key.split("/")[1], []).append(ratio)
        print(f"{key:24s} {1e3 * old[0]:9.1f} {1e3 * new[0]:9.1f} {ratio:8.3f}{same}")
    for d, values in ratios.items():
        print(f"diag/{d}: median new/old {statistics.median(values):.3f} over {len(values)} models")
    return 0


if __name__ == "__main__":
    sys.exit(main())
