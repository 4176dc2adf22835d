"""The same scene through VTK's GPU ray caster, as a peer for benchmarks.

:func:`render_vtk` renders a :class:`dvr_gl.Scene` with ``vtkGPUVolumeRayCastMapper``
offscreen and returns the image in dvr_gl's convention ((H, W, 4) float32, premultiplied
RGBA over transparent black, row 0 on top) together with the median seconds per frame.
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

__all__ = ["VTKPeer", "render_vtk", "renderer_string", "available", "SUPPORTED_MODES"]

SUPPORTED_MODES = ("composite", "mip", "minip", "average", "isosurface")

_vtk = None


_KEPT_WINDOWS = []


class _KeepCurrentContext:
    """Puts back the EGL context that was current before VTK made its own current, so
    that a moderngl context used in the same thread (the dvr_gl Renderer, test fixtures)
    is never left pointing at VTK's. A no-op where libEGL cannot be loaded."""

    _EGL_DRAW, _EGL_READ = 0x3059, 0x305A

    def __init__(self):
        self._egl = None
        try:
            import ctypes
            egl = ctypes.CDLL("libEGL.so.1")
            for name in ("eglGetCurrentContext", "eglGetCurrentDisplay"):
                getattr(egl, name).restype = ctypes.c_void_p
                getattr(egl, name).argtypes = []
            egl.eglGetCurrentSurface.restype = ctypes.c_void_p
            egl.eglGetCurrentSurface.argtypes = [ctypes.c_int]
            egl.eglMakeCurrent.restype = ctypes.c_uint
            egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
            self._egl = egl
        except (OSError, AttributeError):
            self._egl = None
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
        from vtkmodules.vtkCommonCore import VTK_FLOAT
        from vtkmodules.vtkCommonDataModel import vtkImageData, vtkPiecewiseFunction
        from vtkmodules.vtkRenderingCore import (vtkColorTransferFunction, vtkRenderer,
                                                 vtkRenderWindow, vtkVolume, vtkVolumeProperty)
        import vtkmodules.vtkRenderingOpenGL2 as gl2
        from vtkmodules.vtkRenderingVolumeOpenGL2 import vtkOpenGLGPUVolumeRayCastMapper

        _vtk = SimpleNamespace(
            ns=numpy_support, VTK_FLOAT=VTK_FLOAT, vtkImageData=vtkImageData,
            vtkPiecewiseFunction=vtkPiecewiseFunction,
            vtkColorTransferFunction=vtkColorTransferFunction, vtkRenderer=vtkRenderer,
            vtkRenderWindow=vtkRenderWindow, vtkVolume=vtkVolume,
            vtkVolumeProperty=vtkVolumeProperty, gl2=gl2,
            Mapper=vtkOpenGLGPUVolumeRayCastMapper)
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
        self.property = v.vtkVolumeProperty()
        self.property.SetInterpolationTypeToLinear()
        self.property.ShadeOff()
        self.actor = v.vtkVolume()
        self.actor.SetMapper(self.mapper)
        self.actor.SetProperty(self.property)
        self.renderer.AddVolume(self.actor)
        self._volume = None
        self._tf_key = None
        self._image = None
        self._size = None

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
        ctf = v.vtkColorTransferFunction()
        ctf.SetColorSpaceToRGB()
        ctf.ClampingOn()
        for s, r, g, b in tf.color_points:
            ctf.AddRGBPoint(float(s), float(r), float(g), float(b))
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
        step = float(step)
        if not np.isfinite(step) or step <= 0:
            raise ValueError(f"step must be a positive number of world units, got {step!r}")
        if scene.mode not in SUPPORTED_MODES:
            raise NotImplementedError(f"mode {scene.mode!r} is not supported by the VTK peer")
        if scene.shading and scene.mode != "isosurface":
            raise NotImplementedError("shaded modes other than isosurface are not supported by the VTK peer")
        if (scene.width, scene.height) != self._size:
            self.window.SetSize(scene.width, scene.height)
            self._size = (scene.width, scene.height)
        self._set_volume(scene.volume)
        self._set_classification(scene)
        self.mapper.SetSampleDistance(step)
        self._set_camera(scene)
        self._mode = scene.mode
        self._tf = scene.tf
        rng = self._image.GetPointData().GetScalars().GetRange()
        self._scalar_range = (float(rng[0]), float(rng[1]))

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

    def render(self, scene, step, repeats=5, warmup=1):
        """Render ``scene``; returns (image, median seconds per frame over ``repeats``
        frames after ``warmup`` untimed frames). Each timed frame is ``Render()`` plus
        the float read-back, so it ends only when the GL has finished."""
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


def render_vtk(scene, step, repeats=5, warmup=1, data_as_float=False):
    """Render ``scene`` through VTK's GPU ray caster at sample distance ``step`` (world
    units). Returns ``(image, seconds)``: image (H, W, 4) float32 premultiplied RGBA,
    row 0 on top; seconds the median time per frame over ``repeats`` frames after
    ``warmup`` frames. Uses one shared offscreen window per process."""
    return _peer(data_as_float).render(scene, step, repeats=repeats, warmup=warmup)


def renderer_string():
    """The OpenGL renderer VTK renders with in this process."""
    return _peer().renderer_string()
