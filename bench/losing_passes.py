"""What the passes that lose part of the solid cost, and whether the surface foretells them.

    python bench/losing_passes.py [--folder DIR] [--divisions 25 40 60 80] [--repeat 3]

Per model and size h = diagonal / divisions: whether the pass at size h loses part of the
solid, as mesh() judges a pass (mesher._losses on mesh(thin_features=False)), the time of
that pass alone and of the default call (mesh(), which meshes again after a losing pass),
the default call's tets, and two measures of the surface that need no pass: the mean
thickness 2 V / A and the thinnest wall the lattice rows at h measure (walls whose sides
face each other squarely, as the passes after a losing one refine near), both in units of h.
A pass at size that mesh() would refuse (no tets, or under half the solid) counts as losing.
The last lines say whether either measure separates the passes that lose from those that
keep: a threshold would tell beforehand which pass to skip only if every losing pass lay on
one side of it and every keeping one on the other.  Session 56 found neither does on the
corpus (docs/design.md).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from timing import CORPUS, fastest, surface_files


def surface_measures(surface, h: float) -> tuple[float, float]:
    """(mean thickness 2 V / A, thinnest squarely facing wall the rows at h measure), in units
    of h (inf where the rows find no such wall)."""
    from paroct import mesher
    from paroct.frame import fat_frame

    frame = fat_frame(surface.bbox_min, surface.bbox_max, h)
    walls = mesher.surface_thin_features(surface, frame).facing_below(mesher.THIN_FACING)
    thickness = walls.thickness[walls.is_wall]
    return 2 * surface.volume / surface.area / h, float(thickness.min() / h) if thickness.size else np.inf


def _separates(lost: list[float], kept: list[float], name: str) -> str:
    if not lost or not kept:
        return f"{name}: nothing to separate ({len(lost)} losing, {len(kept)} keeping passes)"
    if max(lost) < min(kept):
        return f"{name}: separates them, losing passes below {max(lost):.2f}, keeping ones from {min(kept):.2f}"
    return (f"{name}: does not separate them (losing passes up to {max(lost):.2f}, keeping ones down to "
            f"{min(kept):.2f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--folder", default=str(CORPUS))
    parser.add_argument("--divisions", type=float, nargs="+", default=[25.0, 40.0, 60.0, 80.0])
    parser.add_argument("--repeat", type=int, default=3, help="calls per timing, the fastest counts")
    args = parser.parse_args()

    import paroct
    from compare import warm_up_paroct
    from paroct import mesher
    from paroct.surface import load_surface

    warm_up_paroct()
    print(f"{'model':12s} {'div':>4s} {'lost':>4s} {'pass ms':>8s} {'mesh() ms':>9s} {'tets':>9s} "
          f"{'2V/A / h':>8s} {'wall / h':>8s}  what the pass at size lost")
    measures = {"mean thickness": ([], []), "thinnest wall": ([], [])}
    for path in surface_files(args.folder):
        surface = load_surface(path)
        for div in args.divisions:
            h = surface.diagonal / div
            mean, wall = surface_measures(surface, h)
            try:
                lost = mesher._losses(paroct.mesh(surface, size=h, thin_features=False).report, surface)
            except paroct.ParoctError as error:  # a pass that keeps no tets, or under half the solid, is refused
                lost = str(error) if str(error).startswith(("no tets", "the mesh at boundary size")) else ""
                if not lost:
                    print(f"{path.stem:12s} {div:4g} refused: {str(error)[:100]}")
                    continue
                t_mesh = fastest(lambda: paroct.mesh(surface, size=h), args.repeat)
                tets = paroct.mesh(surface, size=h).report.n_tets
                measures["mean thickness"][0].append(mean)
                measures["thinnest wall"][0].append(wall)
                print(f"{path.stem:12s} {div:4g} {'yes':>4s} {'-':>8s} {t_mesh * 1e3:9.1f} {tets:9d} {mean:8.2f} "
                      f"{wall:8.2f}  refused at size: {lost[:54]}")
                continue
            t_pass = fastest(lambda: paroct.mesh(surface, size=h, thin_features=False), args.repeat)
            t_mesh = fastest(lambda: paroct.mesh(surface, size=h), args.repeat)
            tets = paroct.mesh(surface, size=h).report.n_tets
            for name, value in (("mean thickness", mean), ("thinnest wall", wall)):
                measures[name][0 if lost else 1].append(value)
            print(f"{path.stem:12s} {div:4g} {'yes' if lost else 'no':>4s} {t_pass * 1e3:8.1f} {t_mesh * 1e3:9.1f} "
                  f"{tets:9d} {mean:8.2f} {wall:8.2f}  {lost[:70]}")
    for name, (lost, kept) in measures.items():
        print(_separates(lost, kept, name))


if __name__ == "__main__":
    main()
