"""The GL renderer: one headless context, its program cache, and the store of GPU
resources scenes need (``gl.resources.ResourceStore``: made on first use by the
techniques, kept while the scene's objects live, never per frame)."""

from __future__ import annotations


import copy
import math
import os

import numpy as np

from ..gl.capabilities import context_defines, prefers_compute_stage
from ..gl.context import context_lost, current, describe, shared_context
from ..gl.programs import ProgramCache
from ..gl.resources import ResourceStore
from ..util.progress import Progress
from ..util.cache import LRU, TableCache
from ..util.memory import available_memory
from ..techniques import check_options, get_technique


class Renderer:
    """Renders scenes with GLSL techniques into float images.

    >>> with Renderer(backend="auto") as r:          # doctest: +SKIP
    ...     img = r.render(scene, technique="raycast", step=None)

    ``img`` is (H, W, 4) float32 premultiplied RGBA, row 0 on top. The first render of a
    scene compiles and uploads; later ones reuse the programs, textures and targets.
    To work in the renderer's context yourself, enter it with
    ``dvr_gl.gl.context.current(renderer.ctx)``, not ``with renderer.ctx`` (moderngl's
    does not nest with the renderer's own).
    """

    def __init__(self, backend="auto", ctx=None, max_tile=None):
        """``backend``: "auto" (EGL, then OSMesa), "egl" or "osmesa": a headless context
        shared by the process. ``ctx``: render in this moderngl context instead (a
        window's, as the viewer does); the caller keeps it current and owns it.
        ``max_tile``: the largest side in pixels of one GL target (default: the GL limits,
        at most DEFAULT_MAX_TILE); larger images are rendered in tiles."""
        if max_tile is not None and (isinstance(max_tile, bool) or not isinstance(max_tile, (int, np.integer))
                                     or max_tile < 16):
            raise ValueError(f"max_tile must be an integer >= 16 (pixels), got {max_tile!r}")
        self._max_tile = None if max_tile is None else int(max_tile)
        self._requested = backend
        if ctx is not None:
            self.ctx, self.backend = ctx, "window"
        else:
            self.ctx, self.backend = shared_context(backend)
        self._released = False
        self._new_gpu_state()

    def _new_gpu_state(self):
        """An empty program cache and resource store for ``self.ctx``."""
        self.programs = ProgramCache(self.ctx, context_defines)
        # probed now, not in the middle of a draw: the probe binds its own target and texture
        self.programs.context_defines
        self.resources = ResourceStore(self.ctx)  # what techniques keep on the GPU, by kind and key
        self.created = self.resources.created  # a log of (kind, shape or detail) for every resource made
        self.tables = TableCache()
        self.rows_top_down_wanted, self.top_down_target = False, None    # (_draw, read_target)
        self._error_models = LRU(64)   # tolerance: pilot view and options -> tolerance.ErrorModel
        self._tolerance_picks = LRU(64)  # tolerance: pilot view, options and RMSE -> the Choice timed fastest
        self._mesh_picks = LRU(64)     # a mesh's tolerance: view family, size and RMSE -> mesh_tolerance.MeshChoice
        self._mesh_pilots = LRU(16)    # a mesh's tolerance: view family and size -> mesh_tolerance.PilotRecord

    # -- lifetime ---------------------------------------------------------------------
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def _revive(self):
        """If another library destroyed the shared context (``gl.context.context_lost``),
        move to a new one: the GPU objects died with the old context and are made again
        on demand, so the renderer goes on giving the same images."""
        if self.backend != "window" and not self._released and context_lost(self.ctx):
            self.ctx, self.backend = shared_context(self._requested)
            self._new_gpu_state()

    def release(self):
        if self._released:
            return
        self._released = True
        if context_lost(self.ctx):  # its objects are gone already
            return
        with current(self.ctx):
            self.resources.release()    # leaves the idle framebuffer bound
            self.programs.release()
        # The context itself is shared by the process's renderers and stays (see
        # gl.context.shared_context).

    def gpu_bytes(self) -> int:
        """Bytes of every texture, buffer and render target the renderer holds in its
        resource store (its own bookkeeping; the driver's overheads are not counted)."""
        return self.resources.gpu_bytes()

    def info(self) -> dict:
        self._revive()
        with current(self.ctx):  # another library (VTK) may have made its own context current
            return dict(describe(self.ctx), backend=self.backend)

    @property
    def compute_stage_faster(self) -> bool:
        """Whether per-pixel ray shaders run faster on this GPU as compute shaders than as
        fragment shaders (``capabilities.prefers_compute_stage``: measured once per
        process and device; ``DVR_GL_PIXEL_STAGE=fragment|compute`` decides instead).
        The ray caster's ``stage="auto"`` follows it."""
        forced = os.environ.get("DVR_GL_PIXEL_STAGE")
        if forced:
            if forced not in ("fragment", "compute"):
                raise ValueError(f"DVR_GL_PIXEL_STAGE must be 'fragment' or 'compute', got {forced!r}")
            return forced == "compute"
        with current(self.ctx):
            device = (self.ctx.info.get("GL_VENDOR"), self.ctx.info.get("GL_RENDERER"),
                      self.ctx.info.get("GL_VERSION"))
            if device not in _COMPUTE_FASTER:
                _COMPUTE_FASTER[device] = prefers_compute_stage(self.ctx)
        return _COMPUTE_FASTER[device]

    # -- rendering --------------------------------------------------------------------
    def render(self, scene, technique="raycast", step=None, tolerance=None, **options):
        """Render ``scene``; see the technique's module for its options. Images larger
        than one GL target (``max_tile``) are rendered in tiles, each a window of the
        same camera, into one array: the same pixels as a single render would give.

        ``tolerance``: an RMSE against the exact image; for ray casting the step is chosen
        for it (``dvr_gl.rendering.tolerance``; on a pyramid, the level and step:
        ``dvr_gl.rendering.pyramid``), for a mesh (technique tetra) the fastest way
        of rendering it (``dvr_gl.rendering.mesh_tolerance``); what was chosen is ``last_choice``."""
        if tolerance is not None:
            if step is not None:
                raise ValueError(f"give tolerance or step, not both (got step={step!r}, tolerance={tolerance!r})")
            if scene.is_mesh:
                scene, technique, step, options = self.mesh_tolerance_settings(scene, tolerance, technique, **options)
            elif len(getattr(scene.volume, "levels", ()) or ()) > 1 and not scene.layers:   # a pyramid: its level
                from . import pyramid, pyramid_bricks       # (per_brick=True: a level per brick)
                choose = pyramid_bricks.brick_settings if options.get("per_brick") else pyramid.settings
                scene, step, options, self.last_choice = choose(self, scene, tolerance, technique,
                                                                {k: v for k, v in options.items() if k != "per_brick"})
            else:
                step, chosen = self.tolerance_settings(scene, tolerance, technique, **options)
                options = dict(options, **chosen)
        self._revive()
        with current(self.ctx):
            edge = self.max_tile
            if scene.width <= edge and scene.height <= edge:
                fbo = self._draw(scene, technique, step, options, read_back=True)
                return self.read_target(fbo, scene.width, scene.height)
            check_image_memory(scene.width, scene.height)
            image = np.empty((scene.height, scene.width, 4), np.float32)
            margin = self._tile_margin(technique)
            if edge - 2 * margin < 16:
                raise ValueError(f"max_tile {edge} leaves no room for the {margin}-pixel margin that "
                                 f"{technique}'s point sprites need on each side of a tile")
            parts = tiles(scene.width, scene.height, edge - 2 * margin)
            progress = Progress(len(parts))
            for x, y, w, h in parts:
                # point sprites are clipped by their centres: a margin of the largest
                # sprite's half side keeps those centred just outside the tile
                x0, y0 = max(x - margin, 0), max(y - margin, 0)
                x1, y1 = min(x + w + margin, scene.width), min(y + h + margin, scene.height)
                part = copy.copy(scene)
                part.tile = (x0, y0, x1 - x0, y1 - y0)
                fbo = self._draw(part, technique, step, options, read_back=True)
                pixels = self.read_target(fbo, x1 - x0, y1 - y0)   # row 0 on top: GL row y1 - 1
                top = y1 - y - h
                image[scene.height - y - h:scene.height - y, x:x + w] = pixels[top:top + h, x - x0:x - x0 + w]
                progress.advance(f"{technique} {scene.width}x{scene.height} in tiles")
            progress.close()
            return image

    last_choice = None      # the tolerance.Choice of the last render(tolerance=...)

    def tolerance_settings(self, scene, tolerance, technique="raycast", **options):
        """(step, options) for an RMSE of ``tolerance`` against the exact image
        (``dvr_gl.rendering.tolerance.settings``; also ``last_choice``): the error model and
        the way of sampling are measured once per volume, TF and options and kept across
        views and sizes; each view's choice is checked at up to the tolerance module's
        ``CHECK_SIDE`` pixels."""
        from . import tolerance as tol
        from .filtering import with_texture_unit
        choice = tol.settings(self, scene, tolerance, technique, options)
        self.last_choice = with_texture_unit(self, scene, tolerance, technique, options, choice)
        return self.last_choice.step, dict(self.last_choice.sampling)

    def mesh_tolerance_settings(self, scene, tolerance, technique="tetra", **options):
        """(scene, technique, step, options) that render the mesh ``scene`` the fastest way
        within RMSE ``tolerance`` of the exact image (``dvr_gl.rendering.mesh_tolerance``; also
        ``last_choice``); the choice is kept per view family, size and tolerance."""
        from . import mesh_tolerance as mt
        from .tolerance import check_tolerance
        mt.check_request(technique, options)
        tolerance = check_tolerance(tolerance)
        family = (mt.view_family(scene), scene.width, scene.height)

        def render(s, name, h, opts):
            return self.render(s, name, step=h, **opts)

        def choose():
            record = self._mesh_pilots.get(family, mt.PilotRecord)     # what earlier tolerances measured
            return mt.choose(render, scene, tolerance, self.tables, record)

        self.last_choice = self._mesh_picks.get(family + (tolerance,), choose)
        way = mt.Way(self.last_choice.label, self.last_choice.technique, self.last_choice.options,
                     self.last_choice.grid, self.last_choice.step_spacings)
        return mt.way_arguments(scene, way, self.tables)

    @property
    def max_tile(self):
        """The largest side of one render target: GL's texture, renderbuffer and viewport
        limits, and DEFAULT_MAX_TILE (or the ``max_tile`` given)."""
        if self._max_tile is None:
            with current(self.ctx):
                info = self.ctx.info
            limits = [info.get("GL_MAX_TEXTURE_SIZE"), info.get("GL_MAX_RENDERBUFFER_SIZE"),
                      *(info.get("GL_MAX_VIEWPORT_DIMS") or ())]
            self._max_tile = min([DEFAULT_MAX_TILE] + [int(v) for v in limits if v])
        return self._max_tile

    def _tile_margin(self, technique):
        if not getattr(get_technique(technique), "POINT_SPRITES", False):
            return 0
        with current(self.ctx):
            largest = self.ctx.info.get("GL_POINT_SIZE_RANGE", (1.0, 256.0))[1]
        return int(math.ceil(largest / 2)) + 1

    def render_target(self, scene, technique="raycast", step=None, **options):
        """Render into the renderer's float target and return that framebuffer, without
        reading it back (the viewer draws its colour attachment to the window). The
        framebuffer is reused by the next render of the same size and format. The image
        must fit one target (``max_tile``)."""
        self._revive()
        if max(scene.width, scene.height) > self.max_tile:
            raise ValueError(f"width x height must be at most {self.max_tile} pixels a side for render_target "
                             f"(one GL target), got {scene.width}x{scene.height}; render() tiles larger images")
        with current(self.ctx):
            return self._draw(scene, technique, step, options)

    def _draw(self, scene, technique, step, options, read_back=False):
        if self._released:
            raise RuntimeError("this Renderer has been released")
        tech = get_technique(technique)
        levels = options.get("brick_levels")     # a pyramid's per-brick levels (rendering.pyramid_bricks)
        if levels is not None:
            options = {k: v for k, v in options.items() if k != "brick_levels"}
        check_options(technique, options)
        plan = tech.make_plan(scene, step, tables=self.tables, **options)
        if levels is not None:
            plan.brick_levels = levels
        # a compute pass may store the image's rows top down when it is read back next
        # (gpu.draw_ray_compute): read_target then needs no flip
        self.rows_top_down_wanted, self.top_down_target = read_back, None
        try:
            return tech.draw(self, plan)
        finally:
            self.rows_top_down_wanted = False

    def read_target(self, fbo, width, height):
        """Read back as float32 (GL finishes before this returns), row 0 on top."""
        image = np.empty((height, width, 4), np.float32)     # read straight into NumPy's memory
        fbo.read_into(image, viewport=(0, 0, width, height), components=4, dtype="f4")
        if fbo is self.top_down_target:                      # stored row 0 on top: as it is
            self.top_down_target = None
            return image
        return np.ascontiguousarray(image[::-1])


