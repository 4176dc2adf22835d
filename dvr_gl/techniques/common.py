"""What the techniques share: option checks, the uniforms every shader reads (camera,
volume, transfer function), texture binding, and the eye-space projection of proxy
geometry. Positions on the GPU are relative to the volume box's lower corner. The GPU
objects they keep between frames are made in ``gpu``."""

from __future__ import annotations

import math

import numpy as np

from ..model.camera import MAX_LIGHTS
from ..model.scene import OPTICAL_MODELS, Scene
from .gpu import cull_for_proxy, cell_valid_texture, gradient_texture, preintegration_texture, proxy_vao, target_fbo, tf2d_texture

TARGETS = {"rgba32f": "f4", "rgba16f": "f2", "rgba8": "f1"}


SHADING_TECHNIQUES = ("raycast", "slice3d", "slice2d")   # those with every sample term and optical model
LIGHTING_TECHNIQUES = SHADING_TECHNIQUES + ("tetra", "particles", "splat")   # those that light composite samples
GRADIENTS = ("on_the_fly", "texture")
CLIPPING_TECHNIQUES = ("raycast", "tetra", "slice2d", "slice3d", "particles", "splat")   # those that clip to Scene.clip_planes and crop_box
LAYER_TECHNIQUES = ("raycast",)   # those that render Scene.layers (several volumes, channels, labels)
GEOMETRY_TECHNIQUES = ("raycast", "particles", "slice2d", "slice3d", "tetra", "splat")   # those that end rays at Scene.geometry (opaque surfaces)


