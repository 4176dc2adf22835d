"""The same scene through VTK's GPU ray caster, as a peer for benchmarks.

:func:`render_vtk` renders a :class:`dvr_gl.Scene` with ``vtkGPUVolumeRayCastMapper``
offscreen and returns the image in dvr_gl's convention ((H, W, 4) float32, premultiplied
RGBA over transparent black, row 0 on top) together with the median seconds per frame.
A scene whose data is a :class:`dvr_gl.TetMesh` goes to VTK's projected tetrahedra
(``vtkProjectedTetrahedraMapper``) instead: :func:`render_vtk_mesh` /
:meth:`VTKPeer.render_mesh` (see "Meshes" below).
VTK (``pip install vtk``, the ``bench`` extra) is optional: importing this module does
not import it; the first render does.

How the scene is matched
------------------------
- Volume: a ``vtkImageData`` with the volume's dimensions, spacing and origin and its
  samples in their own dtype (float64 is given to VTK as float32; ``data_as_float=True``
  gives every dtype as float32), trilinear interpolation. VTK's domain is the same box,
  first to last sample, and its texture coordinates put samples on texel centres
  (checked: a MIP of a linear ramp matches the ramp to the lookup table's precision).
- Classification: ``vtkColorTransferFunction`` (RGB space) and ``vtkPiecewiseFunction``
  with the transfer function's control points in data units, both clamped outside their
  ends, as here; ``ScalarOpacityUnitDistance`` = ``tf.unit_distance``. VTK corrects
  opacity per sample with ``1 - (1 - alpha)^(step / unit_distance)``, the contract's
  rule, and classifies through its own lookup tables built over the data's range.
- Sampling: ``AutoAdjustSampleDistances`` off, ``SampleDistance`` = ``step`` (world
  units), ``ImageSampleDistance`` = 1, no jittering, shading off.
- Camera: the same eye, target and up; vertical view angle = ``fov``, or parallel
  projection with parallel scale = ``ortho_height / 2``; the clipping range is reset
  to the volume's bounds (plus a small margin) so nothing in the box is clipped. VTK
  starts rays at its near plane, so an eye inside the box is not matched exactly.
- Modes: composite, mip and minip are VTK's blend modes of those names. ``average``:
  VTK's average blend writes grey ``(m, m, m, 1)``, with ``m`` the opacity-weighted mean
  of the scalar normalised to the array's range; the peer sets the opacity function to
  1, so ``m`` is the plain mean, and classifies it with the scene's transfer function
  (on the CPU, inside the timed frame). ``isosurface``: VTK's iso-surface blend mode
  with shading on, the scene's (ka, kd, ks, shininess), VTK's automatic headlight and
  opacity 1. VTK's lighting is its own: the light is a point at the camera position
  (for an orthographic camera too) and the specular term is Phong's ``(R.V)^n``, not
  the contract's headlight Blinn-Phong ``(N.H)^n`` with H = L = V. They agree where the
  normal is along the ray (a surface facing the camera gets ``c * (ka + kd) + ks``) and
  differ elsewhere; VTK also shades the first sample past the crossing. Isosurface
  images are therefore a looser match than the unshaded modes.

Read-back: premultiplied float RGBA
-----------------------------------
VTK's window framebuffer is 8-bit. To avoid quantising to 1/255 the renderer draws
through a ``vtkFramebufferPass`` whose colour target is RGBA32F and reads that texture
back as float. (The pass must be given a 32-bit fixed-point depth texture: with its
default float depth texture the GPU ray caster draws nothing.) VTK's output is
premultiplied RGBA over transparent black in every mode used here: composite and
isosurface accumulate ``(1 - A) * a * c`` front to back, MIP and MinIP write
``(c * a, a)``, and the volume is blended with (ONE, ONE_MINUS_SRC_ALPHA). A constant box
of colour c gives ``rgb = c * A`` to float precision (``tests/test_vtk_peer.py``).

Known differences from the exact image
--------------------------------------
- Whole steps only: VTK's first sample is one step past the entry and it takes a whole
  number of steps, so a ray of length L absorbs over a length that differs from L by
  up to one step either way (about half a step short on average). For a constant box of
  opacity a per unit distance u this bounds the alpha error by
  ``(1 - A) * ((1 - a)^(-step / u) - 1)``; measured errors reach that bound.
- Texture filtering: VTK uploads integer data in its own type; on Mesa llvmpipe the
  trilinear weights for 8-bit textures have 8-bit precision, so a uint8 ramp is
  interpolated with errors of about 1/255 of the range (float and 16-bit data: ~5e-4,
  the lookup table). ``data_as_float=True`` removes the 8-bit part.
- Early ray termination when the accumulated alpha exceeds 1 - 1/255.

Meshes: projected tetrahedra
----------------------------
``vtkOpenGLProjectedTetrahedraMapper`` on a ``vtkUnstructuredGrid`` built from the mesh
(float64 points, ``VTK_TETRA`` cells, the scalars as float64 point scalars), in the same
window, renderer, float colour target, camera mapping and read-back as grids; the grid's
volume actor is hidden while a mesh is drawn and the other way round. Only unshaded
composite exists there. What VTK does (VTK 9.x source, checked by the tests):

- Sort: every frame, ``vtkCellCenterDepthSort`` (its ``vtkVisibilitySort``) orders the
  cells back to front by their centroids' projection on the view direction (also in
  perspective), in batches of 1000 handed to the GL as they are sorted. A centroid order
  is not a visibility order: neighbouring cells of different sizes, and non-convex
  meshes, can be drawn out of order (no gap or cycle handling). Gaps in a non-convex
  domain need nothing: nothing is drawn there.
- Classification at the vertices only, in 8 bits: colour and "opacity" are looked up at
  each vertex, truncated to ``floor(v * 255.9999) / 255`` and interpolated linearly over
  the projected triangles (pre-classification). Each tet is split into 3 or 4 triangles
  round its thick vertex (Shirley-Tuchman), whose thickness L is exact under an
  orthographic camera and from a 2048-entry square-root table in perspective; the
  fragment gets ``A = 1 - exp(-att * L / unit)`` with ``att`` the mean of the front and
  back values and colour the mean colour, blended (SRC_ALPHA, ONE_MINUS_SRC_ALPHA;
  alpha ONE, ONE_MINUS_SRC_ALPHA): premultiplied RGBA over transparent black.
- Unit distance: VTK reads the scalar opacity as an *extinction* per
  ``ScalarOpacityUnitDistance`` (``1 - exp(-alpha L / u)``), not as the opacity of a slab
  u thick (``1 - (1 - alpha)^(L / u)``). The peer therefore gives VTK ``att = tau / tau_max``
  and unit distance ``1 / tau_max`` (:func:`pt_attenuation`), which is the contract's
  absorption with the 8 bits spent on the range used; ``native_opacity=True`` passes the
  opacity points and ``tf.unit_distance`` unchanged instead (e.g. 18 % less alpha for
  alpha = 0.5 over one unit distance).
- Accuracy (tests/test_vtk_peer.py): a constant cube seen orthographically is the closed
  form to 4e-7; in perspective the per-tet linear thickness is off by up to 7e-2 in alpha
  for one cube of 6 tets filling the view, falling ~4x per halving of the cells; a field
  varying through the cells is off by ~0.1 with 2 cells across a ray and ~0.01 with 8.
- Near plane: a tet with any vertex in front of the near plane is dropped whole (the
  clipping range is reset to the mesh's bounds, so this happens only with the eye inside
  or near the mesh).
- First frame: the mapper binds its vertex attributes only after its first draw, so its
  very first frame lacks the first batch of (up to 1000, farthest) cells; the peer renders
  that frame once, untimed, when it makes the mapper.
- Timing: a frame is ``Render()`` plus the float read-back, as for grids. The mapper's
  sort, projection (one CPU thread) and per-batch uploads and draws run inside
  ``Render()``; ``last_mesh_timings["mapper_draw"]`` holds the mapper's own
  ``TimeToDraw`` per frame, and :meth:`VTKPeer.sort_seconds` times its visibility sort alone.

Headless rendering
------------------
``vtkEGLRenderWindow`` with ``OffScreenRendering`` on: on a machine without a display
this renders on Mesa llvmpipe (or on the GPU's EGL driver where there is one). If the
environment variable ``VTK_DEFAULT_OPENGL_WINDOW`` is set, VTK's own choice is used
instead. :func:`renderer_string` reports the OpenGL renderer VTK got.
"""

