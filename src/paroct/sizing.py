"""Element size control: where the octree must be fine, as seed octants for balancing.

The finest long edge is ``size`` (the frame's h, used all along the boundary); the interior
coarsens up to ``max_size`` (a power-of-two multiple of ``size``).  Between the two, boxes,
spheres and a vectorised size function h(x) ask for smaller elements where they need them.
Sizes are long edges in model units; an octant of level l has long edge h * 2**(levels - l).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .errors import ParoctError
from .frame import CUBE_CORNERS, FatFrame
from .octant import MAX_LEVEL, morton_decode
from .octree import refine_to_level, uniform_leaves

#: Default max_size as a multiple of size.
DEFAULT_MAX_SIZE_FACTOR = 8


@dataclass(frozen=True)
class Box:
    """Elements of long edge at most ``size`` in the axis-aligned box [lo, hi] (model units)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    size: float

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Euclidean distance (N,) of points (N, 3) to the box, 0 inside."""
        gap = np.maximum(np.asarray(self.lo) - points, 0) + np.maximum(points - np.asarray(self.hi), 0)
        return _length(gap)


@dataclass(frozen=True)
class Sphere:
    """Elements of long edge at most ``size`` in the ball of ``radius`` around ``center``."""

    center: tuple[float, float, float]
    radius: float
    size: float

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Euclidean distance (N,) of points (N, 3) to the ball, 0 inside."""
        return np.maximum(_length(points - np.asarray(self.center)) - self.radius, 0.0)


def _length(vectors: np.ndarray) -> np.ndarray:
    """Euclidean length (N,) of vectors (N, 3), without overflow for components up to 1e308
    (a centre 1e300 away is that far, not inf)."""
    return np.hypot(np.hypot(vectors[:, 0], vectors[:, 1]), vectors[:, 2])


Region = Box | Sphere
SizeFunction = Callable[[np.ndarray], np.ndarray]


def is_number(value) -> bool:
    """Whether value is a real number: an int, float or numpy scalar, not a bool."""
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, (int, float, np.integer, np.floating))


def positive_number(name: str, value, *, infinite: bool = False) -> float:
    """value as a float: a real number (is_number), positive and finite (or +inf where
    ``infinite``); else ParoctError naming the option."""
    if not is_number(value):
        raise ParoctError(f"{name} = {_shown(value)}: must be a positive number")
    try:
        number = float(value)
    except OverflowError:  # an int past float's range: its sign decides
        number = float("inf") if value > 0 else float("-inf")
    if not (number > 0 and (np.isfinite(number) or (infinite and number == np.inf))):
        raise ParoctError(f"{name} = {_shown(value)}: must be a positive number")
    return number


def _shown(value) -> str:
    """repr(value), an int of hundreds of digits cut short (10**400: '10000000...', 401 digits)."""
    text = repr(value)
    return f"{text[:9]}... ({len(text.lstrip('-'))} digits)" if len(text) > 40 and is_number(value) else text


def _point(name: str, value) -> np.ndarray:
    """value as a (3,) float64 point of finite coordinates, else ParoctError naming it."""
    try:
        point = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        point = None
    if point is None or point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ParoctError(f"{name} = {value!r}: must be three finite numbers (x, y, z)")
    return point


@dataclass(frozen=True)
class SizeField:
    """What the user asked for: finest size, largest interior size, local refinements, and
    the boundary's own refinement (lfs.py): curvature, elements per full turn of the surface
    (None: not asked), layers, elements across walls (None: not asked), patch_sizes, ((name,
    size), ...) the long edge asked on named boundary patches."""

    size: float
    max_size: float
    regions: tuple = ()
    function: SizeFunction | None = None
    curvature: float | None = None
    layers: float | None = None
    patch_sizes: tuple = ()

    @property
    def asks_boundary(self) -> bool:
        """Whether anything may ask for a boundary finer than size: curvature, layers, patch
        sizes, a region below size or a size function (lfs.py)."""
        return (self.curvature is not None or self.layers is not None or bool(self.patch_sizes)
                or self.function is not None or any(region.size < self.size for region in self.regions))

    @property
    def coarse_depth(self) -> int:
        """Levels between the finest octants and the largest interior ones: log2(max_size / size)."""
        return int(round(np.log2(self.max_size / self.size)))