def check_scene(scene, technique, modes=None, data="volume"):
    """The scene is a Scene of a data kind the technique renders (``data``: "volume" for a
    grid, "mesh" for a TetMesh, or a tuple of both) in one of its modes, lit only where
    the technique lights samples."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a dvr_gl.Scene, got {type(scene).__name__}")
    if scene.illustration and technique not in SHADING_TECHNIQUES:
        if technique == "tetra" and "depth_cue" in scene.illustration and scene.optical_model == "emission":
            raise ValueError("tetra integrates depth_cue along each cell's segment for emission-absorption and "
                             "absorption; with optical_model 'emission' render it with raycast, slice3d or slice2d")
        if technique != "tetra":
            raise ValueError(f"{technique} has no illustration terms yet: they are rendered by "
                             f"{', '.join(SHADING_TECHNIQUES)} and tetra")
    if scene.tf_2d is not None and technique not in SHADING_TECHNIQUES:
        raise ValueError(f"{technique} classifies by value alone; a TransferFunction2D (value and gradient "
                         f"magnitude) is rendered by {', '.join(SHADING_TECHNIQUES)}")
    if scene.shading and technique not in LIGHTING_TECHNIQUES:
        raise ValueError(f"{technique} does not light samples yet: shading=True is rendered by "
                         f"{', '.join(LIGHTING_TECHNIQUES)}")
    if scene.optical_model == "sabella" and technique != "raycast":
        raise ValueError(f"{technique} composites segments in GL's blending, which cannot follow a ray's peak: "
                         f"optical_model 'sabella' is rendered by raycast")
    cell_models = ("absorption", "emission")     # tetra: each defined in closed form for a linear cell
    if scene.optical_model != "emission_absorption" and technique not in SHADING_TECHNIQUES \
            and not (technique == "tetra" and scene.optical_model in cell_models):
        raise ValueError(f"{technique} renders optical_model 'emission_absorption' only; "
                         f"{scene.optical_model!r} is rendered by {', '.join(SHADING_TECHNIQUES)}"
                         + (" (tetra: absorption and emission too)" if technique != "tetra" else ""))
    if scene.is_lazy and technique != "raycast":
        from .lazy_bricks import LazyVolumeTechniqueError     # (lazy_bricks imports this module)
        raise LazyVolumeTechniqueError(technique)
    kinds = (data,) if isinstance(data, str) else tuple(data)      # a technique may take both
    if scene.is_mesh and "mesh" not in kinds:
        raise ValueError(f"{technique} renders a Volume (a grid); this scene holds a TetMesh: "
                         "use technique 'tetra', 'particles' or 'splat'")
    if not scene.is_mesh and "volume" not in kinds:
        raise ValueError(f"{technique} renders a TetMesh; this scene holds a Volume: "
                         "use raycast, slice2d, slice3d, particles or splat")
    if modes is not None and scene.mode not in modes:
        raise ValueError(f"{technique} renders mode {' or '.join(repr(m) for m in modes)}, "
                         f"got mode {scene.mode!r}")
    if scene.geometry and technique not in GEOMETRY_TECHNIQUES:
        raise ValueError(f"{technique} does not draw geometry yet: a scene with geometry is rendered by "
                         f"{', '.join(GEOMETRY_TECHNIQUES) or 'no technique yet'}")
    if scene.layers and technique not in LAYER_TECHNIQUES:
        raise ValueError(f"{technique} renders one volume; a scene with layers (several volumes, channels or "
                         f"label volumes) is rendered by {', '.join(LAYER_TECHNIQUES)}")
    if scene.clips and technique not in CLIPPING_TECHNIQUES:
        raise ValueError(f"{technique} does not clip yet: clip_planes and crop_box are rendered by "
                         f"{', '.join(CLIPPING_TECHNIQUES)}")


def check_target(target):
    if target not in TARGETS:
        raise ValueError(f"target must be one of {', '.join(TARGETS)}, got {target!r}")
    return target


def check_flag(name, value):
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_step(step, volume, name="step"):
    """A positive, finite distance in world units, not absurdly small for the box."""
    if isinstance(step, bool) or not isinstance(step, (int, float, np.floating, np.integer)):
        raise TypeError(f"{name} must be a number (world units), got {step!r}")
    step = float(step)
    if not math.isfinite(step) or step <= 0:
        raise ValueError(f"{name} must be positive and finite, got {step!r}")
    diagonal = float(np.linalg.norm(volume.extent))
    if diagonal / step > 1e6:
        raise ValueError(f"{name} {step!r} is absurdly small for a box {diagonal:.4g} across "
                         f"(over 1e6 samples per ray)")
    return step


def camera_uniforms(scene):
    """Uniforms of shaders/common/camera_ray.glsl."""
    cam = scene.camera
    lo, _ = scene.volume.bounds
    sx, sy = cam.screen_scale(scene.width, scene.height)
    return {"u_viewport": (scene.width, scene.height), "u_tile_origin": scene.tile_origin,
            "u_eye": tuple(cam.eye - lo),
            "u_right": tuple(cam.right), "u_up": tuple(cam.true_up), "u_forward": tuple(cam.forward),
            "u_screen": (sx, sy)}


def volume_uniforms(volume):
    """Uniforms of shaders/common/sampling.glsl and the box."""
    return {"u_extent": tuple(volume.extent), "u_dims": tuple(float(n) for n in volume.dims),
            "u_spacing": tuple(volume.spacing)}


def clip_defines(scene):
    """Switches of shaders/common/clip.glsl for the scene's clip planes and crop box."""
    defines = {}
    if scene.clip_planes:
        defines["N_CLIP_PLANES"] = len(scene.clip_planes)
    if scene.crop_box is not None:
        defines["CROP_BOX"] = 1
    return defines


def clip_uniforms(scene):
    """Uniforms of shaders/common/clip.glsl, in box coordinates (float32 bytes for the
    plane array, which ``bind`` writes whole)."""
    planes, crop = scene.clip_in_box()
    uniforms = {}
    if planes:
        uniforms["u_clip_planes"] = np.array([(*n, d) for n, d in planes], np.float32).tobytes()
    if crop is not None:
        uniforms["u_crop_lo"], uniforms["u_crop_hi"] = tuple(crop[0]), tuple(crop[1])
    return uniforms


def tf_uniforms(lut, tf):
    """Uniforms of shaders/common/classification.glsl and opacity correction."""
    return {"u_tf_lo": lut.lo, "u_tf_scale": lut.scale, "u_tf_size": lut.size,
            "u_inv_unit": 1.0 / tf.unit_distance}


def preintegration_applies(scene):
    """Whether the scene's segments can be pre-integrated (``preintegration_table``
    says why not where they cannot)."""
    return (scene.mode == "composite" and scene.optical_model == "emission_absorption" and scene.tf_2d is None
            and not {"boundary", "silhouette"} & set(scene.illustration))


