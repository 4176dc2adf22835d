"""The cell walk's layers of depth peeling after the first (``techniques.tetra_walk``,
``walk_entries``): a ray that leaves through the convex hull is done (it has nothing
left to enter), later layers draw only the boundary faces off the hull, and the
fragment stage walks in place, shading only the pixels that have an entry in the layer.
None of this may change an image: each is held bit for bit to the walk without it."""

import numpy as np

import dvr_gl
from dvr_gl import Camera, Scene
from dvr_gl.data import delaunay_ball
from dvr_gl.gl.context import current
from dvr_gl.model import mesh as M
from dvr_gl.techniques import tetra_walk
from dvr_gl.techniques.walk_entries import entries, first_entries

from test_tetra import TF, blocks_mesh, cube_mesh, FIVE
from test_tetra_walk import _ball, _bluntfin, walk

NOTCH = Camera((4.5, 3.5, 4.0), (1.0, 0.8, 0.5), fov=35)            # into the L's notch
BEHIND = Camera((9.5, 0.5, 6.5), (0.5, 0.5, 0.5), fov=20)           # along the line through both blocks
L_CELLS = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
TWO_BLOCKS = [(0, 0, 0), (3, 0, 2)]


def walk_state(renderer, plan):
    """(pixels, 4): the walk's state after the last draw (t of the last stop, >= 1e38:
    done; cells visited)."""
    with current(renderer.ctx):
        return np.frombuffer(plan.walk_state.read(), np.float32).reshape(-1, 4)


def on_hull_by_brute_force(mesh):
    """(M, 4) bool: the cell's local face is a boundary face with every point of the mesh
    on its cell's side of its plane (float64, every point tried)."""
    topo = M.topology(mesh)
    planes = topo.cell_planes()
    pts = mesh.points - mesh.bounds[0]
    nb = tetra_walk.neighbours(mesh)
    height = np.einsum("mkj,pj->mkp", planes[..., :3], pts) - planes[..., 3:]
    return (nb < 0) & (height.max(axis=2) <= 1e-9)


def test_hull_faces_are_coded_and_left_out_of_later_layers():
    """``neighbours(hull=True)`` codes HULL exactly across the boundary faces in a supporting
    plane of the mesh's points, -1 across the others; ``reentry_faces`` are the others'
    vertices in ``boundary_faces``; a convex mesh has none."""
    for cells in (L_CELLS, TWO_BLOCKS):
        mesh = blocks_mesh(cells)
        nb = tetra_walk.neighbours(mesh, hull=True)
        hull = on_hull_by_brute_force(mesh)
        assert hull.any() and ((nb < 0) & ~hull).any()
        assert np.array_equal(nb == tetra_walk.HULL, hull)
        assert np.array_equal(nb >= 0, tetra_walk.neighbours(mesh) >= 0)
        faces = tetra_walk.boundary_faces(mesh)
        slots = faces["slot"][tetra_walk.reentry_faces(mesh)].reshape(-1, 3)
        assert (slots == slots[:, :1]).all()         # whole faces, their three vertices
        assert sorted(slots[:, 0]) == sorted(np.flatnonzero(((nb < 0) & ~hull).reshape(-1)))
    assert len(tetra_walk.reentry_faces(cube_mesh(FIVE))) == 0


def test_a_ray_out_through_the_hull_is_done(renderer, monkeypatch):
    """The L seen from behind its corner: the rays that leave through the hull are done
    after their walk; those that leave into the notch are not (they might enter again).
    Without the hull's code every ray that left is still going on; the image is the same."""
    scene = Scene(blocks_mesh(L_CELLS), TF, Camera((-2.5, -2.0, 3.0), (1.0, 1.0, 0.5), fov=40), 48, 48)
    img, plan = walk(renderer, scene)
    state = walk_state(renderer, plan)
    walked = state[:, 2] > 0
    done = state[:, 0] >= 1e38
    assert (walked & done).sum() > 100 and (walked & ~done).sum() > 20
    plain = tetra_walk.neighbours
    monkeypatch.setattr(tetra_walk, "neighbours", lambda mesh, walked=None, hull=False: plain(mesh, walked))
    with dvr_gl.Renderer() as fresh:
        img_plain, plan_plain = walk(fresh, scene)
        state = walk_state(fresh, plan_plain)
    assert not (state[walked, 0] >= 1e38).any()      # none done: the TF never reaches opacity 1 here
    assert np.array_equal(img, img_plain)


