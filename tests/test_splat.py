"""Splatting (technique "splat"), both kernels: GL against its NumPy reference, closed
forms, the error against exact, and what each kernel exists to show.

Tolerance of the tent kernel against its reference (``tent_tolerance``, per pixel). Both
follow the same sheets, samples and classification; GL works in float32. Each sheet
point ``p = o + t d`` is the sum of two terms about ``|o| + t`` long, so GL's is off by
``dp <= 8u (|o| + t)`` (u = 2^-24), which moves the field's value there by at most
``L dp``, ``L = sqrt(3) (max - min of the cell's corners) / (smallest spacing)`` being the
trilinear field's Lipschitz bound in that cell; summing at most 8 weighted values and
dividing by the weights' sum adds ``32u max |v|``. Classification turns a value error
into a colour or opacity error of at most the table's steepest slope, and the table
index carries ``2u`` times its entries; opacity correction turns an opacity error into
at most ``max(1, L_seg / unit)`` times as much (the derivative of ``1 - (1 - a)^x``) and
adds ``64u`` (test_shaders). Front-to-back blending weights are at most 1, so the errors
of the sheets a ray meets add at most linearly: the pixel's bound is that sum.

Tolerance of the Gaussian kernel (``gaussian_tolerance``). Both composite the same
splats in the same order; the kernel's exponent comes from the ray's offset at its
closest approach, whose float32 error is about eps * |q| (|q| the eye's distance from the
splat), so the exponent m^2 (at most cutoff^2) is off by about 2 cutoff eps |q| / sigma
and each splat's opacity relatively by as much; over the splats that reach a pixel
(opacity adds up to at most 1) that bounds the pixel's error, and every blend adds a
float32 rounding: bound = 2 cutoff eps |q|max / sigma_min + 1e-5. Where a ray passes
within that rounding of a kernel's cutoff (8 eps |q|max / sigma_min standard deviations:
the offset's few operations, a GPU's division at 2.5 ulp), GL may keep a kernel the
reference drops or the reverse; such a pixel may differ by the opacity of those kernels
(``reference.splat.cutoff_ambiguity``; a GPU did so at 2 of 147,456 pixels).
"""

import math

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Camera, Scene, TransferFunction, Volume, metrics, reference
from dvr_gl import data as bundled
from dvr_gl.reference.common import box_rays, plane_inside, slab_segment
from dvr_gl.reference.splat import cutoff_ambiguity
from dvr_gl.techniques import proxy, splat

from test_raycast import TF, VOLUME, blobs, cameras

EPS32 = 2.0 ** -23
U32 = 2.0 ** -24


