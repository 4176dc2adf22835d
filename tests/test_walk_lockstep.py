"""The cell walk where a GL's pixels run in lockstep (``LOCKSTEP_LANES``,
``gl.capabilities.lockstep_lanes``; llvmpipe): code under a branch that no pixel takes
costs there as if taken, so walk.frag integrates the light segments (one piece, optical
depth and relative change of transparency at most 0.3) inline with ``lightSegment``
(common/linear_segment.glsl: no loops, no branches) and leaves the other segments and the
rare steps (zero-volume cells, folded faces) to an outer loop that a group of pixels
enters only when one of them needs it.

Tolerances. ``lightSegment`` against the float64 integral: its 4-point Gauss-Legendre
rule keeps the rule's error below 5e-8 of the colour (``node_count``'s measurement, for
pieces this thin), and float32 arithmetic over a few dozen operations on values of order
1 adds a few 1e-7: 2e-6. The walk with and without lockstep takes the same segments in
the same order and integrates the light ones by rules that differ by that much, so a
pixel of up to a few hundred segments moves by at most ~1e-6 (measured: 3e-7 at 512x512
on the NASA meshes); 2e-6.
"""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Camera, Scene, TetMesh, TransferFunction
from dvr_gl.data import delaunay_ball, synthetic_tf
from dvr_gl.gl import capabilities, harness
from dvr_gl.gl.context import current
from dvr_gl.model.transfer import SegmentKnots
from dvr_gl.reference.linear_segment import linear_segment
from dvr_gl.techniques import tetra

from test_tetra import SIX, TF, VIEWS, cube_mesh
from test_tetra_walk import _bluntfin, walk

LIGHT_TOL = 2e-6
ERT_ALPHA = 1.0 - 2.0 ** -20     # walk.frag's

RAMP = TransferFunction([(0.0, 0.1, 0.2, 0.9), (0.5, 0.2, 0.9, 0.3), (1.0, 0.9, 0.2, 0.1)],
                        [(0.0, 0.0), (0.4, 0.2), (0.6, 0.7), (1.0, 0.3)], unit_distance=0.25)
# twelve knots: more than the light path unrolls (KNOT_CAPACITY 16: its binary search)
MANY = TransferFunction([(0.0, 0.2, 0.2, 0.8), (1.0, 0.8, 0.3, 0.2)],
                        [(float(x), 0.05 + 0.4 * abs(np.sin(3 * x))) for x in np.linspace(0.0, 1.0, 12)],
                        unit_distance=0.05)
# a knot of opacity 1: pieces reaching it end the ray (never light)
OPAQUE = TransferFunction([(0.0, 0.3, 0.3, 0.9), (1.0, 0.9, 0.3, 0.3)], [(0.0, 0.0), (0.7, 0.4), (1.0, 1.0)],
                          unit_distance=0.5)
# a steep, dense band among faint values: runs of segments that are not light, between light
# ones (each waits in the outer loop's pending slot, a second in its held one)
STEEP = TransferFunction([(0.0, 0.2, 0.4, 0.9), (1.0, 0.9, 0.5, 0.1)],
                         [(0.0, 0.02), (0.45, 0.05), (0.5, 0.95), (0.55, 0.05), (1.0, 0.3)], unit_distance=0.3)

# steep, nearly opaque bands in a dense field: rays that turn opaque with segments waiting
DENSE_STEEP = TransferFunction([(0.0, 0.2, 0.4, 0.9), (1.0, 0.9, 0.5, 0.1)],
                               [(0.0, 0.3), (0.3, 0.35), (0.33, 0.98), (0.36, 0.35), (0.6, 0.4), (0.63, 0.99),
                                (0.66, 0.4), (1.0, 0.5)], unit_distance=0.05)


