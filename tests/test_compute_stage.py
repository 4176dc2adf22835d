"""The compute stage of the per-pixel ray shaders (``stage="compute"``: the ray caster's
and the cell walk's shader built as a compute shader, one invocation a pixel;
``techniques.gpu.pixel_stage``). It is the same GLSL as the fragment stage with only
the pixel's coordinate and the output's store changed (common/pixel_stage.glsl), so it
is held to the same bounds against the same references as the fragment stage, and on
llvmpipe, whose code generation is the same for both, to the fragment stage's image bit
for bit. ``stage="auto"`` takes compute only where the renderer measured it
``COMPUTE_MARGIN`` times faster (GPUs whose graphics pipeline reaches a few of their cores)."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import Scene, metrics, reference
from dvr_gl.gl.capabilities import COMPUTE_MARGIN, pixel_stage_times
from dvr_gl.gl.context import current
from dvr_gl.techniques import raycast, tetra

from test_raycast import MODES, TF, TF_LOW, VOLUME, cameras, derived_tolerance
from test_tetra import FIVE, GL_TOL, SIX, TF as TET_TF, VIEWS, closed_form_boxes, cube_mesh


def needs_compute(renderer):
    if renderer.ctx.version_code < 430:
        pytest.skip("this context has no compute shaders (OpenGL < 4.3)")


def is_llvmpipe(renderer):
    with current(renderer.ctx):
        return "llvmpipe" in renderer.ctx.info["GL_RENDERER"]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("camera", ["perspective", "ortho", "eye_inside", "eye_on_face_plane"])
def test_compute_ray_caster_matches_reference(renderer, mode, camera):
    """test_raycast's twin comparison, run in the compute stage: within the same derived bound."""
    needs_compute(renderer)
    scene = Scene(VOLUME, TF_LOW if mode == "minip" else TF, cameras(VOLUME)[camera], width=40, height=32,
                  mode=mode, iso_value=45.0 if mode == "isosurface" else None)
    opts = dict(step=0.7, ert_transmittance=0.0)
    gl = renderer.render(scene, stage="compute", **opts)
    ref = reference.render(scene, **opts)
    tol = derived_tolerance(raycast.make_plan(scene, **opts))
    assert ref[..., 3].max() > 0.05
    if mode == "isosurface":      # grazing rays may find the crossing in one arithmetic only
        assert (np.abs(gl - ref).max(axis=-1) > tol).sum() <= 2
    else:
        assert metrics.max_abs_error(gl, ref) <= tol


OPTIONS = [{}, dict(jitter_seed=5), dict(skip_empty=False, ert_transmittance=0.0), dict(preintegrate=True),
           dict(preintegrate=True, refine=4), dict(target="rgba16f"), dict(target="rgba8")]


@pytest.mark.parametrize("opts", OPTIONS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "defaults")
def test_compute_and_fragment_stages_agree(ctx, renderer, opts):
    """Skipping, early termination, jitter, pre-integration with refinement, low-precision
    targets, clipping and shading: the same image from both stages (bit for bit on
    llvmpipe; elsewhere each is within the twin's bound, so within twice it of the other)."""
    needs_compute(renderer)
    lit = Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=37, height=29, shading=True,
                clip_planes=[((14.0, 6.0, 14.0), (1.0, 0.3, 0.2))])
    for scene in (Scene(VOLUME, TF, cameras(VOLUME)["perspective"], width=37, height=29), lit):
        a = renderer.render(scene, stage="fragment", **opts)
        b = renderer.render(scene, stage="compute", **opts)
        assert b[..., 3].max() > 0.05
        if is_llvmpipe(renderer):
            assert np.array_equal(a, b)
        else:
            plan = raycast.make_plan(scene, **{k: v for k, v in opts.items() if k != "target"})
            assert np.abs(a - b).max() <= 2 * derived_tolerance(plan) + (2 / 255 if opts.get("target") else 0)


def test_compute_stage_in_tiles_is_the_whole_image(ctx, renderer):
    """Tiles (a window of the camera per target) give the one-target image in the compute stage."""
    needs_compute(renderer)
    scene = Scene(VOLUME, TF, cameras(VOLUME)["ortho"], width=45, height=38)
    whole = renderer.render(scene, stage="compute")
    tiled = dvr_gl.Renderer(max_tile=16).render(scene, stage="compute")
    assert np.array_equal(whole, tiled) if is_llvmpipe(renderer) else np.abs(whole - tiled).max() < 1e-5
    # render_target keeps GL's row order (the viewer draws it); render() reads rows stored top down
    with current(renderer.ctx):
        fbo = renderer.render_target(scene, stage="compute")
        assert np.array_equal(renderer.read_target(fbo, scene.width, scene.height), whole)