def tent_tolerance(plan, position=True):
    """(H, W, 1): the bound on |GL - reference| of the module docstring, per pixel;
    ``position=False`` leaves out the sheet points' position error (two GL renders of
    the same sheets)."""
    scene = plan.scene
    volume, cam, sheets = scene.volume, scene.camera, plan.sheets
    o, d, t0, t1 = box_rays(scene)
    cos_theta = d @ cam.forward
    values = volume.values()
    nz, ny, nx = values.shape
    eight = [values[z:z + nz - 1, y:y + ny - 1, x:x + nx - 1] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    lipschitz = math.sqrt(3) * (np.maximum.reduce(eight) - np.minimum.reduce(eight)) / volume.min_spacing
    biggest = float(np.abs(values).max())
    table = plan.lut.table.astype(np.float64)
    slope = float(np.abs(np.diff(table, axis=0)).max()) * plan.lut.scale
    fixed = 2 * U32 * plan.lut.size * slope / plan.lut.scale + 64 * U32
    bound = np.zeros(len(o))
    reach = np.linalg.norm(o, axis=1)
    for k in range(sheets.count):
        t = (sheets.far_depth - k * sheets.spacing) / cos_theta
        rows = np.nonzero(plane_inside(k, sheets.count, t, t0, t1))[0]
        near = (sheets.far_depth - (k + 1) * sheets.spacing) / cos_theta[rows]
        far = (sheets.far_depth - (k - 1) * sheets.spacing) / cos_theta[rows]
        a, b = slab_segment(k, sheets.count, t[rows], near, far, t0[rows], t1[rows])
        gain = np.maximum(1.0, (b - a) / scene.tf.unit_distance)
        cell = np.clip(np.floor((o[rows] + t[rows, None] * d[rows]) / volume.spacing).astype(int), 0,
                       np.array([nx - 2, ny - 2, nz - 2]))
        dp = 8 * U32 * (reach[rows] + t[rows]) if position else 0.0
        value_error = lipschitz[cell[:, 2], cell[:, 1], cell[:, 0]] * dp + 32 * U32 * biggest
        bound[rows] += gain * slope * value_error + fixed
    # rays that cross no sheet get 3D slicing's gap pass: at most three pieces of a chord
    # two sheet distances long, each bounded as one slice
    from test_slicing import per_slice_tolerance
    gap = (bound == 0) & (t1 > t0)
    bound[gap] = 3 * per_slice_tolerance(plan.gap) * max(1.0, 2 * sheets.spacing / scene.tf.unit_distance)
    return bound.reshape(scene.height, scene.width, 1)


def gaussian_tolerance(scene, plan):
    """(H, W, 1): the float32 bound, plus the opacity of kernels within rounding of
    their cutoff at each pixel."""
    lo, hi = scene.volume.bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    far = float(np.linalg.norm(corners - scene.camera.eye, axis=1).max())
    rounding = EPS32 * far / float(plan.sigma.min())
    return 2 * plan.cutoff * rounding + 1e-5 + cutoff_ambiguity(plan, 8 * rounding)[..., None]


def bound(scene, plan):
    """The bound on |GL - reference| of the plan's kernel, (H, W, 1)."""
    return tent_tolerance(plan) if plan.kernel == "tent" else gaussian_tolerance(scene, plan)


def assert_matches_reference(renderer, scene, **options):
    img = renderer.render(scene, technique="splat", **options)
    ref = dvr_gl.reference.render(scene, technique="splat", **options)
    plan = splat.make_plan(scene, **options)
    assert ref[..., 3].max() > 0.1
    tol = bound(scene, plan)
    assert np.all(np.abs(img - ref) <= tol), (np.abs(img - ref).max(), np.min(tol))
    return img


# -- the tent kernel ---------------------------------------------------------------------

ANISOTROPIC = blobs(spacing=(1.0, 0.5, 1.7))


@pytest.mark.parametrize("shading", [False, True], ids=["unlit", "lit"])
@pytest.mark.parametrize("data,options", [("isotropic", {}), ("anisotropic", {"density": 2})], ids=str)
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside", "eye_on_face_plane", "axis_aligned",
                                    "diagonal_45"])
def test_tent_matches_reference(renderer, camera, data, options, shading):
    """Six views (perspective, orthographic, eye inside, on a face plane, along an axis, at
    45 degrees) of the smooth blobs, isotropic and with spacing 1 : 0.5 : 1.7 at density 2,
    unlit and lit, within the per-pixel bound of the module docstring (lit: times the
    brightest lit colour, plus the lighting's float32 error)."""
    from test_point_lighting import brightest, lighting_error
    volume = VOLUME if data == "isotropic" else ANISOTROPIC
    scene = Scene(volume, TF, cameras(volume)[camera], 40, 32, shading=shading)
    gl = renderer.render(scene, technique="splat", **options)
    ref = reference.render(scene, technique="splat", **options)
    plan = splat.make_plan(scene, **options)
    assert ref[..., 3].max() > 0.3 and plan.kernel == "tent"
    tol = tent_tolerance(plan) * brightest(scene) + lighting_error(scene) if shading else tent_tolerance(plan)
    assert np.all(np.abs(gl - ref) <= tol), (np.abs(gl - ref).max(), float(np.max(np.abs(gl - ref) / tol)))


@pytest.mark.parametrize("target", ["rgba16f", "rgba8"])
def test_tent_low_precision_targets_match_the_rounding_model(renderer, target):
    """Each sheet is blended into a half-float or 8-bit target, which rounds every time;
    the reference rounds as the target does (``blend_under``). A value that the two
    arithmetics put on either side of a rounding boundary differs by one unit in the last
    place, and blending under later sheets never enlarges a difference: at most one unit
    per sheet, on top of the float32 bound."""
    ulp = {"rgba16f": 2.0 ** -11, "rgba8": 1 / 255}[target]
    for camera in ("perspective", "ortho"):
        scene = Scene(VOLUME, TF, cameras(VOLUME)[camera], 40, 32)
        gl = renderer.render(scene, technique="splat", target=target)
        ref = reference.render(scene, technique="splat", target=target)
        plan = splat.make_plan(scene, target=target)
        assert ref[..., 3].max() > 0.5
        assert np.all(np.abs(gl - ref) <= tent_tolerance(plan) + ulp * plan.count)
        exact32 = renderer.render(scene, technique="splat")
        assert np.abs(gl - exact32).max() > 0.2 * ulp       # the target does round


