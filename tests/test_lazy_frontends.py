"""A store through the front ends: ``dvr-gl info STORE`` describes it from its metadata
without reading a sample, and ``dvr-gl view STORE`` opens it lazily (a LazyVolume drawn
by the ray caster, the only technique offered; the histogram of the TF editor left
empty rather than read from every sample), its frame the headless render's."""

import io

import numpy as np
import pytest

from dvr_gl import data
from dvr_gl.formats import to_png_array
from dvr_gl.model.lazy_volume import LazyVolume

zarr = pytest.importorskip("zarr")
pytest.importorskip("dvr_gl.frontends.viewer")
import test_viewer  # noqa: E402

display, open_viewer = test_viewer.display, test_viewer.open_viewer      # the viewer's fixtures
press, png = test_viewer.press, test_viewer.png


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))
    head = data.ct_head()
    path = tmp_path / "head.zarr"
    array = zarr.create_array(str(path), shape=head.shape, chunks=(32, 32, 32), dtype=head.data.dtype)
    array[...] = head.data
    return str(path)


def test_info_describes_a_store_without_reading_it(store, monkeypatch):
    from dvr_gl.frontends import cli

    def no_read(*_):
        raise AssertionError("info read samples")
    monkeypatch.setattr(LazyVolume, "read", no_read)
    out = io.StringIO()
    assert cli.cmd_info_file(cli.build_parser().parse_args(["info", store]), out) == 0
    text = out.getvalue()
    assert "format     zarr v3" in text and "shape      64x64x93 (x, y, z)" in text and "int16" in text


def test_view_opens_a_store_lazily(store, open_viewer, renderer, tmp_path):
    v = open_viewer(store, "--size", "96x80", "--screenshot", str(tmp_path / "store.png"))
    assert isinstance(v.settings.volume, LazyVolume)
    assert list(v.available_techniques) == ["raycast"]
    v.refine()
    press(v, "s")
    image = png(tmp_path / "store.png")
    assert image.shape[:2] == (80, 96) and image[..., 3].max() > 50, "the head must show"
    scene, name, step, options = v.render_arguments()
    assert isinstance(scene.volume, LazyVolume)
    headless = to_png_array(renderer.render(scene, name, step, **options), v.settings.background)
    # the same scene through the same passes: the window's GL and the headless one are
    # both llvmpipe here, which round alike (test_viewer's rule for one driver)
    assert int(np.abs(image.astype(int) - headless.astype(int)).max()) <= 1
