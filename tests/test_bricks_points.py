"""Bricked point techniques (``techniques/point_bricks.py``) against the whole volume.

Why the images agree. Neither particles nor splats draw the grid from a 3-D texture: what
bricks change is where the primitives are made, each brick from its own block of samples.
Every primitive is then the whole volume's, bit for bit, by construction: positions are a
cell index plus a fraction (or a sample index) times the spacing in float64, values and
gradients come from the same corners with the block's first sample subtracted from whole
sample coordinates (exact), and the particles' random streams are per generation tile,
not per brick. The tests check that first (the same particles, splats and samples), then
the images: the Gaussian splats are composited in the single texture's order and the
tent's samples are the same in the same order, so those images are equal bit for bit;
the particles are drawn brick by brick into one depth test, which keeps the nearest
sphere whatever the order: equal unless two particles on one pixel reach the same 24-bit
depth (then the first drawn wins). That tie is possible, not expected at these sizes, and
none occurs here: the bound asserted is 0.
"""

import functools
import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl import data
from dvr_gl.techniques import bricks, point_bricks, splat
from dvr_gl.techniques import particle_sets as pbvr
from test_geometry import icosphere

SHARED_DATA = os.environ.get("DVR_GL_DATA") or os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "shared", "data")
CHEST = os.path.join(SHARED_DATA, "vtkjs_lidc2_ct", "LIDC2_256x256x133_uint8.raw.gz")
SIZE = 40


@functools.lru_cache(maxsize=None)
def _volume(name):
    if name == "head":
        return data.ct_head(), data.ct_head_tf()
    if not os.path.exists(CHEST):
        pytest.skip(f"shared data not found: {CHEST}")
    from dvr_gl.frontends import inputs
    volume, _ = inputs.load_input(CHEST)
    tf = inputs.PRESETS["ct_bone_8bit"](volume)
    if name == "chest_middle":     # the tent's samples take seconds on the whole chest: its middle
        volume = dvr_gl.Volume(volume.data[30:110, 60:190, 60:190], spacing=volume.spacing)
    return volume, tf


def _scene(name, view="oblique", **options):
    volume, tf = _volume(name)
    if view == "oblique":
        camera = dvr_gl.default_camera(volume, azimuth=35, elevation=25)
    else:
        camera = dvr_gl.default_camera(volume, azimuth=-20, elevation=10, ortho=True)
    return dvr_gl.Scene(volume, tf, camera, width=SIZE, height=SIZE, **options)


def _by_position(points, *columns):
    order = np.lexsort(points.T[::-1])
    return [points[order]] + [c[order] for c in columns]


# ----------------------------------------------------------------------------- the primitives

@pytest.mark.parametrize("brick", [32, 20])      # 20: tiles of 32 cells straddle bricks
def test_bricks_make_the_whole_volumes_particles(brick):
    volume, tf = _volume("head")
    whole = pbvr.generate(volume, tf, 0.6, seed=3, repetition=1)
    made = point_bricks.particle_bricks(volume, tf, 0.6, 3, 1, "rejection", brick, lit=True)
    assert len(made.pieces) > 1 and made.count == whole.count > 1000
    assert made.candidates == whole.candidates and made.cells == whole.cells
    joined = made.joined(tf)
    for a, b in zip(_by_position(whole.points, whole.scalars, whole.colors, whole.owners),
                    _by_position(joined.points, joined.scalars, joined.colors, joined.owners)):
        np.testing.assert_array_equal(a, b)
    # each brick holds the particles of its own cells, lit from its own block
    shape = [n - 1 for n in volume.shape]
    for brick_, piece in zip(made.bricks, made.pieces):
        cell = np.array(np.unravel_index(piece.owners, shape)).T
        lo, hi = np.array(brick_.cells).T
        assert ((cell >= lo) & (cell < hi)).all()
    a = _by_position(whole.points, pbvr.particle_gradients(whole, volume))[1]
    b = _by_position(joined.points, np.concatenate(made.gradients))[1]
    np.testing.assert_array_equal(a, b)


def test_bricks_read_only_their_blocks(monkeypatch):
    """Making the primitives reads brick blocks (and nothing of the whole volume)."""
    volume, tf = _volume("head")
    boxes = []
    real = point_bricks.read_block
    monkeypatch.setattr(point_bricks, "read_block", lambda v, *box: boxes.append(box) or real(v, *box))
    values = type(volume).values
    monkeypatch.setattr(type(volume), "values", lambda self, *a, **k: pytest.fail("the whole volume was read")
                        if self is volume else values(self, *a, **k))
    point_bricks.particle_bricks(volume, tf, 0.6, 0, 0, "rejection", 32, lit=False)
    splat.bricked_splats(volume, tf, 2, 32)
    splat.bricked_tent_samples(volume, dvr_gl.model.transfer.LookupTable(tf), True, 32)
    allowed = {tuple(v for pair in b.samples for v in pair) for b in bricks.partition(volume.shape, 32, 1)}
    assert boxes and set(boxes) <= allowed