def test_tent_matches_reference_on_the_ct_head(renderer):
    """The CT head (large jumps between neighbours: a looser bound where they are) from
    outside, orthographically and from inside."""
    head = bundled.ct_head()
    lo, hi = head.bounds
    c = (lo + hi) / 2
    for cam in (dvr_gl.default_camera(head, azimuth=30, elevation=15),
                Camera(c + np.array([0, 40, 300.0]), c, ortho_height=220),
                Camera(c + np.array([10, 5, 20.0]), c + np.array([30, 0, -60.0]), fov=70)):
        assert_matches_reference(renderer, Scene(head, bundled.ct_head_tf(), cam, 64, 56))


def constant_box(spacing=(1.0, 1.0, 1.0), n=(9, 10, 11), alpha=0.3, unit=2.0):
    volume = Volume(np.full(n, 7.0, np.float32), spacing=spacing)
    tf = TransferFunction([(0, 0.9, 0.6, 0.2), (10, 0.9, 0.6, 0.2)], [(0, alpha), (10, alpha)], unit_distance=unit)
    return volume, tf


@pytest.mark.parametrize("view", ["along_z_ortho", "oblique", "eye_inside", "anisotropic"])
def test_tent_constant_box_closed_form(renderer, view):
    """A constant field: every sheet point has the value (the tents' weights add up to 1,
    and the sum over them divided by it is exact), and the pieces of a ray that the sheets
    stand for tile its chord, whatever the per-pixel distance between sheets under
    perspective. So a pixel whose ray meets a sheet inside the box has
    ``A = 1 - (1 - alpha)^(chord / u)`` and colour ``c A``; so does one that meets none
    (a chord shorter than the sheets' distance, at the silhouette), through 3D slicing's
    gap pass on the same planes (it used to stay empty). Bound as the hard cases': 64u
    per segment plus the chord's float32 error times tau."""
    spacing = (1.0, 0.6, 1.7) if view == "anisotropic" else (1.0, 1.0, 1.0)
    volume, tf = constant_box(spacing)
    lo, hi = volume.bounds
    c = (lo + hi) / 2
    cam = {"along_z_ortho": Camera(c + [0.3, 0.2, 40.0], c + [0.3, 0.2, 0.0], ortho_height=14.0),
           "oblique": dvr_gl.default_camera(volume, azimuth=35, elevation=25),
           "eye_inside": Camera(c + [1.0, 0.5, 1.5], c - [3.0, 1.0, 1.0], fov=80),
           "anisotropic": dvr_gl.default_camera(volume, azimuth=-50, elevation=35)}[view]
    scene = Scene(volume, tf, cam, 48, 40)
    img = renderer.render(scene, technique="splat")
    plan = splat.make_plan(scene)
    o, d, t0, t1 = box_rays(scene)
    chord = np.maximum(t1 - t0, 0.0)
    sheets = plan.sheets
    cos_theta = d @ cam.forward
    met = np.zeros(len(o), bool)
    for k in range(sheets.count):
        met |= plane_inside(k, sheets.count, (sheets.far_depth - k * sheets.spacing) / cos_theta, t0, t1)
    want = (-np.expm1(chord / tf.unit_distance * math.log1p(-0.3))).reshape(40, 48)
    assert (~met & (chord > 0)).any() or view != "oblique"        # gap rays are in the test
    tau = -math.log1p(-0.3) / tf.unit_distance
    segments = float(chord.max()) / sheets.spacing + 3
    tol = 64 * U32 * segments + tau * 8 * U32 * float(t1[chord > 0].max())
    assert want.max() > 0.5 and met.sum() > 0.3 * met.size
    assert np.abs(img[..., 3] - want).max() <= tol
    assert np.allclose(img[..., :3], img[..., 3:] * np.array([0.9, 0.6, 0.2]), atol=1e-6)


