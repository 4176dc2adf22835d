"""The exact image of several volumes (dvr_gl/reference/exact_layers.py) against closed
forms and against the one-volume exact image (dvr_gl/reference/exact.py).

Closed forms: constant boxes under constant transfer functions (or label colours) make
the mixture's extinction and colour constant between the points where an orthographic
ray enters or leaves a box, so the pixel is a finite sum over those segments:
``C = sum_k T_k c_k (1 - exp(-tau_k L_k))``, ``T_{k+1} = T_k exp(-tau_k L_k)``, with
``tau_k`` the sum of the boxes' taus and ``c_k`` their tau-weighted mean colour. The
boxes' entries and exits are computed here from the faces' world planes.

Small images only: the file runs in a few seconds."""

import math

import numpy as np
import pytest

from dvr_gl import Camera, LabelColors, Layer, Scene, Surface, TransferFunction, Volume
from dvr_gl.reference import exact_layers
from dvr_gl.reference.exact import exact

def render_layers(scene):
    """The layer integrator on any scene, one volume included (``exact`` sends it only
    scenes with layers)."""
    with np.errstate(all="ignore"):
        return exact_layers.render_layers(scene)


def render(scene):
    return exact(scene, cache=False)


def constant_tf(alpha, color, unit_distance=1.0):
    return TransferFunction([(0.0, *color), (1.0, *color)], [(0.0, alpha), (1.0, alpha)], unit_distance=unit_distance)


def rotation(axis, angle, shift=(0.0, 0.0, 0.0)):
    """4x4 rigid motion: a rotation by ``angle`` about the unit ``axis``, then ``shift``."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = R, shift
    return m


def moved_camera(camera, layer):
    """The camera that sees ``layer`` placed as ``camera`` sees its volume unplaced."""
    kw = dict(ortho_height=camera.ortho_height) if camera.is_ortho else dict(fov=camera.fov)
    return Camera(layer.to_world([camera.eye])[0], layer.to_world([camera.target])[0], layer.rotation @ camera.up, **kw)


def local_camera(camera, layer):
    """The camera that sees ``layer``'s volume unplaced as ``camera`` sees it placed."""
    kw = dict(ortho_height=camera.ortho_height) if camera.is_ortho else dict(fov=camera.fov)
    return Camera(layer.to_local([camera.eye])[0], layer.to_local([camera.target])[0],
                  layer.direction_to_local(camera.up), **kw)


def box_interval(layer, o, d):
    """Where rays o + t d (t >= 0) are inside the layer's box: from its faces' world planes."""
    lo, hi = layer.volume.bounds
    t0, t1 = np.zeros(len(o)), np.full(len(o), np.inf)
    for k in range(3):
        n = layer.rotation[:, k]                       # the local axis k in the world
        height = (o - layer.translation) @ n           # local coordinate k of the origin
        speed = d @ n
        with np.errstate(divide="ignore"):
            ta, tb = (lo[k] - height) / speed, (hi[k] - height) / speed
        t0 = np.maximum(t0, np.minimum(ta, tb))
        t1 = np.minimum(t1, np.maximum(ta, tb))
    return t0, t1


def piecewise_constant(o, d, media, t_end=None):
    """The pixels of rays through boxes of constant medium: ``media`` is a list of
    (layer, tau, colour, opaque); an opaque box ends the ray at its entry with the mean
    colour of the boxes opaque there."""
    n = len(o)
    spans = [box_interval(layer, o, d) for layer, *_ in media]
    if t_end is not None:
        spans = [(a, np.minimum(b, t_end)) for a, b in spans]
    out = np.zeros((n, 4))
    for r in range(n):
        cuts = sorted({v for a, b in spans for v in (a[r], b[r]) if b[r] > a[r]})
        T, C = 1.0, np.zeros(3)
        for ta, tb in zip(cuts[:-1], cuts[1:]):
            inside = [m for m, (a, b) in zip(media, spans) if a[r] <= 0.5 * (ta + tb) <= b[r]]
            if not inside:
                continue
            opaque = [m for m in inside if m[3] and abs(box_interval(m[0], o[r:r + 1], d[r:r + 1])[0][0] - ta) < 1e-12]
            if opaque:
                C = C + T * np.mean([m[2] for m in opaque], axis=0)
                T = 0.0
                break
            tau = sum(m[1] for m in inside)
            color = sum(m[1] * np.asarray(m[2]) for m in inside) / tau
            C = C + T * color * -math.expm1(-tau * (tb - ta))
            T *= math.exp(-tau * (tb - ta))
        out[r, :3], out[r, 3] = C, 1.0 - T
    return out


