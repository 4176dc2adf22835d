"""Error targets for meshes: the fastest way of rendering a TetMesh within a requested RMSE.

``Renderer.render(scene, "tetra", tolerance=E)`` with a mesh scene renders the mesh the
fastest way whose image is within RMSE ``E`` of the exact image
(``dvr_gl.reference.exact``). The ways (``WAYS``, one line each) render the same field:

- projected tetrahedra, ``tetra``, with each of its visibility sorts (``mpvo`` is exact;
  ``centroid`` can misorder cells where they are far from round; a sort the installed
  ``tetra.SORTS`` lacks is left out), and the cell walk with table-integrated segments
  (``segments="table"``, ``dvr_gl.model.segment_table``: no attenuation inside a segment;
  a scene it does not take, such as a shaded one, is left out as any way that cannot
  render the scene);
- the mesh resampled once onto a regular grid (``dvr_gl.model.mesh_grid``: the linear
  field of the containing cell at each sample, NaN outside the domain) of ``grid``
  samples along its longest side (at most ``MAX_GRID_SAMPLES`` in all), its boundary
  grown by one sample (``grow_boundary``), ray cast at a ``step`` of so many grid
  spacings. Between samples the grid's field is trilinear, not linear, and near the
  boundary its domain is within about a cell of the mesh's: a different field, whose
  error is measured like any other.

No way's error is assumed. A pilot renders each way on the same view at no more than
``PILOT_SIDE`` pixels a side and measures its RMSE against the exact image of the pilot;
the ways within ``SAFETY * E`` are then timed on the view at up to ``TIMING_SIDE``
pixels (median of ``TIMING_REPEATS`` frames after one untimed one) and the fastest is
taken. Grid ways are measured in order of their expected cost (grid samples per step);
once one is within the margin, the grid ways expected to be dearer are neither
resampled nor rendered (a finer grid or step costs more and is not needed), and only the
cheapest grid way within the margin, with every tetra way within it, is timed.
``SAFETY`` (0.7) covers what the pilot's pixels and its view do not see of the frames
the choice is used for.

The choice is kept per *view family*: the scene with the camera's direction taken out
(its target, projection and distance, to a quarter octave, stay in), the image size and
the tolerance. Turning the mesh keeps the choice, so a second frame costs a plain frame
of the chosen way; a resampled grid is kept in the renderer's table cache per mesh and
shape. What the pilot measured (a ``PilotRecord``) is kept per family and size too, so
another tolerance renders only the ways not measured yet. What was chosen and measured
is ``Renderer.last_choice`` (a ``MeshChoice``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .tolerance import check_tolerance, median_seconds, rmse, scaled_scene

PILOT_SIDE = 64
SAFETY = 0.7
TIMING_SIDE = 256
TIMING_REPEATS = 3


@dataclass(frozen=True)
class Way:
    """One way of rendering a mesh: a technique and its options; for a grid way, the
    grid's samples along the mesh's longest side and the ray caster's step in grid
    spacings (``grid`` None: the technique renders the mesh itself)."""
    label: str
    technique: str
    options: tuple = ()
    grid: int = None
    step: float = None

    @property
    def cost(self):
        """Expected cost of a grid way: samples along a ray through the grid."""
        return self.grid / self.step if self.grid is not None else 0.0


# the candidates, one line each (a tetra sort the installed technique lacks is skipped)
WAYS = (
    Way("tetra mpvo", "tetra", (("sort", "mpvo"),)),
    Way("tetra centroid", "tetra", (("sort", "centroid"),)),
    Way("tetra walk", "tetra", (("sort", "walk"),)),
    Way("tetra walk, table segments", "tetra", (("sort", "walk"), ("segments", "table"))),
    Way("grid 64, step 1", "raycast", grid=64, step=1.0),
    Way("grid 64, step 1/2", "raycast", grid=64, step=0.5),
    Way("grid 128, step 1", "raycast", grid=128, step=1.0),
    Way("grid 128, step 1/2", "raycast", grid=128, step=0.5),
    Way("grid 192, step 1", "raycast", grid=192, step=1.0),
    Way("grid 256, step 2", "raycast", grid=256, step=2.0),    # the grid, not the step, sets most of the error
    Way("grid 256, step 1", "raycast", grid=256, step=1.0),
    Way("grid 256, step 1/2", "raycast", grid=256, step=0.5),
    Way("grid 384, step 2", "raycast", grid=384, step=2.0),
    Way("grid 384, step 1", "raycast", grid=384, step=1.0),
    Way("grid 512, step 2", "raycast", grid=512, step=2.0),
    Way("grid 512, step 1", "raycast", grid=512, step=1.0),
)
MAX_GRID_SAMPLES = 1 << 25     # a larger grid (128 MiB of float32) is not made


def available_ways(ways=WAYS):
    """The ways this installation can render: the tetra sorts it has, and the grid ways."""
    from ..techniques import tetra
    return [w for w in ways if w.technique != "tetra" or dict(w.options).get("sort", "mpvo") in tetra.SORTS]


def fits(way, mesh):
    """Whether the way's grid (if any) is within MAX_GRID_SAMPLES for ``mesh``."""
    from ..model.mesh_grid import grid_shape
    return way.grid is None or math.prod(grid_shape(mesh, way.grid)) <= MAX_GRID_SAMPLES