@pytest.mark.parametrize("name", ["perspective", "anisotropic"])
def test_tent_error_falls_with_density_at_second_order(name):
    """Against exact, in the reference with the exact TF: each halving of the distance
    between sheets (density 1, 2, 4; and sheet_spacing) cuts the error about four times,
    as the midpoint rule's does; the sheets are the ray caster's samples at that step,
    so the tent is as accurate as the float64 midpoint marcher (within 1.5x)."""
    volume = VOLUME if name == "perspective" else ANISOTROPIC
    scene = Scene(volume, TF, cameras(volume)["perspective"], 40, 32)
    exact = reference.exact(scene)
    errors = [metrics.rmse(reference.render(scene, technique="splat", density=k, lut_exact=True), exact)
              for k in (1, 2, 4)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert orders.min() > 1.6, (errors, orders)
    h = volume.min_spacing
    assert metrics.rmse(reference.render(scene, technique="splat", sheet_spacing=h / 2, lut_exact=True),
                        exact) == pytest.approx(errors[1], rel=1e-9)
    marcher = metrics.rmse(reference.render(scene, technique="raycast", step=h, lut_exact=True), exact)
    assert errors[0] <= 1.5 * marcher, (errors[0], marcher)


def test_tent_gl_error_falls_with_density_on_the_ct_head(renderer):
    """The issue's must-show in small (48x48; docs/notes/points.md has it at 128x128 beside VTK):
    density 2 at most half density 1's error against exact."""
    head = bundled.ct_head()
    scene = Scene(head, bundled.ct_head_tf(), dvr_gl.default_camera(head, azimuth=30, elevation=15), 48, 48)
    exact = reference.exact(scene)
    one, two = (metrics.rmse(renderer.render(scene, technique="splat", density=k), exact) for k in (1, 2))
    assert two < 0.5 * one, (one, two)


def two_band_tf():
    """Opaque only between two transparent bands (values below 20, and 55 to 70): a
    partial sum of a cell's corners (what skipping would leave without dividing by the
    weights) lands in the opaque band where the field itself is transparent."""
    return TransferFunction(color=[(0, 0.2, 0.5, 1.0), (100, 1.0, 0.8, 0.2)],
                            opacity=[(20, 0.0), (30, 0.6), (50, 0.6), (55, 0.0), (70, 0.0), (80, 0.4)],
                            unit_distance=1.0)


def two_slabs():
    """Value 60 (in two_band_tf's upper transparent band) below z = 6, 40 (opaque) above: the
    cells a layer or two below the interface are transparent, with some corners splatted
    (those of the interface cells) and some not."""
    data = np.full((12, 13, 14), 60.0, np.float32)
    data[6:] = 40.0
    return Volume(data, spacing=(1.0, 0.9, 1.1))


@pytest.mark.parametrize("data", ["blobs", "two_slabs"])
@pytest.mark.parametrize("camera", ["perspective", "eye_inside"])
def test_skipping_transparent_samples_changes_no_pixel(renderer, data, camera):
    """Samples all of whose cells are transparent are not splatted: far fewer samples, the
    reference's image bit for bit the same, GL's within the rounding of summing the same
    tents in other groups (``tent_tolerance`` without the position error). Without the
    division by the weights' sum, a transparent cell with splatted and skipped corners
    would take a partial sum, between 0 and 60 on the two slabs: opaque."""
    volume = VOLUME if data == "blobs" else two_slabs()
    scene = Scene(volume, two_band_tf(), cameras(volume)[camera], 40, 32)
    skipped = splat.make_plan(scene)
    every = splat.make_plan(scene, skip_empty=False)
    assert skipped.samples.count < 0.7 * every.samples.count == 0.7 * volume.data.size
    ref_skip = reference.render(scene, technique="splat")
    np.testing.assert_array_equal(ref_skip, reference.render(scene, technique="splat", skip_empty=False))
    gl_skip = renderer.render(scene, technique="splat")
    gl_every = renderer.render(scene, technique="splat", skip_empty=False)
    assert ref_skip[..., 3].max() > 0.3
    assert np.all(np.abs(gl_skip - gl_every) <= tent_tolerance(skipped, position=False))
    assert np.array_equal(gl_skip[..., 3] > 0, gl_every[..., 3] > 0)


def test_the_samples_splatted_are_the_corners_of_visible_cells():
    """By brute force on a small volume: a sample is splatted exactly when one of its
    cells has a value range with non-zero opacity in the table; an empty TF splats
    nothing and draws nothing."""
    volume = blobs(shape=(7, 8, 9))
    tf = two_band_tf()
    plan = splat.make_plan(Scene(volume, tf, dvr_gl.default_camera(volume), 16, 16))
    v = volume.values()
    want = np.zeros(v.shape, bool)
    for z, y, x in np.ndindex(6, 7, 8):
        cell = v[z:z + 2, y:y + 2, x:x + 2]
        if plan.lut.max_opacity_between(cell.min(), cell.max()) > 0:
            want[z:z + 2, y:y + 2, x:x + 2] = True
    np.testing.assert_array_equal(plan.samples.mask, want)
    assert 0 < want.sum() < want.size
    empty = TransferFunction([(0, 1, 1, 1), (100, 1, 1, 1)], [(0, 0.0), (100, 0.0)])
    blank = Scene(volume, empty, dvr_gl.default_camera(volume), 16, 16)
    assert splat.make_plan(blank).samples.count == 0
    with dvr_gl.Renderer() as r:
        assert r.render(blank, technique="splat").max() == 0.0


def test_nan_samples_mask_their_cells(renderer):
    """z-layers 5.. are NaN: with masking the domain is the box z <= 4, whose chord gives
    the closed form (as the hard case for the other techniques). A sheet whose point
    falls in a masked cell drops its piece of the ray, one in a valid cell keeps it
    whole, so beyond float32 rounding the bound adds tau times the longest piece."""
    data = np.full((9, 7, 8), 10.0, np.float32)
    data[5:] = np.nan
    vol = Volume(data, mask_nonfinite=True)
    tf = TransferFunction(color=[(0, 0.2, 0.6, 1.0)], opacity=[(0, 0.3)], unit_distance=1.0)
    cam = dvr_gl.default_camera(vol, azimuth=30, elevation=20)
    scene = Scene(vol, tf, cam, 32, 32)
    o, d = cam.rays(32, 32)
    from dvr_gl.reference.common import ray_box
    t0, t1 = ray_box(o.reshape(-1, 3), d.reshape(-1, 3), np.zeros(3), np.array([7.0, 6.0, 4.0]))
    chord = np.maximum(t1 - t0, 0).reshape(32, 32)
    want = -np.expm1(chord * np.log1p(-0.3))
    gl = renderer.render(scene, technique="splat")
    ref = reference.render(scene, technique="splat")
    plan = splat.make_plan(scene)
    longest = 1.5 * plan.step / float((d.reshape(-1, 3) @ cam.forward).min())
    tau = -np.log1p(-0.3)
    assert want.max() > 0.5 and np.isfinite(gl).all()
    assert np.abs(gl[..., 3] - want).max() <= 64 * U32 * (float(chord.max()) / plan.step + 3) + tau * longest
    assert np.all(np.abs(gl - ref) <= tent_tolerance(plan))


def test_quads_cover_exactly_the_cut_through_a_run_of_supports():
    """The splat vertex shader's rectangle (its NumPy twin ``run_quads``) against the cut
    of 3D slicing's plane-box code through the run's whole support (the box from one
    spacing before its first sample to one after its last): the same bounding rectangle,
    for random views, spacings, run lengths and sheet offsets, single samples included."""
    rng = np.random.default_rng(7)
    for _ in range(60):
        forward = rng.normal(size=3)
        forward /= np.linalg.norm(forward)
        if rng.random() < 0.2:                       # along an axis, and just off it
            forward = np.eye(3)[rng.integers(3)] + rng.choice([0.0, 1e-7]) * rng.normal(size=3)
            forward /= np.linalg.norm(forward)
        spacing = rng.uniform(0.3, 2.0, 3)
        axis = int(rng.integers(3))
        right = np.cross(forward, [0.3, 1.0, 0.2])
        right /= np.linalg.norm(right)
        u, v = splat.run_frame(forward, axis, right)
        table = splat.section_table(spacing, forward, u, v)
        length = int(rng.integers(1, 6))
        lo = -spacing
        hi = spacing.copy()
        hi[axis] += (length - 1) * spacing[axis]
        corners = proxy.box_corners(lo, hi)
        depth = corners @ forward
        for delta0 in rng.uniform(depth.min(), depth.max(), 5):
            quad = splat.run_quads(table, forward, axis, u, v, spacing, np.array([length]), np.array([delta0]))[0]
            vertices, counts = proxy.plane_polygons(corners, forward, np.array([delta0]))
            if counts[0] == 0:
                continue
            cut = vertices[0, :counts[0]] - delta0 * forward
            want = [(cut @ u).min(), (cut @ u).max(), (cut @ v).min(), (cut @ v).max()]
            np.testing.assert_allclose(quad, want, atol=1e-9 * float(np.abs(hi).max()))


def test_gaussian_matches_reference(renderer):
    head = bundled.ct_head()
    lo, hi = head.bounds
    c = (lo + hi) / 2
    tf = bundled.ct_head_tf()
    for cam, options in ((dvr_gl.default_camera(head, azimuth=30, elevation=15), {}),
                         (Camera(c + np.array([0, 40, 300.0]), c, ortho_height=220), {"radius": 0.7}),
                         (Camera(c + np.array([10, 5, 20.0]), c + np.array([30, 0, -60.0]), fov=70), {})):
        assert_matches_reference(renderer, Scene(head, tf, cam, 64, 56), kernel="gaussian", **options)
    field = bundled.synthetic(24)        # anisotropic resampling at density 2
    field = Volume(field.data, spacing=(1.0, 0.6, 1.8))
    cam = dvr_gl.default_camera(field, azimuth=35, elevation=25)
    assert_matches_reference(renderer, Scene(field, bundled.synthetic_tf(), cam, 48, 48), kernel="gaussian", density=2)


def test_options_are_checked():
    vol = bundled.ct_head()
    scene = Scene(vol, bundled.ct_head_tf(), dvr_gl.default_camera(vol), 16, 16)
    for kwargs, words in (({"density": 0}, "density"), ({"density": 2.5}, "density"),
                          ({"kernel": "box"}, "kernel must be one of tent, gaussian"),
                          ({"radius": 0.5}, "radius size the Gaussian kernel"),
                          ({"cutoff": 2.0}, "cutoff size the Gaussian kernel"),
                          ({"kernel": "gaussian", "radius": 0}, "radius"),
                          ({"kernel": "gaussian", "cutoff": float("inf")}, "cutoff"),
                          ({"kernel": "gaussian", "sheet_spacing": 1.0}, "sheet_spacing is the tent kernel's"),
                          ({"kernel": "gaussian", "skip_empty": False}, "skip_empty is the tent kernel's"),
                          ({"sheet_spacing": -1.0}, "sheet_spacing"),
                          ({"sheet_spacing": 1.0, "density": 2}, "give density or sheet_spacing"),
                          ({"step": 1.0}, "step"), ({"target": "x"}, "target")):
        with pytest.raises(ValueError, match=words):
            splat.make_plan(scene, **kwargs)
    with pytest.raises(TypeError, match="skip_empty"):
        splat.make_plan(scene, skip_empty=1)
    with pytest.raises(ValueError, match="composite"):
        splat.make_plan(scene.replace(mode="mip"))
    ball = Scene(bundled.delaunay_ball(), bundled.synthetic_tf(), scene.camera, 16, 16)
    with pytest.raises(ValueError, match="density applies to grids"):
        splat.make_plan(ball, density=2)
    with pytest.raises(ValueError, match="a TetMesh is splatted with kernel 'gaussian'"):
        splat.make_plan(ball, kernel="tent")
    assert splat.make_plan(ball).kernel == "gaussian" and splat.make_plan(scene).kernel == "tent"


def one_sample(radius, spacing=(1.0, 1.0, 1.0), alpha=0.2):
    v = np.zeros((9, 9, 9))
    v[4, 4, 4] = 1.0
    vol = Volume(v, spacing=spacing)
    tf = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.0), (1, alpha)], unit_distance=2.0)
    return vol, tf


