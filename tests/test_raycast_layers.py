"""Ray casting several volumes (Scene.layers): GL against its NumPy twin, the one-volume
path untouched, convergence to the exact image, and the options it refuses."""

import numpy as np
import pytest

import dvr_gl
from dvr_gl import data, metrics, reference
from dvr_gl.data.phantoms import marschner_lobb
from dvr_gl.model.layers import Extent, LabelColors, Layer, channel_layers, union_bounds
from dvr_gl.reference import raycast_layers as twin
from dvr_gl.techniques import raycast, raycast_layers

U32 = 2.0 ** -24


def rotation(axis, degrees):
    """The 3x3 rotation by ``degrees`` about ``axis`` (Rodrigues)."""
    a = np.radians(degrees)
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def placed(axis, degrees, translation):
    m = np.eye(4)
    m[:3, :3] = rotation(axis, degrees)
    m[:3, 3] = translation
    return m


def head_and_field(size, blend="mix", **kwargs):
    """The CT head (3.2 x 3.2 x 1.5 mm) and a Marschner-Lobb field on a 3 mm grid, turned
    35 degrees about (1, 1, 0) and moved into the head: two grids that overlap."""
    field = dvr_gl.Volume(marschner_lobb(25).data, spacing=(3.0, 3.0, 3.0))
    tf = dvr_gl.TransferFunction(color=[(0.0, 0.1, 0.3, 1.0), (1.0, 0.2, 1.0, 0.4)],
                                 opacity=[(0.35, 0.0), (0.5, 0.25), (0.65, 0.0)], unit_distance=1.5)
    layers = [Layer(data.ct_head(), data.ct_head_tf()), Layer(field, tf, placed((1, 1, 0), 35, (60.0, 40.0, 30.0)))]
    camera = dvr_gl.default_camera(Extent(union_bounds(layers)), azimuth=30, elevation=20)
    return dvr_gl.Scene.from_layers(layers, camera=camera, width=size, height=size, blend=blend, **kwargs)


def three_channels(n=40):
    """(3, n, n, n) float32 on [0, 63]^3: the tilted torus and blobs of ``data.synthetic``,
    a rod along a diagonal, and three blobs; and the spacing."""
    axis = np.linspace(0.0, 63.0, n)
    z, y, x = np.meshgrid(axis, axis, axis, indexing="ij")
    torus = data.synthetic_field(x, y, z)
    p = np.stack([x, y, z], axis=-1) - 31.5
    along = p @ (np.array([1.0, -1.0, 0.5]) / 1.5)
    rod = np.exp(-((p * p).sum(axis=-1) - along ** 2) / (2 * 3.0 ** 2))
    blobs = sum(np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / (2 * 5.0 ** 2))
                for cx, cy, cz in ((20, 30, 40), (40, 25, 25), (30, 45, 30)))
    return np.stack([torus, rod, blobs]).astype(np.float32), 63.0 / (n - 1)


def channels_scene(size, blend="add", **kwargs):
    """Three channels of one grid, magenta, green and cyan (``channel_layers``)."""
    channels, h = three_channels()
    layers = channel_layers(channels, spacing=(h, h, h), max_opacity=0.25)
    camera = dvr_gl.default_camera(layers[0].volume, azimuth=40, elevation=25)
    return dvr_gl.Scene.from_layers(layers, camera=camera, width=size, height=size, blend=blend, **kwargs)


def head_labels():
    """Labels on every second sample of the head: 1 at the skin's boundary, 2 in bone.
    An odd count per axis: the midpoint of the stretch from a face to the opposite one
    (an odd segment count's middle midpoint) is then on a sample plane, not on a
    half-index plane where rounding picks the label (the twin's ties)."""
    head = data.ct_head()
    v = head.values(np.float64)[::2, :61:2, :61:2]
    labels = np.zeros(v.shape, np.uint8)
    labels[(v > 500) & (v < 950)] = 1
    labels[v > 1250] = 2
    return dvr_gl.Volume(labels, spacing=tuple(2 * s for s in head.spacing))