@dataclass(frozen=True)
class MeshChoice:
    """What ``tolerance=`` picked for a mesh: the way (its label, technique, options,
    grid and step), the error measured on the pilot, the frame time it was picked on,
    what this request's pilot cost (seconds: nothing when the family's record had all it
    needed), and ``measured``: (label, pilot RMSE, frame seconds or None) of every way
    the pilot rendered."""
    tolerance: float
    label: str
    technique: str
    options: tuple
    grid: int
    step_spacings: float
    pilot_rmse: float
    frame_seconds: float
    pilot_size: tuple
    pilot_seconds: float
    measured: tuple

    @property
    def predicted_rmse(self):
        """The error expected of a frame: the pilot's."""
        return self.pilot_rmse


def view_family(scene):
    """The digest of the scene with its camera turned to one fixed direction about the
    same target, at the same distance to a quarter octave: a key for choices that hold
    while the view turns."""
    from ..model.camera import Camera
    cam = scene.camera
    distance = float(np.linalg.norm(cam.eye - cam.target)) or 1.0
    distance = 2.0 ** (round(4 * math.log2(distance)) / 4)
    fixed = Camera(cam.target + np.array([0.0, 0.0, distance]), cam.target, (0.0, 1.0, 0.0),
                   fov=cam.fov or 30.0, ortho_height=cam.ortho_height)
    return scene.replace(camera=fixed).digest()


def grid_volume(tables, mesh, samples):
    """The mesh resampled onto the grid of ``samples`` along its longest side, its
    boundary grown by one sample (``grow_boundary``), made once per mesh and shape while
    they stay in ``tables``."""
    from ..model import mesh_grid
    shape = mesh_grid.grid_shape(mesh, samples)
    return tables.get("mesh_grid_grown:" + "x".join(map(str, shape)), mesh,
                      make=lambda m: grow_boundary(mesh_grid.resample_to_grid(m, shape)))


def grow_boundary(volume):
    """``volume`` (a resampled mesh, NaN outside the domain) with each NaN sample next to
    the domain (along an axis) given the field extrapolated linearly from the two samples
    inside on that axis (or the one, where the next is outside too), averaged over the
    axes that have one. The ray caster drops a grid cell with a corner outside the domain,
    so the plain grid's domain is up to a cell smaller than the mesh's, which is where
    most of its error is (at silhouettes and a hollow mesh's inner walls); grown by one
    sample it is within about a cell either way, and measured no worse (RMSE 2x lower
    on the combustor and the LOX post, docs/notes/mesh_tolerance.md)."""
    from ..model.volume import Volume
    values = volume.data
    total = np.zeros(values.shape, np.float32)
    count = np.zeros(values.shape, np.uint8)
    outside = ~np.isfinite(values)

    def along(axis, start, stop):
        sl = [slice(None)] * 3
        sl[axis] = slice(start, stop)
        return tuple(sl)
    for axis in range(3):
        n = values.shape[axis]
        # (target, its neighbour, the one after) going up the axis, then down
        for target, near, far_to, far_from in ((along(axis, 1, n), along(axis, 0, n - 1), along(axis, 1, None),
                                                along(axis, 0, n - 2)),
                                               (along(axis, 0, n - 1), along(axis, 1, n), along(axis, 0, n - 2),
                                                along(axis, 2, n))):
            first = values[near]
            second = np.full(first.shape, np.nan, np.float32)
            second[far_to] = values[far_from]
            guess = np.where(np.isfinite(second), 2.0 * first - second, first)
            take = outside[target] & np.isfinite(guess)
            t, c = total[target], count[target]      # views: written in place
            t[take] += guess[take]
            c[take] += 1
    grown = values.copy()
    fill = count > 0
    grown[fill] = total[fill] / count[fill]
    return Volume(grown, spacing=volume.spacing, origin=volume.origin, mask_nonfinite=True)