@pytest.mark.parametrize("spacing", [(1.0, 1.0, 1.0), (1.5, 0.7, 2.5)])
def test_footprint_integrates_to_the_kernel(renderer, spacing):
    """One sample, seen orthographically: the optical depth summed over the image times the
    pixel area is the sample's extinction times its cell volume (the kernel has unit
    integral once renormalised for its truncation), from any direction."""
    vol, tf = one_sample(0.7, spacing)
    c = (vol.bounds[0] + vol.bounds[1]) / 2
    tau_v = -math.log1p(-0.2) / 2.0 * float(np.prod(spacing))
    for direction in ((0, 0, 1.0), (1.0, 0.6, 0.3), (0.2, -1.0, 0.5)):
        d = np.array(direction) / np.linalg.norm(direction)
        up = (0, 1, 0) if abs(d[1]) < 0.9 else (1, 0, 0)
        cam = Camera(c + 30 * d, c, up=up, ortho_height=14.0)
        scene = Scene(vol, tf, cam, 160, 160)
        pixel_area = (14.0 / 160) ** 2
        for image in (renderer.render(scene, technique="splat", kernel="gaussian", radius=0.7),
                      dvr_gl.reference.render(scene, technique="splat", kernel="gaussian", radius=0.7)):
            od = -np.log1p(-np.asarray(image[..., 3], np.float64))
            assert od.sum() * pixel_area == pytest.approx(tau_v, rel=2e-3)


