"""The scene: plain, validated data that knows nothing of GL. ``Scene`` holds a volume
(or mesh), a transfer function, a camera, the image size, the mode and the extras; the
classes it is made of live beside it (volume, mesh, transfer_function, camera) and are
imported here too.

Every class here checks its input once, at construction, and raises ``TypeError`` or
``ValueError`` with a message naming the parameter and the offending value. Objects are
immutable afterwards (arrays are stored read-only), so renderers may cache GPU resources
by object identity.

Conventions (see docs/contract.md, the image contract): data is ``(nz, ny, nx)``, x fastest;
spacing and origin are given in x, y, z order; sample ``data[k, j, i]`` sits at
``origin + (i*sx, j*sy, k*sz)``; the field is the trilinear interpolant of the samples on
the closed box from the first to the last sample.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from .camera import HEADLIGHT, MAX_LIGHTS, Camera, Light, anatomical_frame, default_camera
from .checks import _finite_number
from .clipping import check_clip_planes, check_crop_box, plane_offsets
from .geometry import check_geometry
from .layers import Extent, Layer, check_layers, union_bounds
from .mesh import TetMesh
from .transfer_function import TransferFunction, TransferFunction2D
from .volume import Volume

__all__ = ["Camera", "Light", "Scene", "TetMesh", "TransferFunction", "TransferFunction2D", "Volume",
           "anatomical_frame", "default_camera", "MODES", "SHADED_MODES", "OPTICAL_MODELS", "ILLUSTRATION_TERMS",
           "MAX_IMAGE_SIDE", "MAX_LIGHTS"]

MODES = ("composite", "mip", "minip", "average", "isosurface")
SHADED_MODES = ("composite", "isosurface")
# composite mode's optical models (Max 1995): emission and absorption (the contract's
# default), absorption only (C = 0, A = 1 - T), emission only (C = integral c tau dt, A = 0);
# and Sabella's (1988) colouring: brightness A = 1 - T, hue from the TF colour at the ray's
# peak value, saturation fading with the peak's depth
OPTICAL_MODELS = ("emission_absorption", "absorption", "emission", "sabella")
# The volume-illustration terms of Ebert and Rheingans (2000) a lit or unlit composite
# scene switches on by name, with their default parameters (see Scene):
ILLUSTRATION_TERMS = {
    "boundary": (0.2, 0.8, 1.0),                      # k_gc, k_gs, k_ge
    "silhouette": (0.2, 0.8, 1.0),                    # k_sc, k_ss, k_se
    "tone": ((0.4, 0.4, 0.0), (0.0, 0.0, 0.4)),       # warm, cool (RGB)
    "depth_cue": (0.6,),                              # strength
}
GRADIENT_TERMS = ("boundary", "silhouette", "tone")   # the terms that read the gradient


def _illustration(value):
    """{term: parameters} from None, a term name, an iterable of names or a dict."""
    if value is None:
        return {}
    if isinstance(value, str):
        value = [value]
    items = value.items() if isinstance(value, dict) else ((name, None) for name in value)
    out = {}
    for name, params in items:
        if name not in ILLUSTRATION_TERMS:
            raise ValueError(f"illustration terms are {', '.join(ILLUSTRATION_TERMS)}, got {name!r}")
        default = ILLUSTRATION_TERMS[name]
        params = default if params is None else params
        if name == "tone":
            try:
                warm, cool = (tuple(float(v) for v in rgb) for rgb in params)
            except (TypeError, ValueError):
                raise ValueError(f"tone must be (warm RGB, cool RGB), got {params!r}") from None
            if len(warm) != 3 or len(cool) != 3 or not all(math.isfinite(v) and v >= 0 for v in warm + cool):
                raise ValueError(f"tone must be two RGB triples of finite non-negative numbers, got {params!r}")
            out[name] = (warm, cool)
            continue
        try:
            params = tuple(float(v) for v in (params if np.ndim(params) else [params]))
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be {len(default)} numbers, got {params!r}") from None
        if len(params) != len(default) or not all(math.isfinite(v) for v in params):
            raise ValueError(f"{name} must be {len(default)} finite numbers, got {params!r}")
        if name in ("boundary", "silhouette") and not (params[0] > 0 and params[1] >= 0 and params[2] > 0):
            raise ValueError(f"{name} needs a positive constant term (it keeps opaque material opaque), a "
                             f"non-negative scale and a positive exponent, got {params!r}")
        if name == "depth_cue" and not 0 <= params[0] <= 1:
            raise ValueError(f"depth_cue strength must be in [0, 1], got {params[0]!r}")
        out[name] = params
    return out  # modes a lit sample has a meaning in (isosurface always is)
MAX_IMAGE_SIDE = 65536  # larger than one GL target: rendered in tiles


class Scene:
    """What to render: a volume (a ``Volume`` grid or a ``TetMesh``), its classification,
    a camera, an image size and a mode.

    ``clip_planes``, up to six ``(point, normal)`` pairs in world units, each keep the
    side of their plane the normal points to; ``crop_box``, a ``(lower, upper)`` pair of
    world corners, keeps what lies inside it (``dvr_gl.model.clipping``). The image is
    that of the data in the kept region alone. ``geometry``: opaque
    :class:`dvr_gl.Surface` triangle meshes inside or around the data, which end the rays
    that meet them (``dvr_gl.model.geometry``).

    ``layers``: more volumes, each a :class:`dvr_gl.Layer` (a grid, its own transfer
    function or label colours, and its rigid placement in the world), drawn with the
    scene's own volume, which is the first layer; ``blend`` says how they combine: "mix"
    (one medium: extinctions and emissions add where layers overlap) or "add" (each
    layer's image alone, the images summed). See ``dvr_gl.model.layers``;
    :meth:`from_layers` builds a scene from a list of layers."""

    def __init__(self, volume, tf, camera, width=512, height=512, mode="composite",
                 iso_value=None, shading=False, phong=(0.3, 0.7, 0.2, 32.0), lights=(HEADLIGHT,),
                 optical_model="emission_absorption", illustration=None, clip_planes=(), crop_box=None,
                 geometry=(), layers=(), blend="mix"):
        from .lazy_volume import LazyVolume     # (a store read brick by brick: ray casting only)
        if not isinstance(volume, (Volume, TetMesh, LazyVolume)):
            raise TypeError(f"volume must be a dvr_gl.Volume or dvr_gl.TetMesh, got {type(volume).__name__} "
                            f"(or, for raycast, a store read lazily: dvr_gl.model.lazy_volume.LazyVolume)")
        if not isinstance(tf, (TransferFunction, TransferFunction2D)):
            raise TypeError(f"tf must be a dvr_gl.TransferFunction or TransferFunction2D, got {type(tf).__name__}")
        if not isinstance(camera, Camera):
            raise TypeError(f"camera must be a dvr_gl.Camera, got {type(camera).__name__}")
        tf_2d = tf if isinstance(tf, TransferFunction2D) else None
        if tf_2d is not None:
            if mode != "composite":
                raise ValueError(f"a TransferFunction2D classifies composite samples (it needs each sample's "
                                 f"gradient), got mode={mode!r}")
            if optical_model == "sabella":
                raise ValueError("optical_model='sabella' colours a ray from its peak value alone; "
                                 "a TransferFunction2D needs the gradient too")
            if isinstance(volume, TetMesh):
                raise ValueError("a TransferFunction2D is rendered for grids (a Volume: raycast, slice3d, "
                                 "slice2d); a TetMesh scene takes a 1D TransferFunction")
            if optical_model == "emission" and np.any(tf_2d.table[:, :, 3] >= 1):
                raise ValueError("optical_model='emission' needs opacities below 1 (tau is infinite where "
                                 "alpha = 1), got alpha = 1 in the TransferFunction2D's table")
            tf = tf_2d.envelope
        for name, value in (("width", width), ("height", height)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name} must be an integer, got {value!r}")
            if not 1 <= value <= MAX_IMAGE_SIDE:
                raise ValueError(f"{name} must be between 1 and {MAX_IMAGE_SIDE} pixels, got {value!r}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        if mode == "isosurface":
            if iso_value is None:
                raise ValueError("iso_value is required for mode='isosurface', got None")
            iso_value = _finite_number("iso_value", iso_value)
        elif iso_value is not None:
            iso_value = _finite_number("iso_value", iso_value)
        if not isinstance(shading, (bool, np.bool_)):
            raise TypeError(f"shading must be True or False, got {shading!r}")
        if shading and mode not in SHADED_MODES:
            raise ValueError(f"shading applies to modes {' and '.join(SHADED_MODES)} (a lit sample needs a "
                             f"position on the ray), got shading=True with mode={mode!r}")
        try:
            phong = tuple(float(v) for v in phong)
        except (TypeError, ValueError):
            raise TypeError(f"phong must be (ka, kd, ks, shininess), got {phong!r}") from None
        if len(phong) != 4 or not all(math.isfinite(v) and v >= 0 for v in phong):
            raise ValueError(f"phong must be four finite non-negative numbers (ka, kd, ks, shininess), got {phong!r}")
        if optical_model not in OPTICAL_MODELS:
            raise ValueError(f"optical_model must be one of {', '.join(OPTICAL_MODELS)}, got {optical_model!r}")
        if optical_model != "emission_absorption":
            if mode != "composite":
                raise ValueError(f"optical_model applies to mode 'composite', got optical_model={optical_model!r} "
                                 f"with mode={mode!r}")
            if optical_model == "absorption" and shading:
                raise ValueError("optical_model='absorption' emits nothing, so there is nothing to light: "
                                 "got shading=True")
            if optical_model == "sabella" and (shading or illustration):
                raise ValueError("optical_model='sabella' colours each ray from its peak value; shading and "
                                 "illustration terms do not apply")
            if optical_model == "emission":
                opaque = [s for s, a in tf.opacity_points if a >= 1]
                if opaque:
                    raise ValueError(f"optical_model='emission' needs opacities below 1 (tau is infinite where "
                                     f"alpha = 1), got alpha = 1 at s = {opaque[0]:g}")
        illustration = _illustration(illustration)
        if illustration and mode != "composite":
            raise ValueError(f"illustration terms apply to mode 'composite', got mode={mode!r}")
        if isinstance(lights, Light):
            lights = (lights,)
        try:
            lights = tuple(lights)
        except TypeError:
            raise TypeError(f"lights must be a dvr_gl.Light or a sequence of them, got {lights!r}") from None
        if not 1 <= len(lights) <= MAX_LIGHTS or not all(isinstance(l, Light) for l in lights):
            raise ValueError(f"lights must be 1 to {MAX_LIGHTS} dvr_gl.Light objects, got {lights!r}")
        geometry = check_geometry(geometry)
        clip_planes = check_clip_planes(clip_planes)
        layers = check_layers(layers, volume, tf, mode=mode, blend=blend, shading=shading,
                              optical_model=optical_model, tf_2d=tf_2d, illustration=illustration)
        crop_box = check_crop_box(crop_box, union_bounds((Layer(volume, tf),) + layers) if layers else volume.bounds)
        self.volume = volume
        self.tf = tf              # a TransferFunction2D's envelope when given one
        self.tf_2d = tf_2d        # the TransferFunction2D, or None
        self.camera = camera
        self.lights = lights
        self.optical_model = optical_model
        self.illustration = illustration
        self.width = int(width)
        self.height = int(height)
        self.mode = mode
        self.iso_value = iso_value
        self.shading = bool(shading)
        self.phong = phong
        self.clip_planes = clip_planes   # ((point, normal), ...), world units
        self.crop_box = crop_box         # (lower, upper) world corners, or None
        self.geometry = geometry         # opaque Surfaces that end rays
        self.layers = layers             # more volumes (Layer), drawn with this one
        self.blend = blend               # how layers combine: "mix" or "add"

    @classmethod
    def from_layers(cls, layers, camera=None, **kwargs):
        """A scene of several volumes: the first layer (a scan, unplaced: it gives the
        world its frame) becomes the scene's own volume and transfer function, the others
        its ``layers``. ``camera`` defaults to ``default_camera`` of the box around all."""
        layers = list(layers)
        if not layers or not all(isinstance(layer, Layer) for layer in layers):
            raise TypeError(f"layers must be a non-empty list of dvr_gl.Layer, got {layers!r}")
        first = layers[0]
        if first.is_labels or first.placed:
            raise ValueError("the first layer gives the scene its world: it must be a scan (a TransferFunction) "
                             "with no matrix; put a label volume or a placed volume after it")
        if camera is None:
            camera = default_camera(Extent(union_bounds(layers)))
        return cls(first.volume, first.tf, camera, layers=layers[1:], **kwargs)

    @property
    def all_layers(self):
        """Every volume of the scene as a Layer, its own first."""
        return (Layer(self.volume, self.tf),) + self.layers

    @property
    def bounds(self):
        """(lower, upper) world box around the scene's data, its layers included."""
        return union_bounds(self.all_layers) if self.layers else self.volume.bounds

    # The part of the image a render covers, (x, y, width, height) in pixels with y from
    # the bottom (GL window coordinates); None is the whole image. Set by the Renderer on
    # copies of a scene when it renders an image larger than one GL target in tiles.
    tile = None

    @property
    def tile_origin(self):
        """Lower-left pixel of the tile (0, 0 for the whole image)."""
        return (0, 0) if self.tile is None else (self.tile[0], self.tile[1])

    @property
    def target_size(self):
        """(width, height) of what one render draws: the tile's, or the image's."""
        return (self.width, self.height) if self.tile is None else (self.tile[2], self.tile[3])

    @property
    def clips(self):
        """True when clip planes or a crop box cut the data."""
        return bool(self.clip_planes) or self.crop_box is not None

    def clip_in_box(self):
        """The clip planes as (unit normal, offset) pairs and the crop box as (lower,
        upper), both relative to the data's lower corner (the shaders' coordinates)."""
        lo = self.volume.bounds[0]
        crop = None if self.crop_box is None else (self.crop_box[0] - lo, self.crop_box[1] - lo)
        return plane_offsets(self.clip_planes, lo), crop

    @property
    def is_mesh(self):
        """True when the scene's data is a TetMesh (rendered by cell projection)."""
        return isinstance(self.volume, TetMesh)

    @property
    def is_lazy(self):
        """True when the scene's data is a LazyVolume (samples read brick by brick)."""
        from .lazy_volume import LazyVolume
        return isinstance(self.volume, LazyVolume)

    @property
    def headlight_only(self):
        """True for the contract's default light: one headlight of intensity 1."""
        return len(self.lights) == 1 and self.lights[0].is_headlight and self.lights[0].intensity == 1.0

    @property
    def reads_gradient(self):
        """Whether samples read the gradient: lit, classified by a 2D TF, or an
        illustration term that does."""
        return (self.shaded or self.tf_2d is not None
                or any(name in self.illustration for name in GRADIENT_TERMS))

    @property
    def shaded(self):
        """True when samples are lit (isosurface mode always is)."""
        return self.shading or self.mode == "isosurface"

    def replace(self, **changes):
        """A copy with some fields changed (validated again)."""
        args = dict(volume=self.volume, tf=self.tf if self.tf_2d is None else self.tf_2d, camera=self.camera, width=self.width,
                    height=self.height, mode=self.mode, iso_value=self.iso_value,
                    shading=self.shading, phong=self.phong, lights=self.lights,
                    optical_model=self.optical_model, illustration=dict(self.illustration),
                    clip_planes=self.clip_planes, crop_box=self.crop_box, geometry=self.geometry,
                    layers=self.layers, blend=self.blend)
        args.update(changes)
        return Scene(**args)

    def digest(self):
        """A content hash of everything that defines the image."""
        h = hashlib.sha256()
        h.update(self.volume.digest().encode())
        for part in (self.tf.key(), self.camera.key(),
                     (self.width, self.height, self.mode, self.iso_value, self.shading, self.phong)):
            h.update(repr(part).encode())
        if not self.headlight_only:   # the default light leaves earlier digests (and caches) as they were
            h.update(repr(tuple(light.key() for light in self.lights)).encode())
        if self.optical_model != "emission_absorption":
            h.update(self.optical_model.encode())
        if self.clips:                # unclipped scenes keep their earlier digests (and caches)
            planes = [[float(v) for v in (*p, *n)] for p, n in self.clip_planes]
            crop = None if self.crop_box is None else [float(v) for v in (*self.crop_box[0], *self.crop_box[1])]
            h.update(repr((planes, crop)).encode())
        if self.geometry:
            h.update(repr([s.digest() for s in self.geometry]).encode())
        if self.layers:               # one-volume scenes keep their earlier digests (and caches)
            h.update(repr(([layer.digest() for layer in self.layers], self.blend)).encode())
        if self.illustration:
            h.update(repr(sorted(self.illustration.items())).encode())
        if self.tf_2d is not None:
            h.update(repr(self.tf_2d.key()).encode())
        return h.hexdigest()

    def __repr__(self):
        return (f"Scene({self.volume!r}, {self.tf!r}, {self.camera!r}, {self.width}x{self.height}, "
                f"mode={self.mode!r}, iso_value={self.iso_value})")


