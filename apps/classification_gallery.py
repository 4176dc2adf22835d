"""The CT head under 1D and 2D transfer functions, each picture above its function drawn
over the (value, gradient magnitude) plane: docs/tf2d.png.

    python apps/classification_gallery.py [--out docs/tf2d.png] [--size 320]
"""

import argparse
import os

import numpy as np

import dvr_gl
from dvr_gl.bench.common import datasets
from dvr_gl.model.field import gradient_max
from dvr_gl.model.transfer2d import gradient_modulated, levoy_isocontours, levoy_region_boundaries, load_tf2d_json

HERE = os.path.dirname(os.path.abspath(__file__))


def functions(volume, tf):
    """(title, transfer function) for each panel."""
    lo, hi = volume.data_range
    g_range = (0.0, gradient_max(volume))
    return [
        ("1D (the bench TF)", tf),
        ("gradient-modulated\n(Levoy)", gradient_modulated(tf, g_range)),
        ("iso-contours: skin, bone\n(Levoy)", levoy_isocontours(
            [(1000, 2.0, (0.93, 0.72, 0.58), 0.3), (2300, 1.5, (1.0, 0.98, 0.9), 1.0)], (lo, hi), g_range,
            unit_distance=tf.unit_distance)),
        ("region boundaries\n(Levoy)", levoy_region_boundaries(
            [(400, (0.5, 0.3, 0.25), 0.0), (1000, (0.93, 0.72, 0.58), 0.5), (2300, (1.0, 0.98, 0.9), 1.0),
             (hi, (1.0, 1.0, 1.0), 1.0)], g_range, unit_distance=tf.unit_distance)),
        ("widgets (Kniss):\ndocs/tf/ct_skin_bone_2d.json", load_tf2d_json(
            os.path.join(HERE, os.pardir, "docs", "tf", "ct_skin_bone_2d.json"), (lo, hi), g_range)),
    ]


def table_image(tf, volume, n_v=256, n_g=96):
    """The function over (value, |g|), |g| upwards: its colour over dark grey with the
    opacity scaled to the function's largest (so faint functions show their shape)."""
    lo, hi = volume.data_range
    s = np.linspace(lo, hi, n_v)
    g = np.linspace(0.0, gradient_max(volume), n_g)
    S, G = np.meshgrid(s, g)
    if isinstance(tf, dvr_gl.TransferFunction2D):
        rgba, _ = tf.lookup(S, G)
    else:
        rgba = np.concatenate([tf.color(S), tf.opacity(S)[..., None]], axis=-1)
    a = rgba[..., 3:4] / max(float(rgba[..., 3].max()), 1e-12)
    return (rgba[..., :3] * a + 0.15 * (1 - a))[::-1]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=os.path.join(HERE, os.pardir, "docs", "tf2d.png"))
    p.add_argument("--size", type=int, default=320)
    args = p.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    (_, volume, tf, camera), = datasets(["head"])
    panels = functions(volume, tf)
    fig = Figure(figsize=(3.2 * len(panels), 5.4), constrained_layout=True)
    axes = fig.subplots(2, len(panels), height_ratios=[3.2, 1.4])
    with dvr_gl.Renderer() as renderer:
        for k, (title, f) in enumerate(panels):
            scene = dvr_gl.Scene(volume, f, camera, width=args.size, height=args.size, shading=True)
            img = renderer.render(scene, technique="raycast", step=0.5 * volume.min_spacing, gradients="texture")
            rgb = np.clip(img[..., :3] + (1 - img[..., 3:4]), 0, 1)
            axes[0, k].imshow(rgb)
            axes[0, k].set_title(title, fontsize=9)
            axes[0, k].axis("off")
            lo, hi = volume.data_range
            axes[1, k].imshow(table_image(f, volume), aspect="auto",
                              extent=(lo, hi, 0.0, gradient_max(volume)))
            axes[1, k].set_xlabel("value", fontsize=8)
            axes[1, k].set_ylabel("|gradient|", fontsize=8)
            axes[1, k].tick_params(labelsize=7)
    tmp = args.out + ".tmp.png"
    fig.savefig(tmp, dpi=100)
    os.replace(tmp, args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
