"""Pyramids: ``formats.stores.build_pyramid`` writes an OME-Zarr multiscale image that
``open_store`` reads back (shapes, scales, translations, the means), and ``tolerance=E``
on it (``rendering.pyramid``) draws from the coarsest level whose image is within ``E``.

What is checked against what: the level choice measures its error against a Richardson
image of level 0 made of GL frames; here the image it returns is compared with
``reference.exact`` of level 0's samples held in memory, a different integrator that
shares nothing with the choice, and must be within ``E`` on the very pixels returned
(the request is no larger than the check, so no sampling margin is involved)."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl.formats.errors import InputError
from dvr_gl.formats.stores import build_pyramid, describe_store, open_store, pyramid_path, pyramid_shapes
from dvr_gl.model.lazy_volume import LazyVolume
from dvr_gl.model.volume import Volume
from dvr_gl.reference.exact import exact
from dvr_gl.rendering import pyramid
from dvr_gl.rendering.pyramid import PyramidError

zarr = pytest.importorskip("zarr")

SHAPE = (24, 28, 26)           # (nz, ny, nx)
SPACING = (1.0, 0.8, 1.2)      # (x, y, z)
SIZE = 32


@pytest.fixture(autouse=True)
def cache_folder(tmp_path, monkeypatch):
    """Summaries and exact images go to a folder of the test's own."""
    monkeypatch.setenv("DVR_GL_CACHE", str(tmp_path / "cache"))


def _samples():
    """A bright shell around a softer blob with fine ripples: detail that coarse levels lose."""
    nz, ny, nx = SHAPE
    z, y, x = np.mgrid[0:nz, 0:ny, 0:nx].astype(np.float64)
    r = np.sqrt((x - 13) ** 2 + (y - 14) ** 2 + (z - 12) ** 2)
    shell = 200 * np.exp(-(r - 8.0) ** 2 / 2.0)
    blob = 120 * np.exp(-r ** 2 / 20.0) * (1 + 0.5 * np.sin(1.7 * x) * np.sin(1.3 * y))
    return np.clip(shell + blob, 0, 255).astype(np.uint8)


def _store(tmp_path, samples, name="scan.zarr"):
    path = str(tmp_path / name)
    array = zarr.create_array(path, shape=samples.shape, chunks=(8, 8, 8), dtype=samples.dtype)
    array[...] = samples
    return path


def _tf():
    return dvr_gl.TransferFunction(color=[(0.0, 0.9, 0.5, 0.2), (255.0, 1.0, 1.0, 0.9)],
                                   opacity=[(0.0, 0.0), (60.0, 0.0), (150.0, 0.25), (255.0, 0.8)],
                                   unit_distance=1.0)


def _scene(volume):
    camera = dvr_gl.default_camera(volume, azimuth=30, elevation=20)
    return dvr_gl.Scene(volume, _tf(), camera, width=SIZE, height=SIZE, shading=False)


def _rmse(a, b):
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


def test_build_pyramid_writes_levels_open_store_reads(tmp_path):
    samples = _samples()
    source = _store(tmp_path, samples)
    out = build_pyramid(source, levels=3, spacing=SPACING, origin=(1.0, 2.0, 3.0), chunks=8, progress=False)
    assert out == pyramid_path(source) == str(tmp_path / "scan.pyramid.ome.zarr")
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]      # renamed when whole
    volume = open_store(out)
    assert volume.store_format.startswith("OME-Zarr")
    assert [level.shape for level in volume.levels] == [(24, 28, 26), (12, 14, 13), (6, 7, 6)]
    for k, level in enumerate(volume.levels):
        np.testing.assert_allclose(level.spacing, np.array(SPACING) * 2 ** k)
        # each level's samples sit at the centres of the finer level's 2x2x2 groups
        np.testing.assert_allclose(level.origin, np.array([1.0, 2.0, 3.0]) + np.array(SPACING) * (2 ** k - 1) / 2)
    np.testing.assert_array_equal(volume.read(0, 24, 0, 28, 0, 26), samples)
    from dvr_gl.formats.stores import open_level
    level1 = open_level(volume, 1).read(0, 12, 0, 14, 0, 13)
    z, y, x = 5, 9, 11          # one mean by hand
    block = samples[2 * z:2 * z + 2, 2 * y:2 * y + 2, 2 * x:2 * x + 2].astype(np.float64)
    assert level1[z, y, x] == int(np.rint(block.mean()))
    means = samples.reshape(12, 2, 14, 2, 13, 2).astype(np.float64).mean(axis=(1, 3, 5))
    np.testing.assert_array_equal(level1, np.rint(means).astype(np.uint8))
    lines = describe_store(out)
    assert sum(line.startswith("level ") for line in lines) == 3
    # the default count: halved until the largest side is at most PYRAMID_SMALLEST (32)
    assert pyramid_shapes((133, 256, 256)) == [(133, 256, 256), (66, 128, 128), (33, 64, 64), (16, 32, 32)]
    assert pyramid_shapes((3, 64, 64))[-1] == (3, 32, 32)      # an axis is not halved below 2 samples
    with pytest.raises(InputError) as e:
        build_pyramid(source, levels=3, progress=False)
    assert e.value.field == "out" and "overwrite" in str(e.value)
    build_pyramid(source, levels=2, overwrite=True, progress=False)
    assert len(open_store(out).levels) == 2