def test_bricks_make_the_whole_volumes_splats():
    volume, tf = _volume("head")
    whole = splat.make_splats(volume, tf, 2)
    made, key = splat.bricked_splats(volume, tf, 2, 32)
    order = np.argsort(key)
    assert made.count == whole.count > 0 and len(np.unique(key)) == len(key)
    np.testing.assert_array_equal(made.points[order], whole.points)
    np.testing.assert_array_equal(made.samples[order], whole.samples)
    lut = dvr_gl.model.transfer.LookupTable(tf)
    for skip_empty in (True, False):
        a, b = splat.tent_samples(volume, lut, skip_empty), splat.bricked_tent_samples(volume, lut, skip_empty, 32)
        for name in ("values", "at", "mask"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    samples = splat.tent_samples(volume, lut)
    np.testing.assert_array_equal(point_bricks.tent_gradients_bricked(samples, volume, 32),
                                  splat.tent_gradients(samples, volume))


# ----------------------------------------------------------------------------- the images

CASES = [("particles", {}), ("splat", {}), ("splat", {"kernel": "gaussian"})]


# the head at both sizes; the chest (slower to make) at one size per technique, the
# tent's on the chest's middle (80 x 130 x 130 samples)
IMAGES = [("head", brick, *case) for brick in (32, 64) for case in CASES] + [
    ("chest", 32, *CASES[0]), ("chest_middle", 64, *CASES[1]), ("chest", 32, *CASES[2])]


@pytest.mark.parametrize("name,brick,technique,options", IMAGES)
def test_bricked_images_equal_the_whole_volumes(renderer, name, brick, technique, options):
    scene = _scene(name)
    single = renderer.render(scene, technique, **options)
    assert single[..., 3].max() > 0.5
    np.testing.assert_array_equal(renderer.render(scene, technique, brick_size=brick, **options), single)


@pytest.mark.parametrize("technique,options", CASES)
def test_lit_clipped_orthographic_and_geometry_bricks(renderer, technique, options):
    volume, _ = _volume("head")
    centre = (volume.bounds[0] + volume.bounds[1]) / 2
    sphere = icosphere(centre + [10.0, -20.0, 5.0], 45.0, color=(0.3, 0.5, 0.9))     # opaque geometry
    for scene in (_scene("head", shading=True), _scene("head", "ortho", clip_planes=[(centre, (1.0, 0.3, 0.2))]),
                  _scene("head", geometry=[sphere])):
        single = renderer.render(scene, technique, **options)
        np.testing.assert_array_equal(renderer.render(scene, technique, brick_size=16, **options), single)


def test_particle_repetitions_and_density(renderer):
    scene = _scene("head")
    np.testing.assert_array_equal(renderer.render(scene, "particles", repetitions=3, brick_size=32),
                                  renderer.render(scene, "particles", repetitions=3))
    np.testing.assert_array_equal(renderer.render(scene, "splat", kernel="gaussian", density=2, brick_size=32),
                                  renderer.render(scene, "splat", kernel="gaussian", density=2))


def test_bricks_name_what_they_do_not_take(renderer):
    scene = _scene("head")
    with pytest.raises(ValueError, match="brick_size must be at least 1"):
        renderer.render(scene, "particles", brick_size=0)
    with pytest.raises(TypeError, match="brick_size"):
        renderer.render(scene, "splat", brick_size=2.5)
    mesh = dvr_gl.Scene(_small_mesh(), scene.tf, scene.camera, width=SIZE, height=SIZE)
    for technique in ("particles", "splat"):
        with pytest.raises(ValueError, match=f"brick_size cuts a grid into bricks; {technique}"):
            renderer.render(mesh, technique, brick_size=8)
    holes = scene.volume.data.astype(np.float32)
    holes[5, 5, 5] = np.nan
    masked = dvr_gl.Scene(dvr_gl.Volume(holes, spacing=scene.volume.spacing, mask_nonfinite=True), scene.tf,
                          scene.camera, width=SIZE, height=SIZE)
    with pytest.raises(ValueError, match="bricked splat .* non-finite"):
        renderer.render(masked, "splat", brick_size=8)


def _small_mesh():
    points = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100]], float)
    return dvr_gl.TetMesh(points, np.array([[0, 1, 2, 3]]), np.array([0.0, 1000.0, 2000.0, 3000.0]))