LABEL_COLORS = LabelColors({1: (1.0, 0.6, 0.3, 0.01), 2: (0.2, 0.6, 1.0, 0.04)}, unit_distance=1.5)


def scan_and_labels(size, blend="mix", colors=LABEL_COLORS, **kwargs):
    """The head in grey and a segmentation of it on a coarser grid, turned 20 degrees
    about an axis oblique to the view (few rays run from a face of the label box to the
    opposite one, where equal segments put midpoints on half-index planes by construction)."""
    tf = dvr_gl.TransferFunction(color=[(0.0, 0.6, 0.6, 0.6), (3000.0, 1.0, 1.0, 1.0)],
                                 opacity=[(400.0, 0.0), (1500.0, 0.03), (3000.0, 0.08)], unit_distance=1.5)
    layers = [Layer(data.ct_head(), tf), Layer(head_labels(), colors, placed((1, 0.3, 0.2), 20, (12.0, -8.0, 0.7)))]
    camera = dvr_gl.Camera((100.0, -380.0, 60.0), (100.0, 100.0, 70.0), up=(0, 0, -1), fov=35)
    return dvr_gl.Scene.from_layers(layers, camera=camera, width=size, height=size, blend=blend, **kwargs)


def sample_bounds(plan):
    """A bound on one sample's float32 error in the shader, per layer, for the twin's
    ``audit["sample_bound"]``: (layer, index coordinates, values, segment lengths) ->
    bounds. Summed over a pixel's samples it bounds |GL - twin| there, as
    ``test_raycast.derived_tolerance`` bounds one volume's, with the local gradient and
    table slope in place of their largest values.

    Positions: the cuts (each layer's box in its own frame), a stretch's equal segments and
    the midpoints in each frame carry a few units of rounding, 8 u R (R: the eye's distance
    from the box plus the union box's diagonal, the largest coordinate met), and the texel
    position 4 u n spacings; they move a scan's value by at most G times that, G a bound on
    the trilinear field's gradient over the sample's cell and its neighbours
    (``raycast.gradient_bounds``); the trilinear arithmetic adds 16 u max|v|. The table
    index carries 2 u (entries); classification turns a value error into at most the
    steepest table slope within reach of the value. A label's class is read exactly (its
    ties with rounding are the twin's ``ties``, counted apart). Opacity correction and
    compositing: 64 u per sample and per segment. A segment's opacity and colour,
    ``1 - exp(-h sum tau_i)`` and ``sum c_i tau_i / sum tau_i`` times it, change with a
    layer's alpha by at most ``2 h / (u (1 - alpha))`` times alpha's error (tau = -log(1 -
    alpha) / u), or by it. Errors add over a ray's segments (transmittance <= 1) and over
    the layers."""
    from scipy.ndimage import maximum_filter1d
    scene = plan.scene
    lo, hi = (np.asarray(b, np.float64) for b in scene.bounds)
    reach = float(np.linalg.norm(scene.camera.eye - lo)) + float(np.linalg.norm(hi - lo))
    layers = []
    for layer, table in zip(plan.layers, plan.tables):
        volume, unit = layer.volume, layer.tf.unit_distance
        if layer.is_labels:
            a_max = min(float(table.table[:, 3].max()), 1 - 1e-6)
            layers.append((unit, None, np.full(2, a_max)))
            continue
        cells = raycast.gradient_bounds(volume, radius=1).astype(np.float64)
        position = 8 * U32 * reach + 4 * U32 * float(volume.dims.max()) * float(max(volume.spacing))
        v_max = float(np.abs(volume.values(np.float64)).max())
        worst = float(cells.max()) * position + 16 * U32 * v_max
        rows = table.table.astype(np.float64)
        window = 2 * (int(np.ceil(worst * table.scale)) + 1) + 1
        slope = maximum_filter1d(np.abs(np.diff(rows, axis=0)).max(axis=1) * table.scale, window, mode="nearest")
        alpha = np.minimum(maximum_filter1d(rows[:, 3], window, mode="nearest"), 1 - 1e-6)
        layers.append((unit, (cells, position, v_max, slope, table), alpha))

    def bound(i, x, s, h):
        unit, scan, alpha = layers[i]
        if scan is None:
            return 64 * U32 * np.maximum(1.0, 2 * h / (unit * (1 - alpha[0]))) + 64 * U32
        cells, position, v_max, slope, table = scan
        cell = np.clip(np.floor(x).astype(np.int64), 0, np.array(cells.shape[::-1]) - 1)
        value_err = cells[cell[:, 2], cell[:, 1], cell[:, 0]] * position + 16 * U32 * v_max
        u = np.clip((s - table.lo) * table.scale, 0, table.size - 1)
        entry = np.minimum(np.floor(u).astype(np.int64), table.size - 2)
        per_sample = slope[entry] * value_err + 2 * U32 * table.size * slope[entry] / table.scale + 64 * U32
        return per_sample * np.maximum(1.0, 2 * h / (unit * (1 - alpha[entry]))) + 64 * U32
    return bound


