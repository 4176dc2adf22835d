"""dvr_gl.formats and dvr_gl.data: volume loading (every format, every bad input), PNG writing
(un-premultiplying, background compositing, rounding, atomic writes), the CLI parsers,
and the bundled data sets. No GL."""

import gzip
import os
import stat
import zlib

import nrrd
import numpy as np
import pytest
from PIL import Image

import dvr_gl
from dvr_gl import data
from dvr_gl.formats import (InputError, MissingFileError, load_volume, parse_orientation, parse_size, parse_triplet,
                       save_png, to_png_array)

SHARED = os.environ.get("DVR_GL_DATA") or os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                                       os.pardir, "shared", "data")
# the real files live in the shared data folder beside the checkout (CI has it)
needs_shared_data = pytest.mark.skipif(not os.path.isdir(SHARED), reason="the shared data folder is not beside "
                                                                         "the checkout (or at $DVR_GL_DATA)")
HEADSQ = os.path.join(SHARED, "vtk_headsq_quarter")
LIDC = os.path.join(SHARED, "vtkjs_lidc2_ct")
HEADMR = os.path.join(SHARED, "vtk_headmr")


@pytest.fixture
def vol_i16():
    rng = np.random.default_rng(1)
    return rng.integers(-3000, 3000, size=(5, 4, 3), dtype=np.int16)  # (nz, ny, nx), all different


def _err(excinfo):
    return excinfo.value.field, str(excinfo.value)


# ============================================================================ .npy / .npz

def test_npy_round_trip(tmp_path, vol_i16):
    p = tmp_path / "v.npy"
    np.save(p, vol_i16)
    v = load_volume(p)
    assert v.data.dtype == np.int16 and np.array_equal(v.data, vol_i16)
    assert v.spacing.tolist() == [1, 1, 1] and v.origin.tolist() == [0, 0, 0]
    v = load_volume(str(p), spacing=(0.5, 2, 3), origin="1,2,3")
    assert v.spacing.tolist() == [0.5, 2, 3] and v.origin.tolist() == [1, 2, 3]
    # shape and dtype are checks for self-describing files
    assert load_volume(p, shape=(5, 4, 3), dtype="int16").shape == (5, 4, 3)


def test_npz_round_trip(tmp_path, vol_i16):
    p = tmp_path / "v.npz"
    np.savez_compressed(p, data=vol_i16, spacing=[3.2, 3.2, 1.5], origin=[-1, 0, 1])
    v = load_volume(p)
    assert np.array_equal(v.data, vol_i16)
    assert v.spacing.tolist() == [3.2, 3.2, 1.5] and v.origin.tolist() == [-1, 0, 1]


def test_npy_float_and_big_endian_become_native(tmp_path):
    a = np.linspace(0, 1, 2 * 3 * 4).reshape(2, 3, 4).astype(">f4")
    p = tmp_path / "be.npy"
    np.save(p, a)
    v = load_volume(p)
    assert v.data.dtype == np.float32 and v.data.dtype.isnative
    assert np.array_equal(v.data, a.astype(np.float32))


@pytest.mark.parametrize("src, expect", [
    (np.array([-128, 0, 127], np.int8), np.int16),
    (np.array([0.5, -2, 7], np.float16), np.float32),
    (np.array([True, False, True]), np.uint8),
    (np.array([-2 ** 24, 0, 2 ** 24], np.int32), np.float32),
    (np.array([0, 1, 2 ** 24 + 1], np.uint32), np.float64),
    (np.array([-(2 ** 53), 0, 2 ** 53], np.int64), np.float64),
])
def test_dtypes_are_widened_without_loss(tmp_path, src, expect):
    a = np.resize(src, (2, 2, 3))
    p = tmp_path / "w.npy"
    np.save(p, a)
    v = load_volume(p)
    assert v.data.dtype == expect
    assert np.array_equal(v.data.astype(np.float64), a.astype(np.float64))
    assert np.array_equal(v.data.astype(a.dtype), a)  # exact: converts back


def test_integers_beyond_float64_are_refused(tmp_path):
    p = tmp_path / "big.npy"
    np.save(p, np.full((2, 2, 2), 2 ** 53 + 1, np.uint64))
    with pytest.raises(InputError) as e:
        load_volume(p)
    field, msg = _err(e)
    assert field == "dtype" and "uint64" in msg and str(2 ** 53 + 1) in msg


# ============================================================================ raw

def test_raw_round_trip(tmp_path, vol_i16):
    p = tmp_path / "v.raw"
    vol_i16.tofile(p)
    v = load_volume(p, shape="5,4,3", dtype="int16", spacing="1,2,3")
    assert np.array_equal(v.data, vol_i16) and v.spacing.tolist() == [1, 2, 3]
    # any extension is raw
    q = tmp_path / "v.bin"
    vol_i16.tofile(q)
    assert np.array_equal(load_volume(q, shape=(5, 4, 3), dtype=np.int16, spacing=(1, 1, 1)).data, vol_i16)


def test_raw_big_endian(tmp_path):
    a = np.arange(2 * 3 * 4, dtype=np.uint16).reshape(2, 3, 4) * 1000
    p = tmp_path / "be.raw"
    a.astype(">u2").tofile(p)
    v = load_volume(p, shape=(2, 3, 4), dtype=">u2", spacing=(1, 1, 1))
    assert v.data.dtype == np.uint16 and v.data.dtype.isnative and np.array_equal(v.data, a)