def preintegration_table(scene, step, tables, size=None):
    """The scene's pre-integrated table for segments ``step`` long (built once per TF,
    value range, step and size; ``size`` nodes, by default ``preintegration.TABLE_SIZE``)."""
    from ..model.preintegration import TABLE_SIZE, ZERO_LENGTH, build_table
    size = TABLE_SIZE if size is None else size
    if scene.optical_model != "emission_absorption":
        raise ValueError(f"preintegrate tables emission-absorption segments; optical_model "
                         f"{scene.optical_model!r} is sampled at segment midpoints (preintegrate=False)")
    if scene.tf_2d is not None:
        raise ValueError("preintegrate tables segments by the values at their ends; a TransferFunction2D "
                         "also needs the gradient along them (preintegrate=False)")
    scaled = [name for name in ("boundary", "silhouette") if name in scene.illustration]
    if scaled:
        raise ValueError(f"preintegrate tables the TF's own extinction; {' and '.join(scaled)} enhancement "
                         f"scales it per sample (preintegrate=False)")
    volume, tf = scene.volume, scene.tf
    # the zero-length colour does not depend on the length: one per TF for all steps
    zero = tables.get(f"preintegration_zero:{size}", volume, tf, make=lambda v, t: build_table(
        t, v.data_range, ZERO_LENGTH * v.min_spacing, size=size, zero=False))
    return tables.get(f"preintegration:{size}", volume, tf, step,
                      make=lambda v, t, length: build_table(t, v.data_range, length, size=size, zero=zero))


def point_shading_defines(scene):
    """The lighting defines of the point primitives (particles, splats), whose gradients
    come with each point: SHADING, and LIGHTS beyond the default headlight."""
    if not scene.shading:
        return {}
    return {"SHADING": 1, **({} if scene.headlight_only else {"LIGHTS": 1})}


def shading_defines(scene, gradients):
    """The defines of shaders/common/shading.glsl (and the optical model of
    classification.glsl) a scene needs: none for plain emission-absorption samples.
    ``gradients`` is "on_the_fly" (six field lookups per sample that needs one) or
    "texture" (one lookup in a gradient texture made once per volume: the same gradient,
    see ``model.field.sample_gradients``, for three times the volume's memory)."""
    if gradients not in GRADIENTS:
        raise ValueError(f"gradients must be one of {', '.join(GRADIENTS)}, got {gradients!r}")
    defines = {}
    composite = scene.mode == "composite"
    if composite and (scene.shading or scene.illustration or scene.tf_2d is not None):
        defines["SAMPLE_TERMS"] = 1
    if scene.tf_2d is not None:
        defines["TF_2D"] = 1
    if scene.shading and composite:
        defines["SHADING"] = 1
    for name in scene.illustration:
        defines[name.upper()] = 1
    if scene.reads_gradient and gradients == "texture":
        defines["GRADIENT_TEXTURE"] = 1
    if scene.shaded and not scene.headlight_only:
        defines["LIGHTS"] = 1
    model = OPTICAL_MODELS.index(scene.optical_model)
    if model:
        defines["OPTICAL_MODEL"] = model   # the numbers of shaders/common/classification.glsl
    return defines


def illustration_uniforms(renderer, scene):
    """Uniforms of the illustration terms in shaders/common/shading.glsl."""
    from ..model.field import depth_range, gradient_max
    terms = scene.illustration
    out = {}
    if "tone" in terms:
        light = scene.lights[0].world_direction(scene.camera)
        out.update(u_tone_warm=terms["tone"][0], u_tone_cool=terms["tone"][1],
                   u_tone_light=(0.0, 0.0, 0.0) if light is None else tuple(light))
    if "depth_cue" in terms:
        near, far = depth_range(scene)
        out["u_depth_cue"] = (near, far, terms["depth_cue"][0])
    if "boundary" in terms:
        volume = scene.volume
        out["u_boundary"] = terms["boundary"]
        out["u_gradient_max"] = renderer.tables.get("gradient_max", volume, make=gradient_max)
    if "silhouette" in terms:
        out["u_silhouette"] = terms["silhouette"]
    return out