from __future__ import annotations

import os
import statistics
import time

import numpy as np

__all__ = ["VTKPeer", "render_vtk", "render_vtk_mesh", "renderer_string", "available", "SUPPORTED_MODES"]

SUPPORTED_MODES = ("composite", "mip", "minip", "average", "isosurface")

_vtk = None


_KEPT_WINDOWS = []



def _color_function(v, tf):
    """VTK's colour transfer function of ``tf`` (RGB, clamped like dvr_gl's)."""
    ctf = v.vtkColorTransferFunction()
    ctf.SetColorSpaceToRGB()
    ctf.ClampingOn()
    for s, r, g, b in tf.color_points:
        ctf.AddRGBPoint(float(s), float(r), float(g), float(b))
    return ctf

class _KeepCurrentContext:
    """Puts back the EGL context that was current before VTK made its own current, so
    that a moderngl context used in the same thread (the dvr_gl Renderer, test fixtures)
    is never left pointing at VTK's. A no-op where libEGL cannot be loaded."""

    _EGL_DRAW, _EGL_READ = 0x3059, 0x305A

    def __init__(self):
        from ..gl.context import egl_library
        self._egl = egl_library()
        self._saved = None

    def __enter__(self):
        egl = self._egl
        if egl is not None:
            ctx = egl.eglGetCurrentContext()
            self._saved = (egl.eglGetCurrentDisplay(), egl.eglGetCurrentSurface(self._EGL_DRAW),
                           egl.eglGetCurrentSurface(self._EGL_READ), ctx) if ctx else None
        return self

    def __exit__(self, *exc):
        if self._saved is not None:
            self._egl.eglMakeCurrent(*self._saved)
            self._saved = None
        return False