def test_gaussian_constant_box_closed_form(renderer):
    """A constant field: at radius 0.7 the kernels' sum is flat to 1e-4 inside the box, so
    a ray through the middle sees the closed form 1 - (1 - alpha)^(L / u)."""
    n = 17
    vol = Volume(np.full((n, n, n), 0.5))
    tf = TransferFunction([(0, 0.9, 0.6, 0.2), (1, 0.9, 0.6, 0.2)], [(0, 0.2), (1, 0.2)], unit_distance=4.0)
    scene = Scene(vol, tf, Camera((8.0, 8.0, 40.0), (8.0, 8.0, 8.0), ortho_height=24.0), 48, 48)
    img = renderer.render(scene, technique="splat", kernel="gaussian", radius=0.7)
    # the samples' trapezoid weights carry exactly the box's depth; the kernels reach past
    # it, and the ray through the middle collects all of it
    want = 1 - (1 - 0.2) ** (16.0 / 4.0)
    assert img[24, 24, 3] == pytest.approx(want, abs=2e-3)
    assert np.allclose(img[..., :3], img[..., 3:] * np.array([0.9, 0.6, 0.2]), atol=1e-6)


def test_gaussian_holes_against_blur_and_density():
    """Against exact: too small a kernel leaves holes (stripes between sample planes), too
    large a kernel blurs; the default lies between, and density=2 lowers the error."""
    vol = bundled.synthetic(32)
    scene = Scene(vol, bundled.synthetic_tf(), dvr_gl.default_camera(vol, azimuth=25, elevation=20), 64, 64)
    exact = dvr_gl.reference.exact(scene)
    with dvr_gl.Renderer() as r:
        rmse = {k: math.sqrt(np.mean((r.render(scene, technique="splat", kernel="gaussian", radius=k) - exact) ** 2))
                for k in (0.2, splat.DEFAULT_RADIUS, 1.0)}
        dense = math.sqrt(np.mean((r.render(scene, technique="splat", kernel="gaussian", density=2) - exact) ** 2))
    assert rmse[splat.DEFAULT_RADIUS] < rmse[0.2] and rmse[splat.DEFAULT_RADIUS] < rmse[1.0], rmse
    assert dense < 0.7 * rmse[splat.DEFAULT_RADIUS], (dense, rmse)


