"""Volumes over time and movies: VolumeSeries from arrays and files (its errors name the
step and the file), the frames a movie draws, .mp4 and .gif files read back (frame count,
size, an orbit that turns, nothing black), the temporary file gone after success and
failure, and the command line's errors naming the option. Small sizes and few frames."""

import os

import numpy as np
import pytest

import dvr_gl
from dvr_gl.formats import InputError, MissingFileError, load_series
from dvr_gl.frontends import cli
from dvr_gl.frontends.movie import (ORBIT_FRAMES, MovieDependencyError, frame_plan, render_movie,
                                    resolve_movie_tf)
from dvr_gl.frontends.inputs import resolve_tf
from dvr_gl.model.series import StepMismatchError, VolumeSeries

iio = pytest.importorskip("imageio.v3", reason="movies need the movie extra: pip install \"dvr-gl[movie]\"")
pytest.importorskip("imageio_ffmpeg", reason="movies need the movie extra: pip install \"dvr-gl[movie]\"")


def _blob_series(steps=4, n=16):
    """A Gaussian blob moving along x, one step per position: (steps, n, n, n) float32
    whose steps have different ranges (the blob brightens)."""
    z, y, x = np.meshgrid(*(np.arange(n, dtype=np.float32),) * 3, indexing="ij")
    frames = []
    for t in range(steps):
        cx = 4 + t * (n - 8) / max(steps - 1, 1)
        frames.append((1 + t) * np.exp(-((x - cx) ** 2 + (y - n / 2) ** 2 + (z - n / 2) ** 2) / 8.0))
    return np.stack(frames).astype(np.float32)


def _read(path):
    frames = iio.imread(path, index=None, **({"plugin": "FFMPEG"} if str(path).endswith(".mp4") else {}))
    return np.asarray(frames)[..., :3]


# ============================================================================ VolumeSeries

def test_series_from_a_4d_array():
    a = _blob_series()
    s = VolumeSeries.from_array(a, spacing=(1, 2, 3), origin=(5, 0, 0))
    assert len(s) == 4 and s.shape == (16, 16, 16)
    assert isinstance(s[2], dvr_gl.Volume) and np.array_equal(s[2].data, a[2])
    assert np.array_equal(s[-1].data, a[3]) and [v.shape for v in s] == [(16, 16, 16)] * 4
    assert tuple(s.spacing) == (1, 2, 3) and tuple(s.origin) == (5, 0, 0)
    assert s.data_range == (float(a.min()), float(a.max()))           # every step, not the first
    assert s.data_range[1] > s[0].data_range[1]
    assert len(s[1:3]) == 2 and np.array_equal(s[1:3][0].data, a[1])
    assert s.pooled().data_range == s.data_range and s.pooled().shape == (64, 16, 16)
    with pytest.raises(IndexError, match="step 4"):
        s[4]
    with pytest.raises(ValueError, match="4-D"):
        VolumeSeries.from_array(a[0])


def test_series_from_files_sorted_naturally(tmp_path):
    a = _blob_series(3)
    names = ["t_2.npy", "t_10.npy", "t_1.npy"]                       # t_1, t_2, t_10 by number
    for name, step in zip(names, (a[1], a[2], a[0])):
        np.save(tmp_path / name, step)
    s = load_series(str(tmp_path / "t_*.npy"), spacing=(2, 2, 2))
    assert [os.path.basename(n) for n in s.names] == ["t_1.npy", "t_2.npy", "t_10.npy"]
    assert all(np.array_equal(s[i].data, a[i]) for i in range(3)) and tuple(s.spacing) == (2, 2, 2)
    listed = load_series([tmp_path / "t_10.npy", tmp_path / "t_1.npy"])   # a list keeps its order
    assert np.array_equal(listed[0].data, a[2]) and len(listed) == 2