def add_optional_inputs(renderer, plan, textures, uniforms):
    """Add what a plan's optional features read: the pre-integration table, the
    masked-cell texture and the lighting."""
    scene = plan.scene
    if getattr(plan, "preint", None) is not None:
        textures["t_preint"] = preintegration_texture(renderer, plan.preint, getattr(plan, "preint_fine", None))
        uniforms.update(plan.preint.uniforms())
    if scene.volume.has_nonfinite:
        textures["t_cell_valid"] = cell_valid_texture(renderer, scene.volume)
    if scene.shaded or scene.illustration or scene.tf_2d is not None:
        uniforms.update(sample_term_uniforms(renderer, scene, plan.defines))
        if plan.defines.get("GRADIENT_TEXTURE"):
            textures["t_gradient"] = gradient_texture(renderer, scene.volume)
    if scene.tf_2d is not None:
        textures["t_tf2d"] = tf2d_texture(renderer, scene.tf_2d)
        uniforms.update(tf2d_uniforms(scene.tf_2d))


def tf2d_uniforms(tf_2d):
    """Uniforms of ``lookupTF2D`` (shaders/common/classification.glsl)."""
    n_g, n_v, _ = tf_2d.table.shape
    (v0, v1), (g0, g1) = tf_2d.value_range, tf_2d.gradient_range
    return {"u_tf2d_lo": (v0, g0), "u_tf2d_scale": ((n_v - 1) / (v1 - v0), (n_g - 1) / (g1 - g0)),
            "u_tf2d_size": (n_v, n_g)}


def sample_term_uniforms(renderer, scene, defines):
    """Uniforms of shaders/common/shading.glsl for a lit or illustrated scene: the
    gradient threshold, the lights and the illustration terms."""
    from ..model.field import gradient_epsilon
    out = {"u_phong": scene.phong, "u_gradient_epsilon": gradient_epsilon(scene.volume),
           **illustration_uniforms(renderer, scene)}
    if defines.get("LIGHTS"):
        out.update(light_uniforms(scene))
    return out


def light_uniforms(scene):
    """The scene's lights as the uniforms of ``phongTerms`` (shaders/common/shading.glsl):
    their count and, per light, (world direction towards it, or 0 for a headlight;
    intensity)."""
    lights = np.zeros((MAX_LIGHTS, 4), np.float32)
    for row, light in zip(lights, scene.lights):
        direction = light.world_direction(scene.camera)
        row[:3] = 0.0 if direction is None else direction
        row[3] = light.intensity
    return {"u_light_count": len(scene.lights), "u_lights": [tuple(row) for row in lights.tolist()]}


def bind(prog, textures, uniforms, first_unit=0):
    """Bind ``textures`` (sampler name -> texture) to consecutive units from
    ``first_unit`` (two programs drawn in turn take units of their own) and set the
    uniforms the program has (the compiler drops those a variant does not use)."""
    for unit, (name, tex) in enumerate(textures.items(), start=first_unit):
        tex.use(location=unit)
        member = prog.get(name, None)       # (not `name in prog`: moderngl's walks every member)
        if member is not None:
            member.value = unit
    for name, value in uniforms.items():
        member = prog.get(name, None)
        if member is not None:
            if isinstance(value, bytes):       # a uniform array, written whole
                member.write(value)
            else:
                member.value = value


def eye_view_projection(scene, near, far):
    """View-projection matrix (float64, row-vector convention as pyrr writes it) for
    box-relative positions, perspective or orthographic as the camera is, with the given
    near and far distances along the view direction."""
    import pyrr
    cam = scene.camera
    lo, _ = scene.volume.bounds
    eye = cam.eye - lo
    hx, hy = cam.screen_scale(scene.width, scene.height)
    if cam.is_ortho:
        proj = pyrr.matrix44.create_orthogonal_projection(-hx, hx, -hy, hy, near, far, dtype=np.float64)
    else:
        proj = pyrr.matrix44.create_perspective_projection(cam.fov, scene.width / scene.height, near, far,
                                                           dtype=np.float64)
    view = pyrr.matrix44.create_look_at(eye, eye + cam.forward, cam.true_up, dtype=np.float64)
    return view @ proj @ tile_matrix(scene)


