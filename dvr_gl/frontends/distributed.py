"""Sort-last ray casting of a volume's bricks on a Dask cluster (``dask.distributed``).

The volume is cut into bricks as the bricked ray caster cuts it (``techniques.bricks``:
bricks own disjoint cell ranges; each ray sample is taken by the one brick whose owned
box holds its segment's midpoint). The brick layers along one axis are dealt out as
**slabs** of whole layers, one slab per share, and each share is rendered by one worker
process: its own headless :class:`~dvr_gl.rendering.renderer.Renderer` (one per process,
kept between frames), its bricks read where they are stored (a store by its path,
opened by the worker; anything else sent once), drawn in the global visibility order into
a target cleared to transparent black. That gives the slab's premultiplied partial image:
the same samples as on one machine (the same segment grid from the same box entry; a
brick pass does not start rays of its own), composited from zero instead of from the
slabs in front. Only the window of the screen that the slab's box covers is rendered and
sent back.

A slab is convex and every ray moves monotonically along the slab axis, so each ray meets
the slabs in one order: perspective rays in growing distance from the slab that holds
the eye, orthographic rays along the sign of the view direction. The client composites
the partials front to back in that order with the over operator,
``C = C_front + (1 - A_front) C_back`` (float64, rounded to float32 once), which is
associative: the image is the single machine's with the same ``brick_size`` up to the
float32 rounding of the sums in each partial (bounded in docs/notes/distributed.md and
tests/test_distributed.py). One share gives the single machine's image bit for bit.

Early ray termination (``ert_transmittance``, default 1e-3 as in ``dvr_gl.render``)
acts within each partial, which does not know the opacity in front of it: a ray ends in
a slab once that slab's own transmittance falls below the threshold, and is not ended by
the slabs in front. Either way the light that differs lies behind a transmittance below
the threshold, so the distributed and single-machine images differ by at most
``ert_transmittance`` per channel on top of rounding; ``ert_transmittance=0`` removes it.

Only mode ``composite`` is composited this way. ``mip``, ``minip`` and ``average`` would
need each partial's raw extreme (or sums) before classification, which the bricked
passes classify at the end: they are a :class:`DistributedModeError` (render them on one
machine). Tasks are pure (the same share of the same scene gives the same partial, bit
for bit, on any worker), so a worker that dies mid-frame has its task rerun by Dask
elsewhere without changing the image.
"""

from __future__ import annotations

import copy
import math
import os
import pickle
import time
import uuid
from dataclasses import dataclass, field

import numpy as np

DEFAULT_CONNECT_TIMEOUT = 10.0     # seconds to reach a scheduler before giving up
DEFAULT_BRICK = 64                 # cells a side of an in-memory volume's bricks, unless too few per slab
GROW_PIXELS = 0.125                # bricks' proxies grow by at most 2^-3 px (GL's 4 subpixel bits)
WINDOW_MARGIN = 2                  # pixels around a slab's projected box


class SchedulerUnreachable(ConnectionError):
    """No Dask scheduler answered at ``address`` within ``timeout`` seconds."""

    def __init__(self, address, timeout, reason=""):
        self.address, self.timeout, self.reason = address, timeout, reason
        super().__init__(f"no Dask scheduler answered at {address} within {timeout:g} s"
                         + (f" ({reason})" if reason else "")
                         + "; start one (dask scheduler) or leave out scheduler/--scheduler for a local cluster")

    def __reduce__(self):
        return type(self), (self.address, self.timeout, self.reason)


class BrickReadError(OSError):
    """Reading brick ``index`` (bz, by, bx) failed on a worker; ``block`` is the samples
    (z0, z1, y0, y1, x0, x1) it reads."""

    def __init__(self, index, block, source, reason):
        self.index, self.block, self.source, self.reason = tuple(index), tuple(block), source, reason
        z0, z1, y0, y1, x0, x1 = self.block
        super().__init__(f"brick {self.index} (samples z {z0}:{z1}, y {y0}:{y1}, x {x0}:{x1}) of {source} "
                         f"could not be read on a worker: {reason}")

    def __reduce__(self):
        return type(self), (self.index, self.block, self.source, self.reason)