def _import_vtk():
    """Import the VTK modules this peer needs (once); raises ImportError without VTK."""
    global _vtk
    if _vtk is None:
        from types import SimpleNamespace

        from vtkmodules.util import numpy_support
        from vtkmodules.vtkCommonCore import VTK_FLOAT, vtkPoints
        from vtkmodules.vtkCommonDataModel import (VTK_TETRA, vtkCellArray, vtkImageData,
                                                   vtkPiecewiseFunction, vtkUnstructuredGrid)
        from vtkmodules.vtkRenderingCore import (vtkColorTransferFunction, vtkRenderer,
                                                 vtkRenderWindow, vtkVolume, vtkVolumeProperty)
        import vtkmodules.vtkRenderingOpenGL2 as gl2
        from vtkmodules.vtkRenderingVolumeOpenGL2 import (vtkOpenGLGPUVolumeRayCastMapper,
                                                          vtkOpenGLProjectedTetrahedraMapper)

        _vtk = SimpleNamespace(
            ns=numpy_support, VTK_FLOAT=VTK_FLOAT, vtkImageData=vtkImageData,
            vtkPiecewiseFunction=vtkPiecewiseFunction,
            vtkColorTransferFunction=vtkColorTransferFunction, vtkRenderer=vtkRenderer,
            vtkRenderWindow=vtkRenderWindow, vtkVolume=vtkVolume,
            vtkVolumeProperty=vtkVolumeProperty, gl2=gl2,
            Mapper=vtkOpenGLGPUVolumeRayCastMapper, PTMapper=vtkOpenGLProjectedTetrahedraMapper,
            vtkPoints=vtkPoints, vtkCellArray=vtkCellArray, vtkUnstructuredGrid=vtkUnstructuredGrid,
            VTK_TETRA=VTK_TETRA)
    return _vtk


def available() -> bool:
    """True if VTK can be imported."""
    try:
        _import_vtk()
    except ImportError:
        return False
    return True


def _new_window(v):
    if os.environ.get("VTK_DEFAULT_OPENGL_WINDOW"):
        return v.vtkRenderWindow()
    return v.gl2.vtkEGLRenderWindow()