def tile_matrix(scene):
    """Clip-space transform from the whole image to the scene's tile (identity without
    one): x' = (x - c w) * s per axis, c the tile's centre and s the image over the tile
    size (row-vector convention, like pyrr)."""
    m = np.eye(4)
    if scene.tile is None:
        return m
    x, y, w, h = scene.tile
    for axis, (start, size, full) in enumerate(((x, w, scene.width), (y, h, scene.height))):
        scale = full / size
        centre = (2.0 * start + size) / full - 1.0
        m[axis, axis] = scale
        m[3, axis] = -centre * scale
    return m


def cleared_target(renderer, scene, target):
    """The renderer's float target for this image size and format, bound and cleared to
    transparent black: where every technique draws."""
    fbo = target_fbo(renderer, *scene.target_size, TARGETS[target])
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 0.0)
    return fbo


def knot_uniforms(prog, knots, capacity):
    """The transfer function's knots (a SegmentKnots) as the uniform arrays of
    shaders/common/linear_segment.glsl, padded to the program's KNOT_CAPACITY."""
    rows = knots.texture_rows()
    for name, row in (("u_knot_color", rows[0]), ("u_knot_opacity", rows[1])):
        padded = np.zeros((capacity, 4), np.float32)
        padded[:len(row)] = row
        if name in prog:
            prog[name].write(padded.tobytes())


def data_projection(scene, near=None):
    """View-projection of positions relative to the data's lower corner, for techniques
    that draw without a depth test or with their own depths: near at ``near_plane``
    (perspective; or ``near`` when given) or at the rays' start plane (orthographic), far
    behind every point of the data's bounding box."""
    cam = scene.camera
    lo, _ = scene.volume.bounds
    extent = scene.volume.extent
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]) * extent
    depth = (corners - (cam.eye - lo)) @ cam.forward
    diag = float(np.linalg.norm(extent)) or 1.0
    far = max(float(depth.max()), 0.0) * 1.01 + 1e-3 * diag
    if near is None:
        near = 0.0 if cam.is_ortho else near_plane(scene, far)
    return eye_view_projection(scene, near, far)


#: the nearest a perspective near plane may be, as a fraction of the far plane: float32
#: clip depths keep about 2 near / depth of resolution below 1, so a near plane much
#: closer than 1e-7 far leaves every vertex's z and w equal to rounding, and GL's far
#: clip drops geometry at random (a 9-unit box seen from 119 units lost slice pieces,
#: particles and splats with a near plane of 1e-6 of its diagonal)
NEAR_FRACTION = 1e-5


def near_plane(scene, far):
    """The perspective near plane for drawing the data's geometry: a quarter of the box's
    nearest depth when all of the box is in front of the eye (nothing of the data is
    nearer), else ``NEAR_FRACTION`` of ``far``."""
    dmin, _ = box_depth_range(scene)
    diag = float(np.linalg.norm(scene.volume.extent)) or 1.0
    if dmin > 0:
        return 0.25 * dmin
    return max(NEAR_FRACTION * far, 1e-6 * diag)


INFLATE = 1e-3  # slice and sheet polygons are cut from the box grown by this fraction of its diagonal


def inflated_corners(volume):
    """The corners of the volume's box grown by ``INFLATE`` of its diagonal on every side:
    the slicing techniques' polygons cover every pixel whose ray meets a plane inside the
    box, and their fragments decide coverage themselves."""
    from .proxy import box_corners
    margin = INFLATE * float(np.linalg.norm(volume.extent))
    return box_corners(np.full(3, -margin), volume.extent + margin)


def plane_triangles(scene, far_depth, step, count):
    """The planes perpendicular to the view at depths ``far_depth - k * step`` (k <
    ``count``) cut against the slightly grown box, as fan triangles drawn plane by plane:
    (positions (n, 3) float32, each vertex's plane index (n,) int32, and per plane its
    first vertex and vertex count (count, 2))."""
    from . import proxy
    cam = scene.camera
    offsets = proxy.plane_offsets(cam.forward, cam.eye - scene.volume.bounds[0], far_depth, step, count)
    vertices, counts = proxy.plane_polygons(inflated_corners(scene.volume), cam.forward, offsets)
    positions, planes = proxy.fan_triangles(vertices, counts)
    per_plane = 3 * np.maximum(counts - 2, 0)
    starts = np.concatenate([[0], np.cumsum(per_plane)[:-1]])
    return positions, planes, np.stack([starts, per_plane], axis=1)