class DistributedModeError(ValueError):
    """A scene the distributed renderer does not composite (its mode or contents)."""


# ----------------------------------------------------------------------------- shares of the volume

@dataclass(frozen=True)
class Share:
    """One worker's part of a frame: ``slab`` its place along ``axis`` (0 z, 1 y, 2 x),
    ``layers`` its brick layers [l0, l1) there, ``bricks`` their indices (bz, by, bx),
    ``cells`` the cells it owns along the axis, and ``window`` (x, y, w, h) the pixels its
    partial covers (y from the bottom, as GL and ``Scene.tile``)."""
    slab: int
    axis: int
    layers: tuple
    bricks: frozenset
    cells: tuple
    window: tuple


def slab_layers(weights, parts):
    """``parts`` contiguous runs [l0, l1) of brick layers (at most one per layer), cut where
    the running sum of ``weights`` (one per layer: its bricks that draw anything) comes
    nearest each even share of the total, so that every run has a like amount of work."""
    weights = np.asarray(weights, np.float64) + 1e-9      # (every layer counts a little)
    n_layers = len(weights)
    parts = max(1, min(int(parts), n_layers))
    ends = np.cumsum(weights)
    cuts = [0]
    for i in range(1, parts):
        target = ends[-1] * i / parts
        cut = int(np.searchsorted(ends, target, side="left")) + 1      # the first run reaching it ...
        if cut > 1 and target - ends[cut - 2] < ends[cut - 1] - target:
            cut -= 1                                                    # ... or one layer short, if nearer
        cuts.append(min(max(cut, cuts[-1] + 1), n_layers - (parts - i)))
    cuts.append(n_layers)
    return [(cuts[i], cuts[i + 1]) for i in range(parts)]


def occupied_layers(scene, bricks, brick_size, axis, skip_empty=True, tables=None):
    """Per brick layer along ``axis``, how many of its bricks can show anything under the
    scene's TF (all of them where empty bricks are not skipped): a LazyVolume's from its
    summary, an in-memory volume's from its bricks' value ranges (kept in ``tables``, a
    ``util.cache.TableCache``, between frames)."""
    from ..model.transfer import LookupTable
    from ..techniques.bricks import brick_occupancy, lazy_occupied, value_ranges
    occupied = np.ones(len(bricks), bool)
    if skip_empty and scene.mode == "composite":
        lut = LookupTable(scene.tf)
        if scene.is_lazy:
            occupied = lazy_occupied(scene.volume, bricks, brick_size, lut, True)
        else:
            kind = f"distributed_ranges:{brick_size}:{len(bricks)}"
            ranges = (value_ranges(scene.volume, bricks) if tables is None
                      else tables.get(kind, scene.volume, make=lambda volume: value_ranges(volume, bricks)))
            occupied = brick_occupancy(ranges, lut)
    n_layers = 1 + max(b.index[axis] for b in bricks)
    return np.bincount([b.index[axis] for b in bricks], weights=occupied.astype(float), minlength=n_layers)


def slab_axis(shape, brick_size):
    """The axis with the most brick layers (z on a tie: whole planes of a C-ordered store)."""
    layers = [max(1, math.ceil(max(n - 1, 1) / brick_size)) for n in shape]
    return int(np.argmax(layers))


def eye_layer(volume, axis, layer_faces, eye):
    """The brick layer holding the eye along ``axis`` (-1 before the first, the layer count
    after the last), decided as ``bricks.visibility_order`` decides it: the float32 eye
    against the float32 faces."""
    spacing = float(volume.spacing[2 - axis])
    faces32 = (np.asarray(layer_faces, np.float64) * spacing).astype(np.float32)
    return int(np.searchsorted(faces32[1:-1], np.float32(eye[2 - axis]), side="right"))