def compare(renderer, scene, excluded=None, extra=0.0, **opts):
    """GL and twin images, the largest error over the pixels compared in units of their
    bound, and the bound per pixel (``sample_bounds``, plus ``extra``; mip, minip and
    average classify one value per layer, its bound four times the largest sample's).
    Pixels with ties (the twin's ``audit``) and ``excluded`` ones are left out; ties must
    be few."""
    opts.setdefault("ert_transmittance", 0.0)
    plan = raycast.make_plan(scene, **opts)
    assert isinstance(plan, raycast_layers.LayersPlan)
    audit = {"sample_bound": sample_bounds(plan)}
    ref = twin.render_plan(plan, audit=audit)
    gl = renderer.render(scene, **opts)
    assert gl.shape == ref.shape
    assert ref[..., 3].max() > 0.2, "the scene must show something"
    assert audit["ties"].sum() <= 0.02 * audit["ties"].size, audit["ties"].sum()
    skip = audit["ties"] if excluded is None else audit["ties"] | excluded
    bound = audit["bound"] * (4 if scene.mode in ("mip", "minip", "average") else 1) + extra
    error = np.abs(gl - ref).max(axis=-1)
    # (a pixel without samples has bound 0 and must be exactly 0)
    ratio = np.divide(error, bound, out=np.where(error > 0, np.inf, 0.0), where=bound > 0)
    worst = np.where(skip, 0.0, ratio).max()
    return gl, ref, worst, bound


@pytest.mark.parametrize("blend", ["mix", "add"])
def test_overlapping_grids_one_rotated_match_the_twin(renderer, blend):
    scene = head_and_field(40, blend)
    gl, ref, worst, _ = compare(renderer, scene, step=1.5)
    assert worst <= 1, worst
    head_alone = renderer.render(scene.replace(layers=()), step=1.5, ert_transmittance=0.0)
    assert metrics.max_abs_error(gl, head_alone) > 0.1       # the field shows


@pytest.mark.parametrize("camera", ["ortho", "eye_inside"])
def test_orthographic_and_inside_cameras_match_the_twin(renderer, camera):
    """The rays start on the plane through the eye (orthographic), or at an eye inside the
    boxes (the proxy is then one full-screen triangle)."""
    scene = head_and_field(32, "mix")
    lo, hi = (np.asarray(b) for b in scene.bounds)
    centre = (lo + hi) / 2
    cams = {"ortho": dvr_gl.default_camera(Extent(scene.bounds), azimuth=-20, elevation=10, ortho=True),
            "eye_inside": dvr_gl.Camera(centre + [10.0, -5.0, 8.0], centre + [60.0, 20.0, 0.0], fov=70)}
    _, _, worst, _ = compare(renderer, scene.replace(camera=cams[camera]), step=1.5)
    assert worst <= 1, worst