def plane_projection(plan):
    """View-projection whose near and far planes keep every one of a plan's planes (depths
    ``plan.far_depth - k * plan.step``, k < ``plan.count``) well inside them, for geometry
    drawn on those planes (a tiny near plane would leave no depth precision at the far
    ones)."""
    nearest = plan.far_depth - (plan.count - 1) * plan.step
    if plan.scene.camera.is_ortho:
        return eye_view_projection(plan.scene, 0.5 * nearest, plan.far_depth + plan.step)
    return eye_view_projection(plan.scene, 0.5 * nearest, 2.0 * plan.far_depth + plan.step)


def box_depth_range(scene):
    """Smallest and largest depth (distance along the view direction from the eye) of
    the volume box's corners."""
    cam = scene.camera
    lo, _ = scene.volume.bounds
    extent = scene.volume.extent
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]) * extent
    depth = (corners - (cam.eye - lo)) @ cam.forward
    return float(depth.min()), float(depth.max())



def box_proxy(scene, grow_pixels=0.0):
    """The geometry that makes one fragment per pixel the volume box covers:
    ("box", model-view-projection of the unit cube's back faces) or, with the eye inside
    or nearly on the box, ("fullscreen", identity) for one full-screen triangle.
    ``grow_pixels`` grows the box on every side by at least that many pixels of the image
    (measured at the box's farthest depth), so that rasterisation, which snaps vertices
    to a grid (``grow_pixels(ctx)``), never drops a pixel whose ray meets the box: the
    shaders decide coverage themselves."""
    import pyrr
    kind, view_proj, grow = box_view(scene, grow_pixels)
    if kind == "fullscreen":
        return kind, view_proj
    extent = scene.volume.extent
    model = (pyrr.matrix44.create_from_scale(extent + 2 * grow, dtype=np.float64)
             @ pyrr.matrix44.create_from_translation(np.full(3, -grow), dtype=np.float64))
    return "box", model @ view_proj


def box_view(scene, grow_pixels=0.0, pad=0.0):
    """(kind, view-projection, grow) behind ``box_proxy``: for "box", the view-projection
    of box-relative positions whose near and far planes clip nothing within
    ``max(grow, pad)`` world units of the box (``grow``: ``grow_pixels`` pixels at its
    farthest depth); "fullscreen" (identity, grow 0) with the eye inside or nearly on
    the box so grown."""
    cam = scene.camera
    lo, _ = scene.volume.bounds
    extent = scene.volume.extent
    eye = cam.eye - lo
    dmin, dmax = box_depth_range(scene)
    hx, hy = cam.screen_scale(scene.width, scene.height)
    pixel = 2.0 * hy / scene.height * (1.0 if cam.is_ortho else max(dmax, 0.0))
    grow = grow_pixels * pixel
    reach = max(grow, pad)
    margin = 1e-3 * float(np.linalg.norm(extent)) + 2.0 * reach
    if cam.is_ortho:
        near, far = dmin - margin, dmax + margin
    else:
        gap = np.maximum(np.maximum(-eye, eye - extent), 0.0)
        distance = float(np.linalg.norm(gap))
        if distance < margin:
            return "fullscreen", np.eye(4), 0.0
        # Every point within `reach` of the box is at least `distance - reach * sqrt(3)`
        # from the eye and, where it is in view, within the view's diagonal half-angle of
        # the axis, so this near plane clips none of them.
        near = 0.5 * (distance - 1.75 * reach) / math.sqrt(1.0 + hx * hx + hy * hy)
        far = dmax * 1.01 + margin
    return "box", eye_view_projection(scene, near, far), grow


def grow_pixels(ctx):
    """How far proxies whose fragments decide coverage themselves are grown, in pixels:
    twice the rasteriser's vertex snapping, 2^-GL_SUBPIXEL_BITS (GL promises at least 4
    bits; llvmpipe has 8)."""
    bits = ctx.info.get("GL_SUBPIXEL_BITS") or 4
    return 2.0 ** (1 - min(int(bits), 12))