def slab_order(scene, shares):
    """The shares front to back for every ray: perspective, by distance in layers from the
    one holding the eye (a ray leaves it one way and meets the others in that order);
    orthographic, along the view direction's sign on the axis."""
    if not shares:
        return []
    axis = shares[0].axis
    camera = scene.camera
    if camera.is_ortho:
        sign = float(np.sign(camera.forward[2 - axis]))
        return sorted(shares, key=lambda s: sign * s.slab)
    eye = np.asarray(camera.eye, np.float64) - scene.volume.bounds[0]
    faces = [s.cells[0] for s in shares] + [shares[-1].cells[1]]
    e = eye_layer(scene.volume, axis, faces, eye)          # the slab holding the eye
    return sorted(shares, key=lambda s: abs(s.slab - e))


def screen_window(scene, axis, cells):
    """(x, y, w, h) of the pixels a slab owning ``cells`` [c0, c1) along ``axis`` can
    touch: its box, grown as the brick proxies are, projected, plus a margin; the whole
    image when the eye is in or near the box (full-screen proxies) or the box reaches
    behind the eye."""
    from ..techniques.common import box_view
    full = (0, 0, scene.width, scene.height)
    kind, view_proj, grow = box_view(scene, GROW_PIXELS)
    if kind != "box":
        return full
    volume = scene.volume
    spacing = np.asarray(volume.spacing, np.float64)
    cells_max = np.maximum(np.asarray(volume.dims) - 1, 1).astype(np.float64)
    lo, hi = np.zeros(3), cells_max * spacing
    lo[2 - axis], hi[2 - axis] = cells[0] * spacing[2 - axis], cells[1] * spacing[2 - axis]
    lo, hi = lo - grow, hi + grow
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    clip = corners @ view_proj
    if np.any(clip[:, 3] <= 0):
        return full
    ndc = clip[:, :2] / clip[:, 3:4]
    px = (ndc[:, 0] + 1) * 0.5 * scene.width
    py = (ndc[:, 1] + 1) * 0.5 * scene.height
    x0 = max(int(math.floor(px.min())) - WINDOW_MARGIN, 0)
    y0 = max(int(math.floor(py.min())) - WINDOW_MARGIN, 0)
    x1 = min(int(math.ceil(px.max())) + WINDOW_MARGIN, scene.width)
    y1 = min(int(math.ceil(py.max())) + WINDOW_MARGIN, scene.height)
    if x1 <= x0 or y1 <= y0:
        return (0, 0, 0, 0)              # off screen: nothing to draw
    return (x0, y0, x1 - x0, y1 - y0)


def plan_shares(scene, brick_size, halo, parts, axis=None, skip_empty=True, tables=None):
    """The shares of ``scene``'s volume for ``parts`` workers: slabs of whole brick layers
    along ``axis`` (default ``slab_axis``), balanced by the bricks that draw anything
    (``occupied_layers``), each with its window of the screen."""
    from ..techniques.bricks import partition
    shape = scene.volume.shape
    axis = slab_axis(shape, brick_size) if axis is None else int(axis)
    bricks = partition(shape, brick_size, halo)
    edges = sorted({b.cells[axis][0] for b in bricks}) + [max(shape[axis] - 1, 1)]
    weights = occupied_layers(scene, bricks, brick_size, axis, skip_empty, tables)
    shares = []
    for slab, (l0, l1) in enumerate(slab_layers(weights, parts)):
        cells = (edges[l0], edges[l1])
        owned = frozenset(b.index for b in bricks if l0 <= b.index[axis] < l1)
        shares.append(Share(slab, axis, (l0, l1), owned, cells, screen_window(scene, axis, cells)))
    return shares


def composite(partials, width, height):
    """The image of ``partials`` [(window, premultiplied RGBA rows top first), ...] given
    front to back: the over operator, ``C = C_front + (1 - A_front) C_back``, accumulated
    in float64 and rounded to float32 once. A window of (x, y, w, h) covers rows
    ``height - y - h`` to ``height - y`` from the top."""
    image = np.zeros((height, width, 4), np.float64)
    for (x, y, w, h), part in partials:
        if w == 0 or h == 0:
            continue
        region = image[height - y - h:height - y, x:x + w]
        region += (1.0 - region[..., 3:4]) * part
    return image.astype(np.float32)