def _light_segments(renderer, tf, sf, sb, length):
    """(light, premultiplied rgba) of lightSegment on the GPU, one row a segment."""
    knots = SegmentKnots(tf)
    capacity = tetra.knot_capacity(knots.count)
    rows = knots.texture_rows()
    uniforms = {"u_knot_count": knots.count, "u_inv_unit": float(knots.inv_unit)}
    for name, row in (("u_knot_color", rows[0]), ("u_knot_opacity", rows[1])):
        padded = np.zeros((capacity, 4), np.float32)
        padded[:len(row)] = row
        uniforms[name] = [tuple(map(float, r)) for r in padded]
    inputs = np.stack([sf, sb, length, np.zeros_like(sf)], axis=1)
    out = harness.evaluate(renderer.ctx, ["common/linear_segment.glsl"],
                           "bool light; vec4 v = lightSegment(in0.x, in0.y, in0.z, light); "
                           "out0 = light ? v : vec4(-1.0);",
                           [inputs], uniforms=uniforms, defines={"KNOT_CAPACITY": capacity})
    return out[:, 0] >= 0.0, out


@pytest.mark.parametrize("tf", [RAMP, MANY, OPAQUE], ids=["ramp", "twelve-knots", "opacity-one"])
def test_light_segments_are_the_exact_integral(renderer, tf):
    """Random segments, short to long, in every interval and across knots: those
    lightSegment takes are the float64 integral within LIGHT_TOL; it takes every
    one-piece segment well inside its limits, and segments across knots too (piece by
    piece), but none that reaches opacity 1."""
    rng = np.random.default_rng(5)
    n = 4000
    sf = rng.uniform(-0.1, 1.1, n)
    sb = sf + rng.normal(0.0, 0.05, n) * rng.choice([0.1, 1.0, 4.0], n)
    length = rng.uniform(0.0, 0.2, n) * rng.choice([0.05, 1.0], n) + 1e-4
    light, got = _light_segments(renderer, tf, sf, sb, length)
    want = linear_segment(SegmentKnots(tf), sf, sb, length)
    assert np.abs(got[light] - want[light]).max() < LIGHT_TOL

    # the rule for one piece, in float64: clear, or od and |r| at most 0.3 and not opaque
    knots = SegmentKnots(tf)
    lo, hi = np.minimum(sf, sb), np.maximum(sf, sb)
    inside = ((knots.s[None, :] > lo[:, None]) & (knots.s[None, :] < hi[:, None])).any(axis=1)
    up = sb >= sf
    j = np.where(up, np.searchsorted(knots.s, sf, side="right"), np.searchsorted(knots.s, sf, side="left")) - 1
    _, aa, wa = knots.at(j, sf)
    _, ab, wb = knots.at(j, sb)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (wb - wa) / wa
        mean_log = np.where(np.abs(r) < 1e-8, r / 2, (1 + r) * np.log1p(r) / r - 1)
        od = length * knots.inv_unit * (-np.log(wa) - mean_log)
    clearly_light = ~inside & (wb > 1e-3) & (np.abs(r) < 0.29) & (od < 0.29)
    clearly_light |= ~inside & (aa <= 0) & (ab <= 0)
    assert light[clearly_light].all()
    assert (light & inside).any()                               # across knots, piece by piece
    assert light.mean() > 0.3 and (~light).mean() > 0.1        # both ways are exercised
    opaque = knots.alpha >= 1.0
    if opaque.any():
        reaches = ((knots.s[opaque][None, :] >= lo[:, None]) & (knots.s[opaque][None, :] <= hi[:, None])).any(axis=1)
        assert reaches.any() and not light[reaches & (length > 0)].any()


def test_llvmpipe_runs_its_lanes_in_lockstep(renderer):
    """The probe says lockstep on llvmpipe (whose untaken branches cost as taken ones)."""
    with current(renderer.ctx):
        name = renderer.ctx.info["GL_RENDERER"]
    if "llvmpipe" not in name:
        pytest.skip(f"not llvmpipe: {name}")
    assert capabilities.lockstep_lanes(renderer.ctx)
    assert renderer.programs.context_defines["LOCKSTEP_LANES"] == 1


@pytest.fixture(scope="module")
def lockstep_renderers():
    """Two renderers, the walk built with LOCKSTEP_LANES 0 and 1 whatever the GL is."""
    made = {}
    for lockstep in (0, 1):
        r = dvr_gl.Renderer()
        r.programs.context_defines["LOCKSTEP_LANES"] = lockstep
        made[lockstep] = r
    yield made
    for r in made.values():
        r.release()