_COMPUTE_FASTER = {}     # (vendor, renderer, version) -> the stage probe's verdict, per process
DEFAULT_MAX_TILE = 4096  # a 4096^2 RGBA32F target is 256 MiB


def tiles(width, height, edge):
    """(x, y, w, h) tiles of at most ``edge`` pixels a side covering the image, y from the
    bottom; equal-sized where they can be, so that all but a few targets are reused."""
    nx, ny = -(-width // edge), -(-height // edge)
    xs = np.linspace(0, width, nx + 1).round().astype(int)
    ys = np.linspace(0, height, ny + 1).round().astype(int)
    return [(int(xs[i]), int(ys[j]), int(xs[i + 1] - xs[i]), int(ys[j + 1] - ys[j]))
            for j in range(ny) for i in range(nx)]


class ImageTooLarge(ValueError):
    """The image would not fit in memory."""


def check_image_memory(width, height, copies=1):
    """Raise ImageTooLarge, naming the size, when ``copies`` float32 RGBA images of this
    size would not fit in the memory available."""
    need = width * height * 16 * copies
    have = available_memory()
    if have is not None and need > have:
        raise ImageTooLarge(f"width x height {width}x{height}: the float32 RGBA image needs {need / 2**30:.1f} GiB "
                            f"and {have / 2**30:.1f} GiB of memory is available; render a smaller image")