def constant_volume(shape, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)):
    return Volume(np.full(shape, 0.5), spacing=spacing, origin=origin)


TOP = Camera((1.3, 1.1, 30.0), (1.3, 1.1, 0.0), (0, 1, 0), ortho_height=6.0)


# ----------------------------------------------------------------------------- closed forms
def _two_boxes():
    """Two constant boxes, the second turned about an oblique axis, and their media."""
    a = Layer(constant_volume((3, 4, 5), spacing=(0.6, 0.7, 0.8)), constant_tf(0.3, (0.9, 0.2, 0.1), 0.5))
    b = Layer(constant_volume((4, 3, 3), spacing=(1.1, 0.9, 0.5)), constant_tf(0.6, (0.1, 0.3, 0.9), 2.0),
              rotation((1.0, 2.0, 0.5), 0.7, (0.8, -0.4, 0.6)))
    taus = [-math.log1p(-0.3) / 0.5, -math.log1p(-0.6) / 2.0]
    return a, b, [(a, taus[0], (0.9, 0.2, 0.1), False), (b, taus[1], (0.1, 0.3, 0.9), False)]


@pytest.mark.parametrize("clip", [False, True])
def test_two_constant_boxes_one_rotated_against_closed_form(clip):
    a, b, media = _two_boxes()
    kw = dict(clip_planes=[((1.0, 1.0, 1.0), (0.3, -1.0, 0.4))]) if clip else {}
    scene = Scene.from_layers([a, b], TOP, width=24, height=20, **kw)
    o, d = (x.reshape(-1, 3) for x in TOP.rays(24, 20))
    if clip:   # the plane is a third "box" that keeps what it keeps: cut each span to it
        normal = np.array([0.3, -1.0, 0.4])
        along, height = d @ normal, (o - 1.0) @ normal
        cut = -height / along
        keep0 = np.where(along > 0, cut, 0.0)
        keep1 = np.where(along < 0, cut, np.inf)
        expected = _clipped(o, d, media, keep0, keep1)
    else:
        expected = piecewise_constant(o, d, media)
    image = render(scene).reshape(-1, 4)
    assert np.count_nonzero(expected[:, 3]) > 50                  # many rays see the data
    np.testing.assert_allclose(image, expected, rtol=0, atol=1e-9)


def _clipped(o, d, media, keep0, keep1):
    """``piecewise_constant`` with every box cut to [keep0, keep1] per ray."""
    out = np.zeros((len(o), 4))
    for r in range(len(o)):
        class Cut:
            pass
        sub = []
        for layer, tau, color, opaque in media:
            a, b = box_interval(layer, o[r:r + 1], d[r:r + 1])
            a, b = max(a[0], keep0[r]), min(b[0], keep1[r])
            sub.append((a, b, tau, color))
        cuts = sorted({v for a, b, *_ in sub for v in (a, b) if b > a})
        T, C = 1.0, np.zeros(3)
        for ta, tb in zip(cuts[:-1], cuts[1:]):
            inside = [m for m in sub if m[0] <= 0.5 * (ta + tb) <= m[1]]
            if inside:
                tau = sum(m[2] for m in inside)
                color = sum(m[2] * np.asarray(m[3]) for m in inside) / tau
                C = C + T * color * -math.expm1(-tau * (tb - ta))
                T *= math.exp(-tau * (tb - ta))
        out[r, :3], out[r, 3] = C, 1.0 - T
    return out