def test_gaussian_splats_only_samples_with_opacity_in_depth_order(renderer):
    vol = bundled.ct_head()
    tf = bundled.ct_head_tf()
    scene = Scene(vol, tf, dvr_gl.default_camera(vol, azimuth=30, elevation=15), 32, 32)
    plan = splat.make_plan(scene, kernel="gaussian")
    assert plan.splats.count == int((tf.opacity(vol.values()) > 0).sum())
    eye = scene.camera.eye - vol.bounds[0]
    dist = np.linalg.norm(plan.splats.points[plan.order] - eye, axis=1)
    assert np.all(np.diff(dist) <= 1e-3)                      # farthest first
    empty = TransferFunction([(0, 1, 1, 1), (4000, 1, 1, 1)], [(0, 0.0), (4000, 0.0)])
    blank = scene.replace(tf=empty)
    assert splat.make_plan(blank, kernel="gaussian").splats.count == 0
    assert renderer.render(blank, technique="splat", kernel="gaussian").max() == 0.0


def test_order_is_made_once_per_view(renderer):
    """The samples once per volume and TF, the order once per view, for both kernels."""
    vol = bundled.ct_head()
    scene = Scene(vol, bundled.ct_head_tf(), dvr_gl.default_camera(vol), 16, 16)
    turned = scene.replace(camera=dvr_gl.default_camera(vol, azimuth=40))
    first = splat.make_plan(scene, kernel="gaussian", tables=renderer.tables)
    again = splat.make_plan(scene, kernel="gaussian", tables=renderer.tables)
    assert again.splats is first.splats and again.order is first.order
    other = splat.make_plan(turned, kernel="gaussian", tables=renderer.tables)
    assert other.splats is first.splats and other.order is not first.order
    first = splat.make_plan(scene, tables=renderer.tables)
    again = splat.make_plan(scene, tables=renderer.tables)
    assert again.samples is first.samples and again.sheets is first.sheets
    other = splat.make_plan(turned, tables=renderer.tables)
    assert other.samples is first.samples and other.sheets is not first.sheets