def test_the_walk_in_place_is_the_walk_in_turn(monkeypatch):
    """The fragment stage's walk in place (image load/store, only the pixels with an
    entry shaded) and in two targets used in turn: the same images bit for bit and the
    same cells visited, pixel by pixel, over meshes of one layer and of several, mip,
    the eye inside the mesh, orthographic rays that start inside it, the blunt fin. The
    compute stage too, where the GL has it (llvmpipe: bit for bit). Each way draws the
    same entry passes (the first layer's in one draw by the depth test, none after the
    last ray left the mesh)."""
    ball = delaunay_ball()
    lo, hi = ball.bounds
    centre = (lo + hi) / 2
    mesh, tf = _bluntfin()
    scenes = [Scene(blocks_mesh(L_CELLS), TF, NOTCH, 40, 40), Scene(blocks_mesh(TWO_BLOCKS), TF, BEHIND, 40, 40),
              _ball(size=40), _ball(size=40).replace(mode="mip"),
              _ball(size=40).replace(camera=Camera(centre, centre + [0, 0, -5.0], fov=60)),
              _ball(size=40).replace(camera=Camera(centre, centre + [0, 0, -5.0], ortho_height=60.0)),
              Scene(mesh, tf, dvr_gl.default_camera(mesh, azimuth=30, elevation=20), 48, 48)]
    draws = []          # the entry passes drawn: (way, layer; "pick": the first layer's in one draw)
    monkeypatch.setattr(tetra_walk, "first_entries", lambda *a: draws.append((way, "pick")) or first_entries(*a))
    monkeypatch.setattr(tetra_walk, "entries", lambda *a: draws.append((way, a[10])) or entries(*a))
    results = {}
    with dvr_gl.Renderer() as renderer, current(renderer.ctx):
        compute = renderer.ctx.version_code >= 430 and "llvmpipe" in renderer.ctx.info["GL_RENDERER"]
    for way in ("in place", "in turn", "compute") if compute else ("in place", "in turn"):
        monkeypatch.setattr(tetra_walk, "IN_PLACE", way == "in place")
        with dvr_gl.Renderer() as renderer:
            results[way] = []
            for scene in scenes:
                img, plan = walk(renderer, scene, "compute" if way == "compute" else "fragment")
                results[way].append((img, tetra_walk.walk_counts(renderer, plan)[0], plan.walk_passes))
    layers = set()
    for way in results:
        for (a, steps_a, passes_a), (b, steps_b, passes_b) in zip(results["in place"], results[way]):
            assert a[..., 3].max() > 0.2
            assert np.array_equal(a, b) and np.array_equal(steps_a, steps_b) and passes_a == passes_b
            layers.add(passes_a)
    assert max(layers) >= 2
    for way in results:     # the same entry passes: none after the last ray left
        assert [d for w, d in draws if w == way] == [d for w, d in draws if w == "in place"]


def test_a_frame_draws_the_layers_the_last_one_had_entries_in(renderer):
    """Two blocks seen along the line through both (two layers), then a view into one
    (one layer): that frame draws the second layer without reading its count (and finds
    it empty), the next frame with that view only the first."""
    mesh = blocks_mesh(TWO_BLOCKS)
    _, first = walk(renderer, Scene(mesh, TF, BEHIND, 32, 32))
    _, second = walk(renderer, Scene(mesh, TF, NOTCH, 32, 32))
    _, third = walk(renderer, Scene(mesh, TF, NOTCH, 32, 32))
    assert (first.walk_passes, second.walk_passes, third.walk_passes) == (2, 2, 1)