def draw_box_instances(renderer, prog, scene, instances):
    """Draw ``shaders/common/box_instances.vert`` geometry: the slightly grown box's back
    faces (front faces culled), or the full-screen triangle, ``instances`` times."""
    ctx = renderer.ctx
    kind, view_proj = box_proxy(scene, grow_pixels=grow_pixels(ctx))
    prog["u_view_proj"].write(view_proj.astype("f4").tobytes())
    if kind == "box":
        ctx.enable(ctx.CULL_FACE)
        ctx.cull_face = "front"
    try:
        proxy_vao(renderer, prog, kind).render(instances=instances)
    finally:
        ctx.disable(ctx.CULL_FACE)


class SizedTarget:
    """A float32 framebuffer (colour textures of the given component counts, RGBA by
    default, and a depth attachment when ``depth``) for a technique's own passes, remade
    only when the image size changes."""

    def __init__(self, ctx, depth=False, components=(4,)):
        self.ctx = ctx
        self.depth = depth
        self.components = tuple(components)
        self.size = None
        self.fbo = None

    def get(self, width, height):
        if self.size != (width, height):
            self.release()
            depth = self.ctx.depth_texture((width, height)) if self.depth else None
            colors = [self.ctx.texture((width, height), n, dtype="f4") for n in self.components]
            self.fbo = self.ctx.framebuffer(colors, depth)
            self.size = (width, height)
        return self.fbo

    def release(self):
        if self.fbo is not None:
            for tex in self.fbo.color_attachments:
                tex.release()
            if self.fbo.depth_attachment is not None:
                self.fbo.depth_attachment.release()
            self.fbo.release()
            self.fbo = None


class RepeatedIndices:
    """An index buffer that repeats ``pattern`` (indices into a group of ``stride``
    vertices) for groups 0, 1, ...: index ``stride * k + p``, grown (never shrunk) as
    needed, with one attribute-less vertex array per program. Vertex shaders place their
    vertices by ``gl_VertexID``; indexing shades each vertex once (GL reuses a vertex
    repeated within a draw's index window)."""

    def __init__(self, ctx, pattern, stride=4, minimum=1):
        self.ctx = ctx
        self.pattern = np.asarray(pattern, np.int64).ravel()
        self.stride = int(stride)
        self.minimum = int(minimum)
        self.groups = 0
        self.ibo = None
        self.vaos = {}

    def vao(self, prog, groups):
        """The vertex array of ``prog`` over at least ``groups`` groups."""
        if groups > self.groups:
            self.release()
            self.groups = max(int(groups), 2 * self.groups, self.minimum)
            index = self.stride * np.arange(self.groups, dtype=np.int64)[:, None] + self.pattern
            self.ibo = self.ctx.buffer(index.astype(np.int32).tobytes())
        vao = self.vaos.get(prog.glo)
        if vao is None:
            vao = self.vaos[prog.glo] = self.ctx.vertex_array(prog, [], index_buffer=self.ibo, index_element_size=4)
        return vao

    def release(self):
        for vao in self.vaos.values():
            vao.release()
        self.vaos.clear()
        if self.ibo is not None:
            self.ibo.release()
            self.ibo = None


def draw_ray_proxy(renderer, prog, scene, target, kind, view_proj, surfaces=None):
    """Run ``prog`` once per pixel of the rays into a cleared ``target``: over the back
    faces of the proxy ``kind`` (front faces culled, so one fragment a pixel even with the
    eye close to the box) or a full-screen triangle; with ``surfaces`` every pixel, since
    a surface outside the data shows too. Returns the framebuffer."""
    ctx = renderer.ctx
    if surfaces is not None:
        kind, view_proj = "fullscreen", np.eye(4)
    prog["u_view_proj"].write(view_proj.astype("f4").tobytes())
    vao = proxy_vao(renderer, prog, kind)
    fbo = cleared_target(renderer, scene, target)
    ctx.disable(ctx.BLEND | ctx.DEPTH_TEST)
    cull_for_proxy(ctx, kind)
    vao.render()
    ctx.disable(ctx.CULL_FACE)
    return fbo