class VTKPeer:
    """An offscreen VTK window and volume pipeline, reused across renders.

    The pipeline is rebuilt only for what changed: the image data when the volume object
    changes, the transfer functions when the transfer function changes, and so on.
    """

    def __init__(self, data_as_float=False):
        v = _import_vtk()
        self._v = v
        self.data_as_float = bool(data_as_float)
        self._keep = _KeepCurrentContext()
        self.window = _new_window(v)
        self.window.SetOffScreenRendering(1)
        self.window.SetMultiSamples(0)
        self.window.SetAlphaBitPlanes(1)
        self.renderer = v.vtkRenderer()
        self.renderer.SetBackground(0.0, 0.0, 0.0)
        self.renderer.SetBackgroundAlpha(0.0)
        self.window.AddRenderer(self.renderer)

        # Render into an RGBA32F texture instead of the 8-bit window framebuffer.
        self._fbpass = v.gl2.vtkFramebufferPass()
        self._fbpass.SetColorFormat(v.gl2.vtkTextureObject.Float32)
        self._fbpass.SetDepthFormat(v.gl2.vtkTextureObject.Fixed32)
        self._fbpass.SetDelegatePass(v.gl2.vtkRenderStepsPass())
        self.renderer.SetPass(self._fbpass)

        self.mapper = v.Mapper()
        self.mapper.SetAutoAdjustSampleDistances(0)
        self.mapper.SetImageSampleDistance(1.0)
        self.mapper.SetUseJittering(0)
        self.property, self.actor = self._add_volume(self.mapper)
        self._volume = None
        self._tf_key = None
        self._image = None
        self._size = None
        # The projected-tetrahedra pipeline, made on the first mesh scene.
        self.pt_mapper = None
        self.pt_property = None
        self.pt_actor = None
        self._mesh = None
        self._grid = None
        self._pt_key = None
        self._pt_primed = False
        self.last_mesh_timings = None

    # -- scene -> VTK ------------------------------------------------------------
    def _set_volume(self, volume):
        if self._volume is volume:
            return
        v = self._v
        img = v.vtkImageData()
        nx, ny, nz = (int(n) for n in volume.dims)
        img.SetDimensions(nx, ny, nz)
        img.SetSpacing(*(float(s) for s in volume.spacing))
        img.SetOrigin(*(float(o) for o in volume.origin))
        data = volume.data
        if data.dtype == np.float64 or (self.data_as_float and data.dtype != np.float32):
            data = data.astype(np.float32)
        if volume.has_nonfinite:
            raise NotImplementedError("the VTK peer does not render volumes with masked non-finite samples")
        arr = v.ns.numpy_to_vtk(np.ascontiguousarray(data).ravel(), deep=True)
        arr.SetName("scalars")
        img.GetPointData().SetScalars(arr)
        self.mapper.SetInputData(img)
        self._image = img
        self._volume = volume

    def _set_classification(self, scene):
        key = (scene.tf.key(), scene.mode, scene.iso_value, scene.shaded, scene.phong)
        if key == self._tf_key:
            return
        v = self._v
        tf = scene.tf
        ctf = _color_function(v, tf)
        otf = v.vtkPiecewiseFunction()
        otf.ClampingOn()
        if scene.mode in ("isosurface", "average"):
            # The contract's isosurface is opaque with colour c(v); for the average
            # VTK weights each sample by its opacity, so make that weight 1.
            otf.AddPoint(float(tf.knots[0]), 1.0)
            otf.AddPoint(float(tf.knots[-1]) + 1.0, 1.0)
        else:
            for s, a in tf.opacity_points:
                otf.AddPoint(float(s), float(a))
        p = self.property
        p.SetColor(ctf)
        p.SetScalarOpacity(otf)
        p.SetScalarOpacityUnitDistance(tf.unit_distance)
        p.SetInterpolationTypeToLinear()
        if scene.shaded:
            ka, kd, ks, shininess = scene.phong
            p.ShadeOn()
            p.SetAmbient(ka)
            p.SetDiffuse(kd)
            p.SetSpecular(ks)
            p.SetSpecularPower(shininess)
        else:
            p.ShadeOff()
        m = self.mapper
        if scene.mode == "composite":
            m.SetBlendModeToComposite()
        elif scene.mode == "mip":
            m.SetBlendModeToMaximumIntensity()
        elif scene.mode == "minip":
            m.SetBlendModeToMinimumIntensity()
        elif scene.mode == "average":
            m.SetBlendModeToAverageIntensity()
        elif scene.mode == "isosurface":
            m.SetBlendModeToIsoSurface()
            iso = p.GetIsoSurfaceValues()
            iso.SetNumberOfContours(1)
            iso.SetValue(0, float(scene.iso_value))
        else:  # pragma: no cover - Scene validates modes
            raise NotImplementedError(f"mode {scene.mode!r} is not supported by the VTK peer")
        self._tf_key = key

    def _set_camera(self, scene):
        c = scene.camera
        cam = self.renderer.GetActiveCamera()
        cam.SetPosition(*(float(x) for x in c.eye))
        cam.SetFocalPoint(*(float(x) for x in c.target))
        cam.SetViewUp(*(float(x) for x in c.true_up))
        cam.SetUseHorizontalViewAngle(0)
        if c.is_ortho:
            cam.ParallelProjectionOn()
            cam.SetParallelScale(c.ortho_height / 2.0)
        else:
            cam.ParallelProjectionOff()
            cam.SetViewAngle(c.fov)
        self.renderer.ResetCameraClippingRange(*self._bounds(scene.volume))

    @staticmethod
    def _bounds(volume):
        lo, hi = volume.bounds
        # A little margin so the box faces are never on the clipping planes.
        pad = 1e-3 * float(np.linalg.norm(hi - lo)) + 1e-6
        return (lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad, lo[2] - pad, hi[2] + pad)

    def setup(self, scene, step):
        """Point the pipeline at ``scene`` sampled every ``step`` world units."""
        if scene.is_mesh:
            raise TypeError("a TetMesh scene is rendered by setup_mesh / render_mesh (projected tetrahedra)")
        if step is None:
            raise TypeError("step (world units) is required for a Volume scene")
        step = float(step)
        if not np.isfinite(step) or step <= 0:
            raise ValueError(f"step must be a positive number of world units, got {step!r}")
        if scene.mode not in SUPPORTED_MODES:
            raise NotImplementedError(f"mode {scene.mode!r} is not supported by the VTK peer")
        if (scene.width, scene.height) != self._size:
            self.window.SetSize(scene.width, scene.height)
            self._size = (scene.width, scene.height)
        self._set_volume(scene.volume)
        self._set_classification(scene)
        self.actor.SetVisibility(True)
        if self.pt_actor is not None:
            self.pt_actor.SetVisibility(False)
        self.mapper.SetSampleDistance(step)
        self._set_camera(scene)
        self._mode = scene.mode
        self._tf = scene.tf
        rng = self._image.GetPointData().GetScalars().GetRange()
        self._scalar_range = (float(rng[0]), float(rng[1]))

    # -- meshes: projected tetrahedra -------------------------------------------
    def _ensure_pt(self):
        if self.pt_mapper is not None:
            return
        v = self._v
        self.pt_mapper = v.PTMapper()
        self.pt_property, self.pt_actor = self._add_volume(self.pt_mapper)

    def _add_volume(self, mapper):
        """An unshaded, linearly interpolated volume property and an actor for ``mapper``,
        added to the renderer: (property, actor)."""
        prop = self._v.vtkVolumeProperty()
        prop.SetInterpolationTypeToLinear()
        prop.ShadeOff()
        actor = self._v.vtkVolume()
        actor.SetMapper(mapper)
        actor.SetProperty(prop)
        self.renderer.AddVolume(actor)
        return prop, actor

    def _set_mesh(self, mesh):
        if self._mesh is mesh:
            return
        v = self._v
        ns = v.ns
        pts = v.vtkPoints()
        pts.SetData(ns.numpy_to_vtk(np.ascontiguousarray(mesh.points, dtype=np.float64), deep=True))
        m = mesh.n_tets
        conn = ns.numpy_to_vtkIdTypeArray(np.ascontiguousarray(mesh.tets, dtype=np.int64).ravel(), deep=True)
        offsets = ns.numpy_to_vtkIdTypeArray(np.arange(0, 4 * m + 1, 4, dtype=np.int64), deep=True)
        cells = v.vtkCellArray()
        cells.SetData(offsets, conn)
        grid = v.vtkUnstructuredGrid()
        grid.SetPoints(pts)
        grid.SetCells(v.VTK_TETRA, cells)
        arr = ns.numpy_to_vtk(np.ascontiguousarray(mesh.scalars, dtype=np.float64), deep=True)
        arr.SetName("scalars")
        grid.GetPointData().SetScalars(arr)
        self.pt_mapper.SetInputData(grid)
        self._grid = grid
        self._mesh = mesh

    def _set_mesh_classification(self, tf, native_opacity):
        key = (tf.key(), bool(native_opacity))
        if key == self._pt_key:
            return
        v = self._v
        ctf = _color_function(v, tf)
        otf = v.vtkPiecewiseFunction()
        otf.ClampingOn()
        if native_opacity:
            # As a VTK user would: VTK reads these values as extinction per unit distance.
            for s, a in tf.opacity_points:
                otf.AddPoint(float(s), float(a))
            unit = tf.unit_distance
        else:
            s, att, unit = pt_attenuation(tf)
            for x, y in zip(s, att):
                otf.AddPoint(float(x), float(y))
        p = self.pt_property
        p.SetColor(ctf)
        p.SetScalarOpacity(otf)
        p.SetScalarOpacityUnitDistance(unit)
        self.pt_unit_distance = unit
        self._pt_key = key

    def setup_mesh(self, scene, native_opacity=False):
        """Point the projected-tetrahedra pipeline at the mesh scene ``scene``.

        ``native_opacity=False`` (default) converts the transfer function's opacity into
        the extinction VTK's PT mapper expects (see :func:`pt_attenuation`), so that a
        cell absorbs as the contract says; ``True`` passes the opacity points and
        ``tf.unit_distance`` to VTK unchanged, as a VTK user would, and VTK then reads
        ``alpha`` as the extinction times the unit distance (``1 - exp(-alpha L / u)``
        instead of ``1 - (1 - alpha)^(L / u)``)."""
        if not scene.is_mesh:
            raise TypeError("setup_mesh needs a TetMesh scene; a Volume scene is rendered by setup / render")
        if scene.mode != "composite" or scene.shading:
            raise NotImplementedError(
                f"VTK's projected tetrahedra render only unshaded composite, not mode={scene.mode!r}"
                + (" with shading" if scene.shading else ""))
        self._ensure_pt()
        if (scene.width, scene.height) != self._size:
            self.window.SetSize(scene.width, scene.height)
            self._size = (scene.width, scene.height)
        self._set_mesh(scene.volume)
        self._set_mesh_classification(scene.tf, native_opacity)
        self.actor.SetVisibility(False)
        self.pt_actor.SetVisibility(True)
        self._set_camera(scene)
        self._mode = "composite"
        self._tf = scene.tf
        if not self._pt_primed:
            # VTK's PT mapper drops the first batch of cells (up to 1000, the farthest)
            # of its very first frame: it binds its vertex attributes only once its
            # index buffer has been filled, which happens after that first draw.
            self.frame()
            self._pt_primed = True

    def render_mesh(self, scene, repeats=5, warmup=1, turn=None, native_opacity=False):
        """Render the mesh scene ``scene`` with VTK's projected tetrahedra; returns
        ``(image, times)``: the last frame's image and the seconds of each of the
        ``repeats`` timed frames (after ``warmup`` untimed ones). A timed frame is
        ``Render()`` plus the float read-back, as for grids. ``turn``, if given, maps the
        timed frame's index i to a :class:`dvr_gl.Camera` used for that frame (a new view
        every frame; warm-up frames use the scene's camera). VTK sorts the cells again
        every frame in any case. ``self.last_mesh_timings`` holds the frame times and
        the mapper's own ``TimeToDraw`` (the CPU time of its sort, projection and draw
        calls, without waiting for the GL) of every timed frame."""
        self.setup_mesh(scene, native_opacity=native_opacity)
        image = None
        for _ in range(max(0, int(warmup))):
            image = self.frame()
        times, draws = [], []
        for i in range(max(1, int(repeats))):
            if turn is not None:
                self._set_camera(scene.replace(camera=turn(i)))
            t0 = time.perf_counter()
            image = self.frame()
            times.append(time.perf_counter() - t0)
            draws.append(float(self.pt_mapper.GetTimeToDraw()))
        if turn is not None:
            self._set_camera(scene)
        self.last_mesh_timings = {"frame": times, "mapper_draw": draws}
        return image, times

    def sort_seconds(self, scene, repeats=5):
        """Median seconds of the PT mapper's own visibility sort (its
        ``vtkVisibilitySort``, by default ``vtkCellCenterDepthSort``) traversed in full
        for ``scene``'s camera, back to front, as the mapper does it each frame."""
        self.setup_mesh(scene)
        sort = self.pt_mapper.GetVisibilitySort()
        sort.SetInput(self._grid)
        sort.SetDirectionToBackToFront()
        sort.SetCamera(self.renderer.GetActiveCamera())
        sort.SetMaxCellsReturned(1000)
        times = []
        for _ in range(max(1, int(repeats)) + 1):
            t0 = time.perf_counter()
            sort.InitTraversal()
            while sort.GetNextCells() is not None:
                pass
            times.append(time.perf_counter() - t0)
        return statistics.median(times[1:])

    # -- frames ------------------------------------------------------------------
    def _read(self):
        """The float colour target as (H, W, 4) float32, row 0 on top, premultiplied."""
        w, h = self._size
        tex = self._fbpass.GetColorTexture()
        if (tex.GetWidth(), tex.GetHeight()) != (w, h):
            raise RuntimeError(f"VTK colour target is {tex.GetWidth()}x{tex.GetHeight()}, expected {w}x{h}")
        pbo = tex.Download()
        out = np.empty((h, w, 4), dtype=np.float32)
        if not pbo.Download2D(self._v.VTK_FLOAT, out, [w, h], 4, [0, 0]):
            raise RuntimeError("reading VTK's float colour target back failed")
        out = out[::-1]
        if self._mode == "average":
            return self._classify_average(out)
        return np.ascontiguousarray(out)  # premultiplied already (module docs)

    def _classify_average(self, raw):
        """VTK's average blend writes (m, m, m, 1) with m the mean of the scalar
        normalised to the array's range (opacity-weighted; the opacity function is 1
        here), and discards rays with no sample. Classify m with the scene's function."""
        lo, hi = self._scalar_range
        hit = raw[..., 3] > 0
        s = lo + raw[..., 0].astype(np.float64) * (hi - lo)
        out = np.zeros(raw.shape, dtype=np.float32)
        a = self._tf.opacity(s[hit])
        out[hit, :3] = self._tf.color(s[hit]) * a[:, None]
        out[hit, 3] = a
        return out

    def frame(self):
        """Render one frame and read it back (the read-back waits for the GL to finish)."""
        with self._keep:
            self.window.Render()
            return self._read()

    def render(self, scene, step=None, repeats=5, warmup=1):
        """Render ``scene``; returns (image, median seconds per frame over ``repeats``
        frames after ``warmup`` untimed frames). Each timed frame is ``Render()`` plus
        the float read-back, so it ends only when the GL has finished. A mesh scene
        goes to :meth:`render_mesh` (``step`` is then ignored)."""
        if scene.is_mesh:
            image, times = self.render_mesh(scene, repeats=repeats, warmup=warmup)
            return image, statistics.median(times)
        self.setup(scene, step)
        image = None
        for _ in range(max(0, int(warmup))):
            image = self.frame()
        times = []
        for _ in range(max(1, int(repeats))):
            t0 = time.perf_counter()
            image = self.frame()
            times.append(time.perf_counter() - t0)
        return image, statistics.median(times)

    def renderer_string(self):
        """The OpenGL renderer string of VTK's context (e.g. 'llvmpipe (LLVM 15...)')."""
        if self._size is None:
            self.window.SetSize(8, 8)
            self._size = (8, 8)
        with self._keep:
            self.actor.SetVisibility(self._volume is not None)
            self.window.Render()
            self.actor.SetVisibility(True)
            report = self.window.ReportCapabilities()
        for line in report.splitlines():
            if "OpenGL renderer string" in line:
                return line.split(":", 1)[1].strip()
        return "unknown"

    def close(self):
        with self._keep:
            self.renderer.RemoveAllViewProps()
            self.renderer.ReleaseGraphicsResources(self.window)
        # No window.Finalize(): VTK's EGL window terminates the process's EGL display
        # there, which kills every other context on it (dvr_gl's included). The window
        # is kept until the process exits.
        _KEPT_WINDOWS.append(self.window)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