# ----------------------------------------------------------------------------- on the workers

@dataclass(frozen=True)
class StoreRef:
    """A store-backed LazyVolume as the workers see it: they open ``path`` (and ``key``)
    themselves and give it the client's geometry and brick summary."""
    path: str
    key: object
    spacing: tuple
    origin: tuple
    orientation: object
    summary: object = field(default=None, compare=False, hash=False)   # (not part of its identity)

    @classmethod
    def of(cls, volume):
        path, key = volume.source
        return cls(str(path), key, tuple(volume.spacing.tolist()), tuple(volume.origin.tolist()),
                   volume.orientation, getattr(volume, "_summary", None))

    def open(self):
        from ..formats.stores import open_volume
        volume = open_volume(self.path, key=self.key or None, spacing=self.spacing, origin=self.origin)
        volume.orientation = self.orientation
        if self.summary is not None:
            volume._summary = self.summary
        return volume


@dataclass(frozen=True)
class Shipped:
    """A volume sent to the workers whole (an array in memory, a dask array's graph),
    named by ``token``: a worker keeps the first copy it sees under that name, so that its
    renderer's textures and brick cache (kept by the volume's identity) last across
    frames whatever copy Dask hands a task."""
    token: str
    volume: object = field(compare=False, hash=False)


_WORKER = {"renderers": {}, "volumes": {}}     # per worker process: kept between frames
KEEP_VOLUMES = 4                               # volumes a worker keeps (the oldest dropped first)


def worker_renderer(backend):
    """This process's Renderer for ``backend``, made on first use."""
    renderer = _WORKER["renderers"].get(backend)
    if renderer is None:
        from ..rendering.renderer import Renderer
        renderer = _WORKER["renderers"][backend] = Renderer(backend=backend)
    return renderer


def worker_volume(handle):
    """The volume a task's handle stands for, one object per process: a StoreRef opened
    on first use, a Shipped volume's first copy (anything else: itself)."""
    if not isinstance(handle, (Shipped, StoreRef)):
        return handle
    key = handle.token if isinstance(handle, Shipped) else handle
    volumes = _WORKER["volumes"]
    volume = volumes.get(key)
    if volume is None:
        volume = volumes[key] = handle.open() if isinstance(handle, StoreRef) else handle.volume
        while len(volumes) > KEEP_VOLUMES:
            volumes.pop(next(iter(volumes)))
    return volume


def render_share(stub, handle, share, step, options, backend="auto"):
    """(window, partial): the premultiplied partial image of ``share``'s bricks, rows top
    first, for the scene ``stub`` (a scene without its volume) and the volume ``handle``
    stands for. Pure: the result depends on the arguments alone."""
    from ..gl.context import current
    from ..model.lazy_volume import VolumeReadError
    from ..rendering.renderer import tiles
    from ..techniques import raycast
    x0, y0, w, h = share.window
    if w == 0 or h == 0:
        return share.window, np.zeros((h, w, 4), np.float32)
    scene = copy.copy(stub)
    scene.volume = worker_volume(handle)
    renderer = worker_renderer(backend)
    partial = np.empty((h, w, 4), np.float32)
    try:
        with _single_threaded_dask(), current(renderer.ctx):
            for x, y, tw, th in tiles(w, h, renderer.max_tile):
                part = copy.copy(scene)
                part.tile = (x0 + x, y0 + y, tw, th)
                plan = raycast.make_plan(part, step, tables=renderer.tables, **options)
                plan.brick_subset = share.bricks       # (bricks.draw draws these alone)
                fbo = raycast.draw(renderer, plan)
                partial[h - y - th:h - y, x:x + tw] = renderer.read_target(fbo, tw, th)
    except VolumeReadError as e:
        brick = getattr(e, "brick", None)       # set by the brick textures' read
        if brick is None:
            raise
        samples = tuple(v for pair in brick.samples for v in pair)
        raise BrickReadError(brick.index, samples, scene.volume.describe(), str(e)) from e
    return share.window, partial


