"""
Particles and splatting
=======================

Two point-based techniques, on the bundled synthetic volume (a tilted torus around a
blob, 64 samples a side), beside the ray caster:

- ``particles`` (particle-based volume rendering) turns the field into opaque spheres
  whose density follows the transfer function and draws them with a depth test only.
  Each of ``repetitions`` independent particle sets gives a noisy picture; their average
  converges to the emission-absorption integral.
- ``splat`` gives every sample a reconstruction kernel and draws its footprint: the
  trilinear tent into image-aligned sheets classified after reconstruction (the
  default), or pre-classified Gaussian footprints (``kernel="gaussian"``).
"""

import matplotlib.pyplot as plt

import dvr_gl
from dvr_gl import data
from dvr_gl.formats import to_png_array

volume = data.synthetic()
scene = dvr_gl.Scene(volume, data.synthetic_tf(), dvr_gl.default_camera(volume, azimuth=30, elevation=20),
                     width=192, height=192)

with dvr_gl.Renderer() as renderer:
    images = {
        "particles, 1 set": renderer.render(scene, technique="particles", repetitions=1),
        "particles, 16 sets": renderer.render(scene, technique="particles", repetitions=16),
        "splat (tent)": renderer.render(scene, technique="splat"),
        "splat (gaussian)": renderer.render(scene, technique="splat", kernel="gaussian"),
        "raycast": renderer.render(scene, technique="raycast"),
    }

fig, axes = plt.subplots(1, len(images), figsize=(2.8 * len(images), 3.0))
for ax, (title, image) in zip(axes, images.items()):
    ax.imshow(to_png_array(image, background=(0, 0, 0)))
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
plt.show()

# %%
# Particle sets are made once per data set, transfer function, radius and seed and kept:
# turning the camera reuses them, and ``seed`` makes the picture reproducible.
