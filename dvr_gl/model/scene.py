"""The scene: plain, validated data that knows nothing of GL.

Every class here checks its input once, at construction, and raises ``TypeError`` or
``ValueError`` with a message naming the parameter and the offending value. Objects are
immutable afterwards (arrays are stored read-only), so renderers may cache GPU resources
by object identity.

Conventions (see docs/conventions in the README): data is ``(nz, ny, nx)``, x fastest;
spacing and origin are given in x, y, z order; sample ``data[k, j, i]`` sits at
``origin + (i*sx, j*sy, k*sz)``; the field is the trilinear interpolant of the samples on
the closed box from the first to the last sample.
"""

from __future__ import annotations

import hashlib
import math
from numbers import Real

import numpy as np

SUPPORTED_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)
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


def _vector3(name, value, *, positive=False):
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be three numbers, got {value!r}") from None
    if arr.shape != (3,):
        raise ValueError(f"{name} must have 3 components (x, y, z), got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and not np.all(arr > 0):
        raise ValueError(f"{name} must be positive on every axis, got {value!r}")
    arr.setflags(write=False)
    return arr


def interval(name, value):
    """(low, high) from two finite numbers with low < high, or an error naming ``name``."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be two numbers (low, high), got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"{name} must be two finite numbers with low < high, got {value!r}")
    return lo, hi


def _finite_number(name, value, *, positive=False):
    if isinstance(value, bool) or not isinstance(value, Real):
        raise TypeError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and value <= 0:
        raise ValueError(f"{name} must be positive, got {value!r}")
    return value


class Volume:
    """A structured scalar volume.

    Parameters
    ----------
    data : ndarray (nz, ny, nx) of uint8, uint16, int16, float32 or float64
    spacing, origin : (x, y, z) world units
    mask_nonfinite : if True, NaN/inf samples are allowed and every grid cell with a
        non-finite corner is removed from the domain (no emission, no absorption);
        otherwise non-finite samples are an error.
    orientation : None, or three letters naming where the x, y and z index axes point
        anatomically ("RAS": x towards the patient's right, ...); the first view faces the
        subject and transfer-function presets take it as a scan's.
    modality : None, or the imaging modality as DICOM names it ("CT", "MR", ...), from
        the file's metadata; presets use it (an 8-bit "CT" gets the windowed CT preset).
    orientation_assumed : True where ``orientation`` is the file format's convention
        rather than the file's statement (a MetaImage without orientation fields is in
        ITK's LPS frame; see ``dvr_gl.formats``): the first view uses it, presets do not take
        the volume for a scan because of it.
    """

    def __init__(self, data, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), mask_nonfinite=False,
                 orientation=None, modality=None, orientation_assumed=False):
        if not isinstance(data, np.ndarray):
            raise TypeError(f"data must be a numpy array, got {type(data).__name__}")
        if data.dtype.type not in SUPPORTED_DTYPES:
            names = ", ".join(np.dtype(t).name for t in SUPPORTED_DTYPES)
            raise TypeError(f"data dtype must be one of {names}, got {data.dtype}")
        if data.ndim != 3:
            raise ValueError(f"data must be 3-D (nz, ny, nx), got ndim={data.ndim} shape={data.shape}")
        if min(data.shape) < 2:
            raise ValueError(f"data needs at least 2 samples on every axis, got shape={data.shape}")
        self.spacing = _vector3("spacing", spacing, positive=True)
        self.origin = _vector3("origin", origin)
        self.mask_nonfinite = bool(mask_nonfinite)
        self.orientation = _orientation(orientation)
        self.orientation_assumed = bool(orientation_assumed) and self.orientation is not None
        self.modality = _modality(modality)

        data = np.array(data, copy=True, order="C")
        data.setflags(write=False)
        self.data = data
        finite = np.isfinite(data) if data.dtype.kind == "f" else None
        if finite is not None and not finite.all():
            if not self.mask_nonfinite:
                bad = tuple(int(i) for i in np.argwhere(~finite)[0])
                raise ValueError(
                    f"data has non-finite values (first at index {bad}: {data[bad].item()!r}); "
                    "pass mask_nonfinite=True to treat them as outside the domain")
            if not finite.any():
                raise ValueError("data has no finite value at all")
            self.has_nonfinite = True
        else:
            self.has_nonfinite = False
            finite = None
        valid = data[finite] if finite is not None else data
        self.data_range = (float(valid.min()), float(valid.max()))

        if self.has_nonfinite:
            # A cell (the cube between 8 neighbouring samples) is inside the domain only if
            # all its corners are finite; the texture holds 0 where the data is not finite.
            f = finite
            c = (f[:-1, :-1, :-1] & f[:-1, :-1, 1:] & f[:-1, 1:, :-1] & f[:-1, 1:, 1:]
                 & f[1:, :-1, :-1] & f[1:, :-1, 1:] & f[1:, 1:, :-1] & f[1:, 1:, 1:])
            c.setflags(write=False)
            self.cell_valid = c
        else:
            self.cell_valid = None
        self._digest = None

    # -- geometry ---------------------------------------------------------------
    @property
    def shape(self):
        """(nz, ny, nx)"""
        return self.data.shape

    @property
    def dims(self):
        """Sample counts in x, y, z order."""
        nz, ny, nx = self.data.shape
        return np.array([nx, ny, nz])

    @property
    def extent(self):
        """World size of the domain box, x, y, z."""
        return (self.dims - 1) * self.spacing

    @property
    def bounds(self):
        """(lower corner, upper corner) of the domain box in world units."""
        return self.origin, self.origin + self.extent

    @property
    def min_spacing(self):
        return float(self.spacing.min())

    def values(self, dtype=np.float64):
        """The samples as floats, non-finite ones replaced by 0 (they are masked)."""
        v = self.data.astype(dtype)
        if self.has_nonfinite:
            v[~np.isfinite(v)] = 0
        return v

    def digest(self):
        """A content hash (data, spacing, origin, masking) for caches on disk."""
        if self._digest is None:
            h = hashlib.sha256()
            h.update(str((self.data.dtype.str, self.data.shape)).encode())
            h.update(self.data.tobytes())
            h.update(self.spacing.tobytes() + self.origin.tobytes())
            h.update(b"mask" if self.mask_nonfinite else b"")
            self._digest = h.hexdigest()
        return self._digest

    def __repr__(self):
        return (f"Volume(shape={self.shape}, dtype={self.data.dtype}, spacing={tuple(self.spacing.tolist())}, "
                f"origin={tuple(self.origin.tolist())}, range={self.data_range})")


def _mesh_points(points):
    """(N, 3) finite float64 points, N >= 4, or an error naming the bad one."""
    pts = _array("points", points, np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 4:
        raise ValueError(f"points must have shape (N, 3) with N >= 4, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        bad = int(np.argwhere(~np.isfinite(pts))[0, 0])
        raise ValueError(f"points must be finite, point {bad} is {tuple(pts[bad].tolist())}")
    return pts


class TetMesh:
    """An unstructured tetrahedral mesh with one scalar per point.

    Parameters
    ----------
    points : (N, 3) finite floats, world units
    tets : (M, 4) integer indices into ``points``; either vertex orientation
    scalars : (N,) finite floats, the field's value at each point

    Inside each tetrahedron the field is the linear (barycentric) interpolant; the domain
    is the union of the tetrahedra and need not be convex. Tetrahedra of zero volume are
    kept (they contribute nothing). Arrays are copied and stored read-only; the
    connectivity and plane equations renderers need are derived once, on first use
    (``dvr_gl.model.mesh.topology``).
    """

    def __init__(self, points, tets, scalars):
        pts = _mesh_points(points)
        raw = np.asarray(tets)
        if raw.dtype.kind not in "iu":
            raise TypeError(f"tets must be integer indices, got dtype {raw.dtype}")
        tt = np.array(raw, dtype=np.int64, order="C")
        if tt.ndim != 2 or tt.shape[1] != 4 or len(tt) < 1:
            raise ValueError(f"tets must have shape (M, 4) with M >= 1, got shape {tt.shape}")
        out = (tt < 0) | (tt >= len(pts))
        if out.any():
            i, j = (int(v) for v in np.argwhere(out)[0])
            raise ValueError(f"tets[{i}] has index {int(tt[i, j])} out of range for {len(pts)} points")
        if np.any(np.sort(tt, axis=1)[:, 1:] == np.sort(tt, axis=1)[:, :-1]):
            i = int(np.flatnonzero((np.sort(tt, axis=1)[:, 1:] == np.sort(tt, axis=1)[:, :-1]).any(axis=1))[0])
            raise ValueError(f"tets[{i}] repeats a vertex: {tt[i].tolist()}")
        sc = _array("scalars", scalars, np.float64)
        if sc.shape != (len(pts),):
            raise ValueError(f"scalars must have shape ({len(pts)},), one per point, got shape {sc.shape}")
        if not np.all(np.isfinite(sc)):
            bad = int(np.flatnonzero(~np.isfinite(sc))[0])
            raise ValueError(f"scalars must be finite, scalars[{bad}] is {sc[bad].item()!r}")
        for a in (pts, tt, sc):
            a.setflags(write=False)
        self.points, self.tets, self.scalars = pts, tt, sc
        self.data_range = (float(sc.min()), float(sc.max()))
        self.has_nonfinite = False
        self._digest = None
        self._derived = {}

    @classmethod
    def from_points(cls, points, scalars):
        """The Delaunay tetrahedralisation of scattered points (``scipy.spatial.Delaunay``;
        Qhull's ``Qbb Qc Qz Q12`` options, so co-spherical points are handled and every
        input point is a vertex). Slivers Qhull leaves on the hull are kept: zero-volume
        cells are harmless."""
        from scipy.spatial import Delaunay
        pts = _mesh_points(points)
        try:
            tri = Delaunay(pts, qhull_options="Qbb Qc Qz Q12")
        except Exception as e:  # Qhull raises its own error type for flat input
            raise ValueError(f"points cannot be tetrahedralised (all on a plane or line?): {e}") from None
        return cls(pts, tri.simplices, scalars)

    @property
    def n_points(self):
        return len(self.points)

    @property
    def n_tets(self):
        return len(self.tets)

    @property
    def bounds(self):
        """(lower corner, upper corner) of the points' bounding box, world units."""
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        return lo, hi

    @property
    def origin(self):
        return self.bounds[0]

    @property
    def extent(self):
        lo, hi = self.bounds
        return hi - lo

    @property
    def cell_size(self):
        """The median edge length: the scale of one cell (a TF's default unit distance)."""
        if "cell_size" not in self._derived:
            p = self.points[self.tets]
            e = np.linalg.norm(p[:, [1, 2, 3, 2, 3, 3]] - p[:, [0, 0, 0, 1, 1, 2]], axis=-1)
            self._derived["cell_size"] = float(np.median(e)) or float(np.linalg.norm(self.extent)) or 1.0
        return self._derived["cell_size"]

    def signed_volumes(self):
        """Signed volume of every tetrahedron, float64 (M,)."""
        p = self.points[self.tets]
        a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
        return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0

    def digest(self):
        """A content hash (points, tets, scalars) for caches on disk."""
        if self._digest is None:
            h = hashlib.sha256()
            for a in (self.points, self.tets, self.scalars):
                h.update(str(a.shape).encode())
                h.update(a.tobytes())
            self._digest = h.hexdigest()
        return self._digest

    def __repr__(self):
        return f"TetMesh({self.n_points} points, {self.n_tets} tets, range={self.data_range})"


def _array(name, value, dtype):
    try:
        return np.array(value, dtype=dtype, order="C")
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of numbers, got {type(value).__name__}") from None


def _control_points(name, points, width):
    try:
        arr = np.array(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a list of {width}-tuples of numbers, got {points!r}") from None
    if arr.ndim != 2 or arr.shape[1] != width or arr.shape[0] < 1:
        raise ValueError(f"{name} must be a non-empty list of {width}-tuples, got {points!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {points!r}")
    pos = arr[:, 0]
    if np.any(np.diff(pos) <= 0):
        i = int(np.argmax(np.diff(pos) <= 0))
        raise ValueError(f"{name} positions must be strictly increasing, got {pos[i].item()!r} then {pos[i + 1].item()!r}")
    vals = arr[:, 1:]
    if np.any(vals < 0) or np.any(vals > 1):
        bad = vals[(vals < 0) | (vals > 1)][0].item()
        raise ValueError(f"{name} values must lie in [0, 1], got {bad!r}")
    arr.setflags(write=False)
    return arr


class TransferFunction:
    """Piecewise-linear colour and opacity over data values (not normalised).

    ``opacity`` is the opacity of a slab ``unit_distance`` thick (world units). Both
    functions are linear between their control points and clamped to their end values.
    """

    def __init__(self, color, opacity, unit_distance=1.0):
        self.color_points = _control_points("color", color, 4)
        self.opacity_points = _control_points("opacity", opacity, 2)
        self.unit_distance = _finite_number("unit_distance", unit_distance, positive=True)

    def color(self, s):
        """c(s), shape s.shape + (3,), float64."""
        s = np.asarray(s, dtype=np.float64)
        p = self.color_points
        return np.stack([np.interp(s, p[:, 0], p[:, k]) for k in (1, 2, 3)], axis=-1)

    def opacity(self, s):
        """alpha(s), float64."""
        s = np.asarray(s, dtype=np.float64)
        return np.interp(s, self.opacity_points[:, 0], self.opacity_points[:, 1])

    def extinction(self, s):
        """tau(s) = -ln(1 - alpha(s)) / unit_distance; inf where alpha = 1."""
        a = self.opacity(s)
        with np.errstate(divide="ignore"):
            return -np.log1p(-a) / self.unit_distance

    @property
    def knots(self):
        """All control-point positions, sorted and unique."""
        return np.unique(np.concatenate([self.color_points[:, 0], self.opacity_points[:, 0]]))

    def key(self):
        return (self.color_points.tobytes(), self.opacity_points.tobytes(), self.unit_distance)

    def to_dict(self):
        return {"color": self.color_points.tolist(), "opacity": self.opacity_points.tolist(),
                "unit_distance": self.unit_distance}

    def __repr__(self):
        return (f"TransferFunction({len(self.color_points)} colour points, "
                f"{len(self.opacity_points)} opacity points, unit_distance={self.unit_distance})")


class TransferFunction2D:
    """Colour and opacity over (data value, gradient magnitude): a 2D transfer function
    (Kniss et al. 2001), given as a table.

    ``table`` is (n_gradient, n_value, 4) RGBA in [0, 1]: row i holds gradient magnitude
    ``gradient_range[0] + i * dg``, column j value ``value_range[0] + j * dv``, spaced
    evenly over the two ranges. The function is the table's bilinear interpolant, clamped
    to its edges outside the ranges; opacity, as in ``TransferFunction``, is that of a slab
    ``unit_distance`` thick. The gradient magnitude is the contract's |grad f| (data units
    per world unit). ``dvr_gl.model.transfer2d`` builds tables from widgets (rectangles and
    triangles) and from Levoy's (1988) iso-contour and region-boundary opacities.

    A scene given one classifies every composite sample with it; ``envelope`` is the 1D
    function of the largest opacity over the gradient range at each value, which tells
    where nothing can be visible (empty-space skipping, the exact integrator's busy test).
    """

    def __init__(self, table, value_range, gradient_range, unit_distance=1.0):
        try:
            arr = np.array(table, dtype=np.float64)
        except (TypeError, ValueError):
            raise TypeError(f"table must be an array of numbers, got {type(table).__name__}") from None
        if arr.ndim != 3 or arr.shape[2] != 4 or arr.shape[0] < 2 or arr.shape[1] < 2:
            raise ValueError(f"table must have shape (n_gradient >= 2, n_value >= 2, 4) RGBA, got {arr.shape}")
        if not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > 1):
            bad = arr[~(np.isfinite(arr) & (arr >= 0) & (arr <= 1))][0].item()
            raise ValueError(f"table entries must lie in [0, 1], got {bad!r}")
        ranges = [interval("value_range", value_range), interval("gradient_range", gradient_range)]
        if ranges[1][0] < 0:
            raise ValueError(f"gradient_range must start at 0 or above (a magnitude), got {gradient_range!r}")
        arr.setflags(write=False)
        self.table = arr
        self.value_range, self.gradient_range = ranges
        self.unit_distance = _finite_number("unit_distance", unit_distance, positive=True)
        self.envelope = self._envelope()

    @property
    def values(self):
        """The table's column positions (data values)."""
        return np.linspace(*self.value_range, self.table.shape[1])

    @property
    def gradients(self):
        """The table's row positions (gradient magnitudes)."""
        return np.linspace(*self.gradient_range, self.table.shape[0])

    def _envelope(self):
        alpha = self.table[:, :, 3]
        top = np.argmax(alpha, axis=0)
        cols = np.arange(alpha.shape[1])
        peak = np.minimum(alpha[top, cols], np.nextafter(1.0, 0.0))    # never opaque: it only bounds
        v = self.values
        color = np.column_stack([v, self.table[top, cols, :3]])
        return TransferFunction(color, np.column_stack([v, peak]), self.unit_distance)

    def _weights(self, s, g):
        """Bilinear cells and weights of (value, gradient magnitude) points."""
        out = []
        for x, (lo, hi), n in ((s, self.value_range, self.table.shape[1]), (g, self.gradient_range, self.table.shape[0])):
            u = np.clip((np.asarray(x, np.float64) - lo) * ((n - 1) / (hi - lo)), 0.0, n - 1)
            i0 = np.minimum(np.floor(u).astype(np.int64), n - 2)
            out += [i0, u - i0]
        return out

    def lookup(self, s, g):
        """(rgba, transparency 1 - alpha) at values s and gradient magnitudes g (GLSL
        ``lookupTF2D``): the table's bilinear interpolant, float64."""
        j, fx, i, fy = self._weights(s, g)
        t = self.table
        fx, fy = fx[..., None], fy[..., None]
        rgba = ((t[i, j] * (1 - fx) + t[i, j + 1] * fx) * (1 - fy)
                + (t[i + 1, j] * (1 - fx) + t[i + 1, j + 1] * fx) * fy)
        return rgba, 1.0 - rgba[..., 3]

    def texture_rows(self):
        """(2 n_gradient, n_value, 4) float32 for the shader: the table, then 1 - alpha in
        the red channel of as many rows (precise near opacity 1)."""
        n_g, n_v, _ = self.table.shape
        out = np.zeros((2 * n_g, n_v, 4), np.float32)
        out[:n_g] = self.table
        out[n_g:, :, 0] = 1.0 - self.table[:, :, 3]
        return out

    def key(self):
        return ("2d", self.table.tobytes(), self.value_range, self.gradient_range, self.unit_distance)

    def __repr__(self):
        n_g, n_v, _ = self.table.shape
        return (f"TransferFunction2D({n_v} values in {self.value_range}, {n_g} gradient magnitudes in "
                f"{self.gradient_range}, unit_distance={self.unit_distance})")


class Camera:
    """A pinhole (``fov`` vertical, degrees) or orthographic (``ortho_height``) camera.

    Rays start at the eye (perspective) or on the plane through the eye normal to the
    view direction (orthographic); nothing behind that start is seen.
    """

    def __init__(self, eye, target, up=(0.0, 1.0, 0.0), fov=30.0, ortho_height=None):
        self.eye = _vector3("eye", eye)
        self.target = _vector3("target", target)
        self.up = _vector3("up", up)
        view = self.target - self.eye
        dist = float(np.linalg.norm(view))
        if dist <= 1e-12 * max(1.0, float(np.abs(self.eye).max())):
            raise ValueError(f"eye must differ from target, both are {tuple(self.eye.tolist())}")
        forward = view / dist
        up_len = float(np.linalg.norm(self.up))
        if up_len == 0:
            raise ValueError(f"up must be a non-zero vector, got {tuple(self.up.tolist())}")
        right = np.cross(forward, self.up / up_len)
        if np.linalg.norm(right) < 1e-9:
            raise ValueError(f"up {tuple(self.up.tolist())} is parallel to the view direction {tuple(forward.tolist())}")
        right /= np.linalg.norm(right)
        self.forward = forward
        self.right = right
        self.true_up = np.cross(right, forward)
        self.distance = dist
        if ortho_height is not None:
            self.ortho_height = _finite_number("ortho_height", ortho_height, positive=True)
            self.fov = None
        else:
            self.fov = _finite_number("fov", fov, positive=True)
            if self.fov >= 180:
                raise ValueError(f"fov must be below 180 degrees, got {fov!r}")
            self.ortho_height = None

    @property
    def is_ortho(self):
        return self.ortho_height is not None

    def screen_scale(self, width, height):
        """Half-extent of the view at unit distance (perspective) or in world units
        (orthographic), as (x, y)."""
        aspect = width / height
        half_h = self.ortho_height / 2 if self.is_ortho else math.tan(math.radians(self.fov) / 2)
        return half_h * aspect, half_h

    def rays(self, width, height):
        """Ray origins and unit directions, each (H, W, 3) float64, row 0 on top,
        through pixel centres."""
        sx, sy = self.screen_scale(width, height)
        x = (2 * (np.arange(width) + 0.5) / width - 1) * sx
        y = (1 - 2 * (np.arange(height) + 0.5) / height) * sy
        xx, yy = np.meshgrid(x, y)
        offset = xx[..., None] * self.right + yy[..., None] * self.true_up
        if self.is_ortho:
            origins = self.eye + offset
            dirs = np.broadcast_to(self.forward, origins.shape).copy()
        else:
            dirs = self.forward + offset
            dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
            origins = np.broadcast_to(self.eye, dirs.shape).copy()
        return origins, dirs

    def key(self):
        return (self.eye.tobytes(), self.target.tobytes(), self.up.tobytes(), self.fov, self.ortho_height)

    def __repr__(self):
        proj = f"ortho_height={self.ortho_height}" if self.is_ortho else f"fov={self.fov}"
        return f"Camera(eye={tuple(self.eye.tolist())}, target={tuple(self.target.tolist())}, up={tuple(self.up.tolist())}, {proj})"


class Light:
    """A light for lit scenes (``Scene(shading=True)`` and isosurfaces).

    ``Light()`` is the headlight: at every sample the light comes from the eye, along
    the ray (L = V), as the contract's default. ``Light(direction, space)`` is a
    directional light: ``direction`` points from the scene towards the light (the L of
    N.L), in world coordinates (``space="world"``) or in the camera's (``space="view"``:
    x right, y up, z towards the viewer). ``intensity`` scales its diffuse and specular
    terms (the ambient term is the scene's, once)."""

    SPACES = ("world", "view")

    def __init__(self, direction=None, space="world", intensity=1.0):
        if space not in self.SPACES:
            raise ValueError(f"space must be one of {', '.join(self.SPACES)}, got {space!r}")
        if direction is not None:
            direction = _vector3("direction", direction)
            length = float(np.linalg.norm(direction))
            if length == 0:
                raise ValueError(f"direction must not be the zero vector, got {tuple(direction.tolist())!r}")
            direction = direction / length
            direction.setflags(write=False)
        self.direction = direction
        self.space = space
        self.intensity = _finite_number("intensity", intensity)
        if self.intensity < 0:
            raise ValueError(f"intensity must be non-negative, got {intensity!r}")

    @property
    def is_headlight(self):
        return self.direction is None

    def world_direction(self, camera):
        """The unit direction towards the light in world coordinates (None: headlight)."""
        if self.direction is None or self.space == "world":
            return self.direction
        x, y, z = self.direction
        return x * camera.right + y * camera.true_up - z * camera.forward

    def key(self):
        return (None if self.direction is None else self.direction.tobytes(), self.space, self.intensity)

    def __repr__(self):
        if self.direction is None:
            return "Light()" if self.intensity == 1.0 else f"Light(intensity={self.intensity})"
        return (f"Light({tuple(round(v, 6) for v in self.direction.tolist())}, space={self.space!r}, "
                f"intensity={self.intensity})")


MAX_LIGHTS = 4
HEADLIGHT = Light()


class Scene:
    """What to render: a volume (a ``Volume`` grid or a ``TetMesh``), its classification,
    a camera, an image size and a mode."""

    def __init__(self, volume, tf, camera, width=512, height=512, mode="composite",
                 iso_value=None, shading=False, phong=(0.3, 0.7, 0.2, 32.0), lights=(HEADLIGHT,),
                 optical_model="emission_absorption", illustration=None):
        if not isinstance(volume, (Volume, TetMesh)):
            raise TypeError(f"volume must be a dvr_gl.Volume or dvr_gl.TetMesh, got {type(volume).__name__}")
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
    def is_mesh(self):
        """True when the scene's data is a TetMesh (rendered by cell projection)."""
        return isinstance(self.volume, TetMesh)

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
                    optical_model=self.optical_model, illustration=dict(self.illustration))
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
        if self.illustration:
            h.update(repr(sorted(self.illustration.items())).encode())
        if self.tf_2d is not None:
            h.update(repr(self.tf_2d.key()).encode())
        return h.hexdigest()

    def __repr__(self):
        return (f"Scene({self.volume!r}, {self.tf!r}, {self.camera!r}, {self.width}x{self.height}, "
                f"mode={self.mode!r}, iso_value={self.iso_value})")


def anatomical_frame(volume):
    """(front, up) world directions of a volume with an anatomical ``orientation``: the
    anterior direction (where a face looks) and the superior one; None without one."""
    codes = getattr(volume, "orientation", None)
    if codes is None:
        return None
    out = {}
    for axis, letter in enumerate(codes):
        for positive, negative in (("A", "P"), ("S", "I")):
            if letter in (positive, negative):
                v = np.zeros(3)
                v[axis] = 1.0 if letter == positive else -1.0
                out[positive] = v
    return out["A"], out["S"]


def _orientation(codes):
    """None, or three letters naming where the x, y and z axes point: one of R/L, one of
    A/P, one of S/I (as nibabel's ``aff2axcodes``)."""
    if codes is None:
        return None
    try:
        text = codes.upper() if isinstance(codes, str) else "".join(codes).upper()
    except TypeError:
        text = ""
    pair_of = {c: i for i, pair in enumerate(("RL", "AP", "SI")) for c in pair}
    if len(text) != 3 or sorted(pair_of.get(c, -1) for c in text) != [0, 1, 2]:
        raise ValueError(f"orientation must be three letters, one each of R/L, A/P and S/I (as 'RAS'), "
                         f"got {codes!r}")
    return text


def _modality(value):
    """None, or a modality code as DICOM writes it: up to 16 capitals, digits, spaces or
    underscores ("CT", "MR", "PT"), given in either case."""
    if value is None:
        return None
    text = value.strip().upper() if isinstance(value, str) else None
    if not text or len(text) > 16 or not all(c.isascii() and (c.isalnum() or c in " _") for c in text):
        raise ValueError(f"modality must be a code such as 'CT' or 'MR' (up to 16 letters, digits, spaces or "
                         f"underscores), got {value!r}")
    return text


def default_camera(volume, azimuth=0.0, elevation=0.0, zoom=1.0, fov=30.0, ortho=False, front=None, up=None):
    """A camera looking at the centre of the volume's (or mesh's) box along -z with +y up, far enough
    that the box's bounding sphere fits the view; ``azimuth`` turns it about +y and then
    ``elevation`` about the camera's right axis (degrees); ``zoom`` > 1 moves closer.
    ``front`` and ``up`` (unit world directions, together) start it elsewhere: the eye on
    the ``front`` side, ``up`` up (``anatomical_frame`` gives a patient's)."""
    zoom = _finite_number("zoom", zoom, positive=True)
    azimuth = _finite_number("azimuth", azimuth)
    elevation = _finite_number("elevation", elevation)
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2
    az, el = math.radians(azimuth), math.radians(elevation)
    if front is None:
        # Start looking along -z (eye on +z); rotate the eye offset and the up vector together.
        offset = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
        up = np.array([-math.sin(az) * math.sin(el), math.cos(el), -math.cos(az) * math.sin(el)])
    else:
        front = _vector3("front", front) / np.linalg.norm(front)
        up0 = _vector3("up", up) / np.linalg.norm(up)
        if abs(float(front @ up0)) > 1e-9:
            raise ValueError(f"front and up must be perpendicular, got {tuple(front)} and {tuple(up0)}")
        horizontal = math.cos(az) * front + math.sin(az) * np.cross(up0, front)
        offset = math.cos(el) * horizontal + math.sin(el) * up0
        up = math.cos(el) * up0 - math.sin(el) * horizontal
    if ortho:
        return Camera(centre + offset * 2 * radius, centre, up, ortho_height=2 * radius / zoom)
    distance = radius / math.sin(math.radians(fov) / 2) / zoom
    return Camera(centre + offset * distance, centre, up, fov=fov)