class _single_threaded_dask:
    """A dask array read inside a task computes in the task's own thread (the worker has
    one), not on a pool of its own or the cluster."""

    def __enter__(self):
        try:
            import dask
        except ImportError:
            self._set = None
        else:
            self._set = dask.config.set(scheduler="synchronous")
            self._set.__enter__()
        return self

    def __exit__(self, *exc):
        if self._set is not None:
            self._set.__exit__(*exc)


# ----------------------------------------------------------------------------- the client

def _distributed():
    try:
        import distributed
    except ImportError:
        raise ImportError("dvr_gl.distributed needs dask.distributed: pip install \"dvr-gl[dist]\"") from None
    return distributed


def connect(scheduler=None, workers=2, connect_timeout=DEFAULT_CONNECT_TIMEOUT, gl_threads=None):
    """(client, cluster): a client of the scheduler at ``scheduler`` (an address such as
    ``tcp://host:8786``), or of a new LocalCluster of ``workers`` worker processes of one
    thread each (cluster None for a scheduler given). A scheduler that does not answer
    within ``connect_timeout`` seconds is a SchedulerUnreachable naming its address.
    ``gl_threads``: llvmpipe threads per local worker (LP_NUM_THREADS; default the cores
    shared out, at least 1)."""
    distributed = _distributed()
    if scheduler is not None:
        address = str(scheduler)
        try:
            return distributed.Client(address, timeout=connect_timeout), None
        except (OSError, TimeoutError) as e:
            raise SchedulerUnreachable(address, connect_timeout, f"{type(e).__name__}: {e}") from e
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ValueError(f"workers must be a whole number of worker processes >= 1, got {workers!r}")
    threads = gl_threads or max(1, (os.cpu_count() or 1) // int(workers))
    env = {"LP_NUM_THREADS": str(os.environ.get("LP_NUM_THREADS", threads))}
    cluster = distributed.LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                       dashboard_address=None, env=env)
    return distributed.Client(cluster), cluster


