"""A multiscale store in the viewer and the notebook widget: while the view moves they draw
one coarse level (``rendering.pyramid.moving_level``: the finest level of at most
``moving_samples`` samples, chosen from the shapes alone), and the still frame goes
back to level 0, or, with a tolerance, to the level and step ``tolerance=E`` chooses.
Each frame is compared with the headless render of what it says it drew."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl.formats.stores import build_pyramid, open_store
from dvr_gl.rendering import pyramid

zarr = pytest.importorskip("zarr")


@pytest.fixture
def pyramid_store(tmp_path, monkeypatch):
    """The CT head as a zarr store and its 3-level pyramid (64x64x93, 32x32x46, 16x16x23)."""
    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))
    head = dvr_gl.data.ct_head()
    path = tmp_path / "head.zarr"
    array = zarr.create_array(str(path), shape=head.shape, chunks=(32, 32, 32), dtype=head.data.dtype)
    array[...] = head.data
    return build_pyramid(str(path), levels=3, spacing=tuple(head.spacing), progress=False)


def test_the_moving_level_is_the_finest_within_the_budget(pyramid_store):
    volume = open_store(pyramid_store)
    sizes = [int(np.prod(level.shape)) for level in volume.levels]
    assert pyramid.moving_level(volume, sizes[0]) == 0
    assert pyramid.moving_level(volume, sizes[1]) == 1
    assert pyramid.moving_level(volume, sizes[1] - 1) == 2
    assert pyramid.moving_level(volume, 1) == 2                 # none so small: the coarsest
    assert pyramid.moving_volume(volume, sizes[1]).shape == volume.levels[1].shape
    plain = dvr_gl.data.ct_head()
    assert pyramid.moving_level(plain, 1) == 0 and pyramid.moving_volume(plain, 1) is plain


def test_the_widget_drags_a_coarse_level_and_refines_when_still(pyramid_store):
    pytest.importorskip("anywidget")
    from dvr_gl.frontends.notebook import VolumeWidget
    volume = open_store(pyramid_store)
    w = VolumeWidget(volume, size=48)
    w.moving_samples = int(np.prod(volume.levels[1].shape))       # level 1 while dragging
    still = np.asarray(w.image_array)
    view = dict(w.view)
    w.view = dict(view, coarse=True)
    level1 = pyramid.level_volume(volume, 1)
    angles = dict(azimuth=view["azimuth"], elevation=view["elevation"], zoom=view["zoom"])
    expected = dvr_gl.render(level1, size=24, tf=w._tf_for(w.preset), **angles)
    assert np.array_equal(w.image_array, np.asarray(expected))
    assert not np.array_equal(np.asarray(expected), np.asarray(dvr_gl.render(volume, size=24, tf=w._tf_for(w.preset),
                                                                              **angles)))
    w.view = dict(view, coarse=False)                                # still: level 0 again
    assert np.array_equal(w.image_array, still)
    assert np.array_equal(still, np.asarray(dvr_gl.render(volume, size=48, tf=w._tf_for(w.preset), **angles)))


pytest.importorskip("dvr_gl.frontends.viewer")
import test_viewer  # noqa: E402

display, open_viewer = test_viewer.display, test_viewer.open_viewer      # the viewer's fixtures
MOUSE_LEFT, PRESS, RELEASE = test_viewer.MOUSE_LEFT, test_viewer.PRESS, test_viewer.RELEASE


def test_the_viewer_moves_on_a_coarse_level_and_refines_to_the_tolerance(pyramid_store, open_viewer, renderer):
    v = open_viewer(pyramid_store, "--size", "64x48", "--tolerance", "0.05")
    volume = v.settings.volume
    v.moving_samples = int(np.prod(volume.levels[2].shape))        # level 2 while the view moves
    clock = [0.0]
    v.clock = lambda: clock[0]
    v.on_mouse_button(MOUSE_LEFT, PRESS, 0, 20, 20)
    v.on_cursor(24, 20)                                            # dragging: a coarse frame
    clock[0] += 0.03
    v.frame()
    assert v.last_frame.quality == "coarse" and v.last_frame.target_size == (32, 24)
    level2 = pyramid.level_volume(volume, 2)
    assert v.last_frame.step == pytest.approx(v.effective_step() * v.coarse_step * level2.min_spacing
                                              / volume.min_spacing)
    assert getattr(v.renderer, "last_choice", None) is None          # no tolerance choice while moving
    scene, name, step, options = v.render_arguments(32, 24, coarse=True)
    assert scene.volume.shape == volume.levels[2].shape and step == pytest.approx(v.last_frame.step)
    with v.gl():
        moving = v.renderer.read_target(v.presenter.target, 32, 24)
    assert float(np.abs(moving - renderer.render(scene, name, step=step, **options)).max()) <= 1e-6
    v.on_mouse_button(MOUSE_LEFT, RELEASE, 0)
    clock[0] += 1.0                                                # still: settled
    v.refine()
    assert v.last_frame.quality == "full"
    scene, name, step, options = v.render_arguments()
    chosen = v.renderer.last_choice
    assert isinstance(chosen, pyramid.LevelChoice) and chosen.tolerance == pytest.approx(0.05)
    assert scene.volume.shape == chosen.level_shape and step == pytest.approx(chosen.step)
    # the frame the window shows is that render's
    headless = renderer.render(scene, name, step=step, **options)
    with v.gl():
        window = v.renderer.read_target(v.presenter.target, 64, 48)
    assert float(np.abs(window - headless).max()) <= 1e-6


def test_the_viewer_without_a_tolerance_refines_to_level_0(pyramid_store, open_viewer):
    v = open_viewer(pyramid_store, "--size", "64x48")
    volume = v.settings.volume
    v.moving_samples = int(np.prod(volume.levels[1].shape))
    scene, _, _, _ = v.render_arguments(32, 24, coarse=True)
    assert scene.volume.shape == volume.levels[1].shape
    v.refine()
    scene, _, _, _ = v.render_arguments()
    assert scene.volume is volume