def size_field(size: float, max_size: float | None = None, regions: Sequence[Region] = (),
               function: SizeFunction | None = None, curvature: float | None = None,
               layers: float | None = None, patch_sizes=None) -> SizeField:
    """Checked size field.  max_size defaults to DEFAULT_MAX_SIZE_FACTOR * size and is rounded
    down to a power-of-two multiple of size."""
    if max_size is None:
        max_size = DEFAULT_MAX_SIZE_FACTOR * size
    elif positive_number("max_size", max_size) < size:
        raise ParoctError(f"max_size = {max_size:.6g} must be at least size = {size:.6g}")
    depth = int(np.floor(np.log2(max_size / size) + 1e-9))
    depth = min(depth, MAX_LEVEL)
    if isinstance(regions, (Box, Sphere)) or not isinstance(regions, (list, tuple)):
        raise ParoctError(f"regions = {regions!r}: must be a list of paroct.Box and paroct.Sphere")
    for r in regions:
        if not isinstance(r, (Box, Sphere)):
            raise ParoctError(f"refinement region {r!r} is not a paroct Box or Sphere")
        positive_number("refinement region size", r.size)
        if isinstance(r, Box):
            if not np.all(_point("refinement box lo", r.lo) <= _point("refinement box hi", r.hi)):
                raise ParoctError(f"refinement box lo = {r.lo} exceeds hi = {r.hi} in a coordinate (lo must be at most hi)")
        else:
            _point("refinement sphere center", r.center)
            if not (is_number(r.radius) and r.radius == 0):  # radius 0: the sphere's centre alone
                positive_number("refinement sphere radius", r.radius)
    if function is not None and not callable(function):
        raise ParoctError("size_function must be callable: (N, 3) points -> (N,) sizes")
    if curvature is not None:
        curvature = positive_number("curvature", curvature)
    if layers is not None:
        layers = positive_number("layers", layers)
    return SizeField(size=float(size), max_size=float(size * 2**depth), regions=tuple(regions), function=function,
                     curvature=curvature, layers=layers, patch_sizes=checked_patch_sizes(patch_sizes))


def checked_patch_sizes(patch_sizes) -> tuple:
    """patch_sizes (a mapping of patch name to size, or (name, size) pairs, or None) as a tuple
    of (str, float) pairs; ParoctError unless each name is a non-empty string and each size a
    positive number."""
    if patch_sizes is None:
        return ()
    try:
        pairs = list(patch_sizes.items()) if hasattr(patch_sizes, "items") else [tuple(p) for p in patch_sizes]
    except TypeError:
        raise ParoctError(f"patch_sizes = {patch_sizes!r}: must map patch names to sizes") from None
    out = []
    for pair in pairs:
        if len(pair) != 2 or not isinstance(pair[0], str) or not pair[0]:
            raise ParoctError(f"patch size {pair!r}: must be a patch name (a non-empty string) and a size")
        out.append((pair[0], positive_number(f"size of patch {pair[0]!r}", pair[1])))
    return tuple(out)