def test_eight_fetch_trilinear_path_matches_the_twin():
    """Where the texture unit's filter weights are quantised (GPUs) scans are read by eight
    texel fetches, as the one-volume ray caster does: that path, forced on this context,
    meets the same bound."""
    scene = head_and_field(32, "add")
    with dvr_gl.Renderer() as fetching:
        fetching.programs._context_defines = {"TEXTURE_FILTER_EXACT": 0}
        _, _, worst, _ = compare(fetching, scene, step=1.5)
        source = [fs for (_, fs) in fetching.programs.sources.values() if "t_layer0" in fs]
    assert source and all("#define TEXTURE_FILTER_EXACT 0" in fs for fs in source)
    assert worst <= 1, worst


def test_tiles_give_the_whole_image(renderer):
    """An image rendered in tiles (each its own target and tile origin) is the whole one."""
    scene = scan_and_labels(48, "add")
    with dvr_gl.Renderer(max_tile=20) as tiled:
        assert np.array_equal(tiled.render(scene, step=1.5), renderer.render(scene, step=1.5))


@pytest.mark.parametrize("blend, mode", [("mix", "composite"), ("add", "composite"), ("add", "mip"),
                                         ("add", "average")])
def test_three_channels_match_the_twin(renderer, blend, mode):
    scene = channels_scene(40, blend, mode=mode)
    _, _, worst, _ = compare(renderer, scene)
    assert worst <= 1, worst


@pytest.mark.parametrize("blend", ["mix", "add"])
def test_scan_and_labels_match_the_twin(renderer, blend):
    scene = scan_and_labels(40, blend)
    gl, _, worst, _ = compare(renderer, scene, step=1.5)
    assert worst <= 1, worst
    scan_alone = renderer.render(scene.replace(layers=()), step=1.5, ert_transmittance=0.0)
    assert metrics.max_abs_error(gl, scan_alone) > 0.05        # the labels' colours are there


def test_an_opaque_label_ends_the_ray_with_its_colour(renderer):
    """Bone opaque (alpha 1): mixed, every ray that reaches it stops there with A = 1."""
    colors = LabelColors({2: (0.2, 0.6, 1.0, 1.0)}, unit_distance=1.5)
    scene = scan_and_labels(32, "mix", colors=colors)
    gl, ref, worst, _ = compare(renderer, scene, step=1.5)
    assert worst <= 1, worst
    assert (ref[..., 3] == 1.0).sum() > 50 and np.array_equal(gl[..., 3] == 1.0, ref[..., 3] == 1.0)


def test_clip_plane_cuts_every_layer(renderer):
    scene = head_and_field(40, "mix")
    lo, hi = scene.bounds
    cut = scene.replace(clip_planes=[((lo + hi) / 2, (1.0, 0.4, -0.3))])
    gl, _, worst, _ = compare(renderer, cut, step=1.5)
    assert worst <= 1, worst
    whole = renderer.render(scene, step=1.5, ert_transmittance=0.0)
    assert metrics.max_abs_error(gl, whole) > 0.1