def _scenes():
    ball = delaunay_ball()
    yield "ball", Scene(ball, synthetic_tf(), dvr_gl.default_camera(ball, azimuth=30, elevation=20), 64, 64)
    cube = cube_mesh(SIX)
    flat = TetMesh(np.vstack([cube.points, [[0.5, 0.25, 0.0]]]), np.vstack([cube.tets, [[0, 1, 3, 8]]]),
                   np.concatenate([cube.scalars, [0.5]]))
    yield "flat cell", Scene(flat, TF, VIEWS["perspective"], 40, 40)
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.2, 0.25, 0.3]], float)
    folded = TetMesh(pts, np.array([[0, 1, 2, 3], [1, 2, 3, 4]]), np.array([0.1, 0.9, 0.4, 0.6, 0.5]))
    yield "folded pair", Scene(folded, RAMP, Camera((2.0, 1.5, 1.8), (0.3, 0.3, 0.3), fov=35), 40, 40)
    yield "opaque knot", Scene(ball, OPAQUE, dvr_gl.default_camera(ball, azimuth=60, elevation=10), 48, 48)
    yield "steep band", Scene(ball, STEEP, dvr_gl.default_camera(ball, azimuth=10, elevation=40), 48, 48)


@pytest.mark.parametrize("name", ["ball", "flat cell", "folded pair", "opaque knot", "steep band"])
def test_lockstep_walk_is_the_same_image(lockstep_renderers, name):
    """The walk built for lockstep lanes (light segments inline, the rest and the rare
    steps in the outer loop) and without: the same image within 2e-6, no guard reached."""
    scene = dict(_scenes())[name]
    images = {}
    for lockstep, r in lockstep_renderers.items():
        img, plan = walk(r, scene)
        assert dvr_gl.techniques.tetra_walk.walk_counts(r, plan)[1] == 0
        images[lockstep] = img
    assert images[1][..., 3].max() > 0.1
    assert np.abs(images[1] - images[0]).max() < 2e-6


def test_lockstep_walk_on_the_blunt_fin(lockstep_renderers):
    """NASA's blunt fin (zero-volume cells, two layers, light and other segments mixed):
    the same image either way within 2e-6."""
    mesh, tf = _bluntfin()
    scene = Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=30, elevation=20), 64, 64)
    a = walk(lockstep_renderers[0], scene)[0]
    b = walk(lockstep_renderers[1], scene)[0]
    assert b[..., 3].max() > 0.2
    assert np.abs(a - b).max() < 2e-6


@pytest.mark.parametrize("view", [(10, 40), (75, -15)])
def test_a_pixel_does_not_depend_on_its_neighbours(view):
    """With lanes in lockstep a group of pixels goes to the outer loop for one pixel's
    segment, and the others' waiting segments are integrated there too; each pixel must
    still add its segments in the same order and stop at the same one (turning opaque
    with a segment waiting included). Tiles of 19 pixels (groups cut at other places) and
    the compute stage (groups of another shape, llvmpipe: the same code) give the whole
    render's pixels bit for bit; rays that turn opaque are many."""
    ball = delaunay_ball()
    scene = Scene(ball, DENSE_STEEP, dvr_gl.default_camera(ball, azimuth=view[0], elevation=view[1]), 48, 48)
    with dvr_gl.Renderer() as whole, dvr_gl.Renderer(max_tile=19) as tiled:
        for r in (whole, tiled):
            r.programs.context_defines["LOCKSTEP_LANES"] = 1
        img = whole.render(scene, "tetra", sort="walk", stage="fragment")
        assert (img[..., 3] >= ERT_ALPHA - 1e-6).sum() > 300
        assert np.array_equal(tiled.render(scene, "tetra", sort="walk", stage="fragment"), img)
        with current(whole.ctx):
            llvmpipe = "llvmpipe" in whole.ctx.info["GL_RENDERER"]
        if llvmpipe:
            assert np.array_equal(whole.render(scene, "tetra", sort="walk", stage="compute"), img)
