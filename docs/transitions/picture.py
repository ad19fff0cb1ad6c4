"""Draw docs/transitions/templates.png: the eager-rule templates of one Freudenthal chain.

    python docs/transitions/picture.py   (needs matplotlib)

Each panel is the chain tet (0, 1, 3, 7) of a coarse leaf in space, split by the template of
one split mask; the tets are shrunk towards their centroids so that each one shows.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from paroct.frame import LATTICE_TO_SPACE  # noqa: E402
from paroct.transitions import CHAINS, TEMPLATES  # noqa: E402

NAMES = ["v0", "v1", "v2", "v3", "m01", "m12", "m23", "m02", "m13"]
PANELS = [0, 8, 9, 24, 25, 27, 29, 31]


def label_points(chain) -> np.ndarray:
    corners = np.array([[(c >> i) & 1 for i in range(3)] for c in chain], dtype=float) * 2
    mids = [(corners[i] + corners[j]) / 2 for i, j in ((0, 1), (1, 2), (2, 3), (0, 2), (1, 3))]
    return np.vstack([corners, mids]) @ LATTICE_TO_SPACE.T


def main() -> None:
    pts = label_points(CHAINS[0])
    fig = plt.figure(figsize=(12, 6.4))
    colours = plt.cm.tab10(np.arange(10))
    for k, mask in enumerate(PANELS):
        ax = fig.add_subplot(2, 4, k + 1, projection="3d")
        tets = TEMPLATES[mask]
        for t, tet in enumerate(tets):
            p = pts[list(tet)]
            c = p.mean(axis=0)
            p = c + 0.82 * (p - c)
            faces = [[p[a], p[b], p[d]] for a, b, d in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3))]
            ax.add_collection3d(Poly3DCollection(faces, facecolor=colours[t % 10], edgecolor="k", linewidth=0.4, alpha=0.55))
        used = sorted({v for tet in tets for v in tet})
        for v in used:
            ax.text(*pts[v], NAMES[v], fontsize=7)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.view_init(elev=22, azim=-58)
        ax.set_axis_off()
        names = "+".join(n for b, n in enumerate(["e01", "e12", "e23", "e02", "e13"]) if mask >> b & 1) or "no split"
        ax.set_title(f"mask {mask}: {names}\n{len(tets)} tets", fontsize=9)
    fig.suptitle("Eager-rule closure templates of the chain (0, 1, 3, 7); m02, m13 are face centres", fontsize=11)
    fig.tight_layout()
    out = Path(__file__).with_name("templates.png")
    fig.savefig(out, dpi=80)
    print(out)


if __name__ == "__main__":
    main()