def test_mesh_points_are_splatted(renderer):
    """A tetrahedral mesh is splatted at its points: each kernel carries the point's lumped
    volume (the integral of its basis function) and is as wide as its edges on average,
    so over a far orthographic image the optical depth adds up to the integral of the
    extinction (a constant field: tau times the volume); GL matches the reference on the
    Delaunay ball."""
    from dvr_gl import TetMesh
    cube = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float) * 2.0
    six = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
    mesh = TetMesh(cube, six, np.full(8, 0.5))
    tf = TransferFunction([(0, 1, 1, 1), (1, 1, 1, 1)], [(0, 0.05), (1, 0.05)], unit_distance=1.0)
    scene = Scene(mesh, tf, Camera((1.0, 1.3, 30.0), (1.0, 1.0, 1.0), ortho_height=9.0), 180, 180)
    plan = splat.make_plan(scene)
    assert plan.splats.count == 8
    assert plan.splats.samples[:, 3].sum() == pytest.approx(-math.log1p(-0.05) * 8.0, rel=1e-6)
    for image in (renderer.render(scene, technique="splat"), dvr_gl.reference.render(scene, technique="splat")):
        od = -np.log1p(-np.asarray(image[..., 3], np.float64))
        assert od.sum() * (9.0 / 180) ** 2 == pytest.approx(-math.log1p(-0.05) * 8.0, rel=2e-3)
    ball = bundled.delaunay_ball()
    scene = Scene(ball, bundled.synthetic_tf(), dvr_gl.default_camera(ball, azimuth=20, elevation=10), 56, 56)
    img = assert_matches_reference(renderer, scene)
    exact = dvr_gl.reference.exact(scene)
    # the right picture (measured 0.068: Gaussian kernels on 4000 scattered points blur
    # the linear field; a black or noisy image is above 0.15)
    assert math.sqrt(np.mean((img - exact) ** 2)) < 0.1 and img[..., 3].max() > 0.3



def test_gaussian_sprites_larger_than_the_point_size_limit(renderer):
    """A coarse mesh (30 scattered points) at 384x384: kernels one mean edge wide make
    sprites of up to 300 pixels, more than llvmpipe's point-size limit (255), which cut
    them and left GL 0.05 off the reference. The sprites are squares made by a geometry
    shader now, of any size: GL within the Gaussian kernel's bound of the reference."""
    rng = np.random.default_rng(2)
    points = rng.uniform(-1, 1, (30, 3))
    mesh = dvr_gl.TetMesh.from_points(points, rng.random(30))
    tf = TransferFunction([(0, 0.9, 0.5, 0.1), (1, 0.1, 0.5, 0.9)], [(0, 0.3), (1, 0.6)], unit_distance=0.5)
    scene = Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=30, elevation=20), 384, 384)
    plan = splat.make_plan(scene)
    img = renderer.render(scene, technique="splat")
    ref = dvr_gl.reference.render(scene, technique="splat")
    assert ref[..., 3].max() > 0.3
    assert np.all(np.abs(img - ref) <= gaussian_tolerance(scene, plan))
