"""Bricks: ray casting a volume one block of cells at a time.

A volume wider than one 3-D texture (``GL_MAX_3D_TEXTURE_SIZE`` a side), or one a render
asks to cut (``brick_size=N``), is drawn brick by brick. The cells are partitioned into
bricks of ``N`` cells a side (the last along an axis shorter); each brick's texture holds
the samples of its cells plus a halo of ``halo`` samples on every side (clamped to the
volume), so that every lookup a sample in the brick makes (the trilinear corners, and
the six neighbours of a gradient by central differences) reads the texels the whole
texture would, and at the volume's faces the texture's edge is the volume's, so edge
clamping is the same too.

Each ray keeps the samples it has without bricks: segments from the box entry ``t0``,
``step`` long, each sampled at its midpoint. A brick's pass takes the segments whose
midpoint lies in the box of the cells it owns (``lo <= p < hi`` per axis, the volume's
outer faces open), and since every pass computes a midpoint alike, bit for bit, each
sample is taken by exactly one brick. Passes run front to back in an order valid for
every ray (``visibility_order``), and each continues the ray's sums from the image of
the passes before (read from a copy, not blended), so a ray composites the same pieces in
the same order with the same arithmetic as in one pass: early ray termination and an
opaque end included. Modes mip, minip and average carry the ray's extreme (or its two
sums) in the running image instead, classified once at the end (bricks/resolve.frag).
The only difference is the texture coordinate: ``(x - o + 0.5) / m`` in the brick
instead of ``(x + 0.5) / n`` (``x`` the texel coordinate, exact in both, ``o`` the
brick's first sample), each rounded to float32, where the texture unit filters; where
the shader interpolates from fetches, none (``x - o`` is exact), and the image is the
single texture's bit for bit. Texels keep 8- and 16-bit data in 16 bits or fewer
(``texel_format``).

A brick whose value range (its samples and one more each side) has zero opacity under
the transfer function is never uploaded nor drawn (``brick_occupancy``, the test of
empty-space skipping): every sample it owns is exactly transparent.

Brick textures are read through ``read_block(volume, z0, z1, y0, y1, x0, x1)``: a source
with a ``read`` method of that signature (a lazily read store) plugs in there. A
LazyVolume's emptiness comes from its brick summary (``lazy_occupied``) and its bricks
through a BrickCache, one texture at a time (``LazyBrickTextures``; ``lazy_bricks``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gl.resources import texture3d
from .common import TARGETS, bind, box_view, cleared_target, grow_pixels, tf_uniforms
from .gpu import cull_for_proxy, target_fbo, proxy_vao
from ..model.lazy_volume import VolumeReadError, brick_summary
from ..util.memory import BrickCache

OPEN = 3.0e38   # the owned box's bound on the volume's outer faces
MODES = ("composite", "mip", "minip", "average")


def check_brick_size(brick_size):
    """None (bricks only where the volume exceeds a texture) or a whole number >= 1 of
    cells per brick side."""
    if brick_size is None:
        return None
    if isinstance(brick_size, bool) or not isinstance(brick_size, (int, np.integer)):
        raise TypeError(f"brick_size must be a whole number of cells (or None), got {brick_size!r}")
    if brick_size < 1:
        raise ValueError(f"brick_size must be at least 1 cell, got {brick_size!r}")
    return int(brick_size)


def check_bricking(scene, brick_size, preintegrate, gradients):
    """Validate ``brick_size`` for a ray-casting plan and name what bricks do not take yet
    (checked again at draw time when a volume needs bricks without being asked)."""
    brick_size = check_brick_size(brick_size)
    if brick_size is not None:
        unsupported(scene, preintegrate, gradients)
    return brick_size


def unsupported(scene, preintegrate, gradients):
    """A ValueError naming the first thing in the scene that bricked ray casting does not
    do yet."""
    what = None
    if scene.layers:
        what = "several volumes (Scene.layers)"
    elif scene.mode not in MODES:
        what = f"mode {scene.mode!r} (only {', '.join(MODES)})"
    elif scene.optical_model == "sabella":
        what = "optical_model 'sabella'"
    elif preintegrate:
        what = "preintegrate=True"
    elif scene.geometry:
        what = "opaque geometry (Scene.geometry)"
    elif scene.reads_gradient and gradients == "texture":
        what = "gradients='texture'"
    elif scene.volume.has_nonfinite:
        what = "non-finite samples"
    if what is not None:
        raise ValueError(f"bricked ray casting (brick_size) does not yet take {what}")


def halo_for(scene):
    """Samples of halo a brick needs: 1 for the trilinear corners (and a margin for
    rounding), 2 where samples read gradients by central differences."""
    return 2 if scene.reads_gradient else 1


@dataclass(frozen=True)
class Brick:
    """One brick: ``index`` (bz, by, bx); ``cells`` the owned cells, half-open
    ((z0, z1), (y0, y1), (x0, x1)); ``samples`` the block its texture holds, half-open,
    halo included, clamped to the volume."""
    index: tuple
    cells: tuple
    samples: tuple


def partition(shape, brick_size, halo):
    """The bricks of a volume of ``shape`` (nz, ny, nx) samples, z slowest."""
    cells = [max(n - 1, 1) for n in shape]
    edges = [list(range(0, c, brick_size)) + [c] for c in cells]
    bricks = []
    for iz in range(len(edges[0]) - 1):
        for iy in range(len(edges[1]) - 1):
            for ix in range(len(edges[2]) - 1):
                own = tuple((edges[a][i], edges[a][i + 1]) for a, i in enumerate((iz, iy, ix)))
                block = tuple((max(c0 - halo, 0), min(c1 + 1 + halo, n)) for (c0, c1), n in zip(own, shape))
                bricks.append(Brick((iz, iy, ix), own, block))
    return bricks


def read_block(volume, z0, z1, y0, y1, x0, x1):
    """The samples [z0:z1, y0:y1, x0:x1] in the data's own type: the one place bricks
    read data (a source with ``read(z0, z1, y0, y1, x0, x1)`` is read through it)."""
    if hasattr(volume, "read"):
        return np.asarray(volume.read(z0, z1, y0, y1, x0, x1))
    return np.asarray(volume.data[z0:z1, y0:y1, x0:x1])


# 8- and 16-bit integer data: moderngl's dtype for the same integers and the shader's
# BRICK_INTEGER (1: usampler3D, 2: isampler3D)
INTEGER_TEXELS = {np.dtype(np.uint8): ("u1", 1), np.dtype(np.uint16): ("u2", 1),
                  np.dtype(np.int8): ("i1", 2), np.dtype(np.int16): ("i2", 2)}


def texel_format(dtype, filter_exact):
    """(moderngl dtype, shader defines, bytes a sample) of a brick of ``dtype`` data.

    8- and 16-bit integers: where the texture unit filters with float weights
    (``filter_exact``, llvmpipe) as 16-bit normalised texels of the sample less the
    brick's least, filtered by the unit (R8's filter has 8-bit weights there: measured,
    docs/guide/bricks.md); elsewhere as the same integers, interpolated from fetches as
    such contexts interpolate every volume. Other types as float32, as the single
    texture."""
    dtype = np.dtype(dtype)
    if dtype not in INTEGER_TEXELS:
        return "f4", {}, 4
    if filter_exact:
        return "nu2", {"BRICK_NORMALIZED": 1}, 2
    name, kind = INTEGER_TEXELS[dtype]
    return name, {"BRICK_INTEGER": kind}, dtype.itemsize


def filter_is_exact(renderer):
    return bool(renderer.programs.context_defines.get("TEXTURE_FILTER_EXACT", 0))


def bricked_defines(renderer, volume):
    """The shader switches of a bricked draw of ``volume``."""
    dtype = getattr(volume, "dtype", None)        # (a lazily read source's; a Volume's data's)
    _, defines, _ = texel_format(volume.data.dtype if dtype is None else dtype, filter_is_exact(renderer))
    return {"BRICKED": 1, **defines}


def value_ranges(volume, bricks):
    """(lo, hi) float64 per brick over its samples and one more on each side (the margin
    empty-space skipping takes, so rounding in the texture unit cannot leave it)."""
    lo = np.empty(len(bricks))
    hi = np.empty(len(bricks))
    shape = volume.shape
    for i, brick in enumerate(bricks):
        bounds = [(max(c0 - 1, 0), min(c1 + 2, n)) for (c0, c1), n in zip(brick.cells, shape)]
        block = read_block(volume, *(b for pair in bounds for b in pair))
        lo[i], hi[i] = float(block.min()), float(block.max())
    return lo, hi


def brick_occupancy(ranges, lut):
    """True for bricks in which some value has non-zero opacity.

    The shader's float32 arithmetic can move a value and its table index by a few units
    in the last place, never more: trilinear weights are convex, so an interpolated value
    stays within its corners' range up to rounding relative to their magnitude. The
    range is widened by that much, relative, so a brick of constant air (often exactly
    the TF's first control point) still counts as empty."""
    lo, hi = ranges
    rel = 64 * 2.0 ** -24
    smin = lo - rel * np.abs(lo)
    smax = hi + rel * np.abs(hi)
    u0 = (smin - lut.lo) * lut.scale
    u1 = (smax - lut.lo) * lut.scale
    u0 -= rel * np.abs(u0)
    u1 += rel * np.abs(u1)
    return lut.max_opacity_between(lut.lo + u0 / lut.scale, lut.lo + u1 / lut.scale) > 0


def max_3d_texture_size(ctx):
    """GL_MAX_3D_TEXTURE_SIZE of ``ctx`` (the OpenGL 3.3 minimum, 256, if not reported)."""
    from ..gl.capabilities import max_3d_texture_size as probe
    return probe(ctx)


def brick_size_for(renderer, plan):
    """The brick size a draw uses: the plan's, else the largest whose textures fit where a
    side of the volume exceeds the context's 3-D texture limit, else None (one texture)."""
    if plan.brick_size is not None:
        return plan.brick_size
    scene = plan.scene
    limit = max_3d_texture_size(renderer.ctx)
    if max(scene.volume.shape) <= limit:
        return None
    unsupported(scene, plan.preint is not None, "texture" if "GRADIENT_TEXTURE" in plan.defines else "on_the_fly")
    return limit - 1 - 2 * halo_for(scene)


def visibility_order(bricks, volume, camera_eye, camera_forward, is_ortho):
    """The bricks (all of a partition) sorted so that every ray meets them in this order.
    Along a ray each coordinate moves away from the ray's start, so with ``b`` a brick's
    index and ``e`` the index of the brick column holding the eye (perspective: rays start
    there), the sum over axes of ``|b - e|`` grows with each brick a ray enters (a ray
    meets at most one brick of each sum); orthographic rays share one direction ``d`` and
    the sum of ``sign(d) * b`` grows. ``e`` is decided as the shader decides ownership: the
    float32 eye against the float32 faces."""
    index = np.array([b.index[::-1] for b in bricks], np.int64)          # x, y, z
    if is_ortho:
        key = (np.sign(np.asarray(camera_forward, np.float64)) * index).sum(axis=1)
    else:
        eye = np.asarray(camera_eye, np.float32)
        e = np.empty(3)
        for axis in range(3):                  # the eye's brick column along each axis
            faces = np.array(sorted({b.cells[2 - axis][0] for b in bricks}), np.float64)
            faces32 = (faces * volume.spacing[axis]).astype(np.float32)
            e[axis] = np.searchsorted(faces32[1:], eye[axis], side="right")
        key = np.abs(index - e).sum(axis=1)
    return [bricks[i] for i in np.argsort(key, kind="stable")]


def brick_layout(renderer, volume, brick_size, halo):
    """The partition, kept with the volume."""
    return renderer.resources.for_objects("brick_layout", volume, brick_size, halo,
                                          make=lambda: partition(volume.shape, brick_size, halo), capacity=4)


def occupied_bricks(renderer, plan, bricks, brick_size):
    """Per brick, whether any value it can show has non-zero opacity (all True where the
    plan does not skip empty space). A LazyVolume's from its summary (``lazy_bricks``)."""
    if plan.lazy is not None:
        return lazy_occupied(plan.scene.volume, bricks, brick_size, plan.lut, plan.lazy.skip_empty)
    if plan.occupancy is None:
        return np.ones(len(bricks), bool)
    volume, tf = plan.scene.volume, plan.scene.tf
    ranges = renderer.resources.for_objects("brick_value_ranges", volume, brick_size, bricks,
                                            make=lambda: value_ranges(volume, bricks), capacity=4)
    return renderer.resources.for_objects("brick_occupied", volume, tf, bricks,
                                          make=lambda: brick_occupancy(ranges, plan.lut), capacity=4)


class BrickTextures:
    """A volume's brick textures, made on first use (an empty brick's never)."""

    def __init__(self, ctx, volume, filter_exact):
        self.ctx = ctx
        self.volume = volume
        self.filter_exact = filter_exact
        self.textures = {}    # Brick.samples -> (3-D texture (texel_format), value offset)

    def get(self, brick):
        """(texture, offset): a normalised texel t stands for the value t * 65535 + offset."""
        held = self.textures.get(brick.samples)
        if held is None:
            (z0, z1), (y0, y1), (x0, x1) = brick.samples
            block = read_block(self.volume, z0, z1, y0, y1, x0, x1)
            held = self.textures[brick.samples] = upload_block(self.ctx, block, self.filter_exact)
        return held

    def release(self):
        for tex, _ in self.textures.values():
            tex.release()
        self.textures.clear()


def upload_block(ctx, block, filter_exact):
    """(texture, offset) of a brick's samples ``block`` (``texel_format``)."""
    name, defines, _ = texel_format(block.dtype, filter_exact)
    offset = 0
    if "BRICK_NORMALIZED" in defines:      # the brick's span fits 16 bits
        offset = int(block.min())
        tex = texture3d(ctx, (block.astype(np.int32) - offset).astype(np.uint16), 1, name, linear=True)
    elif defines:     # nearest: an integer texture is incomplete with a linear filter
        tex = texture3d(ctx, block, 1, name, linear=False)
    else:
        tex = texture3d(ctx, block.astype(np.float32), 1, "f4", linear=True)
    return tex, float(offset)


def brick_textures(renderer, volume):
    """The volume's BrickTextures, kept for the 2 most recent volumes."""
    return renderer.resources.for_objects("brick_textures", volume,
                                          make=lambda: BrickTextures(renderer.ctx, volume, filter_is_exact(renderer)),
                                          capacity=2)


def brick_uniforms(volume, brick):
    """The brick pass's uniforms: its texture's placement and its owned and grown boxes
    (world units from the volume's lower corner, x, y, z)."""
    spacing = np.asarray(volume.spacing, np.float64)
    n_cells = np.maximum(volume.dims - 1, 1)
    origin = np.array([brick.samples[a][0] for a in (2, 1, 0)], np.float64)
    texels = np.array([brick.samples[a][1] - brick.samples[a][0] for a in (2, 1, 0)], np.float64)
    c0 = np.array([brick.cells[a][0] for a in (2, 1, 0)], np.float64)
    c1 = np.array([brick.cells[a][1] for a in (2, 1, 0)], np.float64)
    # shared faces: the same float32 number for both bricks
    own_lo = np.where(c0 > 0, (c0 * spacing).astype(np.float32), -OPEN)
    own_hi = np.where(c1 < n_cells, (c1 * spacing).astype(np.float32), OPEN)
    margin = 0.5 * spacing
    return {"u_brick_origin": tuple(origin), "u_brick_texels": tuple(texels),
            "u_own_lo": tuple(float(v) for v in own_lo), "u_own_hi": tuple(float(v) for v in own_hi),
            "u_pass_lo": tuple(c0 * spacing - margin), "u_pass_hi": tuple(c1 * spacing + margin)}


def brick_proxy(scene, brick, kind, view_proj, grow):
    """The brick's box grown by ``grow`` as the unit cube's model-view-projection (or the
    full-screen triangle's identity where the whole box's proxy is one)."""
    import pyrr
    if kind == "fullscreen":
        return view_proj
    spacing = np.asarray(scene.volume.spacing, np.float64)
    lo = np.array([brick.cells[a][0] for a in (2, 1, 0)], np.float64) * spacing - grow
    hi = np.array([brick.cells[a][1] for a in (2, 1, 0)], np.float64) * spacing + grow
    model = (pyrr.matrix44.create_from_scale(hi - lo, dtype=np.float64)
             @ pyrr.matrix44.create_from_translation(lo, dtype=np.float64))
    return model @ view_proj


def draw(renderer, plan, prog, textures, brick_size):
    """Ray cast the plan brick by brick with ``prog`` (compiled with BRICKED, its other
    textures and uniforms bound on units from 0); returns the framebuffer of the image."""
    ctx = renderer.ctx
    scene = plan.scene
    volume = scene.volume
    bricks = brick_layout(renderer, volume, brick_size, halo_for(scene))
    occupied = occupied_bricks(renderer, plan, bricks, brick_size)
    camera = scene.camera
    eye = np.asarray(camera.eye, np.float64) - volume.bounds[0]
    drawn = {b.index for b, o in zip(bricks, occupied) if o}
    subset = getattr(plan, "brick_subset", None)    # a partial image of these bricks only (frontends.distributed)
    if subset is not None:
        drawn &= subset
    order = [b for b in visibility_order(bricks, volume, eye, camera.forward, camera.is_ortho) if b.index in drawn]
    width, height = scene.target_size
    running = target_fbo(renderer, width, height, "f4", kind="bricks_running")
    scratch = target_fbo(renderer, width, height, "f4", kind="bricks_pass")
    running.use()
    running.clear(0.0, 0.0, 0.0, 0.0)
    kind, view_proj, grow = box_view(scene, grow_pixels(ctx))
    copy = renderer.programs.get("raycast/raycast.vert", "bricks/copy.frag")
    unit_volume, unit_running = len(textures), len(textures) + 1
    prog["t_volume"].value = unit_volume
    prog["t_accum"].value = unit_running
    copy["t_source"].value = unit_running
    pass_vao = proxy_vao(renderer, prog, kind)
    copy_vao = proxy_vao(renderer, copy, kind)
    ctx.disable(ctx.BLEND | ctx.DEPTH_TEST)
    cull_for_proxy(ctx, kind)
    textures_of = (brick_textures(renderer, volume) if plan.lazy is None
                   else lazy_textures(renderer, volume, plan.lazy.memory, filter_is_exact(renderer)))
    levels = getattr(plan, "brick_levels", None)   # bricks of several pyramid levels (brick_levels.BrickLevels)
    for brick in order:
        placement = brick_uniforms(volume, brick)
        if levels is None:
            tex, offset = textures_of.get(brick)
        else:
            tex, offset, placement = levels.get(renderer, brick, halo_for(scene), placement)
        tex.use(location=unit_volume)
        if "u_brick_offset" in prog:
            prog["u_brick_offset"].value = offset
        for name, value in placement.items():
            if name in prog:        # (u_brick_texels: not where the shader interpolates fetches)
                prog[name].value = value
        mvp = brick_proxy(scene, brick, kind, view_proj, grow).astype("f4").tobytes()
        prog["u_view_proj"].write(mvp)
        copy["u_view_proj"].write(mvp)
        # the pass reads the running image and writes its pixels to the scratch target ...
        running.color_attachments[0].use(location=unit_running)
        scratch.use()
        pass_vao.render()
        # ... which the same proxy copies back
        scratch.color_attachments[0].use(location=unit_running)
        running.use()
        copy_vao.render()
    ctx.disable(ctx.CULL_FACE)
    if levels is not None:
        levels.release()
    if scene.mode == "composite" and TARGETS[plan.target] == "f4":
        return running
    out = cleared_target(renderer, scene, plan.target)   # the running image in the plan's format ...
    last = copy
    if scene.mode != "composite":                       # ... or the state it holds, classified
        last = renderer.programs.get("raycast/raycast.vert", "bricks/resolve.frag",
                                     {"MODE_AVERAGE": int(scene.mode == "average")})
        bind(last, {"t_tf": textures["t_tf"]}, tf_uniforms(plan.lut, scene.tf), first_unit=unit_volume)
        last["t_source"].value = unit_running
    running.color_attachments[0].use(location=unit_running)
    last["u_view_proj"].write(np.eye(4, dtype="f4").tobytes())
    proxy_vao(renderer, last, "fullscreen").render()
    return out


# ----------------------------------------------------------------------------- a LazyVolume's bricks
# (plans: lazy_bricks.plan_lazy)

def summary_for(volume, brick_size):
    """The volume's summary for bricks of ``brick_size`` cells: its last one where that
    has this brick size (any halo of at least 1 sample), else made (or read from the
    cache folder) with the default halo."""
    summary = getattr(volume, "_summary", None)
    if summary is not None and summary.brick == (brick_size,) * 3 and summary.halo >= 1:
        return summary
    return brick_summary(volume, brick_size)


def lazy_occupied(volume, bricks, brick_size, lut, skip_empty):
    """Per brick of the partition, whether it can show anything, from the summary alone
    (all True without skipping). A brick whose range is NaN (no finite sample) counts as
    occupied, so that its read names the problem."""
    if not skip_empty:
        return np.ones(len(bricks), bool)
    summary = summary_for(volume, brick_size)
    lo = np.array([summary.lo[b.index] for b in bricks], np.float64)
    hi = np.array([summary.hi[b.index] for b in bricks], np.float64)
    unknown = np.isnan(lo) | np.isnan(hi)
    occupied = np.ones(len(bricks), bool)
    if (~unknown).any():
        occupied[~unknown] = brick_occupancy((lo[~unknown], hi[~unknown]), lut)
    return occupied


CHUNK_SHARE = 8      # store chunks are cached (not bricks) where one is at most this share of the budget


class LazyBrickTextures:
    """A LazyVolume's brick textures for ``draw``: each brick's samples from the
    BrickCache, one texture on the GPU at a time. Where the store is chunked and a chunk
    is at most 1/CHUNK_SHARE of the budget, the cache holds the store's chunks and a
    brick is put together from them (``LazyVolume.read_chunked``): a brick with its halo
    meets up to 27 chunks, and neighbouring bricks then share their reads; else it holds
    the bricks. ``bricks_read`` counts the bricks whose samples were asked for (the
    cache's ``misses`` and ``bytes_loaded`` count what came from the store)."""

    def __init__(self, ctx, volume, filter_exact, cache):
        self.ctx = ctx
        self.volume = volume
        self.filter_exact = filter_exact
        self.cache = cache
        self.current = None
        self.bricks_read = 0
        chunks = getattr(volume, "chunks", None)
        self.by_chunks = (chunks is not None and hasattr(volume, "read_chunked")
                          and int(np.prod(chunks)) * volume.dtype.itemsize * CHUNK_SHARE <= cache.budget)

    def read(self, brick):
        (z0, z1), (y0, y1), (x0, x1) = brick.samples
        try:
            if self.by_chunks:
                block = self.volume.read_chunked(z0, z1, y0, y1, x0, x1, self.cache)
            else:
                block = read_block(self.volume, z0, z1, y0, y1, x0, x1)
        except VolumeReadError as e:
            e.brick = brick     # whose read failed (its block may be one chunk of it); frontends.distributed names it
            raise
        if block.dtype.kind == "f" and not np.isfinite(block).all():
            raise ValueError(f"bricked ray casting does not yet take non-finite samples: brick {brick.index} "
                             f"(samples z {z0}:{z1}, y {y0}:{y1}, x {x0}:{x1}) of {self.volume.describe()} has some")
        return block

    def get(self, brick):
        """(texture, offset) of ``brick``, as BrickTextures.get; the previous one is released."""
        self.release()
        self.bricks_read += 1
        if self.by_chunks:
            block = self.read(brick)
        else:
            key = tuple(v for pair in brick.samples for v in pair)
            block = self.cache.get(self.volume, key, lambda: self.read(brick))
        self.current = upload_block(self.ctx, block, self.filter_exact)
        return self.current

    def release(self):
        if self.current is not None:
            self.current[0].release()
            self.current = None


def lazy_textures(renderer, volume, memory, filter_exact):
    """The volume's LazyBrickTextures with a BrickCache of ``memory`` bytes, kept for the
    2 most recent (volume, budget) pairs."""
    return renderer.resources.for_objects(
        "lazy_brick_textures", volume, int(memory),
        make=lambda: LazyBrickTextures(renderer.ctx, volume, filter_exact, BrickCache(int(memory))), capacity=2)