@pytest.mark.parametrize("blend", ["mix", "add"])
def test_a_surface_ends_every_layer(renderer, blend):
    """A sphere inside the head and the labels: the rays end at it, its colour behind the
    sum. Pixels whose coverage the rasteriser's snapping can change are left out
    (``test_geometry.coverage_and_reach``); elsewhere the ray's end moves as
    ``test_geometry.surface_tolerance`` derives for a rasterised surface: by the rounding
    of the window position its position is interpolated at (``window_rounding`` px:
    llvmpipe's float positions, or a GPU's sub-pixel grid), moving t by the ``spread`` over
    ``REACH`` px scaled down to it, and of the box-relative position and the dot product,
    8 u (t + |eye| + diagonal); that changes a pixel by at most ``end_rate`` per unit
    length per layer."""
    from test_geometry import REACH, coverage_and_reach, icosphere
    from test_geometry_splat import window_rounding
    scene = scan_and_labels(40, blend)
    lo, hi = scene.bounds
    sphere = icosphere((lo + hi) / 2 + [0.0, -20.0, 0.0], 40.0, color=(0.9, 0.8, 0.2))
    scene = scene.replace(geometry=[sphere])
    ambiguous, hit, spread, t = coverage_and_reach(scene)
    plan = raycast.make_plan(scene, step=1.5, ert_transmittance=0.0)
    ka, kd, ks, _ = scene.phong
    lit = 0.9 * (ka + kd) + ks
    rate = (1 + lit) * sum(end_rate(plan, layer, table) for layer, table in zip(plan.layers, plan.tables))
    diag = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
    dt = (spread * window_rounding(renderer, scene) / REACH
          + 8 * U32 * (np.where(np.isfinite(t), t, 0) + float(np.linalg.norm(scene.camera.eye - lo)) + diag))
    gl, ref, worst, _ = compare(renderer, scene, excluded=ambiguous, extra=rate * dt, step=1.5)
    assert hit.sum() > 100 and ambiguous.sum() < 0.2 * hit.sum()
    assert worst <= 1, worst
    assert np.all(gl[hit & ~ambiguous, 3] == 1.0)


def end_rate(plan, layer, table):
    """How fast a pixel changes with its ray's end per unit length, for one layer: the last
    segment's opacity (tau_max) and its midpoint, which moves by half as much and moves a
    scan's value by G/2 per unit (G its largest gradient bound), classified with the
    table's slope and corrected for the segment's length (as ``test_geometry``'s
    ``surface_tolerance``). A label moved across a half-index plane is one of the twin's ties."""
    rows = table.table.astype(np.float64)
    a_max = min(float(rows[:, 3].max()), 1 - 1e-6)
    rate = -np.log1p(-a_max) / layer.tf.unit_distance
    if not layer.is_labels:
        vol = layer.volume
        values = vol.values(np.float64)
        G = float(np.sqrt(sum((np.abs(np.diff(values, axis=2 - a)).max() / vol.spacing[a]) ** 2 for a in range(3))))
        slope = float(np.abs(np.diff(rows, axis=0)).max()) * table.scale
        rate += plan.step / layer.tf.unit_distance * slope * G / (2 * (1 - a_max))
    return rate


@pytest.mark.parametrize("blend", ["mix", "add"])
def test_one_volume_scene_keeps_the_one_volume_path(renderer, blend):
    """``Scene.from_layers`` with one layer is the plain scene (``layers=()``): the plain
    ray caster's plan and its image, bit for bit."""
    head = data.ct_head()
    camera = dvr_gl.default_camera(head, azimuth=30, elevation=20)
    single = dvr_gl.Scene.from_layers([Layer(head, data.ct_head_tf())], camera=camera, width=32, height=32,
                                      blend=blend)
    plain = dvr_gl.Scene(head, data.ct_head_tf(), camera, 32, 32)
    assert single.layers == () and single.digest() == plain.digest()
    plan = raycast.make_plan(single)
    assert isinstance(plan, raycast.RaycastPlan) and plan.defines == raycast.make_plan(plain).defines
    assert np.array_equal(renderer.render(single), renderer.render(plain))
    assert np.array_equal(reference.render(single, step=1.5), reference.render(plain, step=1.5))


