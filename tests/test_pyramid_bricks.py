"""A level per brick on a pyramid: ``techniques.brick_levels.BrickLevels`` draws level 0's
bricks each from a level of its own in one frame, and ``tolerance=E, per_brick=True``
(``rendering.pyramid_bricks``) picks those levels.

What is checked against what:

- The placement of a coarse level's brick (its block, the shift of its samples, its
  spacing in the shader) against level 0, on fields where every level reconstructs level
  0's interpolant exactly: a field linear along one axis (the 2x2x2 means of a linear
  field are the field at the means' centres, whole numbers here, so no rounding), with a
  TF that is transparent within a few samples of the faces across that axis (where a
  coarse level clamps to its smaller box). Any assignment of levels to bricks must then
  give level 0's bricked image, up to the float32 rounding of the texel coordinate
  (``p / spacing - first``, each a few units in the last place of ~40 texels: ~1e-5 of a
  texel, times the field's slope, 4 per sample, and the TF's steepest slope, 0.015 of
  opacity per unit: ~1e-6 per sample over ~60 samples a ray): within 1e-5. The same
  check with the coarse blocks' first sample moved by a quarter texel is far outside it
  (the test can fail).
- The per-brick choice's image against ``reference.exact`` of level 0's samples in
  memory (an integrator that shares nothing with the choice), on test_pyramid's scene:
  within E on the very pixels returned.
"""

import numpy as np
import pytest

import dvr_gl
from dvr_gl.formats.stores import build_pyramid, open_store
from dvr_gl.rendering import pyramid
from dvr_gl.rendering.pyramid_bricks import BrickChoice, assignment
from dvr_gl.techniques import brick_levels
from dvr_gl.techniques.bricks import partition
from dvr_gl.techniques.brick_levels import BrickLevels

zarr = pytest.importorskip("zarr")
import test_pyramid as tp  # noqa: E402   (its scene, samples and exact image)

chest_like = tp.chest_like        # the module fixture: test_pyramid's pyramid and exact image
BRICK = 8
STEP = 0.5
ROUNDING = 1e-5                   # see the module's docstring


@pytest.fixture(autouse=True)
def cache_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))


def _linear_pyramid(folder, axis):
    """A 3-level pyramid of 10 + 4 i along ``axis`` (0 z, 1 y, 2 x), constant across it."""
    shape = [26, 30, 34]
    shape[axis] = 40
    index = np.indices(shape)[axis]
    samples = (10 + 4 * index).astype(np.uint8)
    path = str(folder / f"linear{axis}.zarr")
    array = zarr.create_array(path, shape=samples.shape, chunks=(8, 8, 8), dtype=samples.dtype)
    array[...] = samples
    out = build_pyramid(path, levels=3, spacing=(1.0, 0.8, 1.2), progress=False)
    volume = open_store(out)
    return volume, [pyramid.level_volume(volume, k) for k in range(3)]


def _band_tf():
    """Transparent below 40 and above 150: within 8 samples of the faces across the axis."""
    return dvr_gl.TransferFunction(color=[(0, 0.2, 0.4, 1.0), (255, 1.0, 0.6, 0.2)],
                                   opacity=[(0, 0), (40, 0), (60, 0.3), (100, 0.05), (130, 0.6), (150, 0), (255, 0)],
                                   unit_distance=1.0)


@pytest.mark.parametrize("shading", [False, True])
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_bricks_of_any_levels_give_level_0s_image_of_a_linear_field(renderer, tmp_path, axis, shading):
    volume, levels = _linear_pyramid(tmp_path, axis)
    scene = dvr_gl.Scene(volume, _band_tf(), dvr_gl.default_camera(volume, azimuth=30, elevation=20),
                         width=48, height=48, shading=shading)
    level0 = renderer.render(scene, step=STEP, brick_size=BRICK)
    assert level0[..., 3].max() > 0.5
    bricks = partition(volume.shape, BRICK, 1)
    rng = np.random.default_rng(axis)
    mixes = [{b.index: int(rng.integers(0, 3)) for b in bricks}, {}]
    for chosen, default in zip(mixes, (0, 2)):
        drawer = BrickLevels(levels, chosen, default=default)
        image = renderer.render(scene, step=STEP, brick_size=BRICK, brick_levels=drawer)
        assert all(n > 0 for n in drawer.drawn[default:]), drawer.drawn     # the levels were drawn
        assert float(np.abs(image - level0).max()) <= ROUNDING
    # each coarse level alone (its own, smaller box) is far from it: the match is the placement's
    alone = renderer.render(scene.replace(volume=levels[2]), step=STEP)
    assert float(np.abs(alone - level0).max()) > 0.1