def test_raw_gz_round_trip(tmp_path):
    a = np.linspace(-1, 1, 4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    p = tmp_path / "v.raw.gz"
    with gzip.open(p, "wb") as f:
        f.write(a.tobytes())
    v = load_volume(p, shape=(4, 5, 6), dtype="float32", spacing=(1, 1, 1))
    assert np.array_equal(v.data, a)


@pytest.mark.skipif(not os.path.isdir(LIDC), reason="shared test data not present")
def test_lidc2_raw_gz_matches_readme_recipe():
    path = os.path.join(LIDC, "LIDC2_256x256x133_uint8.raw.gz")
    ref = np.frombuffer(gzip.open(path).read(), np.uint8).reshape(133, 256, 256)
    v = load_volume(path, shape="133,256,256", dtype="uint8", spacing="1.40625,1.40625,2.5")
    assert v.data.dtype == np.uint8 and np.array_equal(v.data, ref)
    assert v.spacing.tolist() == [1.40625, 1.40625, 2.5]


@pytest.mark.parametrize("given, missing", [
    ({}, "shape"),
    ({"shape": (5, 4, 3)}, "dtype"),
    ({"shape": (5, 4, 3), "dtype": "int16"}, "spacing"),
    ({"dtype": "int16", "spacing": (1, 1, 1)}, "shape"),
])
def test_raw_needs_shape_dtype_spacing(tmp_path, vol_i16, given, missing):
    p = tmp_path / "v.raw"
    vol_i16.tofile(p)
    with pytest.raises(InputError) as e:
        load_volume(p, **given)
    field, msg = _err(e)
    assert field == missing and f"missing: {missing}" in msg and "v.raw" in msg


def test_raw_size_mismatch_names_shape_and_sizes(tmp_path, vol_i16):
    p = tmp_path / "v.raw"
    vol_i16.tofile(p)  # 120 bytes
    with pytest.raises(InputError) as e:
        load_volume(p, shape=(5, 4, 4), dtype="int16", spacing=(1, 1, 1))
    field, msg = _err(e)
    assert field == "shape" and "120 bytes" in msg and "(5, 4, 4)" in msg and "160" in msg
    with pytest.raises(InputError) as e:
        load_volume(p, shape=(5, 4, 2), dtype="int16", spacing=(1, 1, 1))
    assert "40 bytes too many" in str(e.value)


@pytest.mark.parametrize("dtype", ["complex64", "U3", "object", "datetime64", "not-a-type", "V4"])
def test_raw_unsupported_dtype(tmp_path, vol_i16, dtype):
    p = tmp_path / "v.raw"
    vol_i16.tofile(p)
    with pytest.raises(InputError) as e:
        load_volume(p, shape=(5, 4, 3), dtype=dtype, spacing=(1, 1, 1))
    field, msg = _err(e)
    assert field == "dtype" and repr(dtype) in msg and "int16" in msg


@pytest.mark.parametrize("kw, field, fragment", [
    ({"shape": "5,4"}, "shape", "'5,4'"),
    ({"shape": "5,4,x"}, "shape", "'5,4,x'"),
    ({"shape": "5,4,3.5"}, "shape", "'5,4,3.5'"),
    ({"shape": (5, 0, 3)}, "shape", "positive"),
    ({"shape": (5.0, 4, 3)}, "shape", "integers"),
    ({"spacing": "1,0,1"}, "spacing", "positive"),
    ({"spacing": "1,nan,1"}, "spacing", "finite"),
    ({"spacing": (1, -2, 1)}, "spacing", "positive"),
    ({"spacing": 3}, "spacing", "3"),
    ({"origin": "1,2"}, "origin", "'1,2'"),
    ({"origin": (0, float("inf"), 0)}, "origin", "finite"),
])
def test_bad_geometry_arguments(tmp_path, vol_i16, kw, field, fragment):
    p = tmp_path / "v.raw"
    vol_i16.tofile(p)
    args = {"shape": (5, 4, 3), "dtype": "int16", "spacing": (1, 1, 1)}
    args.update(kw)
    with pytest.raises(InputError) as e:
        load_volume(p, **args)
    got_field, msg = _err(e)
    assert got_field == field and fragment in msg


def test_missing_file(tmp_path):
    with pytest.raises(MissingFileError) as e:
        load_volume(tmp_path / "nope.npy")
    assert isinstance(e.value, FileNotFoundError) and isinstance(e.value, ValueError)
    assert e.value.field == "path" and "nope.npy" in str(e.value)
    with pytest.raises(InputError, match="is a folder; read as a DICOM series, it holds 0 image slices"):
        load_volume(tmp_path)


def test_self_describing_files_check_shape_and_dtype(tmp_path, vol_i16):
    p = tmp_path / "v.npy"
    np.save(p, vol_i16)
    with pytest.raises(InputError) as e:
        load_volume(p, shape=(3, 4, 5))
    assert e.value.field == "shape" and "(5, 4, 3)" in str(e.value) and "(3, 4, 5)" in str(e.value)
    with pytest.raises(InputError) as e:
        load_volume(p, dtype="uint8")
    assert e.value.field == "dtype" and "int16" in str(e.value) and "uint8" in str(e.value)


def test_npy_not_3d(tmp_path):
    p = tmp_path / "v.npy"
    np.save(p, np.zeros((4, 4)))
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "path" and "2-D" in str(e.value)


def test_npy_pickled_or_garbage(tmp_path):
    p = tmp_path / "obj.npy"
    np.save(p, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "path"
    q = tmp_path / "junk.npy"
    q.write_bytes(b"not numpy at all")
    with pytest.raises(InputError):
        load_volume(q)


def test_npz_without_data(tmp_path):
    p = tmp_path / "v.npz"
    np.savez(p, volume=np.zeros((2, 2, 2)))
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "data" and "'volume'" in str(e.value)


def test_nonfinite_needs_masking(tmp_path):
    a = np.ones((3, 3, 3), np.float32)
    a[1, 1, 1] = np.nan
    p = tmp_path / "nan.npy"
    np.save(p, a)
    with pytest.raises(ValueError, match="mask_nonfinite"):
        load_volume(p)
    v = load_volume(p, mask_nonfinite=True)
    assert v.has_nonfinite


# ============================================================================ NRRD

@pytest.mark.parametrize("encoding", ["raw", "gzip", "bzip2", "ascii"])
@pytest.mark.parametrize("detached", [False, True])
def test_nrrd_round_trip_pynrrd(tmp_path, vol_i16, encoding, detached):
    p = tmp_path / ("v.nhdr" if detached else "v.nrrd")
    nrrd.write(str(p), vol_i16, {"encoding": encoding, "spacings": [0.5, 0.75, 2.0]},
               detached_header=detached, index_order="C")
    v = load_volume(p)
    assert v.data.dtype == np.int16 and np.array_equal(v.data, vol_i16)
    assert v.spacing.tolist() == [0.5, 0.75, 2.0]


def test_nrrd_space_directions_and_origin(tmp_path):
    a = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
    p = tmp_path / "v.nrrd"
    header = {"space": "left-posterior-superior", "space directions": np.diag([0.5, 0.25, 3.0]),
              "space origin": np.array([10.0, -20.0, 5.0])}
    nrrd.write(str(p), a, header, index_order="C")
    v = load_volume(p)
    assert np.array_equal(v.data, a)
    assert v.spacing.tolist() == [0.5, 0.25, 3.0] and v.origin.tolist() == [10.0, -20.0, 5.0]
    assert v.orientation == "LPS"    # the anatomical space, axis by axis
    # spacing and origin given replace the file's
    v = load_volume(p, spacing=(1, 1, 1), origin=(0, 0, 0))
    assert v.spacing.tolist() == [1, 1, 1] and v.origin.tolist() == [0, 0, 0]


def test_nrrd_rotated_directions_warn_and_use_lengths(tmp_path):
    a = np.zeros((2, 2, 2), np.uint8)
    c, s = np.cos(0.3), np.sin(0.3)
    d = np.array([[2 * c, 2 * s, 0], [-3 * s, 3 * c, 0], [0, 0, -4.0]])
    p = tmp_path / "rot.nrrd"
    nrrd.write(str(p), a, {"space": "right-anterior-superior", "space directions": d}, index_order="C")
    with pytest.warns(UserWarning, match="space directions"):
        v = load_volume(p)
    assert np.allclose(v.spacing, [2, 3, 4])
    # each axis named by its vector's largest component and sign: RAI, a left-handed frame,
    # so the x axis is reversed on loading (io.right_handed) and named L
    assert v.orientation == "LAI"


def test_nrrd_without_an_anatomical_space_takes_the_dicom_convention_as_assumed(tmp_path):
    """A 3D-right-handed or 3D-left-handed space names no anatomy: the axes are read as
    DICOM lays out a slice (x to the patient's left, y to the back), z by the handedness
    (LPS, LPI; a left-handed frame is then loaded with x reversed), marked as assumed;
    without a space there is no orientation."""
    data = np.arange(24, dtype=np.uint8).reshape(2, 3, 4)
    for space, codes, flipped in (("3D-right-handed", "LPS", False), ("3D-left-handed", "RPI", True)):
        p = tmp_path / "plain.nrrd"
        nrrd.write(str(p), data, {"space": space, "spacings": [1, 1, 1]}, index_order="C")
        v = load_volume(p)
        assert v.orientation == codes and v.orientation_assumed
        assert np.array_equal(v.data, data[:, :, ::-1] if flipped else data)
        given = load_volume(p, orientation="RAS")
        assert given.orientation == "RAS" and not given.orientation_assumed
    nrrd.write(str(tmp_path / "none.nrrd"), data, {"spacings": [1, 1, 1]}, index_order="C")
    assert load_volume(tmp_path / "none.nrrd").orientation is None


@pytest.mark.skipif(not os.path.isdir(HEADSQ), reason="shared test data not present")
def test_headsq_detached_multifile_nhdr_matches_readme_recipe():
    ref = np.stack([np.fromfile(os.path.join(HEADSQ, f"quarter.{i}"), dtype="<i2").reshape(64, 64)
                    for i in range(1, 94)])
    v = load_volume(os.path.join(HEADSQ, "quarter.nhdr"))
    assert v.shape == (93, 64, 64) and v.data.dtype == np.int16
    # its space is 3D-left-handed: read as LPI (assumed), a left-handed frame, so x is reversed
    assert v.orientation == "RPI" and v.orientation_assumed
    assert np.array_equal(v.data, ref[:, :, ::-1])
    assert v.spacing.tolist() == [3.2, 3.2, 1.5] and v.origin.tolist() == [0, 0, 0]
    assert v.data_range == (0.0, 3926.0)


def _slices(tmp_path, a, names, encoding="raw"):
    for name, sl in zip(names, a):
        raw = sl.astype("<u2").tobytes()
        if encoding == "gzip":
            raw = gzip.compress(raw)
        (tmp_path / name).write_bytes(raw)


def _nhdr(tmp_path, data_file, sizes="4 3 5", encoding="raw", extra=""):
    p = tmp_path / "h.nhdr"
    p.write_text(f"NRRD0004\n# a comment\ndimension: 3\nsizes: {sizes}\ntype: ushort\nendian: little\n"
                 f"encoding: {encoding}\nspacings: 1 2 3\n{extra}data file: {data_file}\n")
    return p


@pytest.fixture
def vol_u16():
    return (np.arange(5 * 3 * 4, dtype=np.uint16) * 7).reshape(5, 3, 4)


@pytest.mark.parametrize("encoding", ["raw", "gzip"])
def test_nrrd_format_form(tmp_path, vol_u16, encoding):
    _slices(tmp_path, vol_u16, [f"s{i:03d}.raw" for i in range(1, 6)], encoding)
    v = load_volume(_nhdr(tmp_path, "s%03d.raw 1 5 1", encoding=encoding))
    assert np.array_equal(v.data, vol_u16) and v.spacing.tolist() == [1, 2, 3]


def test_nrrd_format_form_negative_step_and_subdim(tmp_path, vol_u16):
    # files numbered downwards: slice 0 is in f10, slice 4 in f2
    _slices(tmp_path, vol_u16, [f"f{i}" for i in range(10, 1, -2)])
    assert np.array_equal(load_volume(_nhdr(tmp_path, "f%d 10 2 -2")).data, vol_u16)
    # subdim 3: one file holding the whole volume; subdim 1: one file per row
    (tmp_path / "all0").write_bytes(vol_u16.astype("<u2").tobytes())
    assert np.array_equal(load_volume(_nhdr(tmp_path, "all%d 0 0 1 3")).data, vol_u16)
    for k, row in enumerate(vol_u16.reshape(15, 4)):
        (tmp_path / f"row{k}").write_bytes(row.astype("<u2").tobytes())
    assert np.array_equal(load_volume(_nhdr(tmp_path, "row%d 0 14 1 1")).data, vol_u16)


def test_nrrd_list_form(tmp_path, vol_u16):
    names = ["a.raw", "b.raw", "c.raw", "d.raw", "e.raw"]
    _slices(tmp_path, vol_u16, names)
    p = _nhdr(tmp_path, "LIST")
    with open(p, "a") as f:
        f.write("\n".join(names) + "\n")
    assert np.array_equal(load_volume(p).data, vol_u16)
    # LIST 3: slabs of the slowest axis (here 5 slabs of one slice, then one slab of five)
    p.write_text(p.read_text().replace("data file: LIST", "data file: LIST 3"))
    assert np.array_equal(load_volume(p).data, vol_u16)
    (tmp_path / "whole.raw").write_bytes(vol_u16.astype("<u2").tobytes())
    q = _nhdr(tmp_path, "LIST 3")
    with open(q, "a") as f:
        f.write("whole.raw\n")
    assert np.array_equal(load_volume(q).data, vol_u16)


def test_nrrd_line_and_byte_skip_apply_to_each_file(tmp_path, vol_u16):
    for i, sl in enumerate(vol_u16):
        (tmp_path / f"k{i}").write_bytes(b"junk line\n" + b"\x00" * 6 + sl.astype("<u2").tobytes())
    p = _nhdr(tmp_path, "k%d 0 4 1", extra="line skip: 1\nbyte skip: 6\n")
    assert np.array_equal(load_volume(p).data, vol_u16)


def test_nrrd_missing_data_file_is_named(tmp_path, vol_u16):
    _slices(tmp_path, vol_u16[:4], [f"s{i}" for i in range(4)])
    with pytest.raises(MissingFileError) as e:
        load_volume(_nhdr(tmp_path, "s%d 0 4 1"))
    assert e.value.field == "data file" and "'s4'" in str(e.value)
    with pytest.raises(MissingFileError) as e:
        load_volume(_nhdr(tmp_path, "single.raw"))
    assert e.value.field == "data file" and "single.raw" in str(e.value)


def test_nrrd_wrong_file_count(tmp_path, vol_u16):
    _slices(tmp_path, vol_u16, [f"s{i}" for i in range(5)])
    with pytest.raises(InputError) as e:
        load_volume(_nhdr(tmp_path, "s%d 0 3 1"))
    assert e.value.field == "data file" and "4 data files" in str(e.value) and "need 5" in str(e.value)
    with pytest.raises(InputError) as e:
        load_volume(_nhdr(tmp_path, "s%d 0 1 1 3"))  # 2 slabs cannot split 5 slices
    assert e.value.field == "data file"
    with pytest.raises(InputError) as e:
        load_volume(_nhdr(tmp_path, "s%d 0 4 0"))
    assert "step" in str(e.value)
    with pytest.raises(InputError) as e:
        load_volume(_nhdr(tmp_path, "s%d 4 0 1"))
    assert "not reached" in str(e.value)
    with pytest.raises(InputError) as e:
        load_volume(_nhdr(tmp_path, "s%d 0 4 1 7"))
    assert "outside [1, 3]" in str(e.value)


def test_nrrd_short_piece(tmp_path, vol_u16):
    _slices(tmp_path, vol_u16, [f"s{i}" for i in range(5)])
    (tmp_path / "s2").write_bytes(b"\x00" * 10)
    with pytest.raises(InputError) as e:
        load_volume(_nhdr(tmp_path, "s%d 0 4 1"))
    assert e.value.field == "data file" and "'s2'" in str(e.value)


def test_nrrd_bad_headers(tmp_path, vol_u16):
    (tmp_path / "d.raw").write_bytes(vol_u16.astype("<u2").tobytes())
    with pytest.raises(InputError) as e:
        load_volume(_nhdr(tmp_path, "d.raw", sizes="60"))
    assert e.value.field == "sizes" and "[60]" in str(e.value)
    p = _nhdr(tmp_path, "d.raw")
    p.write_text(p.read_text().replace("dimension: 3", "dimension: 2").replace("sizes: 4 3 5", "sizes: 12 5"))
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "dimension" and "2-D" in str(e.value)
    p = _nhdr(tmp_path, "d.raw", extra="")
    p.write_text(p.read_text().replace("spacings: 1 2 3", "spacings: 1 0 3"))
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "spacings" and "0" in str(e.value)
    p.write_text(p.read_text().replace("type: ushort\n", ""))
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "type"
    p.write_text("not a nrrd\n")
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "path" and "NRRD" in str(e.value)
    p = _nhdr(tmp_path, "d.raw", sizes="4 3 6")  # the file is one slice short
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert "holds 60 samples" in str(e.value) and "need 72" in str(e.value)
    for old, new, field in (("type: ushort", "type: complex", "type"), ("encoding: raw", "encoding: zip", "encoding"),
                            ("endian: little\n", "", "endian")):
        p = _nhdr(tmp_path, "d.raw")
        p.write_text(p.read_text().replace(old, new))
        with pytest.raises(InputError) as e:
            load_volume(p)
        assert e.value.field == field and (new.split(": ")[-1] if new else "None") in str(e.value)


# ============================================================================ MetaImage

def test_metaimage_detached_local_and_compressed(tmp_path, vol_i16):
    (tmp_path / "v.raw").write_bytes(vol_i16.astype(">i2").tobytes())
    p = tmp_path / "v.mhd"
    p.write_text("ObjectType = Image\nNDims = 3\nDimSize = 3 4 5\nElementType = MET_SHORT\n"
                 "ElementSpacing = 1 2 3\nOffset = 4 5 6\nElementByteOrderMSB = True\n"
                 "ElementDataFile = v.raw\n")
    v = load_volume(p)
    assert np.array_equal(v.data, vol_i16) and v.spacing.tolist() == [1, 2, 3] and v.origin.tolist() == [4, 5, 6]
    q = tmp_path / "v.mha"
    q.write_bytes(b"NDims = 3\nDimSize = 3 4 5\nElementType = MET_SHORT\nCompressedData = True\n"
                  b"ElementDataFile = LOCAL\n" + zlib.compress(vol_i16.astype("<i2").tobytes()))
    assert np.array_equal(load_volume(q).data, vol_i16)
    p.write_text(p.read_text().replace("v.raw", "gone.raw"))
    with pytest.raises(MissingFileError) as e:
        load_volume(p)
    assert e.value.field == "ElementDataFile" and "gone.raw" in str(e.value)


@pytest.mark.skipif(not os.path.isdir(HEADMR), reason="shared test data not present")
def test_metaimage_headmr_matches_readme_recipe():
    ref = np.fromfile(os.path.join(HEADMR, "HeadMRVolume.raw"), dtype=np.uint8).reshape(42, 62, 48)
    v = load_volume(os.path.join(HEADMR, "HeadMRVolume.mhd"))
    assert np.array_equal(v.data, ref) and v.spacing.tolist() == [4, 4, 4]
    # its header says neither: ITK's reading, the identity in LPS, assumed
    assert v.orientation == "LPS" and v.orientation_assumed and v.modality is None
    assert load_volume(os.path.join(HEADMR, "HeadMRVolume.mhd"), orientation="LPS").orientation == "LPS"


def _mhd(tmp_path, *extra):
    """A 4x3x2 uint8 MetaImage with the header lines ``extra``; returns its path."""
    np.arange(24, dtype=np.uint8).tofile(tmp_path / "o.raw")
    p = tmp_path / "o.mhd"
    p.write_text("ObjectType = Image\nNDims = 3\n" + "".join(line + "\n" for line in extra)
                 + "DimSize = 4 3 2\nElementType = MET_UCHAR\nElementDataFile = o.raw\n")
    return p


@pytest.mark.parametrize("written, codes", [
    ("RAI", "LPS"),      # ITK's identity direction: x from right to left, y from anterior, z from inferior
    ("LPS", "LAI"),      # RAI, left-handed: loaded with x reversed (io.right_handed)
    ("LPI", "RAS"), ("rai", "LPS"), ("AIR", "PSL"),
    ("???", None), ("RA?", None), ("RLS", None), ("RAIS", None),
    ("", "LPS"),         # nothing said: ITK's identity in LPS (assumed)
])
def test_metaimage_anatomical_orientation_is_read_in_itks_from_letters(tmp_path, written, codes):
    """MetaIO writes AnatomicalOrientation with the letter each axis comes *from*; dvr_gl's
    orientation names where it points (nibabel's convention). Unknown or malformed: none."""
    assert load_volume(_mhd(tmp_path, f"AnatomicalOrientation = {written}")).orientation == codes


def test_metaimage_transform_matrix_gives_the_orientation(tmp_path):
    """TransformMatrix rows are the index axes' direction cosines in ITK's LPS world; one
    other than the identity decides (with a warning that the volume stays axis-aligned),
    an identity one leaves it to AnatomicalOrientation."""
    identity = "TransformMatrix = 1 0 0 0 1 0 0 0 1"
    alone = load_volume(_mhd(tmp_path, identity))
    assert alone.orientation == "LPS" and alone.orientation_assumed      # as ITK reads it
    assert not load_volume(_mhd(tmp_path, identity, "AnatomicalOrientation = RAI")).orientation_assumed
    assert load_volume(_mhd(tmp_path, identity, "AnatomicalOrientation = RAI")).orientation == "LPS"
    with pytest.warns(UserWarning, match="not the identity"):
        # x along -L (right), y along -P (anterior), z along S: RAS, whatever the letters say
        v = load_volume(_mhd(tmp_path, "TransformMatrix = -1 0 0 0 -1 0 0 0 1", "AnatomicalOrientation = RAI"))
    assert v.orientation == "RAS"
    with pytest.warns(UserWarning, match="not the identity"):   # x to posterior, y superior, z left
        assert load_volume(_mhd(tmp_path, "Rotation = 0 1 0 0 0 1 1 0 0")).orientation == "PSL"
    with pytest.warns(UserWarning, match="not the identity"):   # an oblique axis names no direction
        c = np.sqrt(0.5)
        assert load_volume(_mhd(tmp_path, f"TransformMatrix = {c} {c} 0 {-c} {c} 0 0 0 1")).orientation is None
    for bad in ("1 0 0 0 1 0 0 0", "1 0 0 0 1 0 0 0 x", "1 0 0 0 1 0 0 0 nan"):
        with pytest.raises(InputError) as e:
            load_volume(_mhd(tmp_path, f"TransformMatrix = {bad}"))
        assert e.value.field == "TransformMatrix" and bad in str(e.value)


@pytest.mark.parametrize("written, modality", [
    ("MET_MOD_CT", "CT"), ("MET_MOD_MR", "MR"), ("MET_MOD_US", "US"), ("MET_MOD_OTHER", "OT"),
    ("MET_MOD_UNKNOWN", None), ("SOMETHING", None), (None, None),
])
def test_metaimage_modality(tmp_path, written, modality):
    extra = () if written is None else (f"Modality = {written}",)
    assert load_volume(_mhd(tmp_path, *extra)).modality == modality


def test_nrrd_modality_key_value(tmp_path):
    p = tmp_path / "m.nrrd"
    nrrd.write(str(p), np.zeros((2, 2, 2), np.uint8), {"space": "left-posterior-superior"},
               custom_field_map=None, index_order="C")
    assert load_volume(p).modality is None
    p.write_bytes(p.read_bytes().replace(b"space: left-posterior-superior\n",
                                         b"space: left-posterior-superior\nmodality:=ct\n"))
    assert load_volume(p).modality == "CT"


def test_orientation_given_replaces_or_supplies_the_files(tmp_path):
    plain = tmp_path / "plain.nrrd"
    nrrd.write(str(plain), np.zeros((2, 2, 2), np.uint8), {"space": "3D-left-handed", "spacings": [1, 1, 1]},
               index_order="C")
    assert load_volume(plain).orientation_assumed                                  # the convention
    assert load_volume(plain, orientation="lps").orientation == "LPS"             # replaced
    assert load_volume(plain, orientation="lpi").orientation == "RPI"             # left-handed: x reversed
    lps = tmp_path / "lps.nrrd"
    nrrd.write(str(lps), np.zeros((2, 2, 2), np.uint8), {"space": "left-posterior-superior"}, index_order="C")
    assert load_volume(lps, orientation=" RAS ").orientation == "RAS"            # replaced
    np.save(tmp_path / "a.npy", np.zeros((2, 2, 2), np.float32))
    assert load_volume(tmp_path / "a.npy", orientation="SAL").orientation == "SAL"
    for bad in ("XYZ", "RAL", "RA", "RASS", 3):
        with pytest.raises(InputError) as e:
            load_volume(lps, orientation=bad)
        assert e.value.field == "orientation" and repr(bad) in str(e.value)
    assert parse_orientation("pir") == "PIR"
    with pytest.raises(InputError) as e:
        parse_orientation("LRS", "--orientation")
    assert e.value.field == "--orientation" and "one each of R/L, A/P and S/I" in str(e.value)


# ============================================================================ PNG

def _png(path):
    with Image.open(path) as im:
        return im.mode, np.array(im)


def test_png_unpremultiplies(tmp_path):
    img = np.zeros((2, 3, 4), np.float32)
    img[0, 0] = (0.25, 0.1, 0.0, 0.5)   # straight colour (0.5, 0.2, 0), alpha 0.5
    img[0, 1] = (1.0, 1.0, 1.0, 1.0)
    img[0, 2] = (0.3, 0.2, 0.1, 0.0)    # alpha 0: colour written as 0
    img[1, 0] = (0.001, 0.0, 0.0, 0.001)  # tiny alpha: rounds to 0, so colour 0 too
    img[1, 1] = (0.2, 0.0, 0.0, 0.1)    # colour above alpha (unclamped specular): clipped to 1
    img[1, 2] = (0.5, 0.5, 0.5, 1.5)    # out of range alpha clipped to 1
    p = tmp_path / "a.png"
    assert save_png(p, img) == os.fspath(p)
    mode, px = _png(p)
    assert mode == "RGBA" and px.shape == (2, 3, 4) and px.dtype == np.uint8
    assert px[0, 0].tolist() == [128, 51, 0, 128]
    assert px[0, 1].tolist() == [255, 255, 255, 255]
    assert px[0, 2].tolist() == [0, 0, 0, 0]
    assert px[1, 0].tolist() == [0, 0, 0, 0]
    assert px[1, 1].tolist() == [255, 0, 0, 26]
    assert px[1, 2].tolist() == [128, 128, 128, 255]
    assert np.array_equal(px, to_png_array(img))


def test_png_background_composite(tmp_path):
    rng = np.random.default_rng(2)
    a = rng.random((4, 5, 1))
    straight = rng.random((4, 5, 3))
    img = np.concatenate([straight * a, a], axis=-1).astype(np.float32)
    bg = (0.2, 0.4, 1.0)
    p = tmp_path / "b.png"
    save_png(p, img, background=bg)
    mode, px = _png(p)
    assert mode == "RGB" and px.shape == (4, 5, 3)
    expect = np.rint(np.clip(img[..., :3] + (1 - img[..., 3:]) * np.array(bg), 0, 1) * 255)
    assert np.array_equal(px, expect)
    # transparent over the background is the background; opaque ignores it
    clear = np.zeros((1, 2, 4), np.float32)
    clear[0, 1] = (0.1, 0.2, 0.3, 1.0)
    assert to_png_array(clear, background=(1, 0.5, 0)).tolist() == [[[255, 128, 0], [26, 51, 77]]]


def test_png_rounds_to_nearest():
    levels = np.array([0, 0.5, 1.49, 1.51, 254.49, 254.51, 255]) / 255
    img = np.zeros((1, len(levels), 4))
    img[..., 0] = levels
    img[..., 3] = 1
    assert to_png_array(img)[0, :, 0].tolist() == [0, 0, 1, 2, 254, 255, 255]  # rint: 0.5 -> 0 (half to even)


@pytest.mark.parametrize("image, fragment", [
    (np.zeros((4, 4, 3), np.float32), "(H, W, 4)"),
    (np.zeros((4, 4), np.float32), "(H, W, 4)"),
    (np.zeros((0, 4, 4), np.float32), "(H, W, 4)"),
    (np.zeros((4, 4, 4), np.uint8), "dtype uint8"),
    ([[[0, 0, 0, 0]]], "numpy array"),
    (np.full((2, 2, 4), np.nan, np.float32), "non-finite"),
])
def test_png_bad_image(tmp_path, image, fragment):
    p = tmp_path / "bad.png"
    with pytest.raises(InputError) as e:
        save_png(p, image)
    assert e.value.field == "image" and fragment in str(e.value)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("bg, fragment", [((2, 0, 0), "[0, 1]"), ((0, 0), "three"), ("1,1", "'1,1'")])
def test_png_bad_background(tmp_path, bg, fragment):
    with pytest.raises(InputError) as e:
        save_png(tmp_path / "x.png", np.zeros((1, 1, 4), np.float32), background=bg)
    assert e.value.field == "background" and fragment in str(e.value)
    assert os.listdir(tmp_path) == []


def test_png_missing_directory(tmp_path):
    with pytest.raises(MissingFileError) as e:
        save_png(tmp_path / "no" / "x.png", np.zeros((1, 1, 4), np.float32))
    assert e.value.field == "path"


def test_png_atomic_on_failure(tmp_path, monkeypatch):
    target = tmp_path / "img.png"
    target.write_bytes(b"old contents")

    def failing_save(self, fp, *args, **kwargs):
        fp.write(b"\x89PNG half written")
        raise OSError("disk full")

    monkeypatch.setattr(Image.Image, "save", failing_save)
    with pytest.raises(OSError, match="disk full"):
        save_png(target, np.zeros((2, 2, 4), np.float32))
    assert sorted(os.listdir(tmp_path)) == ["img.png"]  # no temporary left behind
    assert target.read_bytes() == b"old contents"     # the old file untouched
    new = tmp_path / "new.png"
    with pytest.raises(OSError):
        save_png(new, np.zeros((2, 2, 4), np.float32))
    assert sorted(os.listdir(tmp_path)) == ["img.png"]


def test_png_replaces_and_has_normal_permissions(tmp_path):
    target = tmp_path / "img.png"
    target.write_bytes(b"old")
    save_png(target, np.ones((3, 2, 4), np.float32))
    assert _png(target)[1].shape == (3, 2, 4)
    assert os.listdir(tmp_path) == ["img.png"]
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(os.stat(target).st_mode) == 0o666 & ~umask


# ============================================================================ parsers

def test_parse_size():
    assert parse_size("512x256") == (512, 256)
    assert parse_size(" 64X32 ") == (64, 32)
    assert parse_size("128") == (128, 128)
    for bad in ["", "x", "5x", "x5", "-5x5", "5x5x5", "5.5x5", "0x5", "5x99999", "axb"]:
        with pytest.raises(InputError) as e:
            parse_size(bad)
        assert e.value.field == "size" and repr(bad) in str(e.value)


def test_parse_triplet():
    assert parse_triplet("1,2,3") == (1.0, 2.0, 3.0)
    assert parse_triplet(" 1.5 , -2, 3e2") == (1.5, -2.0, 300.0)
    assert parse_triplet("64,64,93", "shape", kind=int) == (64, 64, 93)
    assert parse_triplet((1, 2, 3)) == (1.0, 2.0, 3.0)
    for bad in ["1,2", "1,2,3,4", "1,,3", "a,b,c", "1;2;3", "1,2,inf"]:
        with pytest.raises(InputError) as e:
            parse_triplet(bad, "spacing")
        assert e.value.field == "spacing" and repr(bad) in str(e.value)
    with pytest.raises(InputError, match="positive"):
        parse_triplet("1,0,1", "spacing", positive=True)
    with pytest.raises(InputError, match="integers"):
        parse_triplet("1,2,3.5", "shape", kind=int)


# ============================================================================ bundled data

def test_ct_head():
    v = data.ct_head()
    assert isinstance(v, dvr_gl.Volume) and v is data.ct_head()  # cached, immutable
    assert v.shape == (93, 64, 64) and v.data.dtype == np.int16 and v.data.dtype.isnative
    assert v.spacing.tolist() == [3.2, 3.2, 1.5] and v.origin.tolist() == [0, 0, 0]
    assert v.data_range == (0.0, 3926.0)
    assert not v.data.flags.writeable
    if os.path.isdir(HEADSQ):
        ref = np.stack([np.fromfile(os.path.join(HEADSQ, f"quarter.{i}"), dtype="<i2").reshape(64, 64)
                        for i in range(1, 94)])
        assert np.array_equal(v.data, ref)


def test_ct_head_licence_is_shipped():
    here = os.path.dirname(data.__file__)
    text = open(os.path.join(here, "LICENSE-headsq.txt")).read()
    assert "Copyright (c) 1993-2008 Ken Martin, Will Schroeder, Bill Lorensen" in text
    assert "pyvista/vtk-data" in text and "126ee906165a8b2f984f08259a4a2d32cf3b3409" in text
    assert "Neither name of Ken Martin, Will Schroeder, or Bill Lorensen" in text


def test_synthetic_samples_the_analytic_field():
    v = data.synthetic()
    assert v.shape == (64, 64, 64) and v.data.dtype == np.float32
    assert v.spacing.tolist() == [1, 1, 1] and v.origin.tolist() == [0, 0, 0]
    k, j, i = 10, 40, 33
    assert v.data[k, j, i] == np.float32(data.synthetic_field(i, j, k))
    c = data.SYNTHETIC_EXTENT / 2
    assert abs(data.synthetic_field(c, c, c) - 0.6) < 1e-3  # the centre blob's peak
    assert 0.99 < v.data_range[1] < 1.01
    faces = [v.data[0], v.data[-1], v.data[:, 0], v.data[:, -1], v.data[..., 0], v.data[..., -1]]
    assert max(float(f.max()) for f in faces) < 1e-3
    w = data.synthetic(33)  # same world box, coarser grid, same field
    assert w.shape == (33, 33, 33) and np.allclose(w.extent, v.extent)
    assert w.data[16, 16, 16] == np.float32(data.synthetic_field(c, c, c))
    with pytest.raises(ValueError, match="n must be"):
        data.synthetic(1)
    with pytest.raises(TypeError, match="n must be"):
        data.synthetic(64.0)


def test_default_transfer_functions():
    head_tf, field_tf = data.ct_head_tf(), data.synthetic_tf()
    assert isinstance(head_tf, dvr_gl.TransferFunction) and isinstance(field_tf, dvr_gl.TransferFunction)
    assert head_tf.unit_distance == data.ct_head().min_spacing == 1.5
    assert field_tf.unit_distance == data.synthetic().min_spacing == 1.0
    assert head_tf.opacity(0.0) == 0 and head_tf.opacity(1000.0) == 0 and head_tf.opacity(2000.0) > 0.1
    assert field_tf.opacity(0.05) == 0 and field_tf.opacity(1.0) > 0.5


# -- the Open SciVis raw names, NIfTI, and formats dvr_gl does not read -------------------------

def test_a_raw_name_in_the_open_scivis_convention_gives_shape_and_dtype(tmp_path):
    a = (np.arange(5 * 4 * 3, dtype=np.int16).reshape(5, 4, 3) - 20)
    p = tmp_path / "part_3x4x5_int16.raw"
    p.write_bytes(a.astype("<i2").tobytes())
    v = load_volume(p)
    assert v.data.shape == (5, 4, 3) and v.data.dtype == np.int16 and np.array_equal(v.data, a)
    assert v.spacing.tolist() == [1, 1, 1]
    assert load_volume(p, spacing=(1, 2, 3)).spacing.tolist() == [1, 2, 3]      # options still win
    g = tmp_path / "part_3x4x5_float32.raw.gz"
    g.write_bytes(gzip.compress(a.astype("<f4").tobytes()))
    assert np.array_equal(load_volume(g).data, a.astype(np.float32))
    short = tmp_path / "cut_3x4x6_int16.raw"                                    # the name promises more
    short.write_bytes(a.astype("<i2").tobytes())
    with pytest.raises(InputError, match="shape|size|bytes"):
        load_volume(short)


@pytest.mark.parametrize("name,shape,dtype", [("vtk_neghip/neghip_66x66x66_uint8.raw", (66, 66, 66), np.uint8),
                                              ("vtk_hydrogen/hydrogen_64x64x64_float32.raw", (64, 64, 64), np.float32)])
@needs_shared_data
def test_shared_raw_files_load_by_their_names(name, shape, dtype):
    v = load_volume(os.path.join(SHARED, name))
    assert v.data.shape == shape and v.data.dtype == dtype and v.data.max() > v.data.min()


def test_nifti_through_nibabel(tmp_path):
    nib = pytest.importorskip("nibabel")
    xyz = np.arange(3 * 4 * 5, dtype=np.int16).reshape(3, 4, 5)          # x, y, z index order
    affine = np.diag([1.0, 2.0, 3.0, 1.0])
    affine[:3, 3] = (-5.0, 6.0, 7.5)
    p = tmp_path / "v.nii.gz"
    nib.save(nib.Nifti1Image(xyz, affine), str(p))
    v = load_volume(p)
    assert v.data.shape == (5, 4, 3) and np.array_equal(v.data, np.transpose(xyz, (2, 1, 0)))
    assert v.spacing.tolist() == [1, 2, 3] and v.origin.tolist() == [-5, 6, 7.5]
    assert v.orientation == "RAS"
    flipped = affine.copy()
    flipped[0, 0] = -1.0     # x runs to the left: the camera still finds the face
    nib.save(nib.Nifti1Image(xyz, flipped), str(tmp_path / "f.nii"))
    with pytest.warns(UserWarning, match="axis-aligned"):
        left = load_volume(tmp_path / "f.nii")
    # LAS (radiological storage) is a left-handed frame: x is reversed so no view is a mirror image
    assert left.orientation == "RAS" and np.array_equal(left.data, np.transpose(xyz, (2, 1, 0))[:, :, ::-1])
    rotated = affine.copy()
    rotated[:3, :3] = [[0, -2.0, 0], [1.0, 0, 0], [0, 0, 3.0]]
    nib.save(nib.Nifti1Image(xyz, rotated), str(tmp_path / "r.nii"))
    with pytest.warns(UserWarning, match="axis-aligned"):
        load_volume(tmp_path / "r.nii")
    nib.save(nib.Nifti1Image(np.zeros((3, 4, 5, 2), np.float32), affine), str(tmp_path / "t.nii"))
    with pytest.raises(InputError, match="4-D"):
        load_volume(tmp_path / "t.nii")


@needs_shared_data
def test_shared_mri_loads():
    pytest.importorskip("nibabel")
    v = load_volume(os.path.join(SHARED, "debian_mricron_colin27", "ch2.nii.gz"))
    assert v.data.shape == (181, 217, 181) and v.spacing.tolist() == [1, 1, 1]


def test_a_format_dvr_gl_does_not_read_is_named_with_the_ones_it_does(tmp_path):
    p = tmp_path / "image.png"
    p.write_bytes(b"\x89PNG\r\n")
    with pytest.raises(InputError) as e:
        load_volume(p)
    assert e.value.field == "path" and ".png" in str(e.value) and ".nrrd" in str(e.value) and ".nii" in str(e.value)
    assert "DICOM" in str(e.value) and ".tif" in str(e.value)


@needs_shared_data
def test_vtk_image_data_through_vtk():
    """.vti, legacy structured points and .slc through VTK's readers: the shared files
    hold the same samples as their raw companions."""
    pytest.importorskip("vtk")
    vti = load_volume(os.path.join(SHARED, "vtk_hydrogen", "hydrogen.vti"))
    assert np.array_equal(vti.data, load_volume(os.path.join(SHARED, "vtk_hydrogen",
                                                             "hydrogen_64x64x64_float32.raw")).data)
    slc = load_volume(os.path.join(SHARED, "vtk_neghip", "neghip.slc"))
    assert np.array_equal(slc.data, load_volume(os.path.join(SHARED, "vtk_neghip", "neghip_66x66x66_uint8.raw")).data)
    carotid = load_volume(os.path.join(SHARED, "vtk_carotid", "carotid.vtk"))
    assert carotid.data.shape == (45, 49, 76) and carotid.origin.tolist() == [100, 80, 1]
    with pytest.raises(InputError, match="UNSTRUCTURED_GRID"):
        load_volume(os.path.join(SHARED, "vtk_post_tets", "post.vtk"))


def test_vtk_image_data_written_here(tmp_path):
    vtk = pytest.importorskip("vtk")
    from vtkmodules.util.numpy_support import numpy_to_vtk
    a = np.arange(3 * 4 * 5, dtype=np.int16).reshape(5, 4, 3)       # (nz, ny, nx)
    image = vtk.vtkImageData()
    image.SetDimensions(3, 4, 5)
    image.SetSpacing(0.5, 1.0, 2.0)
    image.SetOrigin(1.0, -2.0, 3.0)
    image.GetPointData().SetScalars(numpy_to_vtk(a.ravel(), deep=True))
    writer = vtk.vtkXMLImageDataWriter()
    writer.SetFileName(str(tmp_path / "a.vti"))
    writer.SetInputData(image)
    writer.Write()
    v = load_volume(tmp_path / "a.vti")
    assert np.array_equal(v.data, a) and v.spacing.tolist() == [0.5, 1, 2] and v.origin.tolist() == [1, -2, 3]


def _write_dicom_series(folder, volume_hu, spacing=(0.7, 0.8), thickness=2.5, series="1.2.3.4", shuffle=True,
                        row=(1, 0, 0), col=(0, 1, 0), prefix="im"):
    """A CT series of (nz, ny, nx) HU values as one file per slice, stored as unsigned
    values with RescaleIntercept -1024, written in a scrambled order."""
    pydicom = pytest.importorskip("pydicom")
    from pydicom.dataset import FileDataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid
    folder.mkdir(parents=True, exist_ok=True)
    normal = np.cross(row, col)
    order = np.random.default_rng(5).permutation(len(volume_hu)) if shuffle else range(len(volume_hu))
    for n, k in enumerate(order):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = FileDataset(str(folder / f"{prefix}{n:03d}.dcm"), {}, file_meta=meta, preamble=b"\0" * 128)
        ds.SOPClassUID = CTImageStorage
        ds.SeriesInstanceUID = series
        ds.Modality = "CT"
        ds.Rows, ds.Columns = volume_hu.shape[1:]
        ds.PixelSpacing = [spacing[1], spacing[0]]
        ds.ImageOrientationPatient = [*row, *col]
        ds.ImagePositionPatient = list(np.array([-100.0, -120.0, 30.0]) + k * thickness * normal)
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 0
        ds.RescaleSlope, ds.RescaleIntercept = 1, -1024
        ds.PixelData = (volume_hu[k] + 1024).astype("<u2").tobytes()
        ds.save_as(str(folder / f"{prefix}{n:03d}.dcm"), enforce_file_format=True)
    return pydicom


def test_dicom_series_sorted_rescaled_and_oriented(tmp_path):
    hu = np.random.default_rng(3).integers(-1000, 2000, (5, 6, 7)).astype(np.int16)
    _write_dicom_series(tmp_path / "ct", hu)
    (tmp_path / "ct" / "notes.txt").write_text("not DICOM")
    v = load_volume(tmp_path / "ct")
    assert v.data.dtype == np.int16 and np.array_equal(v.data, hu)       # sorted by position, in HU
    assert np.allclose(v.spacing, [0.7, 0.8, 2.5]) and np.allclose(v.origin, [-100, -120, 30])
    assert v.orientation == "LPS"                                       # DICOM's patient axes
    assert v.modality == "CT"                                           # the Modality tag
    assert load_volume(tmp_path / "ct", orientation="ras").orientation == "RAS"   # given: replaces it
    one = load_volume(tmp_path / "ct" / "im002.dcm")                    # one file: its whole series
    assert np.array_equal(one.data, hu)
    # another series in the folder is left out, with a warning
    _write_dicom_series(tmp_path / "ct", hu[:2], series="9.9.9", shuffle=False, prefix="other")
    with pytest.warns(UserWarning, match="other series"):
        assert np.array_equal(load_volume(tmp_path / "ct" / "im002.dcm").data, hu)
    with pytest.warns(UserWarning, match="other series"):
        assert load_volume(tmp_path / "ct" / "other001.dcm").shape == (2, 6, 7)


def test_dicom_series_flipped_axes_and_errors(tmp_path):
    hu = np.zeros((3, 4, 5), np.int16)
    _write_dicom_series(tmp_path / "flip", hu, row=(-1, 0, 0), col=(0, 0, -1))
    assert load_volume(tmp_path / "flip").orientation == "RIA"     # normal = row x col points anterior
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="holds 0 image slices"):
        load_volume(tmp_path / "empty")
    with pytest.raises(MissingFileError):
        load_volume(tmp_path / "nowhere.dcm")


def test_tiff_stack(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    a = np.random.default_rng(4).integers(0, 60000, (4, 5, 6)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "stack.tif", a, imagej=True, resolution=(1 / 0.5, 1 / 0.25),
                     metadata={"spacing": 2.0, "unit": "um"})
    v = load_volume(tmp_path / "stack.tif")
    assert np.array_equal(v.data, a) and np.allclose(v.spacing, [0.5, 0.25, 2.0])
    tifffile.imwrite(tmp_path / "plain.tiff", a, photometric="minisblack")
    assert np.allclose(load_volume(tmp_path / "plain.tiff").spacing, [1, 1, 1])
    tifffile.imwrite(tmp_path / "flat.tif", a[0])
    with pytest.raises(InputError, match="one grey page per slice"):
        load_volume(tmp_path / "flat.tif")