def test_opaque_boxes_end_the_ray_with_the_mean_of_their_colours():
    # A (z in [0, 2]) is translucent; B and C are opaque and share their top face z = 1.5
    a = Layer(constant_volume((3, 4, 5), spacing=(0.6, 0.7, 1.0)), constant_tf(0.3, (0.9, 0.2, 0.1)))
    b = Layer(constant_volume((2, 3, 3), spacing=(0.5, 0.5, 1.0)), constant_tf(1.0, (0.0, 1.0, 0.0)),
              rotation((0, 0, 1), 0.4, (0.9, 0.2, 0.5)))
    c = Layer(constant_volume((2, 2, 2), spacing=(1.0, 1.0, 1.0)), constant_tf(1.0, (0.0, 0.0, 1.0)),
              rotation((0, 0, 1), 0.0, (0.5, 0.5, 0.5)))
    scene = Scene.from_layers([a, b, c], TOP, width=24, height=20)
    o, d = (x.reshape(-1, 3) for x in TOP.rays(24, 20))
    tau = -math.log1p(-0.3)
    expected = piecewise_constant(o, d, [(a, tau, (0.9, 0.2, 0.1), False), (b, 0.0, (0.0, 1.0, 0.0), True),
                                         (c, 0.0, (0.0, 0.0, 1.0), True)])
    image = render(scene).reshape(-1, 4)
    assert np.any(expected[:, 3] == 1) and np.any((expected[:, 3] > 0) & (expected[:, 3] < 1))
    np.testing.assert_allclose(image, expected, rtol=0, atol=1e-9)
    # some rays meet both opaque boxes at z = 1.5: they end in the mean of green and blue
    mean = 0.9 * -math.expm1(-0.5 * tau), 0.2 * -math.expm1(-0.5 * tau) + 0.5 * math.exp(-0.5 * tau)
    assert np.any(np.all(np.abs(image[:, :2] - mean) < 1e-9, axis=1))