def way_arguments(scene, way, tables):
    """(scene, technique, step, options) that render ``scene`` (a mesh) the ``way``."""
    if way.grid is None:
        return scene, way.technique, None, dict(way.options)
    grid = grid_volume(tables, scene.volume, way.grid)
    return scene.replace(volume=grid), way.technique, way.step * grid.min_spacing, dict(way.options)


@dataclass
class PilotRecord:
    """What the pilot measured for one view family and size: the pilot view (the family's
    first view asked, at no more than PILOT_SIDE pixels), its exact image, each way's
    error on it and each way's frame time; kept, so that another tolerance renders only
    the ways not measured yet, on the same pilot view, whatever view asks."""
    pilot: object = None
    reference: object = None
    errors: dict = field(default_factory=dict)      # Way -> pilot RMSE against exact
    seconds: dict = field(default_factory=dict)     # Way -> median frame seconds at up to TIMING_SIDE


def choose(render, scene, tolerance, tables, record=None, exact=None, ways=None):
    """The MeshChoice for RMSE ``tolerance``: ``render(scene, technique, step, options)``
    renders an image (read back); ``exact(scene)`` gives the exact image (default
    ``dvr_gl.reference.exact``, cached on disk); ``record`` (a PilotRecord of the same view
    family and size) holds what was measured before and gains what is measured now."""
    tolerance = check_tolerance(tolerance)
    if not scene.is_mesh:
        raise ValueError("the mesh pilot renders TetMesh scenes; a Volume's tolerance chooses the ray caster's step")
    if exact is None:
        from ..reference.exact import exact
    record = PilotRecord() if record is None else record
    ways = [w for w in (available_ways() if ways is None else ways) if fits(w, scene.volume)]
    t0 = time.perf_counter()
    if record.pilot is None:
        record.pilot = scaled_scene(scene, PILOT_SIDE)
        record.reference = exact(record.pilot)
    pilot = record.pilot
    target = SAFETY * tolerance
    grid_met = None
    for way in sorted(ways, key=lambda w: w.cost):
        if way.grid is not None and grid_met is not None and way.cost > grid_met.cost:
            continue                               # a cheaper grid way meets the target already
        if way not in record.errors:
            try:
                record.errors[way] = rmse(render(*way_arguments(pilot, way, tables)), record.reference)
            except ValueError:                     # a way that cannot render this scene
                record.errors[way] = math.inf
        if way.grid is not None and record.errors[way] <= target and grid_met is None:
            grid_met = way
    errors = {w: record.errors[w] for w in ways if w in record.errors and math.isfinite(record.errors[w])}
    within = [w for w, e in errors.items() if e <= target and (w.grid is None or w is grid_met)]
    timed = scaled_scene(scene, TIMING_SIDE)
    if len(within) > 1:
        for way in within:
            if way not in record.seconds:
                args = way_arguments(timed, way, tables)
                record.seconds[way] = median_seconds(lambda: render(*args), TIMING_REPEATS)
        best = min(within, key=lambda w: record.seconds[w])
    elif within:
        best = within[0]
    else:                                         # nothing within the margin: the most accurate
        best = min(errors, key=lambda w: errors[w])
    measured = tuple((w.label, errors[w], record.seconds.get(w)) for w in ways if w in errors)
    return MeshChoice(tolerance=tolerance, label=best.label, technique=best.technique, options=best.options,
                      grid=best.grid, step_spacings=best.step, pilot_rmse=errors[best],
                      frame_seconds=record.seconds.get(best), pilot_size=(pilot.width, pilot.height),
                      pilot_seconds=time.perf_counter() - t0, measured=measured)


def check_request(technique, options):
    """A mesh's tolerance picks the technique and its options: ``technique`` must be
    tetra (the mesh technique asked for) and no option may fix what it picks."""
    if technique != "tetra":
        raise ValueError(f"a mesh with tolerance is rendered by the way the pilot picks; ask for technique "
                         f"'tetra', got {technique!r}")
    if options:
        name = sorted(options)[0]
        raise ValueError(f"tolerance picks the way of rendering the mesh and its options; leave out "
                         f"{name}={options[name]!r}")