@pytest.mark.parametrize("split", ["five", "six"])
@pytest.mark.parametrize("view", ["body_diagonal", "eye_inside"])
def test_compute_walk_is_the_constant_box(ctx, renderer, split, view):
    """The cell walk in the compute stage through shared faces, edges and vertices: the
    constant cube's closed form within tetra's GL_TOL (test_tetra_walk's first case)."""
    needs_compute(renderer)
    scene = Scene(cube_mesh(FIVE if split == "five" else SIX), TET_TF, VIEWS[view], 49, 49)
    img = renderer.render(scene, "tetra", sort="walk", stage="compute")
    want = closed_form_boxes(scene, [((0, 0, 0), (1, 1, 1))])
    assert np.abs(img - want).max() < GL_TOL and img[..., 3].max() > 0.3
    frag = renderer.render(scene, "tetra", sort="walk", stage="fragment")
    if is_llvmpipe(renderer):
        assert np.array_equal(img, frag)
    # convex: one layer, and the pass that finds no entry ends the peeling (an occlusion
    # query that counted discarded fragments would peel on to the cap)
    plan = tetra.make_plan(scene, sort="walk", stage="compute", tables=renderer.tables)
    with current(renderer.ctx):
        tetra.draw(renderer, plan)
    assert plan.walk_passes == 1 and plan.walk_left == 0


def test_compute_walk_on_the_ball_matches_the_twin(renderer):
    needs_compute(renderer)
    from dvr_gl.data import delaunay_ball, synthetic_tf
    mesh = delaunay_ball()
    scene = Scene(mesh, synthetic_tf(), dvr_gl.default_camera(mesh, azimuth=40, elevation=25), 40, 36)
    img = renderer.render(scene, "tetra", sort="walk", stage="compute")
    ref = reference.render(scene, "tetra", sort="walk")
    assert img[..., 3].max() > 0.1 and np.abs(img - ref).max() < GL_TOL


def test_stage_probe_and_choice(ctx, renderer, monkeypatch):
    """The probe times both stages; llvmpipe runs fragment shaders at least as fast, so
    "auto" keeps the fragment stage there; the environment variable decides when set."""
    needs_compute(renderer)
    times = pixel_stage_times(renderer.ctx)
    assert set(times) == {"fragment", "compute"} and min(times.values()) > 0
    # the probe leaves the context clean: a new target after it raises no GL error (ctx)
    renderer.render(Scene(VOLUME, TF, cameras(VOLUME)["ortho"], width=9, height=7))
    if is_llvmpipe(renderer):
        assert times["fragment"] < COMPUTE_MARGIN * times["compute"]
        assert not renderer.compute_stage_faster
    monkeypatch.setenv("DVR_GL_PIXEL_STAGE", "compute")
    assert renderer.compute_stage_faster
    monkeypatch.setenv("DVR_GL_PIXEL_STAGE", "gpu")
    with pytest.raises(ValueError, match="DVR_GL_PIXEL_STAGE.*'gpu'"):
        renderer.compute_stage_faster


def test_a_bad_stage_is_named():
    scene = Scene(VOLUME, TF, cameras(VOLUME)["ortho"], width=8, height=8)
    with pytest.raises(ValueError, match="stage must be one of auto, fragment, compute, got 'vertex'"):
        raycast.make_plan(scene, stage="vertex")
    from dvr_gl.data import delaunay_ball, synthetic_tf
    mesh = delaunay_ball()
    with pytest.raises(ValueError, match="stage must be one of"):
        tetra.make_plan(Scene(mesh, synthetic_tf(), dvr_gl.default_camera(mesh), 8, 8), sort="walk", stage=3)


def test_several_volumes_in_the_compute_stage(ctx, renderer):
    """Layers (a second, rotated and shifted grid mixed in, and two channels added) in
    the compute stage: the fragment stage's image (bit for bit on llvmpipe). What layers
    do not take yet is named."""
    needs_compute(renderer)
    turn = np.radians(30)
    m = np.eye(4)
    m[:3, :3] = [[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]]
    m[:3, 3] = (4.0, 2.0, 1.0)
    cam = cameras(VOLUME)["perspective"]
    for blend in ("mix", "add"):
        scene = Scene.from_layers([dvr_gl.Layer(VOLUME, TF), dvr_gl.Layer(VOLUME, TF, m)], camera=cam,
                                  width=37, height=29, blend=blend)
        a = renderer.render(scene, stage="fragment")
        b = renderer.render(scene, stage="compute")
        assert b[..., 3].max() > 0.1
        if is_llvmpipe(renderer):
            assert np.array_equal(a, b)
        else:
            assert np.abs(a - b).max() < 1e-5
    with pytest.raises(ValueError, match="stage must be one of"):
        raycast.make_plan(scene, stage="vertex")
    with pytest.raises(ValueError, match=r"several volumes \(Scene.layers\) do not yet take interpolation='texture_unit'"):
        raycast.make_plan(scene, interpolation="texture_unit")