class ClusterRenderer:
    """Renders scenes sort-last on a Dask cluster: ``render(scene, ...)`` returns the
    float32 premultiplied RGBA image ``Renderer.render(scene, "raycast", ...)`` gives with
    the same ``brick_size`` (see the module's note for how close). Keeps the cluster, the
    volumes sent and the workers' renderers between frames; close it (or use ``with``).

    ``scheduler``: an address, or None for a LocalCluster of ``workers`` processes;
    ``parts``: shares per frame (default: one per worker); ``axis``: the slab axis (0 z,
    1 y, 2 x; default the one with the most brick layers)."""

    def __init__(self, scheduler=None, workers=2, parts=None, axis=None, backend="auto",
                 connect_timeout=DEFAULT_CONNECT_TIMEOUT, gl_threads=None):
        from ..util.cache import TableCache
        self.client, self.cluster = connect(scheduler, workers, connect_timeout, gl_threads)
        self.parts, self.axis, self.backend = parts, axis, backend
        self._sent = {}          # id(volume) -> (volume, handle or future)
        self.tables = TableCache()   # in-memory volumes' brick value ranges, for the slabs' balance
        self.last_frame = None   # what the last render moved and took

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    @property
    def worker_addresses(self):
        return sorted(self.client.scheduler_info()["workers"])

    def _handle(self, volume):
        """What tasks receive for ``volume``: a StoreRef for a store on disk, else the
        volume as Shipped, scattered to every worker once (a future)."""
        held = self._sent.get(id(volume))
        if held is not None and held[0] is volume:
            return held[1], 0
        sent = 0
        if getattr(volume, "source", None) is not None and getattr(volume, "store_format", None) not in (
                None, "loaded whole"):
            handle = StoreRef.of(volume)
        else:
            import cloudpickle      # (what dask sends a graph's functions with)
            sent = len(cloudpickle.dumps(volume)) * len(self.worker_addresses)
            handle = self.client.scatter(Shipped(uuid.uuid4().hex, volume), broadcast=True, hash=False)
        self._sent[id(volume)] = (volume, handle)
        return handle, sent

    def render(self, scene, step=None, brick_size=None, **options):
        """The image of ``scene`` (one volume, mode composite) by the ray caster's options
        (``step``, ``brick_size``, ``ert_transmittance``, ``skip_empty``, ``memory`` ...)."""
        from ..techniques import check_options
        from ..techniques.bricks import check_brick_size, halo_for, unsupported, summary_for
        check_scene_for_cluster(scene, options)
        check_options("raycast", dict(options, brick_size=brick_size))
        unsupported(scene, options.get("preintegrate", False), options.get("gradients", "on_the_fly"))
        volume = scene.volume
        addresses = self.worker_addresses
        if not addresses:
            raise RuntimeError("the Dask cluster has no workers")
        parts = self.parts or len(addresses)
        brick_size = check_brick_size(brick_size) or default_brick_size(volume, parts)
        if scene.is_lazy and (options.get("skip_empty", True) or scene.shading):
            summary_for(volume, brick_size)       # made once on the client, sent with the volume
        shares = plan_shares(scene, brick_size, halo_for(scene), parts, self.axis, options.get("skip_empty", True),
                             self.tables)
        ordered = slab_order(scene, shares)
        t0 = time.perf_counter()
        handle, scattered = self._handle(volume)
        stub = copy.copy(scene)
        stub.volume = None
        options = dict(options, brick_size=brick_size)
        sent = len(pickle.dumps((stub, handle if isinstance(handle, StoreRef) else None, shares[0], step, options)))
        futures = [self.client.submit(render_share, stub, handle, share, step, options, self.backend,
                                      pure=False, workers=[addresses[i % len(addresses)]],
                                      allow_other_workers=True)
                   for i, share in enumerate(shares)]
        results = dict(zip([s.slab for s in shares], self.client.gather(futures)))
        placed = self.client.who_has(futures)
        image = composite([results[s.slab] for s in ordered], scene.width, scene.height)
        returned = sum(part.nbytes for _, part in results.values())
        self.last_frame = FrameRecord(seconds=time.perf_counter() - t0, shares=len(shares), axis=shares[0].axis,
                                      brick_size=brick_size, partial_bytes=returned, task_bytes=sent * len(shares),
                                      scattered_bytes=scattered,
                                      windows=tuple(results[s.slab][0] for s in ordered),
                                      placed=tuple(tuple(placed.get(f.key, ())) for f in futures))
        return image


@dataclass(frozen=True)
class FrameRecord:
    """One frame: its wall time on the client (tasks, transfers, compositing), the shares,
    and the bytes it moved: partial images back to the client, task arguments out, and
    volumes scattered (sent once, counted on the frame that sent them)."""
    seconds: float
    shares: int
    axis: int
    brick_size: int
    partial_bytes: int
    task_bytes: int
    scattered_bytes: int
    windows: tuple
    placed: tuple = ()      # per share (slab order), the workers that hold its partial

    @property
    def bytes_moved(self):
        return self.partial_bytes + self.task_bytes + self.scattered_bytes


def default_brick_size(volume, parts):
    """A LazyVolume's summary brick size, else DEFAULT_BRICK; either made smaller where it
    would leave fewer brick layers than ``parts`` along the longest axis."""
    from ..techniques.lazy_bricks import summary_brick_size
    size = summary_brick_size(volume) if hasattr(volume, "read") else DEFAULT_BRICK
    cells = max(max(n - 1, 1) for n in volume.shape)
    return max(1, min(size, math.ceil(cells / max(int(parts), 1))))