@pytest.mark.parametrize("levels", [0, -1, 2.5, True])
def test_bad_level_counts_are_named(tmp_path, levels):
    with pytest.raises(InputError) as e:
        build_pyramid(_store(tmp_path, _samples()), levels=levels, progress=False)
    assert e.value.field == "levels"
    assert not (tmp_path / "scan.pyramid.ome.zarr").exists()


def test_too_many_levels_are_named(tmp_path):
    with pytest.raises(InputError, match="cannot be halved"):
        pyramid_shapes((4, 4, 4), levels=3)


@pytest.fixture(scope="module")
def chest_like(tmp_path_factory):
    """The samples, their pyramid (3 levels) and the exact image of level 0 in memory."""
    folder = tmp_path_factory.mktemp("pyramid")
    samples = _samples()
    out = build_pyramid(_store(folder, samples), levels=3, spacing=SPACING, progress=False)
    full = Volume(samples, spacing=SPACING)
    return out, exact(_scene(full), cache=False)


def test_the_chosen_level_is_within_the_tolerance_of_exact(renderer, chest_like):
    path, reference = chest_like
    scene = _scene(open_store(path))
    chosen = {}
    for tolerance in (0.12, 0.04, 0.02):
        image = renderer.render(scene, tolerance=tolerance)
        choice = renderer.last_choice
        assert isinstance(choice, pyramid.LevelChoice)
        chosen[tolerance] = choice.level
        error = _rmse(image, reference)
        assert error <= tolerance, (tolerance, choice.describe(), error)
        # what the choice measured is close to what exact says (its reference is level 0's Richardson image)
        assert choice.checked_rmse == pytest.approx(error, rel=0.25, abs=2e-3)
        # every coarser level measured over the target: the level is the coarsest within E
        for level, _, bound in choice.trials:
            if level > choice.level:
                assert bound > 0.95 * tolerance
    # on this scene: level 2 at 0.12 (bound 0.109), level 1 at 0.04 (0.034), level 0 at 0.02
    assert max(chosen.values()) >= 1 and len(set(chosen.values())) >= 2, chosen
    assert chosen[0.12] >= chosen[0.04] >= chosen[0.02]
    # asked again: kept, nothing measured
    renderer.render(scene, tolerance=0.04)
    assert renderer.last_choice is not None and renderer.last_choice.level == chosen[0.04]


def test_a_tight_tolerance_draws_level_0_with_the_grid_step(renderer, chest_like):
    path, reference = chest_like
    scene = _scene(open_store(path))
    image = renderer.render(scene, tolerance=0.004)
    choice = renderer.last_choice
    assert choice.level == 0 and choice.grid is not None
    assert choice.step == choice.grid.step
    assert all(bound > 0.95 * 0.004 for _, _, bound in choice.trials)
    assert _rmse(image, reference) <= 0.004


@pytest.mark.parametrize("tolerance", [0.0, -0.01, float("nan")])
def test_a_tolerance_that_is_not_positive_is_named(renderer, chest_like, tolerance):
    path, _ = chest_like
    with pytest.raises(PyramidError) as e:
        renderer.render(_scene(open_store(path)), tolerance=tolerance)
    assert e.value.field == "tolerance"


def test_a_store_without_levels_is_named(renderer, tmp_path):
    volume = open_store(_store(tmp_path, _samples()))
    assert len(volume.levels) == 1
    with pytest.raises(PyramidError) as e:
        pyramid.settings(renderer, _scene(volume), 0.05)
    assert e.value.field == "levels" and "build_pyramid" in str(e.value)
    plain = LazyVolume(_samples())
    with pytest.raises(PyramidError, match="levels"):
        pyramid.settings(renderer, _scene(plain), 0.05)


def test_the_command_line_builds_and_reports_the_level(tmp_path, capsys):
    from dvr_gl.frontends import cli
    source = _store(tmp_path, _samples())
    out = tmp_path / "scan.png"
    tf = tmp_path / "tf.json"
    from dvr_gl.model.transfer import save_tf_json
    save_tf_json(str(tf), _tf())
    argv = ["render", source, "-o", str(out), "--size", f"{SIZE}x{SIZE}", "--tf", str(tf), "--no-shading",
            "--build-pyramid", "--pyramid-levels", "3", "--tolerance", "0.08"]
    assert cli.main(argv) == 0
    text = capsys.readouterr().out
    assert "pyramid    wrote" in text and "scan.pyramid.ome.zarr" in text
    assert "for tolerance 0.08" in text and "against level 0's reference" in text
    assert "levels     measured" in text
    assert cli.main(argv) == 0
    assert "there already: reused" in capsys.readouterr().out
    assert len(open_store(str(tmp_path / "scan.pyramid.ome.zarr")).levels) == 3
    assert cli.main(["render", source, "-o", str(out), "--pyramid-levels", "2"]) == 2     # without --build-pyramid
    other = _store(tmp_path, _samples(), name="other.zarr")
    assert cli.main(["render", other, "-o", str(out), "--build-pyramid", "--pyramid-levels", "0"]) == 2
    assert "--pyramid-levels" in capsys.readouterr().err and not (tmp_path / "other.pyramid.ome.zarr").exists()