_shared = {}


def _peer(data_as_float=False):
    key = bool(data_as_float)
    if key not in _shared:
        _shared[key] = VTKPeer(data_as_float=key)
    return _shared[key]


def render_vtk(scene, step=None, repeats=5, warmup=1, data_as_float=False):
    """Render ``scene`` through VTK's GPU ray caster at sample distance ``step`` (world
    units), or a mesh scene through VTK's projected tetrahedra (``step`` ignored).
    Returns ``(image, seconds)``: image (H, W, 4) float32 premultiplied RGBA, row 0 on
    top; seconds the median time per frame over ``repeats`` frames after ``warmup``
    frames. Uses one shared offscreen window per process."""
    return _peer(data_as_float).render(scene, step, repeats=repeats, warmup=warmup)


def render_vtk_mesh(scene, repeats=5, warmup=1, turn=None, native_opacity=False):
    """Render a :class:`dvr_gl.TetMesh` scene through ``vtkProjectedTetrahedraMapper``.
    Returns ``(image, times)``: image as :func:`render_vtk`'s, times the seconds of each
    timed frame (see :meth:`VTKPeer.render_mesh` for ``turn`` and ``native_opacity``).
    Uses the same shared window as :func:`render_vtk`."""
    return _peer().render_mesh(scene, repeats=repeats, warmup=warmup, turn=turn,
                               native_opacity=native_opacity)


