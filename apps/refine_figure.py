"""The narrow-spike CT head pre-integrated at one voxel, refined, and exact, with their
error maps: what refinement where the transfer function has detail buys. Writes a PNG.

    LP_NUM_THREADS=2 python apps/refine_figure.py [--out docs/refine.png] [--size 256]
"""

import argparse
import os

import numpy as np

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.bench.common import datasets, figure_bytes
from dvr_gl.formats import atomic_write
from dvr_gl.rendering.tolerance import median_seconds

from tolerance_vs_vtk import narrow_spike

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(HERE, os.pardir, "docs", "refine.png"))
    p.add_argument("--size", type=int, default=256)
    args = p.parse_args(argv)
    _, volume, tf, camera = datasets(["head"])[0]
    volume, tf, camera = narrow_spike(volume, camera)
    scene = dvr_gl.Scene(volume, tf, camera, args.size, args.size)
    voxel = volume.min_spacing
    settings = [("pre-integrated, step 1 voxel", dict(step=voxel, preintegrate=True)),
                ("refined, step 2 voxels, 6 parts", dict(step=2 * voxel, preintegrate=True, refine=6))]
    exact = reference.exact(scene)
    panels = []
    with dvr_gl.Renderer() as gl:
        for label, options in settings:
            ms = 1e3 * median_seconds(lambda: gl.render(scene, **options))
            image = gl.render(scene, **options)
            panels.append((f"{label}\n{ms:.0f} ms (median of 5), RMSE {metrics.rmse(image, exact):.1e}", image))
    panels.append(("exact (float64)", exact))

    import matplotlib
    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure
    fig = Figure(figsize=(3.2 * len(panels), 6.6), constrained_layout=True)
    axes = fig.subplots(2, len(panels))
    for k, (label, image) in enumerate(panels):
        rgb = np.clip(np.asarray(image, np.float64)[..., :3], 0, 1)     # premultiplied, over black
        axes[0, k].imshow(rgb)
        axes[0, k].set_title(label, fontsize=9)
        err = np.abs(np.asarray(image, np.float64) - exact).max(axis=-1)
        axes[1, k].imshow(np.clip(err * 10, 0, 1), cmap="magma", vmin=0, vmax=1)
        axes[1, k].set_title("|error| x 10, any channel", fontsize=9)
        for ax in axes[:, k]:
            ax.set_axis_off()
    fig.suptitle(f"CT head, opacity spike 1 % of the range wide, {args.size}x{args.size}", fontsize=10)
    atomic_write(args.out, figure_bytes(fig))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