def test_a_transparent_layer_changes_nothing_mixed_or_added(renderer):
    """With a second layer that never absorbs, mixing and adding are the same medium: the
    mixed colour ``sum c_i tau_i / sum tau_i`` is the first layer's, and ``1 - (1 - A_0)(1 - 0)``
    its opacity. GL's two paths agree within their float32 bounds, the twin's to 1e-12."""
    head = data.ct_head()
    clear = dvr_gl.TransferFunction(color=[(0.0, 1, 1, 1), (1.0, 1, 1, 1)], opacity=[(0.0, 0.0), (1.0, 0.0)])
    field = dvr_gl.Volume(marschner_lobb(9).data, spacing=(20.0, 20.0, 20.0))
    images = {}
    for blend in ("mix", "add"):
        scene = dvr_gl.Scene(head, data.ct_head_tf(), dvr_gl.default_camera(head, azimuth=30, elevation=20), 32, 32,
                             layers=[Layer(field, clear, placed((0, 1, 0), 20, (20.0, 10.0, 5.0)))], blend=blend)
        gl, ref, worst, bound = compare(renderer, scene, step=1.5)
        assert worst <= 1, worst
        images[blend] = gl, ref, bound
    assert np.all(np.abs(images["mix"][0] - images["add"][0]).max(axis=-1) <= images["mix"][2] + images["add"][2])
    assert metrics.max_abs_error(images["mix"][1], images["add"][1]) <= 1e-12


@pytest.mark.parametrize("make, blend", [(head_and_field, "mix"), (channels_scene, "add")])
def test_error_against_exact_falls_at_second_order(renderer, tmp_path, make, blend):
    """Midpoints of equal segments between every layer's entry and exit: second order as
    the step halves (from the finest layer's voxel to an eighth of it)."""
    scene = make(24, blend)
    exact = reference.exact(scene, cache_dir=tmp_path)
    voxel = min(layer.volume.min_spacing for layer in scene.all_layers)
    steps = voxel * np.array([1.0, 0.5, 0.25, 0.125])
    errors = np.array([metrics.rmse(renderer.render(scene, step=h, ert_transmittance=0.0), exact) for h in steps])
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert 1.7 < order < 2.6, (errors, order)


@pytest.mark.parametrize("options, message", [
    (dict(preintegrate=True), "preintegrate is not rendered for a scene with layers"),
    (dict(refine=4), "refine splits pre-integrated segments"),
    (dict(jitter_seed=3), "jitter_seed is not rendered for a scene with layers"),
    (dict(ert_transmittance=1.5), r"ert_transmittance must be in \[0, 1\)"),
    (dict(step=-1.0), "step must be positive"),
    (dict(target="rgb9"), "target must be one of"),
])
def test_unsupported_options_are_named_errors(renderer, options, message):
    scene = channels_scene(8)
    with pytest.raises(ValueError, match=message):
        renderer.render(scene, **options)
    with pytest.raises(ValueError, match=message):
        reference.render(scene, **options)


def test_masked_samples_in_a_layer_are_a_named_error(renderer):
    values = np.random.default_rng(1).random((8, 8, 8)).astype(np.float32)
    values[3, 4, 5] = np.nan
    masked = dvr_gl.Volume(values, mask_nonfinite=True)
    scene = channels_scene(8).replace(layers=[Layer(masked, dvr_gl.TransferFunction(
        color=[(0.0, 1, 1, 1), (1.0, 1, 1, 1)], opacity=[(0.0, 0.0), (1.0, 0.5)]))])
    with pytest.raises(ValueError, match="masked .non-finite. samples are rendered for one volume alone"):
        renderer.render(scene)


@pytest.mark.parametrize("technique", ["slice2d", "slice3d", "particles", "splat"])
def test_other_techniques_refuse_layers_by_name(renderer, technique):
    with pytest.raises(ValueError, match="a scene with layers .* is rendered by raycast"):
        renderer.render(channels_scene(8), technique)


