"""Sort-last rendering on a Dask cluster (``dvr_gl.frontends.distributed``) against one
Renderer, on a two-worker LocalCluster of processes started once for the module.

Why the images agree, and by how much: the partials take the samples the single image
takes (the same bricks, segment grid and shader; one share is the single image bit for
bit), and the over operator is associative, so the only difference is float32 rounding
in the shader's front-to-back sums. One over step ``C + (1 - A) piece`` rounds three
times (1 - A, the product, the sum), each by at most U = 2^-24 of a result no larger than
CMAX (the largest colour, 1 for an unlit TF with colours in [0, 1]; opacity at most 1);
an error in a ray's opacity reaches its colour through the pieces behind, whose colours
sum to at most CMAX. So each image is within 3 U (1 + CMAX) per segment of exact
arithmetic on the same pieces; a ray has at most ``max_segments`` segments; the two
images are each that far from it, and the client's float64 composite is rounded to
float32 once (U more). A sample lost or doubled, or two slabs composited in the wrong
order, moves pixels by 1e-2 or more (checked below), far above these bounds (~1e-4).
"""

import os
import socket

import numpy as np
import pytest

import dvr_gl
from dvr_gl import data
from dvr_gl.frontends import distributed as dist
from dvr_gl.techniques import raycast

U = 2.0 ** -24
CMAX = 1.0
SIZE = 48
BRICK = 16


def over_bound(scene, step=None):
    segments = raycast.make_plan(scene, step).max_segments
    return 2 * 3 * U * (1 + CMAX) * segments + U


@pytest.fixture(scope="module")
def cluster():
    with dist.ClusterRenderer(workers=2, gl_threads=1) as renderer:
        yield renderer


@pytest.fixture(scope="module")
def single():
    with dvr_gl.Renderer() as renderer:
        yield renderer


def head_scene(**camera):
    head, tf = data.ct_head(), data.ct_head_tf()
    return dvr_gl.Scene(head, tf, dvr_gl.default_camera(head, **camera), width=SIZE, height=SIZE)


OBLIQUE = dict(azimuth=30.0, elevation=20.0)


def test_two_slabs_give_the_single_renderers_image(cluster, single):
    scene = head_scene(**OBLIQUE)
    expected = single.render(scene, "raycast", brick_size=BRICK, ert_transmittance=0.0)
    image = cluster.render(scene, brick_size=BRICK, ert_transmittance=0.0)
    assert image.dtype == np.float32 and image.shape == (SIZE, SIZE, 4)
    assert expected[..., 3].max() > 0.5                      # the head is there to compare
    assert cluster.last_frame.shares == 2
    assert np.abs(image - expected).max() <= over_bound(scene)
    # the check can fail: the same partials composited back to front are far off
    assert np.abs(image - expected).max() < 1e-2 < _reversed_composite_error(cluster, scene, expected)


def _reversed_composite_error(cluster, scene, expected):
    shares = dist.plan_shares(scene, BRICK, 1, 2)
    stub = _stub(scene)
    parts = [dist.render_share(stub, scene.volume, s, None, {"brick_size": BRICK, "ert_transmittance": 0.0})
             for s in dist.slab_order(scene, shares)]
    return np.abs(dist.composite(parts[::-1], SIZE, SIZE) - expected).max()


def _shipped(scene):
    import uuid
    return dist.Shipped(uuid.uuid4().hex, scene.volume)      # (as ClusterRenderer sends a volume)


def _stub(scene):
    import copy
    stub = copy.copy(scene)
    stub.volume = None
    return stub


def test_one_share_is_the_single_image_bit_for_bit(single):
    scene = head_scene(**OBLIQUE)
    expected = single.render(scene, "raycast", brick_size=BRICK)     # early termination on: one share ends rays alike
    shares = dist.plan_shares(scene, BRICK, 1, 1)
    assert len(shares) == 1
    part = dist.render_share(_stub(scene), _shipped(scene), shares[0], None, {"brick_size": BRICK})
    assert np.array_equal(dist.composite([part], SIZE, SIZE), expected)


def test_one_two_and_four_shares_agree(cluster):
    scene = head_scene(**OBLIQUE)
    images = {}
    for parts in (1, 2, 4):
        cluster.parts = parts
        try:
            images[parts] = cluster.render(scene, brick_size=BRICK, ert_transmittance=0.0)
        finally:
            cluster.parts = None
        assert cluster.last_frame.shares == parts
    bound = over_bound(scene)
    assert np.abs(images[2] - images[1]).max() <= bound
    assert np.abs(images[4] - images[1]).max() <= bound


@pytest.mark.parametrize("camera, parts", [(dict(azimuth=200.0, elevation=-30.0, ortho=True), 3),
                                           (dict(azimuth=10.0, elevation=5.0, zoom=6.0), 4)],
                         ids=["orthographic-from-behind", "eye-inside"])
def test_slab_order_and_windows_hold_for_other_views(cluster, single, camera, parts):
    scene = head_scene(**camera)
    expected = single.render(scene, "raycast", brick_size=BRICK, ert_transmittance=0.0)
    cluster.parts = parts
    try:
        image = cluster.render(scene, brick_size=BRICK, ert_transmittance=0.0)
    finally:
        cluster.parts = None
    assert expected[..., 3].max() > 0.1
    assert np.abs(image - expected).max() <= over_bound(scene)
    if camera.get("zoom", 1) > 1:      # inside the box: full-screen partials
        assert all(w == (0, 0, SIZE, SIZE) for w in cluster.last_frame.windows)