ALPHA_CAP = 1.0 - 1.0 / 1024


def pt_attenuation(tf, per_segment=16):
    """The opacity function and unit distance that make VTK's PT mapper absorb as the
    contract says. Returns ``(s, att, unit)``: control points ``(s, att)`` for VTK's
    scalar opacity and its ``ScalarOpacityUnitDistance``.

    VTK's PT mapper reads the scalar opacity ``att`` (8-bit, ``floor(att * 255.9999) /
    255``, so in [0, 1]) as an extinction: a cell of thickness L absorbs
    ``1 - exp(-att * L / unit)``. The contract's extinction is ``tau(s) = -ln(1 -
    alpha(s)) / u``, so ``att = tau / tau_max`` with ``unit = 1 / tau_max`` spends the
    8 bits on the range the function uses (the largest extinction is 1.0, exact).
    ``tau`` is not linear between the opacity points, so each segment gets
    ``per_segment`` pieces (VTK classifies at the vertices only, so this matters only
    there). Opacities above ``ALPHA_CAP`` (1 - 1/1024) are capped: ``alpha = 1`` is an
    infinite extinction that no finite table holds."""
    pts = tf.opacity_points
    if len(pts) == 1:
        s = pts[:, 0].copy()
    else:
        s = np.unique(np.concatenate([np.linspace(a, b, per_segment + 1)
                                      for a, b in zip(pts[:-1, 0], pts[1:, 0])]))
    alpha = np.minimum(tf.opacity(s), ALPHA_CAP)
    tau = -np.log1p(-alpha) / tf.unit_distance
    tau_max = float(tau.max())
    if tau_max <= 0:
        return s, np.zeros_like(s), tf.unit_distance
    return s, tau / tau_max, 1.0 / tau_max


def renderer_string():
    """The OpenGL renderer VTK renders with in this process."""
    return _peer().renderer_string()