def blocks_scene(size, blend):
    """Dense blocks that start one sample past a brick face (samples 10 to 22 of 33, bricks
    of 8 cells; the brick before is empty with its margin): a ray that skipped a segment
    too many past an empty brick, or started too late, would lose their front."""
    values = np.zeros((33, 33, 33), np.float32)
    values[10:23, 10:23, 10:23] = 1.0
    labels = np.zeros((25, 25, 25), np.uint8)
    labels[10:17, 10:17, 10:17] = 1
    tf = dvr_gl.TransferFunction(color=[(0.0, 1.0, 0.8, 0.2), (1.0, 1.0, 0.8, 0.2)],
                                 opacity=[(0.0, 0.0), (1.0, 0.6)], unit_distance=1.0)
    layers = [Layer(dvr_gl.Volume(values), tf),
              Layer(dvr_gl.Volume(labels, spacing=(1.5, 1.5, 1.5)), LabelColors({1: (0.1, 0.4, 1.0, 0.6)}),
                    placed((1, 2, 0.5), 30, (-6.0, 4.0, 2.0)))]
    camera = dvr_gl.default_camera(Extent(union_bounds(layers)), azimuth=25, elevation=15)
    return dvr_gl.Scene.from_layers(layers, camera=camera, width=size, height=size, blend=blend)


def skip_scenes():
    """The scenes above, dense blocks at brick faces, and the head and field seen
    orthographically and from inside."""
    scene = head_and_field(32, "mix")
    lo, hi = (np.asarray(b) for b in scene.bounds)
    centre = (lo + hi) / 2
    return [blocks_scene(48, "mix"), blocks_scene(48, "add"), head_and_field(40, "mix"), head_and_field(40, "add"),
            channels_scene(40, "add"),
            channels_scene(40, "mix"), scan_and_labels(40, "mix"), scan_and_labels(40, "add"),
            scan_and_labels(32, "mix", colors=LabelColors({2: (0.2, 0.6, 1.0, 1.0)}, unit_distance=1.5)),
            scene.replace(camera=dvr_gl.default_camera(Extent(scene.bounds), azimuth=-20, elevation=10, ortho=True)),
            scene.replace(camera=dvr_gl.Camera(centre + [10.0, -5.0, 8.0], centre + [60.0, 20.0, 0.0], fov=70))]


def test_empty_space_skipping_changes_no_bit(renderer):
    """Skipping bricks empty in every layer holding the ray (composite) gives the image
    rendered without it, bit for bit, at the default step and at one that puts midpoints
    elsewhere; the head's bricks of air are empty, so the skip is taken."""
    for scene in skip_scenes():
        plan = raycast_layers.make_plan(scene)
        if plan.occupancy is None:      # (the channels: every brick occupied, nothing to skip)
            assert "SKIP_EMPTY" not in plan.defines
        else:
            assert plan.defines["SKIP_EMPTY"] == 1 and len(plan.occupancy) == len(scene.all_layers)
        for step in (None, 1.3):
            on = renderer.render(scene, step=step)
            off = renderer.render(scene, step=step, skip_empty=False)
            assert np.array_equal(on, off), (scene.blend, step)
    assert not raycast_layers.make_plan(head_and_field(8)).occupancy[0].all()
    assert "SKIP_EMPTY" not in raycast_layers.make_plan(channels_scene(8, mode="mip")).defines


def test_label_bricks_are_empty_without_a_visible_label_nearby():
    """A label brick is occupied when a label with opacity lies among its samples or one
    beyond: a lone label at sample 8 (shared by bricks 0 and 1) or 9 (brick 0's margin)
    marks both, at 10 only brick 1, and a label without opacity none."""
    colors = LabelColors({2: (1.0, 1.0, 1.0, 0.5), 3: (1.0, 1.0, 1.0, 0.0)})
    for index, occupied in ((4, [0]), (8, [0, 1]), (9, [0, 1]), (10, [1])):
        labels = np.zeros((17, 17, 17), np.uint8)
        labels[index, 4, 4] = 2
        labels[4, 12, 12] = 3
        bricks = raycast_layers.label_occupancy(dvr_gl.Volume(labels), colors)
        expected = np.zeros((2, 2, 2), bool)
        expected[occupied, 0, 0] = True
        assert np.array_equal(bricks, expected), index