def test_early_ray_termination_moves_pixels_by_at_most_its_threshold(cluster, single):
    scene = head_scene(**OBLIQUE)
    ert = 1e-3
    expected = single.render(scene, "raycast", brick_size=BRICK, ert_transmittance=ert)
    image = cluster.render(scene, brick_size=BRICK, ert_transmittance=ert)
    assert np.abs(image - expected).max() <= ert + over_bound(scene)


def test_a_task_gives_the_same_partial_when_run_again():
    # what a retry after a worker's death does: the same arguments, maybe a fresh process
    scene = head_scene(**OBLIQUE)
    share = dist.plan_shares(scene, BRICK, 1, 2)[1]
    options = {"brick_size": BRICK}
    first = dist.render_share(_stub(scene), _shipped(scene), share, None, options)
    again = dist.render_share(_stub(scene), _shipped(scene), share, None, options)
    for renderer in dist._WORKER["renderers"].values():
        renderer.release()
    dist._WORKER["renderers"].clear()        # as in a new worker process
    fresh = dist.render_share(_stub(scene), _shipped(scene), share, None, options)
    assert first[0] == again[0] == fresh[0]
    assert np.array_equal(first[1], again[1]) and np.array_equal(first[1], fresh[1])
    assert first[1][..., 3].max() > 0.1


@pytest.mark.parametrize("mode", ["mip", "minip", "average"])
def test_modes_other_than_composite_are_named(cluster, mode):
    head, tf = data.ct_head(), data.ct_head_tf()
    scene = dvr_gl.Scene(head, tf, dvr_gl.default_camera(head), width=8, height=8, mode=mode)
    with pytest.raises(dist.DistributedModeError, match=f"mode '{mode}'"):
        cluster.render(scene, brick_size=BRICK)


def test_an_unreachable_scheduler_is_named():
    with socket.socket() as s:          # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    with pytest.raises(dist.SchedulerUnreachable, match=address.replace(".", r"\.")) as info:
        dist.ClusterRenderer(scheduler=address, connect_timeout=1.0)
    assert info.value.address == address


def test_a_brick_that_cannot_be_read_is_named(cluster, tmp_path):
    zarr = pytest.importorskip("zarr")
    from dvr_gl.formats import open_volume
    path = tmp_path / "ball.zarr"
    z, y, x = np.mgrid[0:40, 0:40, 0:40]
    samples = (255 - np.minimum(((x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2) // 2, 255)).astype(np.uint8)
    array = zarr.create_array(store=str(path), shape=samples.shape, chunks=(16, 16, 16), dtype="uint8")
    array[:] = samples
    chunk = path / "c" / "2" / "2" / "2"            # samples 32:40 on each axis
    assert chunk.exists()
    chunk.write_bytes(b"not a chunk")
    volume = open_volume(str(path))
    tf = dvr_gl.TransferFunction(color=[(0.0, 1.0, 1.0, 1.0)], opacity=[(0.0, 0.05), (255.0, 0.5)])
    scene = dvr_gl.Scene(volume, tf, dvr_gl.default_camera(volume), width=16, height=16)
    with pytest.raises(dist.BrickReadError) as info:
        cluster.render(scene, brick_size=BRICK, skip_empty=False)
    index, block = info.value.index, info.value.block
    assert str(index) in str(info.value)
    assert all(hi > 32 for hi in block[1::2])     # a brick whose samples meet the broken chunk
    assert block[0::2] == tuple(max(0, i * BRICK - 1) for i in index)


def test_cli_renders_on_a_cluster(cluster, single, tmp_path):
    from dvr_gl.frontends.cli import main
    base = ["render", "builtin:ct_head", "--size", "48", "--brick-size", "16", "--no-shading"]
    assert main(base + ["-o", str(tmp_path / "one.png")]) == 0
    assert main(base + ["-o", str(tmp_path / "many.png"), "--scheduler", cluster.cluster.scheduler_address]) == 0
    one, many = _png(tmp_path / "one.png"), _png(tmp_path / "many.png")
    # 8 bits: the images agree to ~1e-6 with early termination off (1e-3 on), under one level
    assert np.abs(one.astype(int) - many.astype(int)).max() <= 1
    assert main(base + ["-o", str(tmp_path / "bad.png"), "--workers", "0"]) == 2


def _png(path):
    from PIL import Image
    return np.asarray(Image.open(path))


def _die_once(marker, *args):
    """render_share, but the first attempt ends its worker process mid-task."""
    if not os.path.exists(marker):
        with open(marker, "w"):
            pass
        os._exit(1)
    return dist.render_share(*args)


def test_a_worker_that_dies_mid_frame_changes_nothing(cluster, tmp_path):
    # last in this file: the cluster's nanny starts a new worker process in its place
    import sys
    import cloudpickle
    cloudpickle.register_pickle_by_value(sys.modules[__name__])     # (the workers cannot import the tests)
    scene = head_scene(**OBLIQUE)
    options = {"brick_size": BRICK}
    expected = cluster.render(scene, **options)
    shares = dist.plan_shares(scene, BRICK, 1, 2)
    marker = tmp_path / "died"
    futures = [cluster.client.submit(_die_once if s.slab == 0 else dist.render_share,
                                     *((str(marker),) if s.slab == 0 else ()), _stub(scene), _shipped(scene), s, None,
                                     options, pure=False) for s in shares]
    parts = dict(zip([s.slab for s in shares], cluster.client.gather(futures)))
    assert marker.exists()                  # a worker did die in the middle of this frame
    image = dist.composite([parts[s.slab] for s in dist.slab_order(scene, shares)], SIZE, SIZE)
    assert np.array_equal(image, expected)