def test_a_coarse_block_moved_by_a_quarter_texel_is_seen(renderer, tmp_path, monkeypatch):
    volume, levels = _linear_pyramid(tmp_path, 0)
    scene = dvr_gl.Scene(volume, _band_tf(), dvr_gl.default_camera(volume, azimuth=30, elevation=20),
                         width=48, height=48, shading=False)
    level0 = renderer.render(scene, step=STEP, brick_size=BRICK)
    placed = brick_levels.level_block
    monkeypatch.setattr(brick_levels, "level_block",
                        lambda *a: (placed(*a)[0], tuple(v + 0.25 for v in placed(*a)[1])))
    image = renderer.render(scene, step=STEP, brick_size=BRICK, brick_levels=BrickLevels(levels, {}, default=1))
    assert float(np.abs(image - level0).max()) > 100 * ROUNDING


def test_bad_brick_levels_are_named(tmp_path):
    volume, levels = _linear_pyramid(tmp_path, 0)
    with pytest.raises(ValueError, match=r"brick \(0, 0, 0\): level 3 is not one of the 3 levels"):
        BrickLevels(levels, {(0, 0, 0): 3})
    other = open_store(build_pyramid(str(_float_store(tmp_path)), levels=2, progress=False))
    with pytest.raises(ValueError, match="share a dtype"):      # (one shader draws the frame)
        BrickLevels([levels[0], other], {})


def _float_store(folder):
    path = folder / "floats.zarr"
    array = zarr.create_array(str(path), shape=(8, 8, 8), chunks=(8, 8, 8), dtype=np.float32)
    array[...] = 1.0
    return path


def test_assignment_takes_the_coarsest_level_within_the_threshold():
    scores = np.array([[0, 0.1, 0.3], [0, 0.5, 0.5], [0, 0.0, 0.0]])
    assert assignment(scores, 0.2, 0).tolist() == [1, 0, 2]
    assert assignment(scores, 0.2, 1).tolist() == [1, 1, 2]      # never finer than the one-level choice
    assert assignment(scores, 1.0, 0).tolist() == [2, 2, 2]


def test_the_per_brick_choice_is_within_the_tolerance_of_exact(renderer, chest_like):
    path, reference = chest_like
    scene = tp._scene(open_store(path))
    for tolerance in (0.06, 0.02):
        image = renderer.render(scene, tolerance=tolerance, per_brick=True, brick_size=BRICK)
        choice = renderer.last_choice
        assert isinstance(choice, BrickChoice) and choice.mixed, choice.describe()
        single = choice.single
        error = tp._rmse(image, reference)
        assert error <= tolerance, (tolerance, choice.describe(), error)
        assert choice.checked_rmse == pytest.approx(error, rel=0.25, abs=2e-3)
        levels = np.array([level for _, level in choice.chosen])
        # never finer than the one-level choice, coarser for some bricks
        assert levels.min() >= single.level and levels.max() > single.level, (choice.counts, single.level)
        assert sum(choice.counts) == len(partition(scene.volume.shape, BRICK, 0))
        # the threshold taken is the largest measured within the target
        target = 0.95 * tolerance
        taken = max(t for t, _, bound in choice.trials if bound <= target)
        assert all(bound > target for t, _, bound in choice.trials if t > taken)
        assert choice.checked_rmse <= target
    # the one-level choice already at the coarsest level: nothing to mix, its frame
    image = renderer.render(scene, tolerance=0.12, per_brick=True, brick_size=BRICK)
    choice = renderer.last_choice
    assert not choice.mixed and choice.single.level == 2
    assert np.array_equal(image, renderer.render(scene, tolerance=0.12))


def test_a_bad_brick_size_is_named(renderer, chest_like):
    path, _ = chest_like
    with pytest.raises(ValueError, match="brick_size"):
        renderer.render(tp._scene(open_store(path)), tolerance=0.06, per_brick=True, brick_size=0)