def check_scene_for_cluster(scene, options):
    """A DistributedModeError naming what the distributed renderer does not take."""
    what = None
    if getattr(scene, "is_mesh", False):
        what = "a TetMesh (grids only)"
    elif scene.layers:
        what = "several volumes (Scene.layers)"
    elif scene.mode != "composite":
        what = (f"mode {scene.mode!r}: partial images are composited with the over operator (mode 'composite'); "
                "mip, minip and average would need each partial's value before classification")
    elif scene.optical_model == "sabella":
        what = "optical_model 'sabella' (a ray's colour comes from its peak over every slab)"
    elif "tolerance" in options:
        what = "tolerance= (give step=)"
    elif options.get("target", "rgba32f") != "rgba32f":
        what = f"target {options['target']!r} (partials are composited from float32 images: 'rgba32f')"
    if what is not None:
        raise DistributedModeError(f"render_distributed does not take {what}")


def render_distributed(source, *, scheduler=None, workers=2, parts=None, axis=None, backend="auto",
                       connect_timeout=DEFAULT_CONNECT_TIMEOUT, tf=None, size=(512, 512), azimuth=None,
                       elevation=None, zoom=1.0, fov=30.0, ortho=False, shading=None, spacing=None,
                       orientation=None, clip_planes=(), crop_box=None, **options):
    """Render ``source`` sort-last on a Dask cluster and return the float32 premultiplied
    RGBA image (height, width, 4), row 0 on top, as ``dvr_gl.render`` does.

    ``source``: a :class:`dvr_gl.Scene` (used as it is), or anything ``dvr_gl.render``
    takes (a file, a zarr or HDF5 store, a LazyVolume, an array), framed by the same
    keywords (``tf``, ``size``, ``azimuth``, ...). ``scheduler``: a scheduler's address
    (``tcp://host:8786``), else a LocalCluster of ``workers`` worker processes is started
    for this call and closed after it (keep a :class:`ClusterRenderer` for several
    frames). ``options``: the ray caster's (``step``, ``brick_size``,
    ``ert_transmittance``, ``skip_empty``, ``memory`` per worker, ...)."""
    from ..model.scene import Scene
    if isinstance(source, Scene):
        scene = source
    else:
        from ..formats import InputError
        from .inputs import first_camera, load_input, resolve_tf, shading_for
        data, preset = load_input(source, spacing=spacing, orientation=orientation)
        _, tf = resolve_tf(tf, data, preset)
        try:
            width, height = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
        except (TypeError, ValueError, IndexError):
            raise InputError("size", f"expected an int or (width, height), got {size!r}") from None
        scene = Scene(data, tf, first_camera(data, azimuth=azimuth, elevation=elevation, zoom=zoom, fov=fov,
                                             ortho=ortho),
                      width=width, height=height, shading=shading_for("raycast") if shading is None else shading,
                      clip_planes=clip_planes, crop_box=crop_box)
    check_scene_for_cluster(scene, options)          # before a cluster is started
    with ClusterRenderer(scheduler, workers, parts, axis, backend, connect_timeout) as renderer:
        return renderer.render(scene, **options)


def render_for_cli(scene, render_kwargs, workers, scheduler, backend="auto"):
    """``dvr-gl render --workers N`` / ``--scheduler ADDRESS``: (image, time the cluster
    was ready, time the frame ended, the cluster in words)."""
    from .options import UsageError
    options = dict(render_kwargs)
    technique = options.pop("technique", "raycast")
    if technique != "raycast":
        raise UsageError("--workers" if scheduler is None else "--scheduler",
                         f"renders with --technique raycast (bricks), not {technique}")
    if workers is not None and workers < 1:
        raise UsageError("--workers", f"must be at least 1 worker process, got {workers}")
    if "tolerance" in options:
        raise UsageError("--tolerance", "is not taken by a distributed render: give --step")
    check_scene_for_cluster(scene, options)          # before a cluster is started
    with ClusterRenderer(scheduler, workers or 2, backend=backend) as renderer:
        ready = time.perf_counter()
        image = renderer.render(scene, **options)
        done = time.perf_counter()
        where = scheduler if scheduler is not None else "a local cluster"
        frame = renderer.last_frame
        described = (f"{len(renderer.worker_addresses)} Dask workers at {where} ({frame.shares} slabs along "
                     f"{'zyx'[frame.axis]}, bricks of {frame.brick_size})")
    return image, ready, done, described