def _octant_boxes(keys: np.ndarray, level: int, frame: FatFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Space bounding boxes (lo, hi (N, 3)) and sample points (N, 9, 3): the 8 corners and
    the centre, of octants of ``level``."""
    shift = MAX_LEVEL - frame.levels
    side = float(1 << (frame.levels - level))
    anchors = (morton_decode(keys) >> shift).astype(np.float64)
    offsets = np.vstack([CUBE_CORNERS, [[0.5, 0.5, 0.5]]]) * side
    samples = frame.to_space((anchors[:, None, :] + offsets[None]).reshape(-1, 3)).reshape(-1, 9, 3)
    corner = samples[:, 0]
    # Each row of the lattice-to-space map is a permutation of (1/2, 1/2, -1/2).
    return corner - frame.h * side / 2, corner + frame.h * side, samples


def _required_size(field: SizeField, keys: np.ndarray, level: int, frame: FatFrame) -> np.ndarray:
    """Smallest size (N,) asked for anywhere in each octant (regions) or at its corners and
    centre (function)."""
    lo, hi, samples = _octant_boxes(keys, level, frame)
    need = np.full(keys.shape[0], np.inf)
    for r in field.regions:
        if isinstance(r, Box):
            meets = np.all((lo <= np.asarray(r.hi)) & (hi >= np.asarray(r.lo)), axis=1)
        else:
            gap = np.maximum(lo - np.asarray(r.center), 0) + np.maximum(np.asarray(r.center) - hi, 0)
            with np.errstate(over="ignore"):  # a centre 1e300 away is inf away: not met
                # A radius past 1e150 holds every part (coordinates reach 1e100); its square
                # would overflow.
                meets = (gap**2).sum(axis=1) <= min(float(r.radius), 1e150) ** 2
        need[meets] = np.minimum(need[meets], r.size)
    if field.function is not None and keys.shape[0]:
        values = evaluated_size_function(field.function, samples.reshape(-1, 3), "points")
        need = np.minimum(need, values.reshape(-1, 9).min(axis=1))
    return need


def evaluated_size_function(function, points: np.ndarray, what: str) -> np.ndarray:
    """The sizes (N,) float64 a size function gives at points (N, 3), or ParoctError in one
    line if it fails or gives other than positive sizes, one a point; what names the points
    in the message ("points", "points of the surface")."""
    try:
        values = np.asarray(function(points), dtype=np.float64)
    except Exception as exc:  # the user's function failed: say so in one line
        raise ParoctError(f"size_function failed on {points.shape[0]} {what}: {exc}") from None
    if values.shape != (points.shape[0],):
        raise ParoctError(f"size_function returned shape {values.shape} for {points.shape[0]} {what}; "
                          f"expected ({points.shape[0]},)")
    if not np.all(values > 0):
        bad = int(np.argmin(np.where(values > 0, np.inf, 0.0)))  # the first non-positive or NaN one
        x, y, z = points[bad]
        raise ParoctError(f"size_function returned a non-positive or NaN size, {values[bad]:.4g} at ({x:.4g}, "
                          f"{y:.4g}, {z:.4g}), one of the {what} (it is sampled around the part too, up to about "
                          "max_size beyond it)")
    return values


#: size_seeds starts this many levels above max_size, so that pruning can skip whole regions.
PRUNE_DEPTH = 3
#: Classes a size_seeds prune gives an octant.
OUTSIDE, UNDECIDED, WHOLLY_INSIDE = 0, 1, 2


def size_seeds(frame: FatFrame, box_min: np.ndarray, box_max: np.ndarray, field: SizeField,
               prune: Callable[[np.ndarray, int], np.ndarray] | None = None, finest: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seed octants (keys (N,) int64, levels (N,) int8, wholly_inside (N,) bool) covering the
    box: the coarsest octants no larger than max_size whose long edge is at most the size asked
    for in them (never below the finest level).  Sizes smaller than ``size`` are clamped to it.

    prune(keys, level) -> (N,) int8 class of each octant: OUTSIDE (dropped with all its
    descendants, which lets the descent start PRUNE_DEPTH levels above max_size and skip empty
    regions whole), WHOLLY_INSIDE (so are its descendants: they are not asked again) or
    UNDECIDED.  wholly_inside flags the seeds found WHOLLY_INSIDE.  finest: the level of
    long edge ``field.size`` (default frame.levels); a frame refined deeper for thin features
    keeps the field's sizes.
    """
    finest = frame.levels if finest is None else finest
    coarse = max(0, finest - field.coarse_depth)
    level = max(0, coarse - PRUNE_DEPTH) if prune is not None else coarse
    keys, _ = uniform_leaves(frame, box_min, box_max, level)
    inside = np.zeros(keys.shape[0], dtype=bool)
    out_keys, out_levels, out_inside = [], [], []
    while keys.shape[0]:
        if prune is not None:
            ask = np.nonzero(~inside)[0]
            found = prune(keys[ask], level)
            keep = np.ones(keys.shape[0], dtype=bool)
            keep[ask] = found != OUTSIDE
            inside[ask] = found == WHOLLY_INSIDE
            keys, inside = keys[keep], inside[keep]
        if level == finest:
            break
        if level < coarse:
            split = np.ones(keys.shape[0], dtype=bool)
        elif not field.regions and field.function is None:
            break
        else:
            split = _required_size(field, keys, level, frame) < frame.h * 2.0 ** (frame.levels - level)
        out_keys.append(keys[~split])
        out_levels.append(np.full(int((~split).sum()), level, dtype=np.int8))
        out_inside.append(inside[~split])
        keys = refine_to_level(keys[split], level, level + 1)
        inside = np.repeat(inside[split], 8)  # refine_to_level lists each octant's 8 children together
        level += 1
    out_keys.append(keys)
    out_levels.append(np.full(keys.shape[0], level, dtype=np.int8))
    out_inside.append(inside)
    return np.concatenate(out_keys), np.concatenate(out_levels), np.concatenate(out_inside)