def test_series_from_4d_files(tmp_path):
    a = _blob_series(3)
    np.save(tmp_path / "s.npy", a)                                     # .npy: time first
    s = load_series(tmp_path / "s.npy")
    assert len(s) == 3 and np.array_equal(s[1].data, a[1])
    import nrrd
    nan = np.nan
    # time the fastest axis (NRRD's first), as its kinds and its "none" direction say
    nrrd.write(str(tmp_path / "s.nrrd"), np.transpose(a, (0, 3, 2, 1)),
               {"kinds": ["time", "domain", "domain", "domain"], "space": "right-anterior-superior",
                "space directions": [[nan] * 3, [2, 0, 0], [0, 3, 0], [0, 0, 4]]}, index_order="F")
    s = load_series(tmp_path / "s.nrrd")
    assert len(s) == 3 and np.array_equal(s[1].data, a[1])
    assert tuple(s.spacing) == (2, 3, 4) and s.orientation == "RAS"
    nrrd.write(str(tmp_path / "slow.nrrd"), a, index_order="C")      # no kinds: the slowest axis is time
    s = load_series(tmp_path / "slow.nrrd")
    assert len(s) == 3 and np.array_equal(s[2].data, a[2])
    nib = pytest.importorskip("nibabel")
    nib.save(nib.Nifti1Image(np.transpose(a, (3, 2, 1, 0)), np.diag([2.0, 2.0, 2.0, 1.0])), str(tmp_path / "s.nii"))
    s = load_series(tmp_path / "s.nii")                                # NIfTI: time last (x, y, z, t)
    assert len(s) == 3 and np.allclose(s[1].data, a[1]) and tuple(s.spacing) == (2, 2, 2)
    assert s.orientation == "RAS"


def test_series_errors(tmp_path):
    a = _blob_series(3)
    steps = [dvr_gl.Volume(a[0]), dvr_gl.Volume(a[1]), dvr_gl.Volume(a[2, :, :, :12])]
    with pytest.raises(StepMismatchError, match=r"step 2 has shape \(16, 16, 12\)") as e:
        VolumeSeries(steps)
    assert e.value.step == 2 and e.value.field == "shape"
    with pytest.raises(StepMismatchError, match="step 1 has spacing"):
        VolumeSeries([dvr_gl.Volume(a[0]), dvr_gl.Volume(a[1], spacing=(1, 1, 2))])
    with pytest.raises(StepMismatchError, match="step 1 has orientation"):
        VolumeSeries([dvr_gl.Volume(a[0], orientation="RAS"), dvr_gl.Volume(a[1])])
    with pytest.raises(ValueError, match="empty"):
        VolumeSeries([])
    with pytest.raises(TypeError, match="single Volume"):
        VolumeSeries(dvr_gl.Volume(a[0]))
    np.save(tmp_path / "a_1.npy", a[0])
    np.save(tmp_path / "a_2.npy", a[1, :8])
    with pytest.raises(InputError, match=r"a_2\.npy.*step 1.*shape") as e:
        load_series(str(tmp_path / "a_*.npy"))
    assert e.value.field == "path"
    with pytest.raises(InputError, match="empty"):
        load_series([])
    with pytest.raises(MissingFileError, match="no file matches"):
        load_series(str(tmp_path / "none_*.npy"))
    with pytest.raises(InputError, match="no 4-D array"):
        load_series(tmp_path / "a_1.npy")


# ============================================================================ frames

def test_frame_plan():
    assert frame_plan() == [(0, 360 * i / ORBIT_FRAMES) for i in range(ORBIT_FRAMES)]
    assert frame_plan(1, 4, 90) == [(0, 0.0), (0, 22.5), (0, 45.0), (0, 67.5)]
    assert frame_plan(4) == [(0, 0.0), (1, 0.0), (2, 0.0), (3, 0.0)]            # a series: one frame a step
    assert [s for s, _ in frame_plan(3, 6)] == [0, 0, 1, 1, 2, 2]               # held equally long
    assert [t for _, t in frame_plan(2, 4, 360)] == [0.0, 90.0, 180.0, 270.0]   # both
    with pytest.raises(InputError, match="frames"):
        frame_plan(1, 0)
    with pytest.raises(InputError, match="orbit"):
        frame_plan(1, 4, float("nan"))


def test_the_transfer_function_fits_every_step():
    s = VolumeSeries.from_array(_blob_series())
    _, tf = resolve_movie_tf("grey", s)
    _, pooled = resolve_tf("grey", s.pooled())
    _, first = resolve_tf("grey", s[0])
    assert np.array_equal(tf.color_points, pooled.color_points)
    assert tf.color_points[-1, 0] > first.color_points[-1, 0]     # the later, brighter steps widen it


# ============================================================================ movies (GL)

def test_orbit_mp4(renderer, tmp_path):
    path = tmp_path / "head.mp4"
    result = render_movie("builtin:ct_head", path, frames=12, size=(64, 64), renderer=renderer, progress=False)
    assert sorted(os.listdir(tmp_path)) == ["head.mp4"]               # the temporary file is gone
    frames = _read(path)
    assert frames.shape == (12, 64, 64, 3) and result.frames == 12
    assert len(result.render_s) == 12 and result.per_frame_s > 0
    for f in frames:
        assert f.mean() > 50                                           # not black (over white)
        assert (f.astype(int).sum(-1) < 600).mean() > 0.05             # and not empty: the head is there
    steps = [np.abs(frames[i].astype(int) - frames[i + 1].astype(int)).mean() for i in range(11)]
    assert min(steps) > 1.0                                            # it turns, frame by frame
    # a whole turn: the last frame is one step short of the first, the middle one opposite
    assert np.abs(frames[0].astype(int) - frames[6].astype(int)).mean() > min(steps)