@pytest.mark.parametrize("opaque", [False, True])
def test_label_volume_against_closed_form(opaque):
    """Samples 0..5 along x, labels 1 (i < 3) and 2 (i >= 3): a ray along x spends 2.5
    spacings in each label's cells (they change halfway between samples 2 and 3). The
    label volume is turned a quarter about z, so world +y rays run along its +x."""
    labels = np.ones((4, 3, 6), np.uint8)
    labels[:, :, 3:] = 2
    sx = 0.4
    colors = LabelColors({1: (1.0, 0.5, 0.0, 0.3), 2: (0.0, 0.4, 1.0, 1.0 if opaque else 0.6)}, unit_distance=0.5)
    layer = Layer(Volume(labels, spacing=(sx, 0.5, 0.5)), colors, rotation((0, 0, 1), math.pi / 2, (0.2, 0.1, 0.3)))
    base = Layer(constant_volume((2, 2, 2), origin=(-9.0, -9.0, -9.0)), constant_tf(0.0, (1, 1, 1)))
    # looking along world +y: the layer's local +x (a quarter turn about z)
    camera = Camera((-0.3, -20.0, 0.8), (-0.3, 0.0, 0.8), (0, 0, 1), ortho_height=0.6)
    scene = Scene.from_layers([base, layer], camera, width=3, height=3)
    image = render(scene).reshape(-1, 4)
    t1, t2 = -math.log1p(-0.3) / 0.5, -math.log1p(-0.6) / 0.5
    length = 2.5 * sx
    # label 1 (i = 0..2) first
    first = np.array([1.0, 0.5, 0.0]) * -math.expm1(-t1 * length)
    T = math.exp(-t1 * length)
    if opaque:
        expected = np.append(first + T * np.array([0.0, 0.4, 1.0]), 1.0)
    else:
        expected = np.append(first + T * np.array([0.0, 0.4, 1.0]) * -math.expm1(-t2 * length),
                             1 - T * math.exp(-t2 * length))
    np.testing.assert_allclose(image, np.tile(expected, (9, 1)), rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- against one volume
def _scan(seed=0, shape=(7, 8, 9), **kw):
    data = np.random.default_rng(seed).random(shape)
    return Volume(data, **kw)


TF = TransferFunction([(0.0, 1, 0.2, 0.1), (0.4, 0.2, 1, 0.3), (1.0, 0.1, 0.3, 1)],
                      [(0.1, 0.0), (0.5, 0.35), (0.7, 0.05), (0.9, 1.0)], unit_distance=0.7)
CLEAR = constant_tf(0.0, (1, 1, 1))
CAMERA = Camera((9.0, 7.0, 12.0), (2.2, 1.9, 1.8), (0, 1, 0), fov=35)


def test_one_layer_mixture_is_the_one_volume_image():
    vol = _scan(spacing=(0.6, 0.5, 0.55), origin=(0.1, -0.2, 0.3))
    alone = Scene(vol, TF, CAMERA, width=20, height=18)
    reference = render(alone)
    np.testing.assert_allclose(render_layers(alone), reference, rtol=0, atol=1e-10)
    # the same volume as a second, unplaced layer behind a clear first one
    clear = Layer(constant_volume((2, 2, 2), origin=(-30.0, 0.0, 0.0)), CLEAR)
    mixed = Scene.from_layers([clear, Layer(vol, TF)], CAMERA, width=20, height=18)
    assert np.count_nonzero(reference[..., 3] == 1) > 10      # alpha = 1 at a knot ends rays
    np.testing.assert_allclose(render(mixed), reference, rtol=0, atol=1e-10)


@pytest.mark.parametrize("masked", [False, True])
def test_a_placed_layer_is_its_volume_seen_from_the_moved_camera(masked):
    vol = _scan(seed=1, spacing=(0.6, 0.5, 0.55))
    if masked:     # cells with a non-finite corner are outside the layer's domain
        data = vol.data.copy()
        data[3, 4, 4] = data[1, 2, 6] = np.nan
        vol = Volume(data, spacing=(0.6, 0.5, 0.55), mask_nonfinite=True)
    layer = Layer(vol, TF, rotation((0.3, -1.0, 0.6), 1.1, (2.0, -1.0, 0.5)))
    clear = Layer(constant_volume((2, 2, 2), origin=(-30.0, 0.0, 0.0)), CLEAR)
    placed = Scene.from_layers([clear, layer], moved_camera(CAMERA, layer), width=20, height=18)
    np.testing.assert_allclose(render(placed), render(Scene(vol, TF, CAMERA, width=20, height=18)), rtol=0, atol=1e-10)


def test_two_identical_layers_are_one_with_tau_doubled():
    """Opacity constant in s (colour not): two equal layers are one of opacity
    1 - (1 - alpha)^2 and the same colour, exactly, on any field."""
    color = [(0.0, 1, 0, 0), (0.3, 0, 1, 0), (0.6, 0, 0, 1), (1.0, 1, 1, 0)]
    tf = TransferFunction(color, [(0.0, 0.35), (1.0, 0.35)], unit_distance=0.5)
    doubled = TransferFunction(color, [(0.0, 1 - 0.65 ** 2), (1.0, 1 - 0.65 ** 2)], unit_distance=0.5)
    vol = _scan(seed=2, spacing=(0.6, 0.5, 0.55))
    place = rotation((1.0, 1.0, 0.0), 0.5, (0.5, 0.0, -0.5))
    clear = Layer(constant_volume((2, 2, 2), origin=(-30.0, 0.0, 0.0)), CLEAR)
    twice = Scene.from_layers([clear, Layer(vol, tf, place), Layer(vol, tf, place)], CAMERA, width=16, height=14)
    once = Scene.from_layers([clear, Layer(vol, doubled, place)], CAMERA, width=16, height=14)
    expected = render(once)
    assert np.count_nonzero(expected[..., 3] > 0.5) > 20
    np.testing.assert_allclose(render(twice), expected, rtol=0, atol=1e-10)


# ----------------------------------------------------------------------------- add
@pytest.mark.parametrize("mode", ["composite", "mip", "minip", "average"])
def test_add_is_the_sum_of_the_layers_images(mode):
    first = _scan(seed=3, spacing=(0.6, 0.5, 0.55))
    second = _scan(seed=4, shape=(6, 9, 7), spacing=(0.5, 0.45, 0.6))
    tf2 = TransferFunction([(0.0, 0.1, 0.2, 1), (1.0, 1, 1, 0.3)], [(0.3, 0.0), (0.6, 0.4), (1.0, 0.9)])
    layer = Layer(second, tf2, rotation((0.2, 1.0, -0.4), 0.8, (1.0, 0.5, 0.2)))
    scene = Scene.from_layers([Layer(first, TF), layer], CAMERA, width=16, height=14, blend="add", mode=mode)
    one = render(Scene(first, TF, CAMERA, width=16, height=14, mode=mode))
    two = render(Scene(second, tf2, local_camera(CAMERA, layer), width=16, height=14, mode=mode))
    image = render(scene)
    assert np.count_nonzero((one[..., 3] > 0) & (two[..., 3] > 0)) > 10    # the images overlap
    np.testing.assert_allclose(image[..., :3], one[..., :3] + two[..., :3], rtol=0, atol=1e-10)
    np.testing.assert_allclose(image[..., 3], 1 - (1 - one[..., 3]) * (1 - two[..., 3]), rtol=0, atol=1e-10)


# ----------------------------------------------------------------------------- clip and geometry
def test_clip_and_geometry_cut_the_mixture_as_they_cut_one_volume():
    vol = _scan(seed=5, spacing=(0.6, 0.5, 0.55))
    square = Surface([(0.0, -1.0, 1.0), (5.0, -1.0, 1.6), (5.0, 5.0, 2.4), (0.0, 5.0, 1.8)], [(0, 1, 2), (0, 2, 3)],
                     color=(0.3, 0.8, 0.5))
    cuts = dict(clip_planes=[((2.0, 2.0, 2.0), (1.0, -0.4, 0.3))], crop_box=((0.5, 0.2, 0.0), (4.5, 3.0, 3.2)),
                geometry=[square])
    clear = Layer(constant_volume((2, 2, 2), origin=(-30.0, 0.0, 0.0)), CLEAR)
    alone = render(Scene(vol, TF, CAMERA, width=20, height=18, **cuts))
    assert np.count_nonzero(alone[..., 3] == 1) > 20 and np.count_nonzero((alone[..., 3] > 0) & (alone[..., 3] < 1)) > 5
    mixed = render(Scene.from_layers([clear, Layer(vol, TF)], CAMERA, width=20, height=18, **cuts))
    np.testing.assert_allclose(mixed, alone, rtol=0, atol=1e-10)


@pytest.mark.parametrize("blend", ["mix", "add"])
def test_a_surface_ends_the_mixture_against_closed_form(blend):
    """A square at z = 1.2 facing the orthographic rays: each ray's medium stops there and
    the surface, lit by the headlight (``colour (ka + kd) + ks``), goes behind once."""
    a, b, media = _two_boxes()
    color = np.array([0.3, 0.8, 0.5])
    square = Surface([(-1.0, -2.0, 1.2), (2.0, -2.0, 1.2), (2.0, 4.0, 1.2), (-1.0, 4.0, 1.2)], [(0, 1, 2), (0, 2, 3)],
                     color=color)
    scene = Scene.from_layers([a, b], TOP, width=24, height=20, blend=blend, geometry=[square])
    o, d = (x.reshape(-1, 3) for x in TOP.rays(24, 20))
    hit = (o[:, 0] >= -1.0) & (o[:, 0] <= 2.0) & (o[:, 1] >= -2.0) & (o[:, 1] <= 4.0)
    t_end = np.where(hit, 30.0 - 1.2, np.inf)
    if blend == "mix":
        expected = piecewise_constant(o, d, media, t_end)
    else:
        parts = [piecewise_constant(o, d, [m], t_end) for m in media]
        expected = np.concatenate([parts[0][:, :3] + parts[1][:, :3],
                                   1 - (1 - parts[0][:, 3:]) * (1 - parts[1][:, 3:])], axis=1)
    assert 50 < hit.sum() < len(hit) - 50 and np.any(hit & (expected[:, 3] > 0) & (expected[:, 3] < 0.99))
    lit = color * (0.3 + 0.7) + 0.2
    expected[hit, :3] += (1 - expected[hit, 3:]) * lit
    expected[hit, 3] = 1.0
    np.testing.assert_allclose(render(scene).reshape(-1, 4), expected, rtol=0, atol=1e-9)


# ----------------------------------------------------------------------------- cache
def test_the_cache_tells_placements_apart(tmp_path):
    vol = _scan(seed=6)
    scenes = [Scene.from_layers([Layer(vol, TF), Layer(vol, TF, rotation((0, 0, 1), angle, (1.0, 0.0, 0.0)))],
                                CAMERA, width=8, height=8) for angle in (0.2, 0.3)]
    first = exact(scenes[0], cache_dir=tmp_path)
    second = exact(scenes[1], cache_dir=tmp_path)
    assert len(list(tmp_path.iterdir())) == 2 and np.abs(first - second).max() > 1e-3
    np.testing.assert_array_equal(exact(scenes[0], cache_dir=tmp_path), first)