def test_series_gif(renderer, tmp_path):
    series = VolumeSeries.from_array(_blob_series(4))
    path = tmp_path / "blob.gif"
    result = render_movie(series, path, fps=8, size=(48, 40), tf="warm", renderer=renderer, progress=False)
    assert sorted(os.listdir(tmp_path)) == ["blob.gif"] and result.frames == 4
    frames = _read(path)
    assert frames.shape == (4, 40, 48, 3)
    assert all(f.mean() > 50 for f in frames)
    for i in range(3):                                                  # the blob moves
        assert np.abs(frames[i].astype(int) - frames[i + 1].astype(int)).mean() > 0.5
    # spread over more frames than steps: each step held twice, and the orbit turns as well
    render_movie(series, tmp_path / "both.gif", frames=8, orbit=90, size=32, renderer=renderer, progress=False)
    assert _read(tmp_path / "both.gif").shape == (8, 32, 32, 3)


class _FailingRenderer:
    """A renderer that fails on its third frame."""

    def __init__(self, renderer):
        self.renderer, self.calls = renderer, 0

    def render(self, scene, **options):
        self.calls += 1
        if self.calls == 3:
            raise RuntimeError("frame 3 failed")
        return self.renderer.render(scene, **options)


@pytest.mark.parametrize("name", ["x.mp4", "x.gif"])
def test_a_failure_mid_way_leaves_nothing(renderer, tmp_path, name):
    with pytest.raises(RuntimeError, match="frame 3 failed"):
        render_movie(VolumeSeries.from_array(_blob_series(5)), tmp_path / name, size=32,
                     renderer=_FailingRenderer(renderer), progress=False)
    assert os.listdir(tmp_path) == []
    (tmp_path / name).write_bytes(b"old")                               # an earlier movie stays as it was
    with pytest.raises(RuntimeError):
        render_movie(VolumeSeries.from_array(_blob_series(5)), tmp_path / name, size=32,
                     renderer=_FailingRenderer(renderer), progress=False)
    assert os.listdir(tmp_path) == [name] and (tmp_path / name).read_bytes() == b"old"


def test_a_missing_extra_names_it(tmp_path, monkeypatch, capsys):
    import sys
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    with pytest.raises(MovieDependencyError, match=r"dvr-gl\[movie\]"):
        render_movie("builtin:ct_head", tmp_path / "x.mp4", frames=2, size=32)
    assert cli.main(["movie", "builtin:ct_head", "-o", str(tmp_path / "x.mp4")]) == 2
    assert "dvr-gl[movie]" in capsys.readouterr().err and os.listdir(tmp_path) == []


# ============================================================================ the command line

def test_cli_movie_of_a_series(tmp_path, capsys):
    a = _blob_series(4)
    for t in range(4):
        np.save(tmp_path / f"step{t}.npy", a[t])
    out = tmp_path / "steps.gif"
    code = cli.main(["movie", str(tmp_path / "step*.npy"), "-o", str(out), "--size", "32x32", "--fps", "4"])
    text, err = capsys.readouterr()
    assert code == 0, err
    assert "series of 4 steps" in text and "per frame" in text and "first frame" in text
    assert _read(out).shape == (4, 32, 32, 3)


@pytest.mark.parametrize("argv, option, fragment", [
    (["--size", "65x64"], "--size", "even"),
    (["-o", "x.avi"], "--out", ".mp4 or .gif"),
    (["--fps", "0"], "--fps", "positive"),
    (["--fps", "nan"], "--fps", "finite"),
    (["-o", "x.gif", "--fps", "60"], "--fps", "at most 50"),
    (["--frames", "0"], "--frames", "1 or more"),
    (["--orbit", "x"], "--orbit", "number"),
])
def test_cli_movie_errors_name_the_option(tmp_path, monkeypatch, capsys, argv, option, fragment):
    args = ["movie", "builtin:ct_head", "-o", "x.mp4"] + argv
    monkeypatch.chdir(tmp_path)
    code = cli.main(args)
    err = capsys.readouterr().err
    assert code == 2 and option in err and fragment in err, err
    assert "Traceback" not in err and os.listdir(tmp_path) == []
